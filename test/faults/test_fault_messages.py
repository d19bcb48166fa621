"""Fault cases, area "messages": malformed and badly timed messages into fusion_node and
evaluator_node. Every message is either used, or refused by the estimator with a reason, or
dropped and counted by reason; after each fault the node still fuses good input."""

from __future__ import annotations

import math
import random

import numpy as np
import pytest
from faultkit import (
    FRAME,
    RADAR,
    RF,
    T0,
    EvaluatorHarness,
    FusionHarness,
    accounting,
    radar_msg,
    rf_msg,
    straight,
)
from rclpy.context import Context

from uav_fusion.ros import conversions as cv


def track(h: FusionHarness, t_from: float, t_to: float, dt: float = 0.25) -> list[float]:
    """Send a clean radar track over [t_from, t_to); returns the stamps sent."""
    ts = [float(t) for t in np.arange(t_from, t_to, dt)]
    h.send(*(radar_msg(t, *straight(t)) for t in ts))
    return ts


def balanced(h: FusionHarness) -> None:
    """The accounting invariant for both streams, after a flush."""
    d = h.diagnostics()
    assert d["buffer_pending"] == "0"
    for src in (RADAR, RF):
        rec, used, rej, drop = accounting(d, src)
        assert rec == used + rej + drop, (src, d)


def still_fuses(h: FusionHarness, t_from: float) -> None:
    """Good radar after the fault is used (the node is not stuck)."""
    before = int(h.diagnostics().get("used_radar", "0"))
    track(h, t_from, t_from + 2.0)
    h.settle()
    assert int(h.diagnostics()["used_radar"]) >= before + 7


@pytest.mark.fault("MSG-01")
@pytest.mark.parametrize("value", [math.nan, math.inf, -math.inf])
def test_radar_nonfinite_position_dropped_as_nan(ctx: Context, value: float) -> None:
    h = FusionHarness(ctx)
    track(h, T0, T0 + 2.0)
    bad = radar_msg(T0 + 2.0, *straight(T0 + 2.0))
    bad.pose.pose.position.z = value
    h.send(bad)
    assert h.fusion.dropped == {"radar_nan": 1}
    still_fuses(h, T0 + 2.25)
    assert h.diagnostics()["dropped_radar_nan"] == "1"
    balanced(h)
    h.destroy()


@pytest.mark.fault("MSG-02")
def test_rf_partly_nonfinite_dropped_failed_attempt_counted(ctx: Context) -> None:
    h = FusionHarness(ctx)
    track(h, T0, T0 + 2.0)
    half = rf_msg(T0 + 1.1, 310.0, 0.0)
    half.point.y = math.inf
    failed = cv.rf_to_msg(T0 + 1.3, None, FRAME)  # all NaN: a failed attempt, not a fault
    h.send(half, failed)
    assert h.fusion.dropped == {"rf_nan": 1}
    h.settle()
    d = h.diagnostics()
    assert d["rejected_rf_failed_attempt"] == "1"
    balanced(h)
    h.destroy()


def _cov(block: np.ndarray) -> list[float]:
    c = np.zeros((6, 6))
    c[:3, :3] = block
    c[3, 3] = c[4, 4] = c[5, 5] = 1e6
    return [float(v) for v in c.reshape(-1)]


@pytest.mark.fault("MSG-03")
@pytest.mark.parametrize(
    ("name", "block", "text"),
    [
        ("zero", np.zeros((3, 3)), "not positive definite"),
        ("negative", np.diag([25.0, -25.0, 36.0]), "not positive definite"),
        ("asymmetric", np.array([[25.0, 5.0, 0.0], [0.0, 25.0, 0.0], [0.0, 0.0, 36.0]]),
         "not symmetric"),
        ("not_psd", np.array([[25.0, 40.0, 0.0], [40.0, 25.0, 0.0], [0.0, 0.0, 36.0]]),
         "not positive definite"),
        ("nan", np.diag([25.0, math.nan, 36.0]), "non-finite"),
    ],
)
def test_bad_radar_covariance_dropped_with_the_reason_logged(
    ctx: Context, name: str, block: np.ndarray, text: str
) -> None:
    with pytest.raises(cv.MessageError, match=text):
        cv.msg_to_radar_measurement(_bad_cov_msg(block))
    h = FusionHarness(ctx)
    track(h, T0, T0 + 1.0)
    h.send(_bad_cov_msg(block))
    assert h.fusion.dropped == {"radar_bad_covariance": 1}, name
    still_fuses(h, T0 + 1.25)
    balanced(h)
    h.destroy()


def _bad_cov_msg(block: np.ndarray) -> object:
    m = radar_msg(T0 + 1.0, *straight(T0 + 1.0))
    m.pose.covariance = _cov(block)
    return m


@pytest.mark.fault("MSG-04")
def test_wrong_frame_dropped_on_both_streams(ctx: Context) -> None:
    h = FusionHarness(ctx)
    track(h, T0, T0 + 1.0)
    h.send(radar_msg(T0 + 1.0, *straight(T0 + 1.0), frame="map"))
    h.send(rf_msg(T0 + 1.1, 310.0, 0.0, frame=""))
    assert h.fusion.dropped == {"radar_wrong_frame": 1, "rf_wrong_frame": 1}
    still_fuses(h, T0 + 1.25)
    balanced(h)
    h.destroy()


@pytest.mark.fault("MSG-05")
def test_zero_stamp_dropped(ctx: Context) -> None:
    h = FusionHarness(ctx)
    m = radar_msg(T0, *straight(T0))
    m.header.stamp.sec = 0
    m.header.stamp.nanosec = 0
    h.send(m)
    assert h.fusion.dropped == {"radar_zero_stamp": 1}
    still_fuses(h, T0)
    balanced(h)
    h.destroy()


@pytest.mark.fault("MSG-06")
def test_stamp_far_in_the_future_is_dropped_and_does_not_poison_time(ctx: Context) -> None:
    """One radar report stamped a day ahead: dropped as ``future`` once the stream continues
    normally; the reorder buffer and the filter keep working on the real timeline."""
    h = FusionHarness(ctx, reorder_window_s=1.0)
    track(h, T0, T0 + 2.0)
    h.send(radar_msg(T0 + 86400.0, *straight(T0 + 2.0)))
    h.send(rf_msg(T0 + 86400.0 + 3.0, 310.0, 0.0))
    still_fuses(h, T0 + 2.0)
    assert h.fusion.dropped == {"radar_future": 1, "rf_future": 1}
    times = [cv.time_from_stamp(o.header.stamp) for o in h.odom]
    assert max(times) < T0 + 10.0 and times == sorted(times)
    balanced(h)
    h.destroy()


@pytest.mark.fault("MSG-07")
def test_stamp_far_in_the_past_is_dropped_as_late(ctx: Context) -> None:
    h = FusionHarness(ctx, reorder_window_s=1.0)
    track(h, T0, T0 + 5.0)
    h.send(radar_msg(T0 - 3600.0, *straight(T0)), rf_msg(T0 + 1.0, 308.0, 0.0))
    assert h.fusion.dropped == {"late_radar": 1, "late_rf": 1}
    still_fuses(h, T0 + 5.0)
    assert h.diagnostics()["dropped_late_radar"] == "1"
    balanced(h)
    h.destroy()


@pytest.mark.fault("MSG-08")
def test_duplicate_stamps_repeats_dropped_distinct_reports_kept(ctx: Context) -> None:
    """An exact repeat (same stamp, same position) is dropped as ``<source>_duplicate``; two
    different radar reports sharing a stamp are one frame of candidates (one updates, the
    other is refused as ``not_selected``)."""
    h = FusionHarness(ctx)
    track(h, T0, T0 + 2.0)
    dup = radar_msg(T0 + 2.0, *straight(T0 + 2.0))
    h.send(dup, dup)
    fix = rf_msg(T0 + 2.1, 317.0, 1.0)
    h.send(fix, fix)
    e, n, u = straight(T0 + 2.25)
    h.send(radar_msg(T0 + 2.25, e, n, u), radar_msg(T0 + 2.25, e + 60.0, n + 40.0, u))
    h.settle()
    assert h.fusion.dropped == {"radar_duplicate": 1, "rf_duplicate": 1}
    d = h.diagnostics()
    assert d["rejected_radar_not_selected"] == "1"
    assert int(d["used_rf"]) + int(d.get("rejected_rf_nis", "0")) == 1
    balanced(h)
    h.destroy()


@pytest.mark.fault("MSG-09")
def test_out_of_order_bursts_equal_in_order_and_reversed_stream_counted(ctx: Context) -> None:
    """Bursts that interleave the two streams in any order (each stream FIFO, as a reliable
    DDS writer delivers) give exactly the in-order result. A burst whose own radar stamps run
    backwards breaks the per-stream order the buffer relies on: what cannot be put back in
    order is dropped as ``late_radar``, never fused out of order."""
    ts = [float(t) for t in np.arange(T0, T0 + 10.0, 0.25)]
    msgs = [radar_msg(t, *straight(t)) for t in ts]
    rfs = [rf_msg(t + 0.1, straight(t)[0] + 5.0, 3.0) for t in ts[::8]]
    a = FusionHarness(ctx, reorder_window_s=3.0)
    in_order = sorted([*msgs, *rfs], key=lambda m: cv.time_from_stamp(m.header.stamp))
    for m in in_order:
        a.send(m)
    a.settle()
    assert not a.fusion.dropped
    ref = [(cv.time_from_stamp(o.header.stamp), o.pose.pose.position.x) for o in a.odom]
    a.destroy()
    rng = random.Random(5)
    b = FusionHarness(ctx, reorder_window_s=3.0)
    # bursts of 2 s of data (8 radar + 1 RF), the two FIFO streams interleaved at random
    # (each burst is published at once; the executor then takes the two topics in turn)
    it = {0: iter(msgs), 1: iter(rfs)}
    for _ in rfs:
        keys = [0] * 8 + [1]
        rng.shuffle(keys)
        b.send(*(next(it[k]) for k in keys))
    b.settle()
    got = [(cv.time_from_stamp(o.header.stamp), o.pose.pose.position.x) for o in b.odom]
    assert not b.fusion.dropped, b.fusion.dropped
    assert got == ref
    balanced(b)
    b.destroy()
    c = FusionHarness(ctx, reorder_window_s=3.0)
    c.send(*msgs[:8], *rfs[:3])  # RF up to T0 + 4.1 s
    c.send(*reversed(msgs[8:16]))  # radar T0 + 2 ... 3.75 s arrives newest first
    c.send(*msgs[16:])
    c.settle()
    # 3.75 waits, 3.5 is released at once (both streams are past it), 3.25 ... 2.0 are late
    assert c.fusion.dropped == {"late_radar": 6}
    out = [cv.time_from_stamp(o.header.stamp) for o in c.odom]
    assert out == sorted(out)
    balanced(c)
    c.destroy()


@pytest.mark.fault("MSG-10")
def test_rf_burst_of_100_fixes_in_one_second_is_fully_accounted(ctx: Context) -> None:
    h = FusionHarness(ctx)
    track(h, T0, T0 + 2.0)
    rng = np.random.default_rng(1)
    burst = []
    for k in range(100):
        t = T0 + 2.0 + k * 0.01
        e, n, _ = straight(t)
        burst.append(rf_msg(t, e + rng.normal(0, 20.0), n + rng.normal(0, 20.0)))
    h.send(*burst)
    track(h, T0 + 3.0, T0 + 4.0)
    h.settle()
    d = h.diagnostics()
    assert d["received_rf"] == "100"
    rec, used, rej, drop = accounting(d, RF)
    assert rec == used + rej + drop == 100 and drop == 0
    assert used > 0 and int(d["rejected_rf_nis"]) == rej  # outliers go to the NIS gate only
    balanced(h)
    h.destroy()


@pytest.mark.fault("MSG-11")
def test_radar_at_ten_times_its_rate_is_fused_without_loss(ctx: Context) -> None:
    h = FusionHarness(ctx)
    ts = track(h, T0, T0 + 10.0, dt=0.025)  # 40 Hz instead of 4 Hz
    h.settle()
    d = h.diagnostics()
    assert int(d["received_radar"]) == len(ts) == 400
    assert int(d["used_radar"]) == len(ts) and not h.fusion.dropped
    assert len(h.odom) == len(ts)
    h.destroy()


@pytest.mark.fault("MSG-12")
def test_evaluator_drops_malformed_messages_by_topic_and_reason(ctx: Context) -> None:
    from geometry_msgs.msg import PointStamped
    from nav_msgs.msg import Odometry
    from sensor_msgs.msg import NavSatFix

    h = EvaluatorHarness(ctx)
    fix = NavSatFix()
    fix.header.stamp = cv.stamp_from_time(T0)
    fix.header.frame_id = "gps"
    fix.latitude, fix.longitude, fix.altitude = math.nan, -78.69, 100.0
    h.send("truth", fix)
    odo = Odometry()
    odo.header.stamp = cv.stamp_from_time(T0)
    odo.header.frame_id = FRAME
    odo.pose.pose.position.x = math.inf
    h.send("updated", odo)
    wrong = Odometry()
    wrong.header.stamp = cv.stamp_from_time(T0)
    wrong.header.frame_id = "map"
    h.send("coasted", wrong)
    pt = PointStamped()
    pt.header.frame_id = FRAME
    pt.point.x = 1.0
    h.send("rf", pt)  # no stamp
    bad = radar_msg(T0, 300.0, 0.0)
    bad.pose.covariance = _cov(np.diag([1.0, -1.0, 1.0]))
    h.send("radar_raw", bad)
    ev = h.node.evaluate()
    d = dict(ev.dropped)
    assert d.get("rf/fix: zero_stamp") == 1
    assert d.get("radar/raw: bad_covariance") == 1
    assert d.get("fusion/odom/coasted: wrong_frame") == 1
    assert sum(v for k, v in d.items() if "truth" in k) == 1
    assert sum(v for k, v in d.items() if "step" in k or "updated" in k) == 1
    assert ev.rf_attempts == 0 and ev.radar_reports == 0 and ev.steps == 0
    h.destroy()
