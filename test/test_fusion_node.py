"""fusion_node in-process: time order restored from shuffled arrivals, equal to the core run,
bad messages counted, flush service, diagnostics, parameters."""

from __future__ import annotations

import random
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PointStamped, PoseWithCovarianceStamped
from nav_msgs.msg import Odometry
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from std_srvs.srv import Trigger
from test_graph_flight import write_flight

from uav_fusion.core.data import load_flight
from uav_fusion.core.estimators import flight_measurements, load_profile, run_flight
from uav_fusion.core.records import RADAR, Measurement
from uav_fusion.core.site import load_site
from uav_fusion.nodes.fusion_node import FusionNode
from uav_fusion.ros import conversions as cv
from uav_fusion.ros import odometry as od
from uav_fusion.ros.params import ParamError
from uav_fusion.ros.qos import stream_qos

FRAME = "enu_lw1"


@pytest.fixture(scope="module")
def flight_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return write_flight(tmp_path_factory.mktemp("flight") / "short", seconds=30.0)


class Harness:
    """A fusion node plus a node that feeds it and records what it publishes."""

    def __init__(self, ctx: Context, **params: Any) -> None:
        self.fusion = FusionNode(
            context=ctx,
            parameter_overrides=[Parameter(k, value=v) for k, v in params.items()],
        )
        self.io = Node("io", context=ctx)
        qos = stream_qos(5000)
        self.pub_radar = self.io.create_publisher(PoseWithCovarianceStamped, "radar/pose", qos)
        self.pub_rf = self.io.create_publisher(PointStamped, "rf/fix", qos)
        self.odom: list[Odometry] = []
        self.updated: list[Odometry] = []
        self.coasted: list[Odometry] = []
        self.acc_radar: list[PoseWithCovarianceStamped] = []
        self.acc_rf: list[PointStamped] = []
        self.diag: list[DiagnosticArray] = []
        sub = self.io.create_subscription
        sub(Odometry, "fusion/odom", self.odom.append, qos)
        sub(Odometry, "fusion/odom/updated", self.updated.append, qos)
        sub(Odometry, "fusion/odom/coasted", self.coasted.append, qos)
        sub(PoseWithCovarianceStamped, "fusion/accepted/radar", self.acc_radar.append, qos)
        sub(PointStamped, "fusion/accepted/rf", self.acc_rf.append, qos)
        sub(DiagnosticArray, "/diagnostics", self.diag.append, 10)
        self.flush_client = self.io.create_client(Trigger, "fusion/flush")
        self.ex = SingleThreadedExecutor(context=ctx)
        self.ex.add_node(self.fusion)
        self.ex.add_node(self.io)
        self.spin_until(
            lambda: (
                self.pub_radar.get_subscription_count() > 0
                and self.pub_rf.get_subscription_count() > 0
            )
        )

    def spin_until(self, cond: Callable[[], bool], limit_s: float = 60.0) -> None:
        end = time.monotonic() + limit_s
        while not cond():
            assert time.monotonic() < end, "condition not reached"
            self.ex.spin_once(timeout_sec=0.02)

    def flush(self) -> Trigger.Response:
        assert self.flush_client.wait_for_service(timeout_sec=5.0)
        fut = self.flush_client.call_async(Trigger.Request())
        self.spin_until(fut.done)
        res = fut.result()
        assert res is not None
        return res

    def destroy(self) -> None:
        self.fusion.destroy_node()
        self.io.destroy_node()


def _messages(flight_dir: Path) -> tuple[list[tuple[str, Any]], list[tuple[str, Any]]]:
    """(radar messages, RF messages) in time order, as the replays publish them."""
    site = load_site()
    flight = load_flight(flight_dir, site)
    profile = load_profile("paper")
    radar: list[tuple[str, Any]] = []
    for item in flight_measurements(flight, profile, site):
        group = item if isinstance(item, list) else [item]
        for m in group:
            if m.source == RADAR:
                radar.append(("radar", cv.radar_measurement_to_msg(m, FRAME, profile.r_radar)))
    rf = [("rf", cv.rf_attempt_to_msg(a, FRAME)) for a in flight.rf]
    return radar, rf


def _offline(flight_dir: Path) -> list[tuple[float, np.ndarray, bool, bool]]:
    """(t, x, updated, validated) of every filter step of the offline run."""
    site = load_site()
    res = run_flight(load_flight(flight_dir, site), load_profile("paper"), site)
    return [(s.t, s.x, s.updated, s.validated) for s in res.steps if s.updated or s.coasted]


def _feed(h: Harness, order: list[tuple[str, Any]]) -> None:
    for i, (kind, msg) in enumerate(order):
        (h.pub_radar if kind == "radar" else h.pub_rf).publish(msg)
        if i % 3 == 2:
            # Let the node take them. The executor takes one message per subscription in
            # turn, so between two topics the skew of arrival is bounded by what is queued:
            # a few messages (< 1 s of sensor time) here, like the replay's batch span.
            def taken(i: int = i) -> bool:
                return sum(h.fusion.received.values()) >= i + 1

            h.spin_until(taken)


def _shuffled_streams(
    radar: list[tuple[str, Any]], rf: list[tuple[str, Any]], delay_s: float, seed: int
) -> list[tuple[str, Any]]:
    """Interleave the two FIFO streams; RF arrives up to ``delay_s`` sensor seconds late."""
    rng = random.Random(seed)
    keyed = []
    for k, (kind, msg) in enumerate(radar):
        keyed.append((cv.time_from_stamp(msg.header.stamp), 0, k, kind, msg))
    last = -1.0
    for k, (kind, msg) in enumerate(rf):
        last = max(last, cv.time_from_stamp(msg.header.stamp) + rng.uniform(0.0, delay_s))
        keyed.append((last, 1, k, kind, msg))
    keyed.sort(key=lambda e: (e[0], e[1], e[2]))
    return [(kind, msg) for _, _, _, kind, msg in keyed]


@pytest.mark.parametrize(("delay_s", "seed"), [(0.0, 0), (1.5, 1), (1.9, 2)])
def test_late_rf_is_reordered_and_output_equals_offline(
    ctx: Context, flight_dir: Path, delay_s: float, seed: int
) -> None:
    radar, rf = _messages(flight_dir)
    expected = _offline(flight_dir)
    h = Harness(ctx, reorder_window_s=2.0, idle_flush_s=0.0)
    _feed(h, _shuffled_streams(radar, rf, delay_s, seed))
    h.spin_until(lambda: sum(h.fusion.received.values()) == len(radar) + len(rf))
    res = h.flush()
    assert res.success
    h.spin_until(lambda: len(h.odom) == len(expected))
    got = [od.odometry_to_state(o) for o in h.odom]
    assert [g.t for g in got] == [e[0] for e in expected]
    assert np.max(np.abs(np.array([g.x for g in got]) - np.array([e[1] for e in expected]))) < 1e-9
    n_upd = sum(1 for e in expected if e[2])
    h.spin_until(lambda: len(h.updated) == n_upd and len(h.coasted) == len(expected) - n_upd)
    n_valid = sum(1 for e in expected if e[3])  # track starts are not "accepted"
    h.spin_until(lambda: len(h.acc_radar) + len(h.acc_rf) == n_valid)
    assert len(h.acc_rf) > 0 and len(h.coasted) > 0  # both paths exercised
    assert not h.fusion.dropped
    h.destroy()


def test_rf_later_than_the_window_is_dropped_and_counted(ctx: Context, flight_dir: Path) -> None:
    radar, rf = _messages(flight_dir)
    h = Harness(ctx, reorder_window_s=0.5, idle_flush_s=0.0)
    _feed(h, radar + rf)  # every RF message after every radar message
    h.spin_until(lambda: sum(h.fusion.received.values()) == len(radar) + len(rf))
    h.flush()
    assert h.fusion.dropped["late_rf"] > 0
    diag = h.fusion.diagnostics()
    assert int(diag["dropped_late_rf"]) == h.fusion.dropped["late_rf"]
    h.destroy()


def test_bad_messages_are_dropped_by_reason(ctx: Context) -> None:
    h = Harness(ctx, idle_flush_s=0.0)
    t0 = 1759866140.0
    good = Measurement(t0, RADAR, np.array([10.0, 20.0, 30.0]), R=np.eye(3) * 4.0)
    nan = cv.radar_measurement_to_msg(good, FRAME)
    nan.pose.pose.position.y = float("nan")
    badcov = cv.radar_measurement_to_msg(good, FRAME)
    badcov.pose.covariance[0] = -5.0
    wrong = cv.radar_measurement_to_msg(good, "map")
    partial = cv.rf_to_msg(t0, (1.0, 2.0), FRAME)
    partial.point.x = float("nan")
    for m in (nan, badcov, wrong):
        h.pub_radar.publish(m)
    h.pub_rf.publish(partial)
    h.spin_until(lambda: sum(h.fusion.received.values()) == 4)
    assert h.fusion.dropped == {
        "radar_nan": 1,
        "radar_bad_covariance": 1,
        "radar_wrong_frame": 1,
        "rf_nan": 1,
    }
    assert h.flush().success
    assert h.odom == [] and h.fusion.pipeline.buffer.pending == 0
    h.destroy()


@pytest.mark.parametrize("window", [2.0, 0.0], ids=["reorder_window", "zero_wait"])
def test_frame_candidates_with_one_stamp_are_processed_as_one_frame(
    ctx: Context, window: float
) -> None:
    """Radar reports sharing a stamp are one frame of candidates, waiting for each other in a
    reorder window or, with zero wait, the later message joining the frame already fused."""
    h = Harness(ctx, reorder_window_s=window, idle_flush_s=0.0)
    t0 = 1759866140.0
    # a track, then a frame of two candidates: the nearer one updates, the other is not used
    first = Measurement(t0, RADAR, np.array([300.0, 0.0, 50.0]), R=np.eye(3) * 25.0)
    near = Measurement(t0 + 0.25, RADAR, np.array([301.0, 0.5, 50.0]), R=np.eye(3) * 25.0)
    far = Measurement(t0 + 0.25, RADAR, np.array([340.0, 30.0, 60.0]), R=np.eye(3) * 25.0)
    for m in (first, far, near):
        h.pub_radar.publish(cv.radar_measurement_to_msg(m, FRAME))
    h.spin_until(lambda: h.fusion.received[RADAR] == 3)
    h.flush()
    # the first report starts the track (an update, not an accepted measurement)
    h.spin_until(lambda: len(h.acc_radar) >= 1)
    # the frame's nearer candidate updated the track, the other was not selected
    assert h.acc_radar[-1].pose.pose.position.x == 301.0
    if window == 0.0:  # the final track: as if the frame had come in one go
        rw = h.fusion.pipeline.rewinder
        assert rw is not None and rw.rewinds == 1
        assert [(s.status, s.reason) for s in rw.steps] == [
            ("initialised", None), ("discarded", "not_selected"), ("updated", None)]
    else:
        h.spin_until(lambda: len(h.odom) == 2 and len(h.updated) == 2)
        assert h.fusion.output.statuses["discarded"] == 1
    h.destroy()


def test_idle_timer_flushes_the_buffer(ctx: Context) -> None:
    h = Harness(ctx, reorder_window_s=2.0, idle_flush_s=0.2)
    m = Measurement(1759866140.0, RADAR, np.array([300.0, 0.0, 50.0]), R=np.eye(3))
    h.pub_radar.publish(cv.radar_measurement_to_msg(m, FRAME))
    h.spin_until(lambda: h.fusion.received[RADAR] == 1)
    assert h.fusion.pipeline.buffer.pending == 1  # the RF stream has not moved past it yet
    h.spin_until(lambda: len(h.odom) == 1, limit_s=10.0)
    assert h.fusion.pipeline.buffer.pending == 0
    h.destroy()


def test_diagnostics_are_published(ctx: Context) -> None:
    h = Harness(ctx, diagnostics_period_s=0.1)
    h.spin_until(lambda: len(h.diag) > 0, limit_s=10.0)
    st = h.diag[0].status[0]
    keys = {kv.key for kv in st.values}
    assert {"received_radar", "received_rf", "buffer_pending", "steps_published"} <= keys
    h.destroy()


def test_parameters_validated_at_start_and_at_run_time(ctx: Context) -> None:
    with pytest.raises(ParamError, match="reorder_window_s"):
        FusionNode(context=ctx, parameter_overrides=[Parameter("reorder_window_s", value=-1.0)])
    with pytest.raises(ParamError, match="child_frame_id"):
        FusionNode(context=ctx, parameter_overrides=[Parameter("child_frame_id", value="")])
    for lag in (0.0, -1.0):
        with pytest.raises(ParamError, match="max_lag_s"):
            FusionNode(context=ctx, parameter_overrides=[Parameter("max_lag_s", value=lag)])
    with pytest.raises(Exception, match="nope"):
        FusionNode(context=ctx, parameter_overrides=[Parameter("profile", value="nope")])
    node = FusionNode(context=ctx)
    bad = node.set_parameters([Parameter("diagnostics_period_s", value=0.0)])[0]
    assert not bad.successful and "diagnostics_period_s" in bad.reason
    ok = node.set_parameters([Parameter("diagnostics_period_s", value=0.5)])[0]
    assert ok.successful
    assert node._diag_timer.timer_period_ns == 500_000_000
    ro = node.set_parameters([Parameter("reorder_window_s", value=3.0)])[0]
    assert not ro.successful
    node.destroy_node()


def test_main_exits_2_on_bad_parameter() -> None:
    from uav_fusion.nodes.fusion_node import main

    assert main(["fusion_node", "--ros-args", "-p", "reorder_window_s:=-2.0"]) == 2
    assert main(["fusion_node", "--ros-args", "-p", "max_lag_s:=0.0"]) == 2
