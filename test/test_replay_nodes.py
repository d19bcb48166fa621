"""Replay nodes in-process: every record arrives, stamps are sensor times, /clock drives
followers, parameters are validated."""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
from geometry_msgs.msg import PointStamped
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import NavSatFix
from test_graph_flight import write_flight

from uav_fusion.core.data import load_flight
from uav_fusion.nodes.rf_replay import RfReplay
from uav_fusion.nodes.truth_replay import TruthReplay
from uav_fusion.ros import conversions as cv
from uav_fusion.ros.params import ParamError
from uav_fusion.ros.qos import stream_qos


@pytest.fixture(scope="module")
def flight_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return write_flight(tmp_path_factory.mktemp("flight") / "short", seconds=20.0)


def _params(**kw: Any) -> list[Parameter]:
    return [Parameter(k, value=v) for k, v in kw.items()]


class Collector(Node):
    def __init__(self, context: Context, topics: dict[str, type]) -> None:
        super().__init__("collector", context=context)
        self.got: dict[str, list[Any]] = {t: [] for t in topics}
        for topic, typ in topics.items():
            qos = stream_qos(1000) if topic != "/clock" else 10
            self.create_subscription(typ, topic, self._cb(topic), qos)

    def _cb(self, topic: str) -> Callable[[Any], None]:
        return lambda msg: self.got[topic].append(msg)


def spin_until(ex: SingleThreadedExecutor, cond: Callable[[], bool], limit_s: float = 60.0) -> None:
    end = time.monotonic() + limit_s
    while not cond():
        assert time.monotonic() < end, "condition not reached"
        ex.spin_once(timeout_sec=0.05)


def test_rf_and_truth_replay_publish_every_record(ctx: Context, flight_dir: Path) -> None:
    flight = load_flight(flight_dir)
    common = {"flight_dir": str(flight_dir), "rate": 0.0, "wait_for_subscribers_s": 5.0}
    rf = RfReplay(context=ctx, parameter_overrides=_params(**common))
    truth = TruthReplay(context=ctx, parameter_overrides=_params(**common))
    col = Collector(ctx, {"rf/fix": PointStamped, "truth/fix": NavSatFix, "/clock": Clock})
    ex = SingleThreadedExecutor(context=ctx)
    for n in (rf, truth, col):
        ex.add_node(n)
    rf.start_standalone()
    truth.start_standalone()
    end = max(flight.truth[-1].t, flight.rf[-1].t, flight.radar[-1].t)
    spin_until(
        ex,
        lambda: len(col.got["rf/fix"]) == len(flight.rf)
        and len(col.got["truth/fix"]) == len(flight.truth)
        and bool(col.got["/clock"])
        and cv.time_from_stamp(col.got["/clock"][-1].clock) == end,
    )
    assert rf.finished and truth.finished
    # RF: stamps and positions exact, failed attempts as NaN
    for a, msg in zip(flight.rf, col.got["rf/fix"], strict=True):
        assert cv.time_from_stamp(msg.header.stamp) == a.t
        assert msg.header.frame_id == "enu_lw1"
        if a.ok:
            assert (msg.point.x, msg.point.y, msg.point.z) == (a.e, a.n, 0.0)
        else:
            assert cv.is_failed_rf(msg)
    for f, msg in zip(flight.truth, col.got["truth/fix"], strict=True):
        back = cv.navsatfix_to_truth(msg, truth.site)
        assert (back.t, back.e, back.n, back.u) == (f.t, f.e, f.n, f.u)
    # the clock is monotonic and ends at the flight's last time
    clock = [cv.time_from_stamp(c.clock) for c in col.got["/clock"]]
    assert clock == sorted(clock)
    assert clock[0] == min(flight.truth[0].t, flight.rf[0].t, flight.radar[0].t)
    for n in (rf, truth, col):
        n.destroy_node()


def test_follower_replay_follows_the_simulated_clock(ctx: Context, flight_dir: Path) -> None:
    flight = load_flight(flight_dir)
    truth = TruthReplay(
        context=ctx,
        parameter_overrides=_params(flight_dir=str(flight_dir), rate=40.0),
    )
    rf = RfReplay(
        context=ctx,
        parameter_overrides=_params(flight_dir=str(flight_dir), rate=1.0, use_sim_time=True),
    )
    seen: list[tuple[float, float]] = []  # (stamp, follower's sim clock at arrival)

    col = Collector(ctx, {"truth/fix": NavSatFix})

    def on_fix(m: PointStamped) -> None:
        seen.append((cv.time_from_stamp(m.header.stamp), rf.get_clock().now().nanoseconds * 1e-9))

    col.create_subscription(PointStamped, "rf/fix", on_fix, stream_qos(1000))
    ex = SingleThreadedExecutor(context=ctx)
    for n in (truth, rf, col):
        ex.add_node(n)
    truth.start_standalone()
    rf.start_standalone()
    # rate=1.0 on the follower is ignored: it follows the 40x clock, so 20 s take ~0.5 s
    spin_until(ex, lambda: len(seen) == len(flight.rf), limit_s=15.0)
    assert rf.get_parameter("use_sim_time").value is True
    assert rf.get_clock().now().nanoseconds > 0
    # each RF message was published only once the simulated clock had reached its stamp
    for stamp, clock_at_arrival in seen:
        assert clock_at_arrival >= stamp - 1e-6
    for n in (truth, rf, col):
        n.destroy_node()


def test_min_subscribers_holds_the_first_message_until_every_reader_is_there(
    ctx: Context, flight_dir: Path
) -> None:
    """With min_subscribers 2 a replay waits for the second reader of its stream, so both
    readers receive every message (volatile QoS gives a late reader nothing old)."""
    flight = load_flight(flight_dir)
    rf = RfReplay(context=ctx, parameter_overrides=_params(
        flight_dir=str(flight_dir), rate=0.0, min_subscribers=2, wait_for_subscribers_s=60.0,
        publish_fixes=False))
    first = Collector(ctx, {"rf/fix": PointStamped})
    ex = SingleThreadedExecutor(context=ctx)
    for n in (rf, first):
        ex.add_node(n)
    drv = rf.start_standalone()
    spin_until(ex, lambda: rf.pub.get_subscription_count() == 1)
    end = time.monotonic() + 1.0  # 50 ticks of the replay's timer with one reader only
    while time.monotonic() < end:
        ex.spin_once(timeout_sec=0.05)
    assert drv.remaining == len(flight.rf) and first.got["rf/fix"] == []
    second = Node("second", context=ctx)
    got2: list[PointStamped] = []
    second.create_subscription(PointStamped, "rf/fix", got2.append, stream_qos(1000))
    ex.add_node(second)
    spin_until(ex, lambda: len(got2) == len(first.got["rf/fix"]) == len(flight.rf))
    assert [m.header.stamp for m in got2] == [m.header.stamp for m in first.got["rf/fix"]]
    for node in (rf, first, second):
        node.destroy_node()


def test_delay_parameter_publishes_late_but_keeps_stamps(ctx: Context, flight_dir: Path) -> None:
    flight = load_flight(flight_dir)
    rf = RfReplay(
        context=ctx,
        parameter_overrides=_params(
            flight_dir=str(flight_dir), rate=0.0, delay_s=1.5, publish_fixes=False
        ),
    )
    col = Collector(ctx, {"rf/fix": PointStamped})
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(rf)
    ex.add_node(col)
    drv = rf.start_standalone()
    assert [e.due for e in drv.events] == [a.t + 1.5 for a in flight.rf]
    spin_until(ex, lambda: len(col.got["rf/fix"]) == len(flight.rf))
    assert [cv.time_from_stamp(m.header.stamp) for m in col.got["rf/fix"]] == [
        a.t for a in flight.rf
    ]
    rf.destroy_node()
    col.destroy_node()


@pytest.mark.parametrize(
    ("overrides", "needle"),
    [
        ({"rate": -1.0}, "rate"),
        ({"rate": 2}, "rate"),  # an integer where a float is expected
        ({"qos_depth": 0}, "qos_depth"),
        ({"rf_topic": " "}, "rf_topic"),
        ({"flight_dir": "/nonexistent/flight"}, "flight folder not found"),
    ],
)
def test_bad_parameters_are_rejected_with_a_clear_message(
    ctx: Context, flight_dir: Path, overrides: dict[str, Any], needle: str
) -> None:
    kw: dict[str, Any] = {"flight_dir": str(flight_dir), **overrides}
    with pytest.raises(Exception) as info:
        RfReplay(context=ctx, parameter_overrides=_params(**kw))
    assert needle in str(info.value)
    if needle != "flight folder not found":
        assert isinstance(info.value, ParamError)


def test_runtime_parameter_changes_are_validated(ctx: Context, flight_dir: Path) -> None:
    rf = RfReplay(context=ctx, parameter_overrides=_params(flight_dir=str(flight_dir)))
    res = rf.set_parameters([Parameter("rate", value=5.0)])[0]
    assert not res.successful
    assert "read-only" in res.reason and "rate" in res.reason
    assert rf.get_parameter("rate").value == 1.0
    rf.destroy_node()


def test_main_exits_2_on_bad_parameter(flight_dir: Path) -> None:
    from uav_fusion.nodes.rf_replay import main

    code = main(["rf_replay", "--ros-args", "-p", "rate:=-3.0", "-p", f"flight_dir:={flight_dir}"])
    assert code == 2
