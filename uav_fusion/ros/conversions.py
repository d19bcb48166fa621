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
  in Odometry and is lost: :func:`~uav_fusion.ros.odometry.odometry_to_state` returns it as zeros
  (the filter state's messages: :mod:`uav_fusion.ros.odometry`).

Malformed input raises :class:`MessageError` whose ``reason`` is a short counter key
(``nan``, ``bad_covariance``, ``wrong_frame``, ``zero_stamp``, ``bad_stamp`` (negative
seconds, nanoseconds beyond 10^9), ``out_of_range`` (a position beyond
:data:`MAX_ABS_ENU_M`, a truth fix outside the globe or the plausible heights), ``no_fix`` (a
truth NavSatFix with status NO_FIX)) so nodes can count drops.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Sequence

import numpy as np
import numpy.typing as npt
from builtin_interfaces.msg import Time
from geometry_msgs.msg import PointStamped, PoseWithCovarianceStamped
from sensor_msgs.msg import NavSatFix, NavSatStatus, PointCloud2, PointField

from uav_fusion.core.data import clouds
from uav_fusion.core.data.encoding import (
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
from uav_fusion.core.data.radar import H_MAX, H_MIN
from uav_fusion.core.records import (
    RADAR,
    RF,
    Measurement,
    RadarFrame,
    RadarTrack,
    RfAttempt,
    TruthFix,
)
from uav_fusion.core.site import Site

FloatArray = npt.NDArray[np.float64]

#: Relative tolerance of the symmetry check on incoming covariance blocks.
SYMMETRY_RTOL = 1.0e-9
#: Largest plausible ENU coordinate (m) of an incoming position: 10 000 km, far beyond any
#: sensor's reach; anything larger is a corrupted value, never a measurement.
MAX_ABS_ENU_M = 1.0e7
#: Largest plausible variance (m^2) in an incoming covariance (a 1000 km sigma).
MAX_VARIANCE_M2 = 1.0e12
#: Plausible heights (m, WGS84 ellipsoid) of a truth fix; the radar reader's bounds.
TRUTH_H_MIN, TRUTH_H_MAX = H_MIN, H_MAX

_NS = 1_000_000_000

__all__ = [
    "UNKNOWN_VARIANCE",
    "MessageError",
    "ns_to_time",
    "time_to_ns",
]


# --- time ---------------------------------------------------------------------------------


def stamp_from_time(t: float) -> Time:
    """UTC float seconds -> ``builtin_interfaces/Time`` (nearest nanosecond)."""
    sec, nsec = stamp_parts(t)
    return Time(sec=sec, nanosec=nsec)


def time_from_stamp(stamp: Time) -> float:
    """``builtin_interfaces/Time`` -> UTC float seconds (inverse of :func:`stamp_from_time`)."""
    return float(stamp.sec) + float(stamp.nanosec) / _NS


def check_stamp(stamp: Time) -> float:
    sec, nsec = stamp.sec, stamp.nanosec
    if sec == 0 and nsec == 0:
        raise MessageError("zero_stamp", "message has no stamp (0)")
    if sec < 0 or nsec >= _NS:
        raise MessageError("bad_stamp", f"stamp sec={sec}, nanosec={nsec} is not a UTC time")
    return float(sec) + float(nsec) / _NS


def check_position(z: FloatArray, what: str) -> None:
    if not np.all(np.isfinite(z)):
        raise MessageError("nan", f"{what} is not finite")
    if float(np.max(np.abs(z))) > MAX_ABS_ENU_M:
        raise MessageError(
            "out_of_range", f"{what} {z.tolist()} lies beyond {MAX_ABS_ENU_M:g} m of the origin"
        )


def _check_frame(frame_id: str, expected: str | None) -> None:
    if expected and frame_id != expected:
        raise MessageError("wrong_frame", f"frame '{frame_id}', expected '{expected}'")


def check_cov3(
    c00: float, c01: float, c02: float,
    c10: float, c11: float, c12: float,
    c20: float, c21: float, c22: float,
    what: str,
) -> None:
    """Raise :class:`MessageError` unless the 3x3 covariance is finite, symmetric (to
    :data:`SYMMETRY_RTOL` of its largest entry) and positive definite.

    Plain float arithmetic, cheapest test first: finiteness, symmetry, then one Cholesky
    factorisation of the lower triangle (the test ``numpy.linalg.cholesky`` makes), which
    fails at the first pivot that is not > 0.
    """
    isf = math.isfinite
    if not (isf(c00) and isf(c01) and isf(c02) and isf(c10) and isf(c11) and isf(c12)
            and isf(c20) and isf(c21) and isf(c22)):
        raise MessageError("bad_covariance", f"{what} covariance has non-finite entries")
    scale = max(abs(c00), abs(c01), abs(c02), abs(c10), abs(c11), abs(c12), abs(c20),
                abs(c21), abs(c22)) or 1.0
    if scale > MAX_VARIANCE_M2:
        raise MessageError(
            "bad_covariance", f"{what} covariance has entries beyond {MAX_VARIANCE_M2:g} m^2"
        )
    tol = SYMMETRY_RTOL * scale
    if abs(c01 - c10) > tol or abs(c02 - c20) > tol or abs(c12 - c21) > tol:
        raise MessageError("bad_covariance", f"{what} covariance is not symmetric")
    ok = c00 > 0.0
    if ok:
        l00 = math.sqrt(c00)
        l10 = c10 / l00
        l20 = c20 / l00
        d1 = c11 - l10 * l10
        ok = d1 > 0.0
        if ok:
            l21 = (c21 - l20 * l10) / math.sqrt(d1)
            ok = c22 - l20 * l20 - l21 * l21 > 0.0
    if not ok:
        raise MessageError("bad_covariance", f"{what} covariance is not positive definite")


def _check_cov_block(c: FloatArray, what: str) -> None:
    (a, b, d), (e, f, g), (h, i, j) = np.asarray(c, dtype=float).tolist()
    check_cov3(a, b, d, e, f, g, h, i, j, what)


def pose_cov(pos: FloatArray) -> FloatArray:
    return np.array(pose_covariance(pos.tolist()), dtype=np.float64)


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
    msg.pose.covariance = pose_cov(Rm)
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
    header = msg.header
    t = check_stamp(header.stamp)
    if expected_frame and header.frame_id != expected_frame:
        _check_frame(header.frame_id, expected_frame)
    pose = msg.pose
    p = pose.pose.position
    x, y, zz = p.x, p.y, p.z
    if not (math.isfinite(x) and math.isfinite(y) and math.isfinite(zz)):
        raise MessageError("nan", "radar position is not finite")
    if max(abs(x), abs(y), abs(zz)) > MAX_ABS_ENU_M:
        raise MessageError(
            "out_of_range",
            f"radar position {[x, y, zz]} lies beyond {MAX_ABS_ENU_M:g} m of the origin",
        )
    c = pose.covariance[:15].tolist()
    c00, c01, c02, c10, c11, c12, c20, c21, c22 = c[0:3] + c[6:9] + c[12:15]
    check_cov3(c00, c01, c02, c10, c11, c12, c20, c21, c22, "radar position")
    # exactly symmetric (the check allows rounding-size differences)
    s01, s02, s12 = 0.5 * (c01 + c10), 0.5 * (c02 + c20), 0.5 * (c12 + c21)
    R = np.array(((c00, s01, s02), (s01, c11, s12), (s02, s12, c22)))
    return Measurement(t=t, source=RADAR, z=np.array((x, y, zz)), R=R, seq=seq)


def msg_to_radar_report(
    msg: PoseWithCovarianceStamped, expected_frame: str | None = None
) -> RadarFrame:
    """Pose message -> a radar frame of one report carrying the message's position
    covariance (``radar/pose``: the paper's selected reports; no track id, class or range).

    Raises :class:`MessageError` like :func:`msg_to_radar_measurement`."""
    m = msg_to_radar_measurement(msg, expected_frame)
    R = m.R
    assert R is not None
    e, n, u = (float(v) for v in m.z)
    cov = (R[0, 0], R[0, 1], R[0, 2], R[1, 1], R[1, 2], R[2, 2])
    trk = RadarTrack(
        t=m.t, track_id=-1, lat=math.nan, lon=math.nan, h=math.nan, e=e, n=n, u=u,
        vel_ned=None, uav_prob=None, range_m=None, rcs_dbsm=None,
        cov=tuple(float(v) for v in cov),  # type: ignore[arg-type]
    )  # fmt: skip
    return RadarFrame(t=m.t, tracks=(trk,))


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
    header = msg.header
    t = check_stamp(header.stamp)
    if expected_frame and header.frame_id != expected_frame:
        _check_frame(header.frame_id, expected_frame)
    pt = msg.point
    x, y = pt.x, pt.y
    if math.isnan(x) and math.isnan(y) and math.isnan(pt.z):
        return None
    if not (math.isfinite(x) and math.isfinite(y)):
        raise MessageError("nan", "RF fix is partly non-finite")
    if max(abs(x), abs(y)) > MAX_ABS_ENU_M:
        raise MessageError(
            "out_of_range", f"RF fix {[x, y]} lies beyond {MAX_ABS_ENU_M:g} m of the origin"
        )
    return Measurement(t=t, source=RF, z=np.array((x, y)), R=None if R is None else np.array(R),
                       seq=seq)


def msg_to_rf_attempt(msg: PointStamped, expected_frame: str | None = None) -> RfAttempt:
    """Point message -> an RF attempt (``rf/fix``; all-NaN: a failed one, ``ok`` False).

    Raises :class:`MessageError` like :func:`msg_to_rf_measurement`."""
    m = msg_to_rf_measurement(msg, expected_frame)
    if m is None:
        t = time_from_stamp(msg.header.stamp)
        return RfAttempt(t, -1, False, math.nan, math.nan, math.nan, math.nan, None, None, None)
    e, n = (float(v) for v in m.z)
    return RfAttempt(m.t, -1, True, math.nan, math.nan, e, n, None, None, None)


# --- every report and fix: PointCloud2 (layout: uav_fusion.core.data.clouds) -----------------


def cloud_to_msg(t: float, cloud: clouds.Cloud, frame_id: str) -> PointCloud2:
    """A core :class:`~uav_fusion.core.data.clouds.Cloud` as a stamped PointCloud2."""
    msg = PointCloud2()
    msg.header.stamp = stamp_from_time(t)
    msg.header.frame_id = frame_id
    msg.height = 1
    msg.width = cloud.width
    msg.fields = [
        PointField(name=f.name, offset=f.offset, datatype=f.datatype, count=f.count)
        for f in cloud.fields
    ]
    msg.is_bigendian = False
    msg.point_step = cloud.point_step
    msg.row_step = cloud.row_step
    msg.data = cloud.data
    msg.is_dense = False
    return msg


def radar_frame_to_cloud_msg(
    frame: RadarFrame, frame_id: str, cov: clouds.CovFn | None = None
) -> PointCloud2:
    """Every report of a radar frame (``radar/tracks``)."""
    return cloud_to_msg(frame.t, clouds.radar_frame_to_cloud(frame, cov), frame_id)


def rf_attempts_to_cloud_msg(attempts: Sequence[RfAttempt], frame_id: str) -> PointCloud2:
    """RF attempts stamped with the first one's time (``rf/fixes``; one attempt per message
    in the replay)."""
    if not attempts:
        raise MessageError("empty", "no RF attempt to publish")
    return cloud_to_msg(attempts[0].t, clouds.rf_attempts_to_cloud(attempts), frame_id)


def _cloud_fields(msg: PointCloud2) -> list[clouds.CloudField]:
    return [clouds.CloudField(f.name, int(f.offset), int(f.datatype), int(f.count))
            for f in msg.fields]


def _cloud_header(msg: PointCloud2, expected_frame: str | None) -> float:
    t = check_stamp(msg.header.stamp)
    if expected_frame and msg.header.frame_id != expected_frame:
        _check_frame(msg.header.frame_id, expected_frame)
    return t


def msg_to_radar_frame(
    msg: PointCloud2, expected_frame: str | None = None
) -> tuple[RadarFrame, Counter[str]]:
    """``radar/tracks`` -> the frame of its valid reports and the dropped points by reason.

    Raises :class:`MessageError` for an unusable message (stamp, frame, layout)."""
    t = _cloud_header(msg, expected_frame)
    return clouds.cloud_to_radar_frame(
        t, _cloud_fields(msg), int(msg.point_step), int(msg.width), int(msg.height),
        bool(msg.is_bigendian), bytes(msg.data),
    )


def msg_to_rf_attempts(
    msg: PointCloud2, expected_frame: str | None = None
) -> tuple[list[RfAttempt], Counter[str]]:
    """``rf/fixes`` -> its attempts (failed ones as ``ok=False``) and the dropped points.

    Raises :class:`MessageError` for an unusable message (stamp, frame, layout)."""
    t = _cloud_header(msg, expected_frame)
    return clouds.cloud_to_rf_attempts(
        t, _cloud_fields(msg), int(msg.point_step), int(msg.width), int(msg.height),
        bool(msg.is_bigendian), bytes(msg.data),
    )


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
    t = check_stamp(msg.header.stamp)
    if msg.status.status == NavSatStatus.STATUS_NO_FIX:
        raise MessageError("no_fix", "truth fix has status NO_FIX")
    lat, lon, h = float(msg.latitude), float(msg.longitude), float(msg.altitude)
    if not (math.isfinite(lat) and math.isfinite(lon) and math.isfinite(h)):
        raise MessageError("nan", "truth position is not finite")
    if not (-90.0 <= lat <= 90.0 and -180.0 <= lon <= 180.0 and H_MIN <= h <= H_MAX):
        raise MessageError(
            "out_of_range",
            f"truth lat {lat}, lon {lon}, height {h} outside ±90, ±180, [{H_MIN:g}, {H_MAX:g}] m",
        )
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
