"""graph: the whole node graph in one process, run once over a flight.

Creates ``truth_replay``, ``rf_replay``, ``radar_replay``, ``fusion_node`` and (unless
disabled) ``evaluator_node`` in one rclpy context, each reading its parameters as usual
(``--ros-args --params-file config/graph.yaml``; node names are the sections). The three
replays hand their streams to **one** :class:`~uav_fusion.ros.replay.ReplayDriver`, so every
message is published in one global time order on one timeline, and ``/clock`` follows it.
The timeline's settings (``rate``, ``clock_period_s``, ``batch_size``,
``wait_for_subscribers_s``) are ``truth_replay``'s; ``delay_s`` stays per replay.

With ``rate = 0`` a batch is published only once the fusion and evaluator nodes have taken
every earlier message, so nothing is lost and the run is as fast as the nodes allow.
After the last message, the fusion node's reorder buffer is flushed, the graph waits until
the evaluator has every output, writes the evaluator's report and exits.

Messages go through DDS as between separate processes; the executor is single-threaded
(``--threads N`` outside ``--ros-args`` selects a multi-threaded one).
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

from rclpy.context import Context
from rclpy.executors import Executor, MultiThreadedExecutor, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.utilities import get_default_context

from uav_fusion.core.records import RADAR, RF
from uav_fusion.nodes.fusion_node import FusionNode
from uav_fusion.nodes.radar_replay import RadarReplay
from uav_fusion.nodes.rf_replay import RfReplay
from uav_fusion.nodes.truth_replay import TruthReplay
from uav_fusion.ros.app import EXIT_FAILED, EXIT_OK, App, UsageError, run_app
from uav_fusion.ros.replay import ReplayDriver, ReplayNode, flight_span

Overrides = dict[str, dict[str, Any]]


@dataclass
class GraphResult:
    """What one run did."""

    ok: bool
    published: dict[str, int] = field(default_factory=dict)
    steps: int = 0
    report: str | None = None
    wall_s: float = 0.0
    message: str = ""
    #: messages published but never received, by "<subscriber node>: <stream>" (transport loss)
    lost: dict[str, int] = field(default_factory=dict)


def _params(values: dict[str, Any] | None) -> list[Parameter]:
    return [Parameter(k, value=v) for k, v in (values or {}).items()]


class Graph:
    """The nodes, their shared replay timeline and an executor (see the module docstring).

    ``overrides`` maps a node name to parameter values that take precedence over any
    ``--params-file``; ``evaluator`` False leaves the evaluator out.
    """

    def __init__(
        self,
        context: Context | None = None,
        overrides: Overrides | None = None,
        *,
        evaluator: bool = True,
        threads: int = 1,
    ) -> None:
        self.context = context if context is not None else get_default_context()
        ov = overrides or {}
        self.nodes: list[Node] = []
        self.replays: list[ReplayNode] = []

        def make(cls: Callable[..., Node], name: str) -> Any:
            node = cls(context=self.context, parameter_overrides=_params(ov.get(name)))
            self.nodes.append(node)
            return node

        try:
            self.truth: TruthReplay = make(TruthReplay, "truth_replay")
            self.rf: RfReplay = make(RfReplay, "rf_replay")
            self.radar: RadarReplay = make(RadarReplay, "radar_replay")
            self.fusion: FusionNode = make(FusionNode, "fusion_node")
            self.evaluator: Any = None
            if evaluator:
                from uav_fusion.nodes.evaluator_node import EvaluatorNode

                self.evaluator = make(EvaluatorNode, "evaluator_node")
        except BaseException:
            self.destroy()
            raise
        # the fusion node's inputs: radar/pose + rf/fix (paper) or the clouds (tracker
        # profiles); streams nobody in the graph reads are not replayed
        if self.fusion.input.frames:
            self.radar.pose_stream = False
            if self.radar.pub_tracks is None or self.rf.pub_fixes is None:
                self.destroy()
                raise UsageError(
                    "fusion_node runs a tracker: radar_replay publish_tracks and "
                    "rf_replay publish_fixes must be true"
                )
            self.fusion_radar_pub: Any = self.radar.pub_tracks
            self.fusion_rf_pub: Any = self.rf.pub_fixes
        else:
            self.radar.pub_tracks = None
            self.rf.pub_fixes = None
            self.fusion_radar_pub = self.radar.pub
            self.fusion_rf_pub = self.rf.pub
        self.replays = [self.truth, self.rf, self.radar]
        tp = self.truth.p
        self.rate = float(tp["rate"])
        self._lost_offset = (0, 0)  # messages declared lost (fusion, evaluator)
        self._stall: tuple[tuple[int, int], float] | None = None
        self.loss_detected = False
        #: polled by the run loops: True stops them (the runtime's signal flag)
        self.stop_requested: Callable[[], bool] = lambda: False
        self.driver = ReplayDriver(
            self.truth,
            rate=self.rate,
            publish_clock=True,
            # rate 0: a short tick, since each batch waits for the consumers to catch up
            clock_period_s=min(float(tp["clock_period_s"]), 0.002)
            if self.rate == 0.0
            else float(tp["clock_period_s"]),
            wait_for_subscribers_s=float(tp["wait_for_subscribers_s"]),
            batch_size=int(tp["batch_size"]),
            span=flight_span(self.truth.flight),
            batch_span_s=self._batch_span(),
            drained=self.drained,
        )
        self._streams: dict[str, list[Any]] = {}
        for rnode in self.replays:
            for pub, items in rnode.streams():
                self.driver.add(pub, items, float(rnode.p["delay_s"]))
                self._streams.setdefault(rnode.get_name(), []).append(pub)
        self.executor: Executor = (
            SingleThreadedExecutor(context=self.context)
            if threads <= 1
            else MultiThreadedExecutor(num_threads=threads, context=self.context)
        )
        for node in self.nodes:
            self.executor.add_node(node)

    def _batch_span(self) -> float:
        """Sensor seconds one batch may span so that nothing reaches the fusion node late.

        Inside a batch the executor may take one topic's messages before another's, so a
        stream can lag by up to the span; a replay's ``delay_s`` adds to that. Both must
        stay inside what the fusion node takes late (its reorder window, or with zero wait
        ``max_lag_s``): span <= (that - largest delay) / 2.
        """
        window = float(self.fusion.p["reorder_window_s"]) or float(self.fusion.p["max_lag_s"])
        delay = max(float(r.p["delay_s"]) for r in (self.truth, self.rf, self.radar))
        return max(0.01, min(float(self.truth.p["batch_span_s"]), 0.5 * (window - delay)))

    # --- progress -------------------------------------------------------------------------
    def published(self, node: str) -> int:
        return sum(self.driver.published_to(p) for p in self._streams.get(node, []))

    def fusion_inputs_published(self) -> int:
        return self.driver.published_to(self.fusion_radar_pub) + self.driver.published_to(
            self.fusion_rf_pub
        )

    def fusion_caught_up(self) -> bool:
        return self._fusion_count() + self._lost_offset[0] >= self.fusion_inputs_published()

    def _evaluator_truth_pubs(self) -> list[Any]:
        """The truth replay's publishers the evaluator reads: truth/fix, and the per-vehicle
        topics it scores tracks against."""
        pubs: list[Any] = [self.truth.pub]
        ev = self.evaluator
        if ev is not None and ev.tracks_topic:
            pubs += [p for v, p in self.truth.vehicle_pubs.items() if v in ev.vehicle_topics]
        return pubs

    def evaluator_expected(self) -> int:
        f = self.fusion
        n = sum(self.driver.published_to(p) for p in self._evaluator_truth_pubs())
        n += self.driver.published_to(self.rf.pub)
        if self.radar.pub_raw is not None:
            n += self.driver.published_to(self.radar.pub_raw)
        if self.evaluator is not None and bool(self.evaluator.grid_topic):
            n += f.output.grid_published
        if self.evaluator is not None and bool(self.evaluator.tracks_topic):
            n += f.output.tracks_published
        return n + f.output.steps_published + f.output.accepted_published

    def evaluator_caught_up(self) -> bool:
        if self.evaluator is None:
            return True
        return self._evaluator_count() + self._lost_offset[1] >= self.evaluator_expected()

    def drained(self) -> bool:
        """Have the consumers taken every message published so far?

        If they stop receiving for STALL_S while messages are missing, those messages were
        lost in transport (a queue overwrote them): the loss is recorded (see
        :meth:`lost_messages`, :attr:`GraphResult.lost`) and the replay goes on at its rate
        without waiting for the consumers any more.
        """
        if self.loss_detected or (self.fusion_caught_up() and self.evaluator_caught_up()):
            self._stall = None
            return True
        now = time.monotonic()
        n = (self._fusion_count(), self._evaluator_count())
        if self._stall is None or self._stall[0] != n:
            self._stall = (n, now)
            return False
        if now - self._stall[1] <= self.STALL_S:
            return False
        self._lost_offset = (
            max(0, self.fusion_inputs_published() - n[0]),
            max(0, self.evaluator_expected() - n[1]),
        )
        self.loss_detected = True
        self._stall = None
        return True

    # --- running --------------------------------------------------------------------------
    def spin_until(self, cond: Callable[[], bool], timeout_s: float) -> bool:
        end = time.monotonic() + timeout_s
        while not cond():
            if time.monotonic() > end or not self.context.ok() or self.stop_requested():
                return False
            self.executor.spin_once(timeout_sec=0.02)
        return True

    def run(self, timeout_s: float = 3600.0, write_report: bool = True) -> GraphResult:
        """Replay the flight once, flush, and (with an evaluator) write the report."""
        t0 = time.monotonic()
        self.driver.start()
        end = t0 + timeout_s
        res = GraphResult(ok=False)
        if not self.spin_until(lambda: self.driver.done, timeout_s):
            res.message = (
                f"replay did not finish in {timeout_s:g} s ({self.driver.remaining} left)"
            )
            return res
        if not self._until_caught_up(self.fusion_caught_up, self._fusion_count, end):
            return self._lost(res, "fusion_node")
        self.fusion.flush()
        if not self._until_caught_up(self.evaluator_caught_up, self._evaluator_count, end):
            return self._lost(res, "evaluator_node")
        if self.loss_detected or self.lost_messages():
            return self._lost(res, "detected while replaying")
        res.ok = True
        res.steps = self.fusion.steps_published
        res.published = {n.get_name(): self.published(n.get_name()) for n in self.replays}
        if self.evaluator is not None and write_report:
            files = self.evaluator.write_report()
            res.report = str(files.folder)
        res.wall_s = time.monotonic() - t0
        return res

    #: wall seconds without a single new message after which missing messages count as lost
    STALL_S = 2.0

    def _fusion_count(self) -> int:
        return int(sum(self.fusion.received.values()))

    def _evaluator_count(self) -> int:
        return 0 if self.evaluator is None else int(sum(self.evaluator.received.values()))

    def _until_caught_up(
        self, caught_up: Callable[[], bool], count: Callable[[], int], end: float
    ) -> bool:
        """Spin until ``caught_up``; False once nothing new arrived for STALL_S or at ``end``."""
        last, since = count(), time.monotonic()
        while not caught_up():
            now = time.monotonic()
            if now > end or not self.context.ok() or self.stop_requested():
                return False
            n = count()
            if n != last:
                last, since = n, now
            elif now - since > self.STALL_S:
                return False
            self.executor.spin_once(timeout_sec=0.02)
        return True

    def lost_messages(self) -> dict[str, int]:
        """Published minus received, per subscriber and stream (nonzero entries only)."""
        f = self.fusion
        pairs = [
            ("fusion_node: radar", self.driver.published_to(self.fusion_radar_pub),
             f.received[RADAR]),
            ("fusion_node: rf", self.driver.published_to(self.fusion_rf_pub), f.received[RF]),
        ]
        ev = self.evaluator
        if ev is not None:
            got = ev.received
            pairs += [
                ("evaluator_node: truth", self.driver.published_to(self.truth.pub),
                 got[ev.truth_topic]),
                ("evaluator_node: rf", self.driver.published_to(self.rf.pub), got[ev.rf_topic]),
            ]
            if self.radar.pub_raw is not None:
                sent = self.driver.published_to(self.radar.pub_raw)
                pairs.append(("evaluator_node: radar raw", sent, got[ev.radar_raw_topic]))
        return {k: int(a - b) for k, a, b in pairs if a > b}

    def _lost(self, res: GraphResult, who: str) -> GraphResult:
        res.lost = self.lost_messages()
        res.steps = self.fusion.steps_published
        res.published = {n.get_name(): self.published(n.get_name()) for n in self.replays}
        parts = ", ".join(f"{k} {v}" for k, v in sorted(res.lost.items())) or "none counted"
        res.message = (
            f"messages were lost in transport ({who} stopped receiving): {parts}; the "
            "publishing rate is beyond what the graph accepts (use a lower rate or rate 0)"
        )
        return res

    def destroy(self) -> None:
        for node in reversed(self.nodes):
            node.destroy_node()
        self.nodes.clear()


def main(args: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="graph", description=__doc__.split("\n")[0])
    parser.add_argument("--threads", type=int, default=1, help="executor threads (default 1)")
    parser.add_argument("--no-evaluator", action="store_true", help="leave the evaluator out")
    parser.add_argument("--timeout", type=float, default=3600.0, help="give up after seconds")

    def build(plain: list[str]) -> App:
        try:
            opts = parser.parse_args(plain)
        except SystemExit:
            raise UsageError(parser.format_usage().strip()) from None
        graph = Graph(evaluator=not opts.no_evaluator, threads=opts.threads)

        def run(stop_requested: Callable[[], bool]) -> int:
            graph.stop_requested = stop_requested
            res = graph.run(timeout_s=opts.timeout)
            log = graph.truth.get_logger()
            if stop_requested():
                log.info("stopped by a signal before the replay finished")
                return EXIT_OK
            if not res.ok:
                log.error(res.message)
                return EXIT_FAILED
            log.info(
                f"done in {res.wall_s:.1f} s: published {res.published}, "
                f"{res.steps} filter steps" + (f"; report in {res.report}" if res.report else "")
            )
            return EXIT_OK

        return App("graph", list(graph.nodes), run=run, executor=graph.executor,
                   extra={"threads": opts.threads})

    return run_app("graph", build, args)


if __name__ == "__main__":
    sys.exit(main())
