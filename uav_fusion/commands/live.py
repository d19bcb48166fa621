"""``uav_fusion demo --live``: sensor emulator -> stream nodes -> fusion -> evaluator.

The emulator (:mod:`uav_fusion.core.ingest.emulator`) writes the flight's radar, RF and
truth lines, unchanged, at ``--rate`` times real time (20 when 0 is given: a live source has
a pace), with the per-source delays and jitter of ``--delay`` / ``--jitter``, over TCP
(default), UDP or followed files (``--live-via``). ``radar_stream``, ``rf_stream`` and
``truth_stream`` read them and publish the replays' topics with sensor stamps; fusion_node
and evaluator_node run as in the replayed graph (no ``/clock``: every node on the host
clock), all in this process. The emulator runs in a thread of its own.

The run is checked against the offline run of the same flight. With zero wait (``--window``
0, the default) the fusion node fuses every measurement as it arrives, a late one by
re-filtering (``max_lag_s``: 10 s, or more: twice the largest delay + jitter, plus 1 s, plus
one wall second of stall at the rate), and writes what arrived when to
``<out>/arrivals.csv``; the offline run fuses the flight in that order (``uav_fusion run
--arrivals``), and the evaluator's table must equal it. With a reorder window (``--window`` >
0) the window is widened by the largest delay + jitter and one wall second of stall at the
rate, so the node processes everything in the offline order, and the table must equal the
in-order run.

Two things a live stream cannot do as the offline run does: the paper profile's
largest-track choice needs the whole flight (the live graph and its offline reference then use
the ``online`` selection: every report of a frame is a candidate), and the raw radar row
classes a report by the mean UAV probability of its track *so far* (offline: of the whole
track); that row is shown, not compared. The emulator's own schedule (every line sent, when) is
written to ``<out>/emulated.csv``.
"""

from __future__ import annotations

import argparse
import sys
import threading
import time
from pathlib import Path
from typing import Any

#: the rows a live stream cannot reproduce exactly (see the module text)
CAUSAL_ROWS = ("radar_raw",)
#: the fusion node's arrival schedule (what arrived when), and the emulator's (what was sent)
ARRIVALS = "arrivals.csv"
EMULATED = "emulated.csv"


def live_profile(profile: str, out: Path) -> str:
    """``profile``, or a profile that extends it with the ``online`` radar selection when it
    chooses the largest track (written into ``out``)."""
    from uav_fusion.core.estimators import load_profile
    from uav_fusion.core.profiles import profile_path

    prof = load_profile(profile)
    if prof.radar_selection != "largest_track" or prof.uses_tracker:
        return profile
    out.mkdir(parents=True, exist_ok=True)
    path = out / f"{Path(profile).stem}_online.yaml"
    path.write_text(
        "# written by uav_fusion demo --live: a live stream cannot choose the largest track of\n"
        "# the whole flight; every report of a frame is a candidate instead\n"
        f"extends: {profile_path(profile).resolve()}\n"
        "radar_selection: online\n",
        encoding="utf-8",
    )
    return str(path)


class _LiveGraph:
    """The emulator, the stream nodes, fusion_node and evaluator_node of one run."""

    def __init__(self, args: argparse.Namespace, flight_dir: Path, out: Path, profile: str,
                 overrides: dict[str, dict[str, Any]]) -> None:
        self.args = args
        self.flight_dir = flight_dir
        self.out = out
        self.profile = profile
        self.ov = overrides
        self.nodes: list[Any] = []
        self.end = time.monotonic() + float(args.timeout)

    def build(self, ctx: Any) -> None:
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.impl.logging_severity import LoggingSeverity
        from rclpy.logging import set_logger_level
        from rclpy.parameter import Parameter

        from uav_fusion.commands.emulate import per_source
        from uav_fusion.core.data.flight import flight_files
        from uav_fusion.core.estimators import load_profile
        from uav_fusion.core.ingest.emulator import (
            Emulator,
            FileSink,
            Sink,
            TcpServerSink,
            UdpSink,
            plan,
            read_sensor_lines,
        )
        from uav_fusion.core.ingest.transport import UdpReceiver
        from uav_fusion.core.site import load_site
        from uav_fusion.nodes.evaluator_node import EvaluatorNode
        from uav_fusion.nodes.fusion_node import FusionNode
        from uav_fusion.nodes.radar_stream import RadarStream
        from uav_fusion.nodes.rf_stream import RfStream
        from uav_fusion.nodes.truth_stream import TruthStream

        args = self.args
        site = load_site(args.site)
        files = flight_files(self.flight_dir)
        lines = {s: read_sensor_lines(files[s], s, site) for s in ("radar", "rf", "truth")}
        delay = per_source(args.delay, "delay")
        jitter = per_source(args.jitter, "jitter")
        self.sends = plan(lines, delay_s=delay, jitter_s=jitter, seed=args.seed)
        #: records each stream node must publish (lines with a sensor time)
        self.expected = {s: sum(1 for x in self.sends if x.source == s and x.sensor_t is not None)
                         for s in lines}
        lag = max((delay.get(s, 0.0) + jitter.get(s, 0.0) for s in lines), default=0.0)
        fusion_ov = {**self.ov["fusion_node"], "profile": self.profile, "use_sim_time": False,
                     "stall_timeout_s": 0.0}
        if float(args.window) > 0:
            # the reorder window, widened by the lateness and one wall second of stall at the
            # rate: everything in the offline order
            self.window = float(args.window) + lag + self.rate
            fusion_ov.update({"reorder_window_s": self.window, "arrivals_file": ""})
            self.arrivals: Path | None = None
        else:
            # zero wait: late data re-filtered; the node writes what arrived when
            self.window = 0.0
            # sensor seconds: the lateness, and 1 s of wall-clock stall at this rate
            self.max_lag = max(10.0, 2.0 * lag + 1.0 + self.rate)
            self.arrivals = self.out / ARRIVALS
            fusion_ov.update({"reorder_window_s": 0.0, "max_lag_s": self.max_lag,
                              "arrivals_file": str(self.arrivals)})
        eval_ov = {**self.ov["evaluator_node"], "use_sim_time": False}
        if load_profile(self.profile).uses_tracker:
            eval_ov["grid_topic"] = "fusion/odom"

        def params(values: dict[str, Any]) -> list[Parameter]:
            return [Parameter(k, value=v) for k, v in values.items()]

        self.fusion = FusionNode(context=ctx, parameter_overrides=params(fusion_ov))
        self.nodes.append(self.fusion)
        self.evaluator = EvaluatorNode(context=ctx, parameter_overrides=params(eval_ov))
        self.nodes.append(self.evaluator)

        via = args.live_via
        sinks: dict[str, Sink] = {}
        urls: dict[str, str] = {}
        feed_dir = self.out / "sensors"
        for s in lines:
            if via == "tcp":
                srv = TcpServerSink("127.0.0.1", 0)
                sinks[s] = srv
                urls[s] = f"tcp://127.0.0.1:{srv.port}"
            elif via == "file":
                feed_dir.mkdir(parents=True, exist_ok=True)
                path = feed_dir / files[s].name
                sinks[s] = FileSink(path, overwrite=True)
                urls[s] = f"file://{path.resolve()}"
            else:
                urls[s] = "udp://127.0.0.1:0"
        common = {"site_file": args.site or "", "wait_for_subscribers_s": 30.0,
                  "clock_offset_warn_s": 0.0, "stale_s": 0.0}
        kinds = {"radar": RadarStream, "rf": RfStream, "truth": TruthStream}
        self.streams: dict[str, Any] = {}
        for s, cls in kinds.items():
            extra: dict[str, Any] = {"url": urls[s], **common}
            if s == "radar":
                extra["profile"] = self.profile
            node = cls(context=ctx, parameter_overrides=params(extra))
            self.streams[s] = node
            self.nodes.append(node)
            if via == "udp":
                rx = node.ingest.transport
                assert isinstance(rx, UdpReceiver)
                sinks[s] = UdpSink("127.0.0.1", rx.port)
        if args.quiet:
            for n in self.nodes:
                set_logger_level(n.get_logger().name, LoggingSeverity.WARN)
        self.emulator = Emulator(self.sends, sinks, rate=self.rate, wait_s=60.0,
                                 log=lambda t: print(f"demo: emulator: {t}", flush=True))
        self.executor = SingleThreadedExecutor(context=ctx)
        for n in self.nodes:
            self.executor.add_node(n)

    @property
    def rate(self) -> float:
        return float(self.args.rate) if self.args.rate > 0 else 20.0

    def destroy(self) -> None:
        emu = getattr(self, "emulator", None)
        if emu is not None:
            emu.close()
        for n in reversed(self.nodes):
            n.destroy_node()

    def spin_until(self, cond: Any, quiet_s: float = 10.0) -> bool:
        """Spin until ``cond``; False at the timeout, or after ``quiet_s`` without a message
        once the emulator is done."""
        last, since = -1, time.monotonic()
        while not cond():
            now = time.monotonic()
            n = sum(self.fusion.received.values()) + sum(self.evaluator.received.values())
            if n != last:
                last, since = n, now
            if now > self.end or (self.done.is_set() and now - since > quiet_s):
                return False
            self.executor.spin_once(timeout_sec=0.02)
        return True

    def run(self) -> bool:
        """Emulate the flight to the end; True when every line made it through."""
        self.done = threading.Event()
        self.stop = threading.Event()
        self.error: BaseException | None = None

        def emulate() -> None:
            try:
                self.result = self.emulator.run(self.stop)
            except BaseException as exc:  # reported by the main thread
                self.error = exc
            finally:
                self.done.set()

        th = threading.Thread(target=emulate, name="emulator", daemon=True)
        th.start()
        try:
            streams, fusion, ev = self.streams, self.fusion, self.evaluator
            ok = self.spin_until(lambda: self.done.is_set() and all(
                streams[s].ingest.monitor.records >= n for s, n in self.expected.items()))
            if not ok:
                return False
            to_fusion = ((streams["radar"], fusion.input.radar_topic),
                         (streams["rf"], fusion.input.rf_topic))
            ok = self.spin_until(lambda: sum(fusion.received.values()) >= sum(
                node.sent[node.resolve_topic_name(t)] for node, t in to_fusion))
            fusion.flush()
            eval_topics = ((streams["truth"], ev.truth_topic), (streams["rf"], ev.rf_topic),
                           (streams["radar"], ev.radar_raw_topic))
            expected = sum(node.sent[node.resolve_topic_name(t)] for node, t in eval_topics)
            expected += fusion.output.steps_published + fusion.output.accepted_published
            if ev.grid_topic:
                expected += fusion.output.grid_published
            return ok and self.spin_until(lambda: sum(ev.received.values()) >= expected)
        finally:
            self.stop.set()
            th.join(5.0)


def run_live(args: argparse.Namespace, flight_dir: Path, out: Path,
             overrides: dict[str, dict[str, Any]]) -> int:
    """The live run and its comparison with the offline one; the exit status."""
    import rclpy
    from rclpy.context import Context

    from uav_fusion.core.ingest.emulator import write_schedule
    from uav_fusion.core.scoring.evaluation import format_table

    profile = live_profile(args.profile, out)
    ctx = Context()
    rclpy.init(context=ctx, args=[])
    graph = _LiveGraph(args, flight_dir, out, profile, overrides)
    try:
        graph.build(ctx)
        delays = ", ".join(args.delay or []) or "none"
        mode = (f"reorder window {graph.window:g} s" if graph.window > 0
                else f"zero wait, max_lag_s {graph.max_lag:g}")
        print(
            f"demo: live: emulating {flight_dir} at {graph.rate:g}x over {args.live_via} "
            f"(delays {delays}; jitter {', '.join(args.jitter or []) or 'none'}; seed "
            f"{args.seed}) -> radar_stream, rf_stream, truth_stream -> fusion_node (profile "
            f"{Path(profile).stem}, {mode}) -> evaluator_node",
            flush=True,
        )
        t0 = time.monotonic()
        ok = graph.run()
        wall = time.monotonic() - t0
        if graph.error is not None:
            print(f"demo: emulator failed: {graph.error}", file=sys.stderr)
            return 1
        sched = out / EMULATED
        out.mkdir(parents=True, exist_ok=True)
        write_schedule(sched, graph.emulator.rows)
        arrivals = graph.arrivals
        if not ok:
            got = {s: n.ingest.monitor.records for s, n in graph.streams.items()}
            print(f"demo: live: not every line made it through (records {got}, expected "
                  f"{graph.expected})", file=sys.stderr)
            return 1
        live = graph.evaluator.evaluate()
        files = graph.evaluator.write_report()
        per_stream = {s: dict(n.ingest.dropped) for s, n in graph.streams.items()}
        lat = {s: n.ingest.monitor.latency_quantiles() for s, n in graph.streams.items()}
        res = graph.result
        steps = graph.fusion.steps_published
        fdrop = dict(graph.fusion.dropped)
    finally:
        graph.destroy()
        rclpy.shutdown(context=ctx)
    print()
    print(format_table(live))
    print()
    lat_text = ", ".join(f"{s} p50 {a * 1e3:.2f} ms / p99 {b * 1e3:.2f} ms"
                         for s, (a, b) in lat.items())
    print(f"demo: live: {sum(res.sent.values())} lines sent ({res.sent}) in {wall:.1f} s wall; "
          f"emulator lateness p50 {res.lag_p50_s * 1e3:.2f} ms, max {res.lag_max_s * 1e3:.1f} "
          f"ms; line-to-publish {lat_text}; {steps} filter steps; stream drops: "
          f"{ {s: d for s, d in per_stream.items() if d} or 'none'}; fusion drops: "
          f"{fdrop or 'none'}")
    print(f"demo: report written to {files.folder}; the emulator's schedule {sched}"
          + ("" if arrivals is None else f", the fusion node's arrival schedule {arrivals}"))
    if args.no_check:
        return 0
    return compare_offline(args, flight_dir, profile, live, arrivals)


def compare_offline(args: argparse.Namespace, flight_dir: Path, profile: str, live: Any,
                    arrivals: Path | None = None) -> int:
    """Score the flight offline with ``profile`` (in the fusion node's arrival order when it
    wrote one: zero wait); 0 when every row but the causal ones is equal (counts exactly, mean
    and max to 1e-9 m; the rows counted over the raw radar reports compare their counts, not
    that denominator)."""
    from uav_fusion.commands.evaluate import evaluate_flight
    from uav_fusion.core.data import load_flight
    from uav_fusion.core.site import load_site

    t0 = time.perf_counter()
    site = load_site(args.site)
    flight = load_flight(flight_dir, site)
    ref, _ = evaluate_flight(flight, profile, site, arrivals=arrivals)
    same = True
    worst = 0.0
    for a, b in zip(live.rows, ref.rows, strict=True):
        if a.key in CAUSAL_ROWS:
            print(f"demo: row {a.key} (classed live by the track's mean so far): live "
                  f"{a.stats.count}/{a.denominator} reports, offline {b.stats.count}/"
                  f"{b.denominator}")
            continue
        # the raw radar reports are every row's denominator of radar_reports: shown above
        den_differs = a.denominator != b.denominator and a.spec.denominator != "radar_reports"
        if a.stats.count != b.stats.count or den_differs:
            same = False
            print(f"demo: row {a.key}: live {a.stats.count}/{a.denominator}, "
                  f"offline {b.stats.count}/{b.denominator}")
        elif a.stats.count:
            worst = max(worst, abs(a.stats.mean - b.stats.mean), abs(a.stats.max - b.stats.max))
    name = Path(profile).stem
    order = "" if arrivals is None else " in the node's arrival order"
    if same and worst <= 1e-9:
        print(f"demo: live: profile {name}: the live table equals the offline run's{order} in "
              f"every row but {', '.join(CAUSAL_ROWS)} (largest difference {worst:.1e} m; "
              f"offline check {time.perf_counter() - t0:.1f} s)")
        return 0
    print(f"demo: live: profile {name}: live and offline differ (largest difference in "
          f"mean/max {worst:.3g} m)", file=sys.stderr)
    return 1
