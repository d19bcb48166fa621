"""Every conversion between the core's records and ROS 2 messages lives here.

Representations (see ``docs/graph.md`` for the whole table):

- **Time.** A stamp is the sensor's UTC time (``builtin_interfaces/Time``, seconds since the
  Unix epoch). :func:`stamp_from_time` and :func:`time_from_stamp` round-trip every float time
  exactly whenever the float's resolution is coarser than 1 ns, which holds for any time after
  1970-04-08 (|t| >= 2**23 s), i.e. for every real or simulated UTC time we handle.
- **Radar report** -> ``geometry_msgs/PoseWithCovarianceStamped`` in the site's ENU frame
  (``site.frame_id``, origin LW1). ``pose.position`` = (E, N, U) metres. The orientation is not
  measured: identity quaternion, orientation variances :data:`UNKNOWN_VARIANCE` rad^2 and zero
  cross terms. The covariance is 6x6 row-major; its position block is the measurement's R
  (or the configured radar R when the measurement carries none).
- **RF fix** -> ``geometry_msgs/PointStamped``: x = E, y = N, z = 0.0 (TDOA fixes are 2D; z is
  not used). A *failed* localisation attempt is published too, as x = y = z = NaN, so a
  subscriber can count attempts (the denominator of the RF coverage). A message with only some
  coordinates NaN is malformed.
- **Truth** -> ``sensor_msgs/NavSatFix``: latitude/longitude in degrees and altitude as height
  above the WGS84 ellipsoid, which is exactly what NavSatFix's ``altitude`` field specifies
  (the truth reader already turned the log's take-off-relative altitude into HAE). The MAVLink
  fix type maps onto ``NavSatStatus`` (RTK float/fixed -> GBAS_FIX, DGPS -> SBAS_FIX, 2D/3D ->
  FIX, below 2D -> NO_FIX); the position covariance is marked unknown.
- **Filter step** -> ``nav_msgs/Odometry``: ``header.frame_id`` is the ENU frame,
  ``child_frame_id`` the tracked body; pose.position = x[0:3]; orientation identity (unknown,
  variances :data:`UNKNOWN_VARIANCE`), so the body frame is aligned with ENU and the twist's
  linear part is the ENU velocity x[3:6]. Pose covariance position block = P[0:3, 0:3]; twist
  covariance linear block = P[3:6, 3:6]. The position-velocity cross covariance has no place
  in Odometry and is lost: :func:`odometry_to_state` returns it as zeros.

Malformed input raises :class:`MessageError` whose ``reason`` is a short counter key
(``nan``, ``bad_covariance``, ``wrong_frame``, ``zero_stamp``) so nodes can count drops.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Protocol

import numpy as np
import numpy.typing as npt
from builtin_interfaces.msg import Time
from geometry_msgs.msg import PointStamped, PoseWithCovarianceStamped
from nav_msgs.msg import Odometry
from sensor_msgs.msg import NavSatFix, NavSatStatus

from uav_fusion.core.encoding import (
    UNKNOWN_VARIANCE,
    MessageError,
    fix_type_from_status,
    navsat_status,
    ns_to_time,
    pose_covariance,
    rf_point,
    stamp_parts,
    time_to_ns,
)
from uav_fusion.core.records import (
    RADAR,
    RF,
    Measurement,
    RadarTrack,
    RfAttempt,
    TruthFix,
)
from uav_fusion.core.site import Site

FloatArray = npt.NDArray[np.float64]

#: Relative tolerance of the symmetry check on incoming covariance blocks.
SYMMETRY_RTOL = 1.0e-9

_NS = 1_000_000_000

__all__ = [
    "UNKNOWN_VARIANCE",
    "MessageError",
    "ns_to_time",
    "time_to_ns",
]


class StepLike(Protocol):
    """What :func:`step_to_odometry` needs of an estimator step."""

    @property
    def t(self) -> float: ...

    @property
    def x(self) -> FloatArray: ...

    @property
    def P(self) -> FloatArray: ...


# --- time ---------------------------------------------------------------------------------


def stamp_from_time(t: float) -> Time:
    """UTC float seconds -> ``builtin_interfaces/Time`` (nearest nanosecond)."""
    sec, nsec = stamp_parts(t)
    return Time(sec=sec, nanosec=nsec)


def time_from_stamp(stamp: Time) -> float:
    """``builtin_interfaces/Time`` -> UTC float seconds (inverse of :func:`stamp_from_time`)."""
    return float(stamp.sec) + float(stamp.nanosec) / _NS


def _check_stamp(stamp: Time) -> float:
    if stamp.sec == 0 and stamp.nanosec == 0:
        raise MessageError("zero_stamp", "message has no stamp (0)")
    return time_from_stamp(stamp)


def _check_frame(frame_id: str, expected: str | None) -> None:
    if expected and frame_id != expected:
        raise MessageError("wrong_frame", f"frame '{frame_id}', expected '{expected}'")


def _check_cov_block(c: FloatArray, what: str) -> None:
    if not np.all(np.isfinite(c)):
        raise MessageError("bad_covariance", f"{what} covariance has non-finite entries")
    scale = float(np.max(np.abs(c))) or 1.0
    if not np.allclose(c, c.T, rtol=0.0, atol=SYMMETRY_RTOL * scale):
        raise MessageError("bad_covariance", f"{what} covariance is not symmetric")
    try:
        np.linalg.cholesky(c)
    except np.linalg.LinAlgError:
        raise MessageError(
            "bad_covariance", f"{what} covariance is not positive definite"
        ) from None


def _pose_cov(pos: FloatArray) -> list[float]:
    return pose_covariance(pos.tolist())


# --- radar --------------------------------------------------------------------------------


def radar_to_msg(
    t: float, enu: FloatArray | tuple[float, float, float], R: FloatArray, frame_id: str
) -> PoseWithCovarianceStamped:
    """One radar position (ENU metres) with its 3x3 covariance as a pose message."""
    msg = PoseWithCovarianceStamped()
    msg.header.stamp = stamp_from_time(t)
    msg.header.frame_id = frame_id
    p = msg.pose.pose.position
    p.x, p.y, p.z = float(enu[0]), float(enu[1]), float(enu[2])
    msg.pose.pose.orientation.w = 1.0
    Rm = np.asarray(R, dtype=float)
    if Rm.shape != (3, 3):
        raise MessageError("bad_covariance", f"radar R must be 3x3, got {Rm.shape}")
    msg.pose.covariance = _pose_cov(Rm)
    return msg


def radar_measurement_to_msg(
    m: Measurement, frame_id: str, default_R: FloatArray | None = None
) -> PoseWithCovarianceStamped:
    """A radar :class:`Measurement` as a pose; R = ``m.R`` or else ``default_R``."""
    if m.source != RADAR or m.dim != 3:
        raise MessageError("wrong_source", f"not a 3D radar measurement: {m.source}/{m.dim}")
    R = m.R if m.R is not None else default_R
    if R is None:
        raise MessageError("bad_covariance", "radar measurement has no R and no default")
    return radar_to_msg(m.t, m.z, R, frame_id)


def radar_track_to_msg(
    track: RadarTrack, R: FloatArray, frame_id: str
) -> PoseWithCovarianceStamped:
    """A raw radar track report as a pose (used for the raw-report topic)."""
    return radar_to_msg(track.t, (track.e, track.n, track.u), R, frame_id)


def msg_to_radar_measurement(
    msg: PoseWithCovarianceStamped, expected_frame: str | None = None, seq: int = 0
) -> Measurement:
    """Pose message -> 3D radar :class:`Measurement` (R = the covariance's position block).

    Raises :class:`MessageError` on a zero stamp, wrong frame, non-finite position or a
    position covariance that is not finite, symmetric and positive definite.
    """
    t = _check_stamp(msg.header.stamp)
    _check_frame(msg.header.frame_id, expected_frame)
    p = msg.pose.pose.position
    z = np.array([p.x, p.y, p.z], dtype=float)
    if not np.all(np.isfinite(z)):
        raise MessageError("nan", "radar position is not finite")
    cov = np.asarray(msg.pose.covariance, dtype=float).reshape(6, 6)
    R = np.array(cov[:3, :3])
    _check_cov_block(R, "radar position")
    return Measurement(t=t, source=RADAR, z=z, R=R, seq=seq)


# --- RF -----------------------------------------------------------------------------------


def rf_to_msg(t: float, en: tuple[float, float] | None, frame_id: str) -> PointStamped:
    """An RF fix (E, N) as a point; ``en`` None (a failed attempt) -> x = y = z = NaN."""
    msg = PointStamped()
    msg.header.stamp = stamp_from_time(t)
    msg.header.frame_id = frame_id
    if en is None:
        msg.point.x = msg.point.y = msg.point.z = math.nan
    else:
        msg.point.x, msg.point.y, msg.point.z = float(en[0]), float(en[1]), 0.0
    return msg


def rf_attempt_to_msg(a: RfAttempt, frame_id: str) -> PointStamped:
    """An RF localisation attempt (failed ones included) as a point."""
    msg = PointStamped()
    msg.header.stamp = stamp_from_time(a.t)
    msg.header.frame_id = frame_id
    msg.point.x, msg.point.y, msg.point.z = rf_point(a)
    return msg


def rf_measurement_to_msg(m: Measurement, frame_id: str) -> PointStamped:
    """A 2D RF :class:`Measurement` as a point (R is not carried: subscribers use the
    configured RF R)."""
    if m.source != RF or m.dim != 2:
        raise MessageError("wrong_source", f"not a 2D RF measurement: {m.source}/{m.dim}")
    return rf_to_msg(m.t, (float(m.z[0]), float(m.z[1])), frame_id)


def is_failed_rf(msg: PointStamped) -> bool:
    """True for the failed-attempt encoding (x, y and z all NaN)."""
    p = msg.point
    return math.isnan(p.x) and math.isnan(p.y) and math.isnan(p.z)


def msg_to_rf_measurement(
    msg: PointStamped,
    expected_frame: str | None = None,
    R: FloatArray | None = None,
    seq: int = 0,
) -> Measurement | None:
    """Point message -> 2D RF :class:`Measurement`, or None for a failed attempt.

    Raises :class:`MessageError` on a zero stamp, wrong frame or partly non-finite point.
    """
    t = _check_stamp(msg.header.stamp)
    _check_frame(msg.header.frame_id, expected_frame)
    if is_failed_rf(msg):
        return None
    z = np.array([msg.point.x, msg.point.y], dtype=float)
    if not np.all(np.isfinite(z)):
        raise MessageError("nan", "RF fix is partly non-finite")
    return Measurement(t=t, source=RF, z=z, R=None if R is None else np.array(R), seq=seq)


# --- truth --------------------------------------------------------------------------------


def truth_to_navsatfix(fix: TruthFix, frame_id: str) -> NavSatFix:
    """A truth sample as NavSatFix (lat, lon, HAE altitude)."""
    msg = NavSatFix()
    msg.header.stamp = stamp_from_time(fix.t)
    msg.header.frame_id = frame_id
    msg.status.status = navsat_status(fix.fix_type)
    msg.status.service = int(NavSatStatus.SERVICE_GPS)
    msg.latitude, msg.longitude, msg.altitude = float(fix.lat), float(fix.lon), float(fix.h)
    msg.position_covariance_type = int(NavSatFix.COVARIANCE_TYPE_UNKNOWN)
    return msg


def navsatfix_to_truth(msg: NavSatFix, site: Site) -> TruthFix:
    """NavSatFix -> :class:`TruthFix` with ENU from ``site`` (velocity unknown: NaN)."""
    t = _check_stamp(msg.header.stamp)
    lat, lon, h = float(msg.latitude), float(msg.longitude), float(msg.altitude)
    if not (math.isfinite(lat) and math.isfinite(lon) and math.isfinite(h)):
        raise MessageError("nan", "truth position is not finite")
    e, n, u = site.to_enu(lat, lon, h)
    nan = math.nan
    return TruthFix(
        t=t,
        lat=lat,
        lon=lon,
        h=h,
        e=float(e),
        n=float(n),
        u=float(u),
        vel_ned=(nan, nan, nan),
        fix_type=fix_type_from_status(msg.status.status),
        num_sats=0,
    )


# --- filter state -------------------------------------------------------------------------


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
    msg.pose.covariance = _pose_cov(Pm[:3, :3])
    lin = msg.twist.twist.linear
    lin.x, lin.y, lin.z = float(xv[3]), float(xv[4]), float(xv[5])
    msg.twist.covariance = _pose_cov(Pm[3:, 3:])
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
    """Odometry -> state (inverse of :func:`state_to_odometry` up to the lost cross terms)."""
    t = time_from_stamp(msg.header.stamp)
    p, v = msg.pose.pose.position, msg.twist.twist.linear
    x = np.array([p.x, p.y, p.z, v.x, v.y, v.z], dtype=float)
    P = np.zeros((6, 6))
    P[:3, :3] = np.asarray(msg.pose.covariance, dtype=float).reshape(6, 6)[:3, :3]
    P[3:, 3:] = np.asarray(msg.twist.covariance, dtype=float).reshape(6, 6)[:3, :3]
    return OdomState(t, x, P, msg.header.frame_id, msg.child_frame_id)
