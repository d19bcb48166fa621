"""How the core's records map onto ROS 2 message fields, without ROS.

The rules of ``docs/graph.md`` in plain Python, shared by the live conversions
(:mod:`uav_fusion.ros.conversions`, rclpy message classes) and the bag converter
(:mod:`uav_fusion.bag.convert`, rosbags' message classes), so both write the same bytes:

- **Time.** A stamp is the sensor's UTC time as (sec, nanosec), nearest nanosecond.
  :func:`stamp_parts` and :func:`time_from_parts` round-trip every float time exactly whenever
  the float's resolution is coarser than 1 ns, which holds for any time after 1970-04-08
  (|t| >= 2**23 s), i.e. for every real or simulated UTC time we handle.
- **Pose covariance.** 6x6 row-major; the position block is the given 3x3 matrix, the
  orientation variances are :data:`UNKNOWN_VARIANCE` and the cross terms zero.
- **RF fix.** x = E, y = N, z = 0.0; a failed attempt is x = y = z = NaN.
- **Truth fix status.** MAVLink fix type -> ``NavSatStatus`` (RTK float/fixed -> GBAS_FIX,
  DGPS -> SBAS_FIX, 2D/3D -> FIX, below 2D -> NO_FIX), service GPS, covariance unknown.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from uav_fusion.core.errors import UavFusionError
from uav_fusion.core.records import RfAttempt

#: Variance (rad^2, or (rad/s)^2) written for components that are not estimated.
UNKNOWN_VARIANCE = 1.0e6

NS = 1_000_000_000

# sensor_msgs/NavSatStatus and NavSatFix constants (fixed by the message definitions)
STATUS_NO_FIX = -1
STATUS_FIX = 0
STATUS_SBAS_FIX = 1
STATUS_GBAS_FIX = 2
SERVICE_GPS = 1
COVARIANCE_TYPE_UNKNOWN = 0


class MessageError(UavFusionError):
    """A message cannot be built or used; ``reason`` is a short key for drop counters."""

    def __init__(self, reason: str, what: str) -> None:
        self.reason = reason
        super().__init__(f"{reason}: {what}")


def stamp_parts(t: float) -> tuple[int, int]:
    """UTC float seconds -> (sec, nanosec) of a ``builtin_interfaces/Time`` (nearest ns)."""
    if not math.isfinite(t) or t < 0.0:
        raise MessageError("bad_stamp", f"time {t!r} cannot be a ROS stamp")
    sec = math.floor(t)
    nsec = round((t - sec) * NS)  # t - sec is exact for floats
    if nsec >= NS:
        sec, nsec = sec + 1, nsec - NS
    return int(sec), int(nsec)


def time_from_parts(sec: int, nanosec: int) -> float:
    """(sec, nanosec) -> UTC float seconds (inverse of :func:`stamp_parts`)."""
    return float(sec) + float(nanosec) / NS


def time_to_ns(t: float) -> int:
    """UTC float seconds -> integer nanoseconds (the rclpy clock's unit)."""
    sec, nsec = stamp_parts(t)
    return sec * NS + nsec


def ns_to_time(ns: int) -> float:
    """Integer nanoseconds -> UTC float seconds."""
    sec, nsec = divmod(int(ns), NS)
    return float(sec) + float(nsec) / NS


def pose_covariance(block: Sequence[Sequence[float]]) -> list[float]:
    """The 36 row-major entries of a pose covariance whose position block is ``block``."""
    u = UNKNOWN_VARIANCE
    r0, r1, r2 = block[0], block[1], block[2]
    return [
        float(r0[0]), float(r0[1]), float(r0[2]), 0.0, 0.0, 0.0,
        float(r1[0]), float(r1[1]), float(r1[2]), 0.0, 0.0, 0.0,
        float(r2[0]), float(r2[1]), float(r2[2]), 0.0, 0.0, 0.0,
        0.0, 0.0, 0.0, u, 0.0, 0.0,
        0.0, 0.0, 0.0, 0.0, u, 0.0,
        0.0, 0.0, 0.0, 0.0, 0.0, u,
    ]


def rf_point(a: RfAttempt) -> tuple[float, float, float]:
    """The point of an RF attempt: (E, N, 0.0), or NaN x3 for a failed attempt."""
    if a.ok and math.isfinite(a.e) and math.isfinite(a.n):
        return float(a.e), float(a.n), 0.0
    return math.nan, math.nan, math.nan


def navsat_status(fix_type: int) -> int:
    """MAVLink fix type -> ``NavSatStatus.status``."""
    if fix_type >= 5:
        return STATUS_GBAS_FIX
    if fix_type == 4:
        return STATUS_SBAS_FIX
    if fix_type >= 2:
        return STATUS_FIX
    return STATUS_NO_FIX


def fix_type_from_status(status: int) -> int:
    """``NavSatStatus.status`` -> the MAVLink fix type it stands for (lowest of its class)."""
    return {STATUS_GBAS_FIX: 5, STATUS_SBAS_FIX: 4, STATUS_FIX: 3}.get(int(status), 0)
