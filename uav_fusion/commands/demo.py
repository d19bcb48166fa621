"""``uav_fusion demo``: the live node graph on the bundled flight, faster than real time.

Runs truth_replay, rf_replay, radar_replay, fusion_node and evaluator_node in this process
(DDS between them, one shared replay timeline, see ``docs/graph.md``), waits for the end of
the flight, has the evaluator write its report (Table II, metrics, figures) under
``out/demo/`` and prints the table. It then runs the same flight through the core offline
and says whether the live table equals the offline one. With ``--compare`` (default
``tracker``) the graph runs a second time with that profile (report under
``out/demo/<profile>/``), and the two tables are printed side by side. On the bundled flight
it then shows what the tracker is for: both profiles on a stress flight of the accuracy
benchmark, offline (:mod:`uav_fusion.commands.stress_flight`). ``--bag`` plays a bag instead
(:mod:`uav_fusion.commands.playback`), ``--multi`` runs the multi-UAV graph.

DDS discovery is kept on this machine: unless set already, ``ROS_AUTOMATIC_DISCOVERY_RANGE``
is set to LOCALHOST and ``ROS_DOMAIN_ID`` to a random domain for this run.
"""

from __future__ import annotations

import argparse
import os
import random
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any, TypeVar

from uav_fusion.core.errors import ConfigError
from uav_fusion.resources import DEFAULT_FLIGHT, data_path

T = TypeVar("T")

HELP = "run the live node graph on the default flight and write the evaluation to out/demo/"
MULTI_PLAN = "multi_crossing_pair"
DEFAULT_OUT = "out/demo"
#: the fusion node's arrival schedule, written beside the report
ARRIVALS = "arrivals.csv"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--flight",
        help="flight folder in the Dataset-28 layout (default: the bundled default flight)",
    )
    parser.add_argument(
        "--out",
        default=DEFAULT_OUT,
        help=f"report folder (default: {DEFAULT_OUT}; with --multi {DEFAULT_OUT}/multi)",
    )
    parser.add_argument(
        "--rate",
        type=float,
        default=0.0,
        help="replay speed: 0 = as fast as the nodes keep up without loss (default), "
        "1 = real time, 20 = twenty times real time",
    )
    parser.add_argument("--profile", default="paper", help="estimator profile (default: paper)")
    parser.add_argument(
        "--compare",
        default="tracker",
        metavar="PROFILE",
        help="then run the graph again with this profile and print both tables side by side "
        "(default: tracker; 'none' to skip)",
    )
    parser.add_argument("--site", help="site YAML (default: the shipped Lake Wheeler site)")
    parser.add_argument(
        "--window",
        type=float,
        default=0.0,
        metavar="S",
        help="fusion node's reorder window in sensor seconds (default: 0, zero wait: late "
        "measurements are re-filtered)",
    )
    parser.add_argument(
        "--bag",
        metavar="PATH",
        help="play this rosbag2 bag (bag_player) instead of replaying a flight folder; the "
        "offline comparison then needs --flight (the folder the bag was made from)",
    )
    parser.add_argument(
        "--record",
        metavar="DIR",
        help="with --bag: also run bag_recorder and record the fusion node's outputs "
        "and views and its inputs (fusion/*, radar/*, rf/fix, truth/fix, /diagnostics) into "
        "this rosbag2 MCAP directory",
    )
    parser.add_argument(
        "--live",
        action="store_true",
        help="live input: the sensor emulator writes the flight's lines (at --rate, 20 when 0) "
        "to radar_stream, rf_stream and truth_stream, which feed fusion_node and "
        "evaluator_node; checked against the offline run (uav_fusion/commands/live.py)",
    )
    parser.add_argument(
        "--live-via",
        choices=("tcp", "udp", "file"),
        default="tcp",
        help="--live: how the emulator reaches the stream nodes (default tcp)",
    )
    parser.add_argument(
        "--delay",
        action="append",
        metavar="SOURCE=S",
        help="--live: the emulator sends SOURCE's lines S seconds late, e.g. rf=3 (repeatable)",
    )
    parser.add_argument(
        "--jitter",
        action="append",
        metavar="SOURCE=S",
        help="--live: a uniform jitter of +-S seconds on SOURCE's delay, e.g. rf=1",
    )
    parser.add_argument(
        "--seed", type=int, default=0, help="--live: seed of the emulator's jitter (default 0)"
    )
    parser.add_argument(
        "--multi",
        action="store_true",
        help="the multi-UAV graph: a twin flight with several UAVs (generated from "
        "--multi-plan with --multi-seed into <out>/flight unless --flight is given), the "
        "fusion node's multi-UAV tracker on fusion/tracks, scored as a set by the evaluator, "
        "compared with the offline run (profile: tracker unless --profile names another "
        "tracker profile)",
    )
    parser.add_argument(
        "--multi-plan",
        default=MULTI_PLAN,
        metavar="PLAN",
        help=f"--multi: flight plan name or YAML path (default: {MULTI_PLAN})",
    )
    parser.add_argument(
        "--multi-seed", type=int, default=1, metavar="N", help="--multi: twin seed (default: 1)"
    )
    parser.add_argument(
        "--stress",
        action=argparse.BooleanOptionalAction,
        default=None,
        help="after the graph, run paper and the tracker offline on the benchmark's stress "
        "flight zigzag_dash seed 201 (generated into --cache if missing) and print both "
        "(default: on with the bundled flight, off with --flight, --bag or --multi)",
    )
    parser.add_argument(
        "--cache",
        default="out/bench_cache",
        help="the benchmark's flight cache, for --stress (default: out/bench_cache)",
    )
    parser.add_argument("--no-figures", action="store_true", help="write tables only")
    parser.add_argument("--no-check", action="store_true", help="skip the offline comparison")
    parser.add_argument(
        "--timeout", type=float, default=3600.0, metavar="S", help="give up after S seconds"
    )
    parser.add_argument("--quiet", action="store_true", help="only warnings from the nodes")


def _overrides(args: argparse.Namespace, flight_dir: Path, out: Path) -> dict[str, Any]:
    site = args.site or ""
    replay = {"flight_dir": str(flight_dir), "site_file": site}
    return {
        "truth_replay": {**replay, "rate": float(args.rate)},
        "rf_replay": dict(replay),
        "radar_replay": {**replay, "profile": args.profile},
        "fusion_node": {
            "profile": args.profile,
            "site_file": site,
            "use_sim_time": True,
            "reorder_window_s": float(args.window),
            # zero wait: what arrived when, to replay the same order offline
            "arrivals_file": str(out / ARRIVALS) if args.window <= 0 else "",
        },
        "evaluator_node": {
            "site_file": site,
            "output_dir": str(out),
            "figures": not args.no_figures,
            "flight_name": flight_dir.name,
            "rcs_flight_dir": str(flight_dir),
            "log_period_s": 0.0,
            "write_on_shutdown": False,
            "use_sim_time": True,
        },
    }


def run(args: argparse.Namespace) -> int:
    if args.rate < 0:
        raise ConfigError(f"--rate must be >= 0, got {args.rate}")
    flight_dir = Path(args.flight) if args.flight else data_path(DEFAULT_FLIGHT)
    if not flight_dir.is_dir():
        raise ConfigError(f"{flight_dir}: flight folder not found")
    out = Path(args.out)
    if args.record and not args.bag:
        raise ConfigError("--record goes with --bag (record the graph fed by bag_player)")
    if args.record and Path(args.record).exists():
        raise ConfigError(f"{args.record}: already exists; bag_recorder writes a new directory")
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    os.environ.setdefault("ROS_DOMAIN_ID", str(random.SystemRandom().randint(1, 100)))
    if args.multi:
        if args.live:
            raise ConfigError("--multi and --live do not go together")
        if args.bag:
            raise ConfigError("--multi replays a flight folder; it does not go with --bag")
        if args.out == DEFAULT_OUT:  # beside the single-UAV demo's report, not over it
            out = out / "multi"
        return _run_multi(args, out)
    if args.live:
        if args.bag:
            raise ConfigError("--live emulates a flight folder; it does not go with --bag")
        from uav_fusion.commands.live import run_live

        if args.out == DEFAULT_OUT:  # beside the replayed demo's report, not over it
            out = out / "live"
        return run_live(args, flight_dir, out, _overrides(args, flight_dir, out))
    if args.bag:
        from uav_fusion.commands.playback import run_bag

        live = run_bag(args, _overrides(args, flight_dir, out))
        if live is None:
            return 1
        if args.flight and not args.no_check:
            return _compare_offline(args, flight_dir, live, out=out)
        return 0

    from uav_fusion.core.scoring.evaluation import format_table

    profiles = [args.profile]
    if args.compare and args.compare.lower() != "none" and args.compare != args.profile:
        profiles.append(args.compare)
    lives: dict[str, Any] = {}
    folders: dict[str, Path] = {}
    code = 0
    for k, profile in enumerate(profiles):
        folder = folders[profile] = out if k == 0 else out / Path(profile).stem
        live = _run_graph(args, flight_dir, folder, profile)
        if live is None:
            return 1
        lives[profile] = live
        if len(profiles) == 1:
            print()
            print(format_table(live))
            print()
    if len(profiles) > 1:
        print()
        print(format_side_by_side(lives))
        print()
    if not args.no_check:
        for profile, live in lives.items():
            code = max(code, _compare_offline(args, flight_dir, live, profile, folders[profile]))
    if args.stress if args.stress is not None else not args.flight:
        from uav_fusion.commands.stress_flight import run_stress

        code = max(code, run_stress(Path(args.cache), args.site))
    return code


def _replay(
    args: argparse.Namespace,
    ov: dict[str, Any],
    banner: str,
    collect: Callable[[Any], T],
) -> tuple[Any, T, float] | None:
    """Bring the live graph up with the overrides ``ov``, replay the flight and take down
    the graph: the run's result, what ``collect`` took from the graph after the run, and
    the flight's length (s); None when the run failed (said on stderr). ``banner`` opens
    the line that says what is replayed."""
    import rclpy
    from rclpy.context import Context
    from rclpy.impl.logging_severity import LoggingSeverity
    from rclpy.logging import set_logger_level

    from uav_fusion.nodes.graph import Graph

    ctx = Context()
    rclpy.init(context=ctx, args=[])
    graph: Graph | None = None
    try:
        graph = Graph(ctx, ov)
        if args.quiet:
            for n in graph.nodes:
                set_logger_level(n.get_logger().name, LoggingSeverity.WARN)
        print(
            f"demo: {banner}: replaying {ov['radar_replay']['flight_dir']} at "
            + ("full speed (rate 0)" if args.rate == 0 else f"{args.rate:g}x real time")
            + f", ROS_DOMAIN_ID={os.environ['ROS_DOMAIN_ID']}",
            flush=True,
        )
        res = graph.run(timeout_s=args.timeout)
        if not res.ok:
            print(f"demo: {res.message}", file=sys.stderr)
            return None
        return res, collect(graph), graph.driver.t_end - graph.driver.t_start
    finally:
        if graph is not None:
            graph.destroy()
        rclpy.shutdown(context=ctx)


def _run_graph(args: argparse.Namespace, flight_dir: Path, out: Path, profile: str) -> Any:
    """One run of the live graph with ``profile``; its Evaluation, or None on failure."""
    from uav_fusion.core.estimators import load_profile

    ov = _overrides(args, flight_dir, out)
    ov["fusion_node"]["profile"] = profile
    ov["radar_replay"]["profile"] = profile
    if load_profile(profile).uses_tracker:  # score the fixed-rate output too
        ov["evaluator_node"]["grid_topic"] = "fusion/odom"

    def collect(graph: Any) -> tuple[Any, dict[str, int], int]:
        return (
            graph.evaluator.evaluate(),
            dict(graph.fusion.dropped),
            graph.fusion.output.grid_published,
        )

    ran = _replay(args, ov, f"profile {profile}", collect)
    if ran is None:
        return None
    res, (live, dropped, grid), flight_s = ran
    extra = f", {grid} fixed-rate epochs on fusion/odom" if grid else ""
    print(
        f"demo: profile {profile}: {sum(res.published.values())} messages ({res.published}) "
        f"over {flight_s:.0f} s of flight in {res.wall_s:.1f} s wall "
        f"({flight_s / res.wall_s:.0f}x real time); {res.steps} filter steps{extra}; "
        f"fusion drops: {dropped or 'none'}"
    )
    print(f"demo: report written to {res.report}")
    return live


def _multi_flight(args: argparse.Namespace, out: Path) -> Path:
    """The multi-UAV demo's flight: ``--flight``, or a twin flight generated into ``out``."""
    if args.flight:
        return Path(args.flight)
    from uav_fusion.core.site import load_site
    from uav_fusion.core.twin.config import load_twin_config
    from uav_fusion.core.twin.generate import generate_twin
    from uav_fusion.core.twin.trajectory import load_flight_plan
    from uav_fusion.core.twin.writers import write_twin
    from uav_fusion.resources import config_path

    name = str(args.multi_plan)
    path = Path(name) if name.endswith((".yaml", ".yml")) else config_path(
        f"waypoints/{name}.yaml"
    )
    if not path.is_file():
        raise ConfigError(f"--multi-plan: flight plan {path} not found")
    site = load_site(args.site)
    plan = load_flight_plan(path, site)
    twin = generate_twin(site, load_twin_config(), plan, seed=int(args.multi_seed))
    folder = out / "flight"
    if folder.exists():
        import shutil

        shutil.rmtree(folder)
    write_twin(twin, folder)
    print(
        f"demo: generated {plan.name} (seed {args.multi_seed}, "
        f"{1 + len(plan.others)} UAVs) into {folder}",
        flush=True,
    )
    return folder


def _run_multi(args: argparse.Namespace, out: Path) -> int:
    """The multi-UAV graph on one flight, and its comparison with the offline run."""
    from uav_fusion.core.data import load_flight
    from uav_fusion.core.estimators import load_profile
    from uav_fusion.core.site import load_site

    profile_name = args.profile if args.profile != "paper" else "tracker"
    profile = load_profile(profile_name)
    if not profile.uses_tracker:
        raise ConfigError(f"--multi needs a tracker profile; {profile_name!r} is not one")
    flight_dir = _multi_flight(args, out)
    site = load_site(args.site)
    flight = load_flight(flight_dir, site)
    vehicles = list(flight.vehicles)
    ov = _overrides(args, flight_dir, out)
    ov["radar_replay"]["profile"] = profile_name
    ov["fusion_node"].update(
        {"profile": profile_name, "estimator": "multi", "stall_timeout_s": 0.0}
    )
    hz = 10.0
    ov["fusion_node"]["frequency"] = hz
    ov["evaluator_node"].update(
        {
            "grid_topic": "fusion/odom",
            "tracks_topic": "fusion/tracks",
            "tracks_hz": hz,
            "vehicles": ",".join(vehicles),
        }
    )

    def collect(graph: Any) -> tuple[Any, list[Any], int]:
        with graph.evaluator._lock:
            received = sorted(graph.evaluator._tracks, key=lambda r: (r[0], r[1]))
        return graph.evaluator.multi_score(), received, graph.fusion.output.tracks_published

    banner = (
        f"multi-UAV graph, profile {profile_name}, {len(vehicles)} UAVs "
        f"({', '.join(vehicles)})"
    )
    ran = _replay(args, ov, banner, collect)
    if ran is None:
        return 1
    res, (live, received, published), flight_s = ran
    print(
        f"demo: {sum(res.published.values())} messages over {flight_s:.0f} s of flight in "
        f"{res.wall_s:.1f} s wall ({flight_s / res.wall_s:.0f}x real time); {published} track "
        f"messages on fusion/tracks"
    )
    print(f"demo: report written to {res.report}")
    if live is None:
        print("demo: no multi-target score (no truth received)", file=sys.stderr)
        return 1
    print()
    print(format_multi(live))
    print()
    if args.no_check:
        return 0
    return _compare_multi_offline(flight, profile, site, hz, received, live)


def format_multi(sc: Any) -> str:
    """The multi-target score as a small table: the set, then one row per UAV."""
    lines = [
        f"GOSPA (p 2, c 100 m, alpha 2) mean {sc.gospa_mean_m:.1f} m over {sc.epochs} epochs; "
        f"false-track time {sc.false_track_s:.1f} s (and {sc.excused_track_s:.1f} s on UAVs "
        f"not airborne, excused); {sc.id_switches} id switches "
        f"({sc.id_switches_kept} on kept correspondences)",
        f"{'UAV':<8} | {'airborne epochs':>15} | {'coverage %':>10} | {'error mean m':>12} | "
        f"{'p95 m':>7} | {'id switches':>11}",
    ]
    lines.append("-" * len(lines[1]))
    for u in sc.uavs:
        lines.append(
            f"{u.name:<8} | {u.epochs:>15d} | {u.coverage_pct:>10.1f} | {u.err_mean_m:>12.1f} | "
            f"{u.err_p95_m:>7.1f} | {u.id_switches:>11d}"
        )
    return "\n".join(lines)


def _compare_multi_offline(
    flight: Any, profile: Any, site: Any, hz: float, received: list[Any], live: Any
) -> int:
    """Run the multi-UAV tracker over the same flight offline (the grid the node emits while
    processing) and compare its tracks and score with the live ones."""
    import math

    import numpy as np

    from uav_fusion.core.estimators.base import feed, make_estimator
    from uav_fusion.core.scoring.gospa import (
        MultiScoreSettings,
        UavTruth,
        epochs_from_published,
        pool,
        score_flight,
    )

    t_start = time.perf_counter()
    est = make_estimator(profile, site, hz, kind="multi")
    rows: list[tuple[float, int, Any]] = []
    for item in est.flight_input(flight):
        for ep in feed(est, item).tracks:
            rows.extend((ep.t, o.track_id, o.x) for o in ep.tracks)
    rows.sort(key=lambda r: (r[0], r[1]))
    same = [(t, i) for t, i, _ in rows] == [(t, i) for t, i, _ in received]
    worst = max(
        (float(np.max(np.abs(np.asarray(a[2]) - np.asarray(b[2])))) for a, b in
         zip(rows, received, strict=False)),
        default=0.0,
    )  # fmt: skip
    truths = {}
    for v in flight.vehicles:
        t, enu = flight.truth_arrays(v)
        if t.size >= 2:
            truths[v] = UavTruth(t=t, enu=enu)
    t0 = min(float(x.t[0]) for x in truths.values())
    t1 = max(float(x.t[-1]) for x in truths.values())
    ref = pool(
        [
            score_flight(
                truths,
                epochs_from_published(rows, hz, t0, t1),
                MultiScoreSettings(step_s=1.0 / hz),
            )
        ]
    )
    diff = abs(ref.gospa_mean_m - live.gospa_mean_m)
    if same and worst <= 1e-9 and diff <= 1e-9 and not math.isnan(ref.gospa_mean_m):
        print(
            f"demo: the live tracks on fusion/tracks equal the offline run's ({len(rows)} track "
            f"states, largest difference {worst:.1e} m), and so do the scores (GOSPA mean "
            f"{ref.gospa_mean_m:.3f} m both; offline check {time.perf_counter() - t_start:.1f} s)"
        )
        return 0
    print(
        f"demo: live and offline differ: {len(received)} live track states vs {len(rows)} "
        f"offline, largest state difference {worst:.3g} m, GOSPA mean live "
        f"{live.gospa_mean_m:.3f} m vs offline {ref.gospa_mean_m:.3f} m",
        file=sys.stderr,
    )
    return 1


def format_side_by_side(lives: dict[str, Any], digits: int = 1) -> str:
    """Table II's rows for several profiles side by side: count, mean and count coverage."""
    names = list(lives)
    first = lives[names[0]]
    w = 44
    head = f"{'stage':<{w}}" + "".join(
        f" | {n[:24]:>24}" for n in names
    )
    sub = f"{'':<{w}}" + "".join(f" | {'count':>6} {'mean m':>8} {'cov %':>8}" for _ in names)
    lines = [head, sub, "-" * len(sub)]
    for i, row in enumerate(first.rows):
        label = row.spec.label
        label = label if len(label) <= w else label[: w - 1] + "…"
        cells = []
        for n in names:
            r = lives[n].rows[i]
            st = r.stats
            mean = "-" if not st.count else f"{st.mean:.{digits}f}"
            cov = "-" if st.coverage_pct != st.coverage_pct else f"{st.coverage_pct:.1f}"
            cells.append(f" | {st.count:>6d} {mean:>8} {cov:>8}")
        lines.append(f"{label:<{w}}" + "".join(cells))
    lines.append(
        "count coverage over the RF attempts, raw radar reports and filter steps of each run "
        "(the full tables: report.md of each run)"
    )
    return "\n".join(lines)


def _compare_offline(
    args: argparse.Namespace,
    flight_dir: Path,
    live: Any,
    profile: str | None = None,
    out: Path | None = None,
) -> int:
    """Score the same flight offline (in the arrival order the fusion node wrote, when it
    wrote one) and report whether the live table is the same."""
    profile = profile or args.profile
    from uav_fusion.commands.evaluate import evaluate_flight
    from uav_fusion.core.data import load_flight
    from uav_fusion.core.site import load_site

    t0 = time.perf_counter()
    site = load_site(args.site)
    flight = load_flight(flight_dir, site)
    schedule = out / ARRIVALS if out is not None and (out / ARRIVALS).is_file() else None
    ref, _ = evaluate_flight(flight, profile, site, arrivals=schedule)
    same = True
    worst = 0.0
    for a, b in zip(live.rows, ref.rows, strict=True):
        if a.stats.count != b.stats.count or a.denominator != b.denominator:
            same = False
            print(
                f"demo: row {a.key}: live {a.stats.count}/{a.denominator}, "
                f"offline {b.stats.count}/{b.denominator}"
            )
        elif a.stats.count:
            worst = max(worst, abs(a.stats.mean - b.stats.mean), abs(a.stats.max - b.stats.max))
    if same and worst <= 1e-9:
        order = "" if schedule is None else f" in the arrival order the node wrote ({schedule})"
        print(
            f"demo: profile {profile}: the live graph's table equals the offline run's{order} "
            f"(largest difference {worst:.1e} m; offline check {time.perf_counter() - t0:.1f} s)"
        )
        return 0
    print(
        f"demo: profile {profile}: live and offline differ (largest difference in mean/max "
        f"{worst:.3g} m)",
        file=sys.stderr,
    )
    return 1


if __name__ == "__main__":
    from uav_fusion.cli import main

    sys.exit(main(["demo", *sys.argv[1:]]))
