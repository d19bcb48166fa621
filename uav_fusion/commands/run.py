"""``uav_fusion run``: run the estimator over a flight folder, print a summary, write steps."""

from __future__ import annotations

import argparse
import itertools
import math
import time
from pathlib import Path
from typing import Any

from uav_fusion.core.errors import ConfigError
from uav_fusion.core.estimators.steps import Step
from uav_fusion.core.profiles.model import Profile
from uav_fusion.core.records import Flight
from uav_fusion.core.site import Site, load_site
from uav_fusion.resources import DEFAULT_FLIGHT, data_path

HELP = "run the estimator over a flight folder and write every filter step to CSV"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "folder",
        nargs="?",
        help="flight folder in the Dataset-28 layout (default: the bundled default flight)",
    )
    parser.add_argument(
        "--profile", default="paper", help="estimator profile name or YAML path (default: paper)"
    )
    parser.add_argument("--site", help="site YAML (default: the shipped Lake Wheeler site)")
    parser.add_argument("--out", help="CSV file for the steps (one row per measurement)")
    parser.add_argument(
        "--grid",
        metavar="FILE",
        help="CSV file for the fixed-rate output: one row per grid epoch over the truth's span "
        "(what the system publishes then; docs/benchmark.md)",
    )
    parser.add_argument(
        "--grid-hz", type=float, default=10.0, help="rate of --grid (default: 10 Hz)"
    )
    parser.add_argument(
        "--targets",
        metavar="FILE",
        help="also run the multi-UAV tracker (tracker profiles) and write every confirmed "
        "track on a grid (--targets-hz) to this CSV, one row per (epoch, target); with truth, "
        "print its multi-target scores (GOSPA, per UAV coverage, ID switches, false tracks)",
    )
    parser.add_argument(
        "--targets-hz", type=float, default=1.0, help="rate of --targets (default: 1 Hz)"
    )
    parser.add_argument(
        "--rf-file", default="AADM.csv", help="RF CSV name inside the folder (default: AADM.csv)"
    )
    parser.add_argument(
        "--selection",
        choices=("largest_track", "online"),
        help="override the profile's radar track handling",
    )
    parser.add_argument(
        "--sources",
        choices=("both", "radar", "rf"),
        default="both",
        help="fuse both sources (default) or run on one alone",
    )
    parser.add_argument(
        "--strict", action="store_true", help="stop at the first bad input row instead of skipping"
    )
    live = parser.add_argument_group(
        "live arrival order",
        "fuse the inputs in the order a live node receives them (zero wait: a late input is "
        "fused by rewinding and re-filtering), reproducing what the live graph published; "
        "--out then holds the final, re-filtered steps",
    )
    live.add_argument(
        "--arrivals",
        metavar="FILE",
        help="arrival schedule CSV (source,stamp,arrival), e.g. written by uav_fusion emulate",
    )
    live.add_argument(
        "--delay",
        action="append",
        default=[],
        metavar="SOURCE=S[+-J]",
        help="simulate arrivals: SOURCE's inputs come S +- J seconds after their stamp "
        "(uniform; each source in its own order), e.g. --delay rf=3+-1; repeatable",
    )
    live.add_argument("--seed", type=int, default=0, help="seed of the --delay jitter")
    live.add_argument(
        "--max-lag", type=float, default=10.0, metavar="S",
        help="seconds an input may arrive late and still be fused (default: 10)",
    )  # fmt: skip
    live.add_argument(
        "--published",
        metavar="FILE",
        help="CSV of what the live graph published at each arrival (steps and fixed-rate "
        "epochs)",
    )


def run(args: argparse.Namespace) -> int:
    from uav_fusion.core import estimators as est
    from uav_fusion.core.data import load_flight

    site = load_site(args.site)
    profile = est.load_profile(args.profile)
    changes: dict[str, object] = {}
    if args.selection:
        changes["radar_selection"] = args.selection
    if args.sources != "both":
        changes["use_radar"] = args.sources == "radar"
        changes["use_rf"] = args.sources == "rf"
        changes["init_sources"] = (args.sources,)
    if changes:
        try:
            profile = profile.with_changes(**changes)
        except TypeError as exc:
            raise ConfigError(str(exc)) from None
    folder = Path(args.folder) if args.folder else data_path(DEFAULT_FLIGHT)
    flight = load_flight(folder, site, rf_file=args.rf_file, strict=args.strict)
    t0 = time.perf_counter()
    if args.arrivals or args.delay:
        result = run_arrivals(flight, profile, site, args)
    else:
        result = est.run_flight(flight, profile, site)
    elapsed = time.perf_counter() - t0
    n = len(result.steps)
    print(f"flight {flight.name}: profile {profile.name} ({profile.source or 'built in'})")
    for name, rep in sorted(flight.reports.items()):
        print(f"  input {name}: {rep.summary()}")
    info = result.info
    if info is not None:
        sel = "" if info.selected_track_id is None else f", track {info.selected_track_id}"
        how = profile.radar_selection if profile.estimator == "paper" else "every report"
        print(
            f"  radar: {info.radar_reports} reports in {info.radar_frames} frames; "
            f"{info.radar_selected} to the {profile.estimator} estimator ({how}{sel})"
        )
        print(f"  rf: {info.rf_fixes} fixes of {info.rf_attempts} attempts")
    pc = result.paper_counts()
    print(
        f"  filter steps: {pc['all_steps']} = {pc['updated_estimates']} updated "
        f"+ {pc['coasted_estimates']} coasted; {pc['discarded']} discarded"
    )
    print(
        f"  passed the NIS gate: radar {pc['radar_accepted']}, rf {pc['rf_accepted']}; "
        f"confirmed track starts {pc['track_starts']}"
    )
    c0 = result.counters
    print(
        f"  tentative (unconfirmed RF-started tracks, not estimates): {pc['tentative']} steps, "
        f"{c0.get('tentative_started', 0)} tracks started, {c0.get('confirmed', 0)} confirmed, "
        f"{c0.get('tentative_dropped', 0)} dropped, {c0.get('reinit_superseded', 0)} "
        "superseded by radar"
    )
    c = result.counters
    rejected = {k[len("rejected_") :]: v for k, v in c.items() if k.startswith("rejected_")}
    if rejected:
        print("  rejected: " + ", ".join(f"{k}={v}" for k, v in sorted(rejected.items())))
    reinit = {k[len("reinit_") :]: v for k, v in c.items() if k.startswith("reinit_")}
    detail = ", ".join(f"{k}={v}" for k, v in sorted(reinit.items()))
    print(
        f"  confirmed tracks started at once: {c.get('initialised', 0)} initial; track "
        f"restarts: {c.get('reinitialisations', 0)}" + (f" ({detail})" if detail else "")
    )
    rate = n / elapsed if elapsed > 0 else float("inf")
    print(f"  {n} measurements in {elapsed:.3f} s ({rate:.0f}/s)")
    if args.out:
        path = result.write_csv(args.out)
        print(f"steps: {path}")
    if args.grid:
        write_grid(result.steps, flight, profile, site, args.grid, args.grid_hz)
    if args.targets:
        write_targets(flight, profile, site, args.targets, args.targets_hz)
    return 0


PUBLISHED_COLUMNS = (
    "arrival", "source", "stamp", "topic", "t", "status", "x", "y", "z", "vx", "vy", "vz",
)  # fmt: skip


def run_arrivals(flight: Flight, profile: Profile, site: Site, args: argparse.Namespace) -> Any:
    """The profile's estimator fed in live arrival order (zero wait); prints how the order
    differs from the stamps' and whether the final track equals the in-order run."""
    import csv

    from uav_fusion.core.estimators.base import drive, make_estimator
    from uav_fusion.core.estimators.offline import RunResult
    from uav_fusion.core.estimators.selection import input_info
    from uav_fusion.core.live.rewind import simulate
    from uav_fusion.core.live.schedule import delayed, parse_delay, read_schedule

    if not (math.isfinite(args.max_lag) and args.max_lag >= 0):
        raise ConfigError(f"--max-lag must be >= 0, got {args.max_lag}")
    hz = float(args.grid_hz)

    def make() -> Any:
        return make_estimator(profile, site, hz, live=True)

    est = make()
    items = est.flight_input(flight)
    if args.arrivals:
        arrivals = read_schedule(args.arrivals, items)
        what = f"schedule {args.arrivals}"
    else:
        delays = {src: (d, j) for src, d, j in (parse_delay(x) for x in args.delay)}
        arrivals = delayed(items, delays, args.seed)
        what = "delays " + ", ".join(args.delay) + f" (seed {args.seed})"
    outs, rw, _ = simulate(make, arrivals, args.max_lag)
    order = {id(it): n for n, it in enumerate(items)}
    inputs = [a for a in arrivals if id(a[1]) in order]  # not the clock's moves
    behind = sum(1 for a, b in itertools.pairwise(inputs)
                 if order[id(b[1])] < order[id(a[1])])  # fmt: skip
    final = rw.steps
    in_order = drive(make(), items).steps

    def key(s: Step) -> tuple[object, ...]:
        return (s.t, s.source, s.status, repr(s.values))

    same = [key(s) for s in final] == [key(s) for s in in_order]
    print(
        f"arrivals ({what}): {len(inputs)} inputs, {behind} arrived after a later-stamped "
        f"one; {rw.rewinds} rewinds re-filtered {rw.refiltered} inputs; the final track "
        + ("equals the in-order run" if same else "DIFFERS from the in-order run")
    )
    if args.published:
        out = Path(args.published)
        out.parent.mkdir(parents=True, exist_ok=True)
        with out.open("w", newline="", encoding="utf-8") as fh:
            w = csv.writer(fh)
            w.writerow(PUBLISHED_COLUMNS)
            for n, ((src, it), o) in enumerate(zip(arrivals, outs, strict=False)):
                for st in o.steps:
                    w.writerow([n, src, repr(it.t), "steps", repr(st.t), st.status,
                                *(repr(float(v)) for v in st.x)])  # fmt: skip
                for g in o.grid:
                    if not g.published:
                        continue
                    w.writerow([n, src, repr(it.t), "grid", repr(g.t), "published",
                                *(repr(float(v)) for v in g.x)])  # fmt: skip
        print(f"published: {out}")
    info = input_info(flight, profile, est.reads)
    counters = dict(rw.estimator.counters)
    counters["radar_reports"] = info.radar_reports
    return RunResult(steps=final, counters=counters, info=info, profile_name=profile.name)


TARGET_COLUMNS = (
    "t", "target", "e", "n", "u", "ve", "vn", "vu", "var_e", "var_n", "var_u",
    "uav_prob", "emitter", "radar_object", "last_update_t",
)  # fmt: skip


def write_targets(flight: Flight, profile: Profile, site: Site, path: str, hz: float) -> None:
    """Every confirmed track of the multi-UAV tracker on a grid over the truth's span, and
    its multi-target scores against every vehicle's truth."""
    import csv

    from uav_fusion.core.estimators.base import drive, make_estimator
    from uav_fusion.core.estimators.selection import frames_input
    from uav_fusion.core.scoring.gospa import UavTruth, pool, score_flight

    if not profile.uses_tracker:
        raise ConfigError(
            f"--targets needs a tracker profile ('estimator: tracker' or 'multi'); "
            f"{profile.name!r} is not one"
        )
    if not (math.isfinite(hz) and hz > 0):
        raise ConfigError(f"--targets-hz must be > 0, got {hz}")
    stream = list(frames_input(flight, profile))
    spans = [flight.truth_arrays(v)[0] for v in flight.vehicles]
    ts = [float(x) for t in spans for x in (t[:1].tolist() + t[-1:].tolist())]
    if not ts:
        ts = [item.t for item in stream]
    if not ts:
        raise ConfigError("--targets: the flight has neither truth nor measurements")
    t0, t1 = min(ts), max(ts)
    t_run = time.perf_counter()
    est = make_estimator(profile, site, hz, t0, t1, kind="multi")
    epochs = drive(est, stream, t1).tracks
    elapsed = time.perf_counter() - t_run
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    rows = 0
    with out.open("w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh)
        w.writerow(TARGET_COLUMNS)
        for ep in epochs:
            for o in ep.tracks:
                w.writerow(
                    [
                        repr(ep.t), o.track_id, *(repr(float(v)) for v in o.x),
                        *(repr(float(o.P[i, i])) for i in range(3)),
                        f"{o.uav_prob:.6f}", o.emitter or "",
                        "" if o.radar_object is None else o.radar_object,
                        repr(o.last_update_t),
                    ]
                )  # fmt: skip
                rows += 1
    ids = {o.track_id for ep in epochs for o in ep.tracks}
    print(
        f"targets: {out}: {len(epochs)} epochs at {hz:g} Hz, {rows} rows, {len(ids)} track "
        f"ids ({elapsed:.3f} s)"
    )
    truths = {}
    for v in flight.vehicles:
        t, enu = flight.truth_arrays(v)
        if t.size >= 2:
            truths[v] = UavTruth(t=t, enu=enu)
    if not truths:
        return
    sc = pool([score_flight(truths, epochs)])
    print(
        f"  GOSPA (p 2, c 100 m, alpha 2) mean {sc.gospa_mean_m:.1f} m; false-track time "
        f"{sc.false_track_s:.0f} s of {len(epochs) / hz:.0f} s (and {sc.excused_track_s:.0f} s "
        "on UAVs not airborne, excused)"
    )
    for u in sc.uavs:
        print(
            f"  {u.name}: coverage {u.coverage_pct:.1f} % of {u.epochs} airborne epochs, "
            f"error mean {u.err_mean_m:.1f} m, {u.id_switches} id switches "
            f"({u.id_switches_kept} on kept correspondences), "
            f"{u.fragmentations} fragmentations"
        )


def write_grid(
    steps: list[Step], flight: Flight, profile: Profile, site: Site, path: str, hz: float
) -> None:
    """The run's fixed-rate output over the truth's span (the steps' span without truth)."""
    from uav_fusion.core.estimators.consider import published_cov
    from uav_fusion.core.scoring.fixed_rate import FlightTruth, grid_from_steps

    if not (math.isfinite(hz) and hz > 0):
        raise ConfigError(f"--grid-hz must be > 0, got {hz}")
    t0, t1 = FlightTruth.from_flight(flight, site).span
    if not t1 > t0:
        ts = [s.t for s in steps if math.isfinite(s.t)]
        if not ts:
            raise ConfigError("--grid: the run has no steps and the flight no truth")
        t0, t1 = min(ts), max(ts)
    grid = grid_from_steps(steps, profile, hz, t0, t1, consider=published_cov(profile, site))
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    grid.write_csv(str(out))
    n_pub = int(grid.published.sum())
    print(
        f"grid: {out}: {len(grid)} epochs at {hz:g} Hz, {n_pub} with a published track "
        f"(max coast {profile.max_coast_s} s), {grid.restarts} track restarts"
    )
