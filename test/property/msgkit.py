"""The one place the property tests import the message conversions from (the module may
move; only this import then changes), plus Hypothesis strategies for ROS messages with any
field values."""

from __future__ import annotations

from typing import Any

from builtin_interfaces.msg import Time
from geometry_msgs.msg import PointStamped, PoseWithCovarianceStamped
from hypothesis import strategies as st
from nav_msgs.msg import Odometry
from sensor_msgs.msg import NavSatFix

from uav_fusion.ros import conversions as cv

__all__ = ["FRAME", "T0", "cv", "navsatfixes", "odometries", "points", "poses"]

FRAME = "enu_lw1"
T0 = 1759866140.0  # 2025-10-07T19:42:20Z

#: Any float, with the nasty ones drawn often.
any_float = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from([0.0, -0.0, 1e308, -1e308, 5e-324, 1e-300, -999.0, 1e9]),
    st.floats(-5000.0, 5000.0),
)
frames = st.one_of(
    st.just(FRAME), st.sampled_from(["map", "", "ENU_LW1", "enu_lw1 ", "odom"]), st.text(max_size=8)
)


@st.composite
def stamps(draw: st.DrawFn) -> Time:
    """Zero, negative, non-normalised, far future and plausible stamps."""
    kind = draw(st.sampled_from(("zero", "any", "near", "near", "near")))
    if kind == "zero":
        return Time(sec=0, nanosec=0)
    if kind == "any":
        return Time(
            sec=draw(st.integers(-(2**31), 2**31 - 1)), nanosec=draw(st.integers(0, 2**32 - 1))
        )
    return Time(sec=int(T0) + draw(st.integers(0, 600)), nanosec=draw(st.integers(0, 999_999_999)))


@st.composite
def covariances(draw: st.DrawFn) -> list[float]:
    """6x6 row-major: a good diagonal, a damaged good one, or 36 arbitrary values."""
    good = [0.0] * 36
    for i, v in enumerate((25.0, 25.0, 36.0, 1e6, 1e6, 1e6)):
        good[7 * i] = v
    kind = draw(st.sampled_from(("good", "damaged", "any")))
    if kind == "good":
        return good
    if kind == "damaged":
        for _ in range(draw(st.integers(1, 3))):
            good[draw(st.integers(0, 35))] = draw(any_float)
        return good
    return draw(st.lists(any_float, min_size=36, max_size=36))


@st.composite
def poses(draw: st.DrawFn) -> PoseWithCovarianceStamped:
    msg = PoseWithCovarianceStamped()
    msg.header.stamp = draw(stamps())
    msg.header.frame_id = draw(frames)
    p = msg.pose.pose.position
    near = st.floats(-1500.0, 1500.0)
    p.x, p.y = draw(st.one_of(near, any_float)), draw(st.one_of(near, any_float))
    p.z = draw(st.one_of(st.floats(0.0, 300.0), any_float))
    msg.pose.pose.orientation.w = 1.0
    msg.pose.covariance = draw(covariances())
    return msg


@st.composite
def points(draw: st.DrawFn) -> PointStamped:
    msg = PointStamped()
    msg.header.stamp = draw(stamps())
    msg.header.frame_id = draw(frames)
    near = st.floats(-3000.0, 3000.0)
    msg.point.x = draw(st.one_of(near, any_float))
    msg.point.y = draw(st.one_of(near, any_float))
    msg.point.z = draw(st.one_of(st.just(0.0), any_float))
    return msg


@st.composite
def navsatfixes(draw: st.DrawFn) -> NavSatFix:
    msg = NavSatFix()
    msg.header.stamp = draw(stamps())
    msg.header.frame_id = draw(frames)
    msg.status.status = draw(st.sampled_from([-1, 0, 1, 2]))
    msg.latitude = draw(st.one_of(st.floats(35.7, 35.8), any_float))
    msg.longitude = draw(st.one_of(st.floats(-78.72, -78.68), any_float))
    msg.altitude = draw(st.one_of(st.floats(100.0, 400.0), any_float))
    return msg


@st.composite
def odometries(draw: st.DrawFn) -> Odometry:
    msg = Odometry()
    msg.header.stamp = draw(stamps())
    msg.header.frame_id = draw(frames)
    msg.child_frame_id = "uav"
    p, v = msg.pose.pose.position, msg.twist.twist.linear
    p.x, p.y, p.z = (draw(any_float) for _ in range(3))
    v.x, v.y, v.z = (draw(any_float) for _ in range(3))
    msg.pose.pose.orientation.w = 1.0
    msg.pose.covariance = draw(covariances())
    msg.twist.covariance = draw(covariances())
    return msg


def fields(msg: Any) -> str:
    """A short description of a message for assertion messages."""
    return repr(msg)[:400]
