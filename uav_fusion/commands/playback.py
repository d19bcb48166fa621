"""``uav_fusion demo --bag``: fusion_node and evaluator_node fed by bag_player.

The bag's time drives ``/clock``; with ``--record`` a bag_recorder records the fusion node's
outputs and views and its inputs. The caller compares the live table with the offline run.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Callable
from typing import Any

# What ``demo --bag --record`` records: the fusion node's outputs and views, and the inputs
# (so the recording alone opens in Foxglove / RViz with config/foxglove_layout.json and
# config/uav_fusion.rviz; docs/views.md).
RECORDED_INPUTS = ("radar/pose", "radar/raw", "rf/fix", "truth/fix")
RECORDED_TOPICS = (
    "fusion/odom",
    "fusion/odom/updated",
    "fusion/odom/coasted",
    "fusion/accepted/radar",
    "fusion/accepted/rf",
    "fusion/path",
    "fusion/markers",
    "fusion/fix",
    *RECORDED_INPUTS,
    "/diagnostics",
)
TO_EVALUATOR = ("/radar/raw", "/rf/fix", "/truth/fix")
#: messages the fusion or the evaluator node may lag behind before the player waits (a tenth
#: of the streams' queue depth)
BACKLOG = 100


class _BagGraph:
    """The nodes of one bag run in one rclpy context, spun by one executor."""

    def __init__(self, args: argparse.Namespace) -> None:
        self.args = args
        self.rate = args.rate if args.rate > 0 else 20.0  # the player paces by bag time
        self.nodes: list[Any] = []  # destroyed in reverse order, also after a failed build
        self.end = time.monotonic() + float(args.timeout)

    def build(self, overrides: dict[str, Any], ctx: Any) -> None:
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.impl.logging_severity import LoggingSeverity
        from rclpy.logging import set_logger_level
        from rclpy.parameter import Parameter

        from uav_fusion.nodes.bag_player import BagPlayer
        from uav_fusion.nodes.bag_recorder import BagRecorder
        from uav_fusion.nodes.evaluator_node import EvaluatorNode
        from uav_fusion.nodes.fusion_node import FusionNode

        def params(name: str) -> list[Parameter]:
            return [Parameter(k, value=v) for k, v in overrides[name].items()]

        args = self.args
        self.fusion = FusionNode(context=ctx, parameter_overrides=params("fusion_node"))
        self.nodes.append(self.fusion)
        self.evaluator = EvaluatorNode(context=ctx, parameter_overrides=params("evaluator_node"))
        self.nodes.append(self.evaluator)
        # the fusion node's inputs depend on its profile (radar/pose + rf/fix for the paper's
        # filter, radar/tracks + rf/fixes for the trackers); the player plays what some node
        # of this graph takes, so it does not wait for subscribers to the rest
        self.to_fusion = self.fusion.input_topics
        played = {*self.to_fusion, *TO_EVALUATOR}
        if args.record:
            played |= {"/" + t for t in RECORDED_INPUTS}
        self.player = BagPlayer(
            bag=args.bag,
            context=ctx,
            parameter_overrides=[
                Parameter("rate", value=self.rate),
                Parameter("topics", value=sorted(played)),
            ],
        )
        self.nodes.append(self.player)
        # backpressure: the nodes share this process, so the player waits while a node is
        # more than BACKLOG messages behind (on a loaded machine a high rate would otherwise
        # overflow the reliable queues and lose messages)
        self.player.hold = lambda: max(self._backlog()) > BACKLOG
        self.recorder: BagRecorder | None = None
        if args.record:
            self.recorder = BagRecorder(
                output=args.record,
                context=ctx,
                parameter_overrides=[Parameter("topics", value=list(RECORDED_TOPICS))],
            )
            self.nodes.append(self.recorder)
        if args.quiet:
            for n in self.nodes:
                set_logger_level(n.get_logger().name, LoggingSeverity.WARN)
        self.executor = SingleThreadedExecutor(context=ctx)
        for n in self.nodes:
            self.executor.add_node(n)

    def destroy(self) -> None:
        for n in reversed(self.nodes):
            n.destroy_node()

    def spin_until(self, cond: Callable[[], bool]) -> bool:
        """Spin until ``cond``; False at the timeout or 5 s without a message after the end."""
        fusion, evaluator = self.fusion, self.evaluator
        last, since = -1, time.monotonic()
        while not cond():
            now = time.monotonic()
            n = sum(fusion.received.values()) + sum(evaluator.received.values())
            if n != last:
                last, since = n, now
            if now > self.end or (self.player.finished.is_set() and now - since > 5.0):
                return False
            self.executor.spin_once(timeout_sec=0.02)
        return True

    def play(self) -> bool:
        """Play the bag to the end; True when every message reached the nodes (and recorder)."""
        fusion = self.fusion
        self.player.start()
        ok = self.spin_until(
            lambda: self.player.finished.is_set() and self._backlog()[0] <= 0
        )
        fusion.flush()
        fusion.output.publish_views(force=True)  # the final path and markers
        ok = ok and self.spin_until(lambda: self._backlog()[1] <= 0)
        return ok and self._recorded()

    def _due(self) -> tuple[int, int]:
        """Messages due so far at the fusion node and at the evaluator node."""
        fusion, played = self.fusion, self.player.played
        return (
            sum(played[t] for t in self.to_fusion),
            sum(played[t] for t in TO_EVALUATOR)
            + fusion.output.steps_published
            + fusion.output.accepted_published,
        )

    def _backlog(self) -> tuple[int, int]:
        """Messages due but not yet received, at the fusion and the evaluator node."""
        due_f, due_e = self._due()
        return (
            due_f - sum(self.fusion.received.values()),
            due_e - sum(self.evaluator.received.values()),
        )

    def shortfall(self) -> str:
        """What each node received against what it was due (for the error message)."""
        due_f, due_e = self._due()
        text = (
            f"fusion_node {sum(self.fusion.received.values())} of {due_f}, evaluator_node "
            f"{sum(self.evaluator.received.values())} of {due_e}"
        )
        return text + ("" if self.player.finished.is_set() else "; the bag was not played out")

    def _recorded(self) -> bool:
        """Wait until every step and accepted measurement published is in the bag, close it."""
        rec, fusion = self.recorder, self.fusion
        if rec is None:
            return True
        ok = self.spin_until(
            lambda: (
                rec.received["/fusion/odom"] >= fusion.steps_published
                and rec.received["/fusion/accepted/radar"] + rec.received["/fusion/accepted/rf"]
                >= fusion.output.accepted_published
                and rec.received["/fusion/path"] >= fusion.output.paths_published
                and rec.received["/fusion/markers"] >= fusion.output.markers_published
            )
        )
        written = rec.close()
        print(
            f"demo: recorded {written.message_count} messages into {self.args.record}", flush=True
        )
        return ok


def run_bag(args: argparse.Namespace, overrides: dict[str, Any]) -> Any:
    """Play ``args.bag`` into the fusion and evaluator nodes; the live Evaluation, or None."""
    import rclpy
    from rclpy.context import Context

    from uav_fusion.core.scoring.evaluation import format_table

    ctx = Context()
    rclpy.init(context=ctx, args=[])
    graph = _BagGraph(args)
    try:
        graph.build(overrides, ctx)
        print(f"demo: playing {args.bag} at {graph.rate:g}x", flush=True)
        t0 = time.monotonic()
        ok = graph.play()
        if getattr(graph.player, "error", None):
            print(f"demo: bag_player: {graph.player.error}", file=sys.stderr)
            return None
        if not ok:
            print(
                f"demo: not every message of the bag arrived ({graph.shortfall()})",
                file=sys.stderr,
            )
            return None
        wall = time.monotonic() - t0
        live = graph.evaluator.evaluate()
        files = graph.evaluator.write_report()
        played = sum(graph.player.played.values())
        steps = graph.fusion.steps_published
        dropped = dict(graph.fusion.dropped)
    finally:
        graph.destroy()
        rclpy.shutdown(context=ctx)
    print()
    print(format_table(live))
    print()
    print(
        f"demo: {played} messages played in {wall:.1f} s wall; {steps} filter "
        f"steps; fusion drops: {dropped or 'none'}"
    )
    print(f"demo: report written to {files.folder}")
    return live
