"""The filter state as ROS 2 messages: ``nav_msgs/Odometry`` (every step and the fixed-rate
output), ``sensor_msgs/NavSatFix`` of a fused position and ``nav_msgs/Path`` (the
representation: :mod:`uav_fusion.ros.conversions`)."""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Protocol

import numpy as np
import numpy.typing as npt
from geometry_msgs.msg import PoseStamped
from nav_msgs.msg import Odometry, Path
from sensor_msgs.msg import NavSatFix, NavSatStatus

from uav_fusion.core.data.encoding import UNKNOWN_VARIANCE, MessageError
from uav_fusion.ros.conversions import check_position, check_stamp, pose_cov, stamp_from_time

FloatArray = npt.NDArray[np.float64]


class StepLike(Protocol):
    """What :func:`step_to_odometry` needs of an estimator step."""

    @property
    def t(self) -> float: ...

    @property
    def x(self) -> FloatArray: ...

    @property
    def P(self) -> FloatArray: ...



def state_to_odometry(
    t: float, x: FloatArray, P: FloatArray, frame_id: str, child_frame_id: str
) -> Odometry:
    """State [E N U vE vN vU] with covariance P (6x6) as Odometry."""
    xv = np.asarray(x, dtype=float).reshape(6)
    Pm = np.asarray(P, dtype=float).reshape(6, 6)
    msg = Odometry()
    msg.header.stamp = stamp_from_time(t)
    msg.header.frame_id = frame_id
    msg.child_frame_id = child_frame_id
    pos = msg.pose.pose.position
    pos.x, pos.y, pos.z = float(xv[0]), float(xv[1]), float(xv[2])
    msg.pose.pose.orientation.w = 1.0
    msg.pose.covariance = pose_cov(Pm[:3, :3])
    lin = msg.twist.twist.linear
    lin.x, lin.y, lin.z = float(xv[3]), float(xv[4]), float(xv[5])
    msg.twist.covariance = pose_cov(Pm[3:, 3:])
    return msg


def odometry_from_values(
    t: float, v: Sequence[float], frame_id: str, child_frame_id: str
) -> Odometry:
    """Odometry from a step's packed values (x[0:6], then P's 21-entry upper triangle,
    :attr:`uav_fusion.core.estimators.Step.values`): the message :func:`state_to_odometry`
    builds, without building the 6x6 arrays."""
    u = UNKNOWN_VARIANCE
    msg = Odometry()
    h = msg.header
    h.stamp = stamp_from_time(t)
    h.frame_id = frame_id
    msg.child_frame_id = child_frame_id
    pose = msg.pose
    pos = pose.pose.position
    pos.x, pos.y, pos.z = v[0], v[1], v[2]
    pose.pose.orientation.w = 1.0
    # upper-triangle indices (offset 6): P00 0, P01 1, P02 2, P11 6, P12 7, P22 11
    p00, p01, p02, p11, p12, p22 = v[6], v[7], v[8], v[12], v[13], v[17]
    pose.covariance = np.array((
        p00, p01, p02, 0.0, 0.0, 0.0, p01, p11, p12, 0.0, 0.0, 0.0,
        p02, p12, p22, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, u, 0.0, 0.0,
        0.0, 0.0, 0.0, 0.0, u, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, u,
    ))
    twist = msg.twist
    lin = twist.twist.linear
    lin.x, lin.y, lin.z = v[3], v[4], v[5]
    # P33 15, P34 16, P35 17, P44 18, P45 19, P55 20
    q00, q01, q02, q11, q12, q22 = v[21], v[22], v[23], v[24], v[25], v[26]
    twist.covariance = np.array((
        q00, q01, q02, 0.0, 0.0, 0.0, q01, q11, q12, 0.0, 0.0, 0.0,
        q02, q12, q22, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, u, 0.0, 0.0,
        0.0, 0.0, 0.0, 0.0, u, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, u,
    ))
    return msg


def navsatfix_from_enu(
    t: float, lat: float, lon: float, h: float, v: Sequence[float], frame_id: str
) -> NavSatFix:
    """A fused position as NavSatFix: latitude/longitude (deg), altitude HAE (m), position
    covariance = P's position block (ENU, NavSatFix's convention; type KNOWN), status FIX,
    no GNSS service (it is not a satellite fix). ``v`` as in :func:`odometry_from_values`."""
    msg = NavSatFix()
    msg.header.stamp = stamp_from_time(t)
    msg.header.frame_id = frame_id
    msg.status.status = int(NavSatStatus.STATUS_FIX)
    msg.status.service = 0
    msg.latitude, msg.longitude, msg.altitude = lat, lon, h
    p00, p01, p02, p11, p12, p22 = v[6], v[7], v[8], v[12], v[13], v[17]
    msg.position_covariance = np.array((p00, p01, p02, p01, p11, p12, p02, p12, p22))
    msg.position_covariance_type = int(NavSatFix.COVARIANCE_TYPE_KNOWN)
    return msg


def path_from_points(
    points: Iterable[tuple[float, float, float, float]], frame_id: str
) -> Path:
    """nav_msgs/Path of (t, east, north, up) points in ``frame_id`` (orientation identity);
    the path's stamp is the last point's."""
    msg = Path()
    msg.header.frame_id = frame_id
    poses = []
    for t, e, n, u in points:
        ps = PoseStamped()
        ps.header.stamp = stamp_from_time(t)
        ps.header.frame_id = frame_id
        pos = ps.pose.position
        pos.x, pos.y, pos.z = e, n, u
        ps.pose.orientation.w = 1.0
        poses.append(ps)
    msg.poses = poses
    if poses:
        msg.header.stamp = poses[-1].header.stamp
    return msg


def step_to_odometry(step: StepLike, frame_id: str, child_frame_id: str) -> Odometry:
    """An estimator step (``t``, ``x``, ``P``) as Odometry."""
    return state_to_odometry(step.t, step.x, step.P, frame_id, child_frame_id)


@dataclass(frozen=True)
class OdomState:
    """A state read back from Odometry; ``P``'s position-velocity cross blocks are zero."""

    t: float
    x: FloatArray
    P: FloatArray
    frame_id: str
    child_frame_id: str


def odometry_to_state(msg: Odometry) -> OdomState:
    """Odometry -> state (inverse of :func:`state_to_odometry` up to the lost cross terms).

    Raises :class:`MessageError` on a zero or impossible stamp, a non-finite state or a
    position beyond :data:`MAX_ABS_ENU_M`.
    """
    t = check_stamp(msg.header.stamp)
    p, v = msg.pose.pose.position, msg.twist.twist.linear
    x = np.array([p.x, p.y, p.z, v.x, v.y, v.z], dtype=float)
    if not np.all(np.isfinite(x)):
        raise MessageError("nan", "odometry state is not finite")
    check_position(x[:3], "odometry position")
    P = np.zeros((6, 6))
    P[:3, :3] = np.asarray(msg.pose.covariance, dtype=float).reshape(6, 6)[:3, :3]
    P[3:, 3:] = np.asarray(msg.twist.covariance, dtype=float).reshape(6, 6)[:3, :3]
    return OdomState(t, x, P, msg.header.frame_id, msg.child_frame_id)
