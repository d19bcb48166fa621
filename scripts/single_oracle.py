"""How well the single-UAV acceptance could be met if the tracker knew which radar report is
the UAV.

    python scripts/single_oracle.py [--definition accuracy] [--split tune] [--profile tracker]

The tracker issue asks, on every flight, for a position over at least 99 % of the epochs the
radar sees the UAV and for at most 1 % of them more than 100 m off. Every flight of a
benchmark definition's split is scored as ``uav_fusion bench`` scores it (the 10 Hz grid, the
radar-observable epochs from the twin's labels) twice:

* ``tracker``: the single-UAV tracker, as shipped (``bench.run.score_task``);
* ``oracle``: the label oracle of ``scripts/multi_oracle.py`` (the profile's filter, measurement
  models, robust update, gates and deleter, with association from the twin: only reports of
  radar tracks following the UAV, from the first one on, and every fix of its control link)
  with the single-UAV output rule (a track is published until ``max_coast_s`` after its last
  update, as ``grid_from_steps`` publishes the tracker's).

The oracle has none of the tracker's start-up wait (the radar classifier's prior) and never
follows another object, so what it still misses or gets wrong is what the sensors allow this
filter: epochs where the radar's tracks of the UAV are coasts only, and the radar's own report
errors (angle noise and glint at long range, its onboard tracker's lag after a turn).

For each gross epoch of the oracle the script also looks at the UAV's own radar reports of the
last ``--window-s`` (5 s; every report of a radar track then following the UAV, corrected for
the radar's misalignment as the filter takes it): when their median horizontal error is above
100 m, the sensor itself had the UAV more than 100 m off, and no association could have helped.

Printed: per flight, the observable coverage and gross share of both and how many of the
oracle's gross epochs had the radar's own reports that far off; then the pooled figures and
the number of flights meeting each target.
"""

from __future__ import annotations

import argparse
import math
import sys
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np
import numpy.typing as npt

from uav_fusion.core.bench.cache import read_labels
from uav_fusion.core.bench.definition import load_definition
from uav_fusion.core.bench.single import ScoreTask, score_task
from uav_fusion.core.estimators.grid import grid_from_published
from uav_fusion.core.estimators.multi import MultiSettings, run_multi
from uav_fusion.core.estimators.profile import load_profile
from uav_fusion.core.estimators.selection import frames_input
from uav_fusion.core.records import RadarFrame, RfAttempt
from uav_fusion.core.scoring.fixed_rate import (
    FlightTruth,
    GridSamples,
    epoch_errors,
    observable_epochs,
    pool,
    score_grid,
)
from uav_fusion.core.site import load_site
from uav_fusion.core.twin import radar_model
from uav_fusion.resources import DEFAULT_SITE, config_path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from multi_false_tracks import KindsByTrack, kind_at, labelled_flights
from multi_oracle import LabelOracle, vehicle_links

FloatArray = npt.NDArray[np.float64]


def _pct(num: int, den: int) -> float:
    return 100.0 * num / den if den > 0 else float("nan")


def uav_report_errors(
    stream: Sequence[RadarFrame | RfAttempt],
    kinds: KindsByTrack,
    uav_object: int,
    truth_t: FloatArray,
    truth_enu: FloatArray,
    align: Callable[[float, float, float], tuple[float, float, float]] | None,
) -> tuple[FloatArray, FloatArray]:
    """Times and horizontal errors (m) of every report of a radar track then following the
    UAV (twin object ``uav_object``), after ``align`` (the misalignment correction)."""
    ts: list[float] = []
    errs: list[float] = []
    for item in stream:
        if not isinstance(item, RadarFrame):
            continue
        for trk in item.tracks:
            lab = kind_at(kinds, trk.track_id, item.t)
            if lab is None or lab != (radar_model.UAV, uav_object):
                continue
            e, n, _ = (trk.e, trk.n, trk.u) if align is None else align(trk.e, trk.n, trk.u)
            te = float(np.interp(item.t, truth_t, truth_enu[:, 0]))
            tn = float(np.interp(item.t, truth_t, truth_enu[:, 1]))
            ts.append(item.t)
            errs.append(math.hypot(e - te, n - tn))
    return np.asarray(ts, dtype=float), np.asarray(errs, dtype=float)


def sensor_off(
    epoch_t: FloatArray, rep_t: FloatArray, rep_err: FloatArray, window_s: float, limit_m: float
) -> npt.NDArray[np.bool_]:
    """Per epoch: the median error of the reports in ``[t - window_s, t]`` (``rep_t`` sorted)
    is above ``limit_m`` (False without a report there)."""
    out = np.zeros(epoch_t.size, dtype=bool)
    lo = np.searchsorted(rep_t, epoch_t - window_s, side="left")
    hi = np.searchsorted(rep_t, epoch_t, side="right")
    for i, (a, b) in enumerate(zip(lo.tolist(), hi.tolist(), strict=True)):
        if b > a:
            out[i] = float(np.median(rep_err[a:b])) > limit_m
    return out


def observable_figures(s: GridSamples) -> tuple[float, float]:
    """A flight's radar-observable coverage and gross share (of the covered ones), in %."""
    return _pct(s.observable_covered, s.observable), _pct(s.observable_gross, s.observable_covered)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--definition", default="accuracy", help="benchmark definition (accuracy)")
    ap.add_argument("--split", default="tune", choices=("tune", "test"))
    ap.add_argument("--profile", default="tracker")
    ap.add_argument("--cache", default="out/bench_cache", help="flight cache folder")
    ap.add_argument("--coverage-pct", type=float, default=99.0, help="target per flight")
    ap.add_argument("--gross-pct", type=float, default=1.0, help="target per flight")
    ap.add_argument("--window-s", type=float, default=5.0, help="radar reports looked back at")
    args = ap.parse_args(argv)

    site_file = config_path(DEFAULT_SITE)
    site = load_site(site_file)
    definition = load_definition(args.definition)
    profile = load_profile(args.profile)
    settings = definition.settings
    single_rule = MultiSettings(emitter_misses=None, output_coast_s=None, radar_output_s=None)
    runs: dict[str, list[GridSamples]] = {"tracker": [], "oracle": []}
    n_gross = n_off = 0
    off_flights = 0
    for k, n_flights, cf, flight, kinds in labelled_flights(
        definition, args.split, Path(args.cache), site, site_file
    ):
        ours = score_task(ScoreTask(cf, profile, site, definition.grid_hz, settings)).samples
        truth = FlightTruth.from_flight(flight, site)
        objects, emitters = vehicle_links(cf.folder)
        oracle = LabelOracle(
            profile, site, kinds, objects, emitters, list(flight.vehicles), single_rule
        )
        t0, t1 = truth.span
        stream = list(frames_input(flight, profile))
        epochs = run_multi(oracle, stream, definition.grid_hz, t0, t1)
        pub = [(ep.t, ep.tracks[0]) for ep in epochs if ep.tracks]
        grid = grid_from_published(
            [t for t, _ in pub],
            [o.x.tolist() for _, o in pub],
            [o.P for _, o in pub],
            definition.grid_hz,
            t0,
            t1,
            profile.max_coast_s,
        )
        labels = read_labels(cf.folder)
        best = score_grid(grid, truth, labels, settings)
        runs["tracker"].append(ours)
        runs["oracle"].append(best)
        # the oracle's gross epochs, and those where the radar itself had the UAV far off
        ee = epoch_errors(grid, truth, settings)
        obs = observable_epochs(grid.t, ee.airborne, labels, settings.observable_window_s)
        gross = obs & ee.covered & (ee.error_m > settings.gross_error_m)
        tt, enu = flight.truth_arrays()
        align = oracle.alignment.point if oracle.alignment is not None else None
        rep_t, rep_err = uav_report_errors(
            stream, kinds, radar_model.uav_object_id(0), tt, enu, align
        )
        off = gross & sensor_off(grid.t, rep_t, rep_err, args.window_s, settings.gross_error_m)
        n_gross += int(gross.sum())
        n_off += int(off.sum())
        off_pct = 100.0 * float(off.sum()) / max(1, int(obs.sum()))
        off_flights += off_pct > args.gross_pct
        (oc, og), (bc, bg) = observable_figures(ours), observable_figures(best)
        print(
            f"[{k}/{n_flights}] {cf.flight.flight_id}: observable coverage / gross %: "
            f"tracker {oc:.1f} / {og:.2f}, oracle {bc:.1f} / {bg:.2f}; oracle gross epochs "
            f"with the UAV's radar reports > {settings.gross_error_m:g} m off: "
            f"{int(off.sum())} of {int(gross.sum())} ({off_pct:.2f} % of observable)"
        )
        sys.stdout.flush()
    print()
    cov_head = f"cov >= {args.coverage_pct:g}"
    gross_head = f"gross <= {args.gross_pct:g}"
    print(
        f"{'':8} {'mean m':>7} {'p95 m':>7} {'obs cov %':>9} {'obs gross %':>11} "
        f"{cov_head:>10} {gross_head:>10} {'both':>5}"
    )
    for name, samples in runs.items():
        sc = pool(samples, settings)
        figs = [observable_figures(s) for s in samples]
        ok_c = [c >= args.coverage_pct for c, _ in figs]
        ok_g = [g <= args.gross_pct for _, g in figs]
        n = len(samples)
        print(
            f"{name:8} {sc.err_mean_m:7.1f} {sc.err_p95_m:7.1f} {sc.observable_coverage_pct:9.2f} "
            f"{sc.observable_gross_pct:11.2f} {sum(ok_c):>5}/{n:<4} {sum(ok_g):>5}/{n:<4} "
            f"{sum(a and b for a, b in zip(ok_c, ok_g, strict=True)):>2}/{n}"
        )
    print(
        f"oracle gross epochs where the UAV's own radar reports of the last {args.window_s:g} s "
        f"were more than {settings.gross_error_m:g} m off (median, horizontal): {n_off} of "
        f"{n_gross}; on {off_flights} flights those alone exceed {args.gross_pct:g} % of the "
        "observable epochs"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
