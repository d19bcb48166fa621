"""``uav_fusion evaluate``: flight folder -> estimator -> Table II, report folder."""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import Any

from uav_fusion.core.data import uav_class
from uav_fusion.core.errors import ConfigError
from uav_fusion.core.records import Flight, Measurement
from uav_fusion.core.scoring.evaluation import (
    Evaluation,
    Evaluator,
    feed_flight,
    feed_steps,
    format_table,
)
from uav_fusion.core.scoring.report import ReportFiles, write_report
from uav_fusion.core.site import Site, load_site
from uav_fusion.resources import DEFAULT_FLIGHT, data_path

HELP = "run the estimator on a flight folder and score it: Table II, metrics, figures"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "folder",
        nargs="?",
        help="flight folder in the Dataset-28 layout (default: the bundled default flight)",
    )
    parser.add_argument("--profile", default="paper",
                        help="estimator profile name or YAML path (default: paper)")
    parser.add_argument("--site", help="site YAML (default: the shipped Lake Wheeler site)")
    parser.add_argument("--out", help="report folder (default: out/evaluate/<flight name>)")
    parser.add_argument("--rf-file", default="AADM.csv",
                        help="RF CSV name inside the folder (default: AADM.csv)")
    parser.add_argument("--tolerance", type=float, default=1.0, metavar="S",
                        help="age limit of an estimate for the time coverage (default: 1 s)")
    parser.add_argument("--max-truth-gap", type=float, default=2.0, metavar="S",
                        help="longest truth gap interpolated across (default: 2 s)")
    parser.add_argument("--raw-min-uav-prob", type=float, default=None, metavar="P",
                        help="a radar track counts in the raw radar row when its mean "
                        "catProb[0] is at least P (default: the profile's "
                        "evaluation.raw_radar_min_mean_uav_prob, as radar_replay uses)")
    parser.add_argument("--strict", action="store_true",
                        help="stop at the first bad input row instead of skipping it")
    parser.add_argument("--no-figures", action="store_true", help="write tables only")


def evaluate_flight(
    flight: Flight,
    profile_name: str,
    site: Site,
    tolerance_s: float = 1.0,
    max_truth_gap_s: float = 2.0,
    raw_min_uav_prob: float | None = None,
    arrivals: Path | None = None,
) -> tuple[Evaluation, dict[str, str]]:
    """Run the estimator on ``flight`` and score every stage; returns (evaluation, run info).

    ``arrivals``: an arrival schedule (:mod:`uav_fusion.core.live.schedule`); the inputs are
    then fused in that order with zero wait, and the steps scored are those a live node
    published (each at its arrival), as its evaluator scores them.

    The raw radar row takes the reports of the tracks whose mean ``catProb[0]`` reaches
    ``raw_min_uav_prob``, or the profile's ``evaluation.raw_radar_min_mean_uav_prob`` when
    that is None (every report when both are None).
    """
    from uav_fusion.core import estimators as est

    profile = est.load_profile(profile_name)
    try:
        ev = Evaluator(
            radar_enu=site.radar.enu, tolerance_s=tolerance_s, max_truth_gap_s=max_truth_gap_s
        )
    except ValueError as exc:
        raise ConfigError(str(exc)) from None
    t_start = time.perf_counter()
    result = est.run_flight(flight, profile, site)
    steps: list[Any] = list(result.steps)
    if arrivals is not None:
        from uav_fusion.core.live.rewind import simulate
        from uav_fusion.core.live.schedule import read_schedule

        def make() -> Any:
            return est.make_estimator(profile, site, live=True)

        order = read_schedule(arrivals, make().flight_input(flight))
        steps = list(simulate(make, order)[2])
    elapsed = time.perf_counter() - t_start
    measurements: list[Measurement] = []
    for item in est.flight_measurements(flight, profile, site):
        if isinstance(item, list):
            measurements.extend(item)
        else:
            measurements.append(item)
    if raw_min_uav_prob is not None and not 0.0 <= raw_min_uav_prob <= 1.0:
        raise ConfigError(f"--raw-min-uav-prob must lie in [0, 1], got {raw_min_uav_prob}")
    raw_thr = (
        profile.raw_radar_min_mean_uav_prob if raw_min_uav_prob is None else raw_min_uav_prob
    )
    feed_flight(ev, flight, uav_class.uav_class_tracks(flight.radar, raw_thr))
    feed_steps(ev, steps, measurements)
    info = {
        "mode": "offline (uav_fusion evaluate)",
        "flight": f"{flight.name} ({flight.folder})" if flight.folder else flight.name,
        "profile": profile_name,
        "site": str(site.source or site.name),
        "filter run": f"{len(result.steps)} steps in {elapsed:.2f} s"
        + ("" if arrivals is None else f" (in the arrival order of {arrivals})"),
        "raw radar row": "every radar report"
        if raw_thr is None
        else f"reports of radar tracks with mean UAV class probability >= {raw_thr:g}",
    }
    for name, rep in sorted(flight.reports.items()):
        info[f"input {name}"] = rep.summary()
    return ev.evaluate(), info


def run(args: argparse.Namespace) -> int:
    from uav_fusion.core.data import load_flight

    site = load_site(args.site)
    folder = Path(args.folder) if args.folder else data_path(DEFAULT_FLIGHT)
    flight = load_flight(folder, site, rf_file=args.rf_file, strict=args.strict)
    ev, info = evaluate_flight(
        flight, args.profile, site, args.tolerance, args.max_truth_gap, args.raw_min_uav_prob
    )
    out = Path(args.out) if args.out else Path("out") / "evaluate" / flight.name
    files: ReportFiles = write_report(ev, out, site, info, figures=not args.no_figures)
    print(format_table(ev))
    if ev.dropped:
        print("dropped: " + ", ".join(f"{k}={v}" for k, v in sorted(ev.dropped.items())))
    print(f"report: {files.markdown}")
    return 0
