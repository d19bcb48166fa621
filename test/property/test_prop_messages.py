"""ROS messages with any field values into the conversions the fusion and evaluator nodes use.

A message either converts into a record fit for the estimator / evaluator (finite, plausible
position, a stamp that is a real time, a finite symmetric positive-definite covariance in the
right frame) or raises ``MessageError`` with a short reason the nodes count it under. What
converts is then fed to a fresh estimator, whose state must stay finite. Once through the
fusion node in-process: a burst of such messages is dropped and counted by reason, every
message accounted for, and nothing non-finite is published.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
from geometry_msgs.msg import PointStamped, PoseWithCovarianceStamped
from hypothesis import given
from hypothesis import strategies as st
from msgkit import FRAME, T0, cv, navsatfixes, odometries, points, poses
from nav_msgs.msg import Odometry
from propkit import FUZZ_NODE_EXAMPLES, examples
from rclpy.context import Context
from sensor_msgs.msg import NavSatFix

from uav_fusion.core.estimators import FusionEstimator, load_profile
from uav_fusion.core.records import RADAR, RF, Measurement
from uav_fusion.core.site import load_site
from uav_fusion.ros import odometry as od

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "faults"))  # the node harness
SITE = load_site()
PROFILE = load_profile("paper")
REASONS = {"nan", "bad_covariance", "wrong_frame", "zero_stamp", "bad_stamp", "out_of_range"}
TRUTH_REASONS = REASONS | {"no_fix"}


def _check_stamp_value(t: float) -> None:
    assert math.isfinite(t) and t > 0.0


def _state_stays_finite(m: Measurement) -> None:
    """The measurement, then a plausible one after it, through a fresh estimator."""
    est = FusionEstimator(PROFILE, SITE)
    e0, n0, u0 = SITE.radar.enu
    good = Measurement(m.t + 0.25, RADAR, np.array([e0 + 300.0, n0, u0 + 50.0]))
    for meas in (m, good):
        for s in est.process(meas):
            if s.status in ("initialised", "updated", "coasted"):
                assert np.all(np.isfinite(s.x)) and np.all(np.isfinite(s.P)), s
                assert float(np.max(np.abs(s.x[:3]))) <= 2 * cv.MAX_ABS_ENU_M, s.x


@examples(ci=150)
@given(msg=poses())
def test_radar_pose_converts_or_is_dropped_by_reason(msg: PoseWithCovarianceStamped) -> None:
    try:
        m = cv.msg_to_radar_measurement(msg, FRAME)
    except cv.MessageError as exc:
        assert exc.reason in REASONS, exc
        return
    _check_stamp_value(m.t)
    assert m.source == RADAR and np.all(np.isfinite(m.z)) and m.R is not None
    assert np.array_equal(m.R, m.R.T) and np.all(np.linalg.eigvalsh(m.R) > 0)
    _state_stays_finite(m)


@examples(ci=150)
@given(msg=points())
def test_rf_point_converts_or_is_dropped_by_reason(msg: PointStamped) -> None:
    try:
        m = cv.msg_to_rf_measurement(msg, FRAME)
    except cv.MessageError as exc:
        assert exc.reason in REASONS, exc
        return
    if m is None:  # the failed-attempt encoding: counted as an attempt, never a position
        assert cv.is_failed_rf(msg)
        return
    _check_stamp_value(m.t)
    assert m.source == RF and np.all(np.isfinite(m.z))
    _state_stays_finite(m)


@examples(ci=150)
@given(msg=navsatfixes())
def test_truth_navsatfix_converts_or_is_dropped_by_reason(msg: NavSatFix) -> None:
    try:
        fix = cv.navsatfix_to_truth(msg, SITE)
    except cv.MessageError as exc:
        assert exc.reason in TRUTH_REASONS, exc
        return
    _check_stamp_value(fix.t)
    assert -90.0 <= fix.lat <= 90.0 and -180.0 <= fix.lon <= 180.0
    # anywhere on the globe, within an Earth diameter of the site
    assert all(math.isfinite(v) and abs(v) < 1.5e7 for v in (fix.e, fix.n, fix.u))


@examples(ci=100)
@given(msg=odometries())
def test_odometry_converts_or_is_dropped_by_reason(msg: Odometry) -> None:
    try:
        s = od.odometry_to_state(msg)
    except cv.MessageError as exc:
        assert exc.reason in REASONS, exc
        return
    _check_stamp_value(s.t)
    assert np.all(np.isfinite(s.x)) and float(np.max(np.abs(s.x[:3]))) <= cv.MAX_ABS_ENU_M


def _converts(msg: PoseWithCovarianceStamped | PointStamped) -> bool:
    try:
        if hasattr(msg, "pose"):
            cv.msg_to_radar_measurement(msg, FRAME)
        else:
            cv.msg_to_rf_measurement(msg, FRAME)
    except cv.MessageError:
        return False
    return True


@examples(ci=5, fuzz=FUZZ_NODE_EXAMPLES)
@given(
    radar=st.lists(poses(), min_size=1, max_size=20),
    rf=st.lists(points(), min_size=1, max_size=20),
)
def test_fusion_node_drops_and_counts_any_message(
    ctx: Context, radar: list[PoseWithCovarianceStamped], rf: list[PointStamped]
) -> None:
    from faultkit import FusionHarness, accounting

    h = FusionHarness(ctx)
    try:
        e0, n0, u0 = SITE.radar.enu
        # a clean track first, so the damaged input meets a live filter
        clean = [
            cv.radar_to_msg(T0 + 0.25 * k, (e0 + 300.0, n0, u0 + 50.0), np.eye(3) * 25.0, FRAME)
            for k in range(4)
        ]
        h.send(*clean, *radar, *rf)
        h.flush()
        # >=: a late delivery from the previous example's node may still arrive here
        h.spin_until(lambda: len(h.odom) >= h.fusion.steps_published)
        d = h.diagnostics()
        for src, msgs in (("radar", clean + radar), ("rf", rf)):
            received, used, rejected, dropped = accounting(d, src)
            assert received == len(msgs)
            assert received == used + rejected + dropped, d
            assert dropped >= sum(not _converts(m) for m in msgs), d
        for odom in h.odom:
            p, v = odom.pose.pose.position, odom.twist.twist.linear
            vals = (p.x, p.y, p.z, v.x, v.y, v.z, *odom.pose.covariance, *odom.twist.covariance)
            assert all(math.isfinite(x) for x in vals), odom
            assert max(abs(p.x), abs(p.y), abs(p.z)) <= 2 * cv.MAX_ABS_ENU_M
    finally:
        h.destroy()
