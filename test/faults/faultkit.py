"""Harnesses shared by the fault cases: a fusion node or an evaluator node in one in-process
executor with a node that feeds it and records what it publishes."""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PointStamped, PoseWithCovarianceStamped
from nav_msgs.msg import Odometry
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import NavSatFix
from std_srvs.srv import Trigger

from uav_fusion.core.records import RADAR, RF, Measurement
from uav_fusion.ros import conversions as cv
from uav_fusion.ros.qos import stream_qos

FRAME = "enu_lw1"
T0 = 1759866140.0  # 2025-10-07T19:42:20Z, the synthetic flight's start
R_RADAR = np.diag([25.0, 25.0, 36.0])


def radar_msg(
    t: float, e: float, n: float, u: float = 60.0, R: Any = None, frame: str = FRAME
) -> PoseWithCovarianceStamped:
    m = Measurement(t, RADAR, np.array([e, n, u]), R=np.asarray(R if R is not None else R_RADAR))
    return cv.radar_measurement_to_msg(m, frame)


def rf_msg(t: float, e: float, n: float, frame: str = FRAME) -> PointStamped:
    return cv.rf_to_msg(t, (e, n), frame)


def straight(t: float) -> tuple[float, float, float]:
    """A target flying east at 8 m/s, 300 m east of LW1 (near the radar)."""
    return 300.0 + 8.0 * (t - T0), 0.0, 60.0


class Spinner:
    def __init__(self, ctx: Context, nodes: list[Node]) -> None:
        self.ex = SingleThreadedExecutor(context=ctx)
        for n in nodes:
            self.ex.add_node(n)

    def spin_until(self, cond: Callable[[], bool], limit_s: float = 30.0) -> None:
        end = time.monotonic() + limit_s
        while not cond():
            assert time.monotonic() < end, "condition not reached: the node is stuck"
            self.ex.spin_once(timeout_sec=0.02)

    def spin_for(self, seconds: float) -> None:
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            self.ex.spin_once(timeout_sec=0.02)


class FusionHarness(Spinner):
    """A FusionNode plus an io node publishing radar/rf (and /clock) and recording outputs."""

    def __init__(self, ctx: Context, **params: Any) -> None:
        from uav_fusion.nodes.fusion_node import FusionNode

        params.setdefault("idle_flush_s", 0.0)
        self.fusion = FusionNode(
            context=ctx, parameter_overrides=[Parameter(k, value=v) for k, v in params.items()]
        )
        self.io = Node("fault_io", context=ctx)
        qos = stream_qos(5000)
        self.pub_radar = self.io.create_publisher(PoseWithCovarianceStamped, "radar/pose", qos)
        self.pub_rf = self.io.create_publisher(PointStamped, "rf/fix", qos)
        self.pub_clock = self.io.create_publisher(Clock, "/clock", 10)
        self.odom: list[Odometry] = []
        self.updated: list[Odometry] = []
        self.coasted: list[Odometry] = []
        self.acc: list[Any] = []
        self.diag: list[DiagnosticArray] = []
        sub = self.io.create_subscription
        sub(Odometry, "fusion/odom", self.odom.append, qos)
        sub(Odometry, "fusion/odom/updated", self.updated.append, qos)
        sub(Odometry, "fusion/odom/coasted", self.coasted.append, qos)
        sub(PoseWithCovarianceStamped, "fusion/accepted/radar", self.acc.append, qos)
        sub(PointStamped, "fusion/accepted/rf", self.acc.append, qos)
        sub(DiagnosticArray, "/diagnostics", self.diag.append, 10)
        self.flush_client = self.io.create_client(Trigger, "fusion/flush")
        super().__init__(ctx, [self.fusion, self.io])
        self.spin_until(
            lambda: self.pub_radar.get_subscription_count() > 0
            and self.pub_rf.get_subscription_count() > 0
        )
        self.sent = 0

    def send(self, *msgs: Any) -> None:
        """Publish and wait until the node has received every message sent so far."""
        for m in msgs:
            (self.pub_radar if isinstance(m, PoseWithCovarianceStamped) else self.pub_rf).publish(m)
            self.sent += 1
        self.spin_until(lambda: sum(self.fusion.received.values()) >= self.sent)

    def clock(self, t: float) -> None:
        msg = Clock()
        msg.clock = cv.stamp_from_time(t)
        self.pub_clock.publish(msg)
        want = cv.time_to_ns(t)
        self.spin_until(lambda: self.fusion.get_clock().now().nanoseconds == want)

    def flush(self) -> Trigger.Response:
        assert self.flush_client.wait_for_service(timeout_sec=5.0)
        fut = self.flush_client.call_async(Trigger.Request())
        self.spin_until(fut.done)
        res = fut.result()
        assert res is not None
        return res

    def settle(self) -> None:
        """Flush and wait until every published step has come back."""
        self.flush()
        self.spin_until(lambda: len(self.odom) == self.fusion.steps_published)
        self.spin_until(lambda: len(self.acc) == self.fusion.output.accepted_published)

    def diagnostics(self) -> dict[str, str]:
        return self.fusion.diagnostics()

    def destroy(self) -> None:
        self.fusion.destroy_node()
        self.io.destroy_node()


def accounting(diag: dict[str, str], source: str) -> tuple[int, int, int, int]:
    """(received, used, rejected, dropped) of one input stream from the fusion diagnostics.

    used = measurements that updated or started the track; rejected = measurements the
    estimator refused (NIS gate, range gate, not selected, failed RF attempts ...) by reason;
    dropped = messages that never reached the estimator, by reason.
    """
    received = int(diag[f"received_{source}"])
    used = int(diag.get(f"used_{source}", "0"))
    rejected = sum(int(v) for k, v in diag.items() if k.startswith(f"rejected_{source}_"))
    dropped = sum(
        int(v)
        for k, v in diag.items()
        if k.startswith(f"dropped_{source}_") or k == f"dropped_late_{source}"
    )
    return received, used, rejected, dropped


class EvaluatorHarness(Spinner):
    """An EvaluatorNode plus an io node publishing every topic it listens to."""

    def __init__(self, ctx: Context, **params: Any) -> None:
        from uav_fusion.nodes.evaluator_node import EvaluatorNode

        params.setdefault("log_period_s", 0.0)
        params.setdefault("figures", False)
        self.node = EvaluatorNode(
            context=ctx, parameter_overrides=[Parameter(k, value=v) for k, v in params.items()]
        )
        self.io = Node("fault_eval_io", context=ctx)
        qos = stream_qos(5000)
        pub = self.io.create_publisher
        self.pubs: dict[str, Any] = {
            "truth": pub(NavSatFix, "truth/fix", qos),
            "radar_raw": pub(PoseWithCovarianceStamped, "radar/raw", qos),
            "rf": pub(PointStamped, "rf/fix", qos),
            "acc_radar": pub(PoseWithCovarianceStamped, "fusion/accepted/radar", qos),
            "acc_rf": pub(PointStamped, "fusion/accepted/rf", qos),
            "updated": pub(Odometry, "fusion/odom/updated", qos),
            "coasted": pub(Odometry, "fusion/odom/coasted", qos),
        }
        self.pub_clock = pub(Clock, "/clock", 10)
        super().__init__(ctx, [self.node, self.io])
        self.spin_until(lambda: all(p.get_subscription_count() > 0 for p in self.pubs.values()))
        self.sent = 0

    def send(self, topic: str, *msgs: Any) -> None:
        for m in msgs:
            self.pubs[topic].publish(m)
            self.sent += 1
        self.spin_until(lambda: sum(self.node.received.values()) >= self.sent)

    def clock(self, t: float) -> None:
        msg = Clock()
        msg.clock = cv.stamp_from_time(t)
        self.pub_clock.publish(msg)
        want = cv.time_to_ns(t)
        self.spin_until(lambda: self.node.get_clock().now().nanoseconds == want)

    def destroy(self) -> None:
        self.node.destroy_node()
        self.io.destroy_node()


__all__ = [
    "FRAME",
    "RADAR",
    "RF",
    "R_RADAR",
    "T0",
    "EvaluatorHarness",
    "FusionHarness",
    "accounting",
    "radar_msg",
    "rf_msg",
    "straight",
]
