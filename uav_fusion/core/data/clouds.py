"""Every radar report of a frame and every RF fix as ``sensor_msgs/PointCloud2`` points.

The layout of ``radar/tracks`` and ``rf/fixes`` (docs/graph.md) in plain Python, shared by the
live conversions (:mod:`uav_fusion.ros.conversions`, rclpy messages), the bag converter
(:mod:`uav_fusion.bag.convert`, rosbags messages) and the fusion node's decoder, so all write
and read the same bytes. Every field is little-endian, ``count`` 1; positions and every real
value are FLOAT64 so that a decoded report equals the file's value bit for bit (live ==
offline); a value the source does not carry is NaN (an integer one: -1).

``radar/tracks``: one cloud per radar frame, one point per report, header stamp = the frame's
UTC time, ``frame_id`` = the site's ENU frame. Fields, in order:

=================  =========  ==========================================================
name               datatype   meaning
=================  =========  ==========================================================
x, y, z            FLOAT64    report position, ENU metres (E, N, U)
vx, vy, vz         FLOAT64    the radar track's velocity, ENU m/s (NaN x3: not reported)
track_id           INT32      the radar's own track id
uav_prob           FLOAT64    UAV class probability (``catProb[0]``), 0..1
rcs                FLOAT64    radar cross-section, dBsm
range              FLOAT64    slant range reported by the radar, m
radial_velocity    FLOAT64    Doppler velocity, m/s
cov_xx .. cov_zz   FLOAT64    the report's ENU position covariance, m^2 (upper triangle:
                              xx, xy, xz, yy, yz, zz) from the publishing profile's radar
                              model; informative only (a tracker applies its own model)
=================  =========  ==========================================================

``rf/fixes``: one cloud per localisation attempt (one point), stamp = the attempt's UTC time.

=================  =========  ==========================================================
name               datatype   meaning
=================  =========  ==========================================================
x, y, z            FLOAT64    fix E, N (m) and 0.0; NaN x3: the attempt failed
cep                FLOAT64    circular error probable, m
valid_sensors      INT32      sensors that contributed to the fix
total_sensors      INT32      sensors in the network
meas_id            INT32      the Keysight measurement id
center_freq        FLOAT64    centre frequency of the emitter's channel, Hz
rho                FLOAT64    the correlation quality RHO of the solution
=================  =========  ==========================================================

Decoding reads fields by name (extra fields and other orders are accepted). A message whose
layout is unusable (a required field missing or of another type, big-endian data, a size that
does not match) raises :class:`MessageError` (``bad_layout``); a point that cannot be a
measurement (non-finite or partially NaN position or velocity, a position beyond
:data:`MAX_ABS_ENU_M`, a probability outside 0..1, a negative CEP or range) is dropped and
counted by reason, and never reaches a tracker.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from uav_fusion.core.data.encoding import MessageError
from uav_fusion.core.records import RadarFrame, RadarTrack, RfAttempt

#: sensor_msgs/PointField datatypes (fixed by the message definition).
INT32 = 5
FLOAT64 = 8
_NUMPY = {INT32: "<i4", FLOAT64: "<f8"}
_SIZE = {INT32: 4, FLOAT64: 8}

#: Largest plausible ENU coordinate (m) of a point (10 000 km): beyond it a value is corrupt.
MAX_ABS_ENU_M = 1.0e7
#: Largest plausible speed component (m/s) of a radar track.
MAX_ABS_SPEED_MPS = 1.0e4

COV_FIELDS = ("cov_xx", "cov_xy", "cov_xz", "cov_yy", "cov_yz", "cov_zz")
RADAR_FIELDS: tuple[tuple[str, int], ...] = (
    ("x", FLOAT64), ("y", FLOAT64), ("z", FLOAT64),
    ("vx", FLOAT64), ("vy", FLOAT64), ("vz", FLOAT64),
    ("track_id", INT32),
    ("uav_prob", FLOAT64), ("rcs", FLOAT64), ("range", FLOAT64), ("radial_velocity", FLOAT64),
    *((c, FLOAT64) for c in COV_FIELDS),
)
RF_FIELDS: tuple[tuple[str, int], ...] = (
    ("x", FLOAT64), ("y", FLOAT64), ("z", FLOAT64),
    ("cep", FLOAT64),
    ("valid_sensors", INT32), ("total_sensors", INT32), ("meas_id", INT32),
    ("center_freq", FLOAT64), ("rho", FLOAT64),
)
#: Fields a decoder needs (the others are informative).
RADAR_REQUIRED = ("x", "y", "z", "track_id")
RF_REQUIRED = ("x", "y", "z")

_I32 = (-(2**31), 2**31 - 1)


@dataclass(frozen=True)
class CloudField:
    """One ``sensor_msgs/PointField``."""

    name: str
    offset: int
    datatype: int
    count: int = 1


@dataclass(frozen=True)
class Cloud:
    """The payload of a PointCloud2 (height 1, little-endian, ``is_dense`` False)."""

    fields: tuple[CloudField, ...]
    point_step: int
    width: int
    data: bytes

    @property
    def row_step(self) -> int:
        return self.point_step * self.width


def _layout(spec: Sequence[tuple[str, int]]) -> tuple[tuple[CloudField, ...], np.dtype]:
    fields: list[CloudField] = []
    off = 0
    for name, dt in spec:
        fields.append(CloudField(name, off, dt))
        off += _SIZE[dt]
    dtype = np.dtype(
        {
            "names": [f.name for f in fields],
            "formats": [_NUMPY[f.datatype] for f in fields],
            "offsets": [f.offset for f in fields],
            "itemsize": off,
        }
    )
    return tuple(fields), dtype


RADAR_LAYOUT, RADAR_DTYPE = _layout(RADAR_FIELDS)
RF_LAYOUT, RF_DTYPE = _layout(RF_FIELDS)


def _opt(v: float | None) -> float:
    return math.nan if v is None else float(v)


def _opt_int(v: int | None, what: str) -> int:
    if v is None:
        return -1
    if not _I32[0] <= int(v) <= _I32[1]:
        raise MessageError("out_of_range", f"{what} {v} does not fit INT32")
    return int(v)


#: The covariance of a report: ENU position (e, n, u) -> packed upper triangle (6 values).
CovFn = Callable[[float, float, float], Sequence[float]]


def radar_frame_to_cloud(frame: RadarFrame, cov: CovFn | None = None) -> Cloud:
    """Every report of ``frame`` as one cloud (``cov``: the covariance model; None: NaN)."""
    arr = np.zeros(len(frame.tracks), dtype=RADAR_DTYPE)
    for i, tr in enumerate(frame.tracks):
        v = tr.vel_ned
        vx, vy, vz = (math.nan,) * 3 if v is None else (float(v[1]), float(v[0]), -float(v[2]))
        c = (math.nan,) * 6 if cov is None else tuple(float(x) for x in cov(tr.e, tr.n, tr.u))
        arr[i] = (
            float(tr.e), float(tr.n), float(tr.u), vx, vy, vz,
            _opt_int(tr.track_id, "track id"),
            _opt(tr.uav_prob), _opt(tr.rcs_dbsm), _opt(tr.range_m), _opt(tr.radial_velocity),
            *c,
        )
    return Cloud(RADAR_LAYOUT, RADAR_DTYPE.itemsize, len(frame.tracks), arr.tobytes())


def rf_attempts_to_cloud(attempts: Sequence[RfAttempt]) -> Cloud:
    """RF attempts as one cloud (a failed attempt: x = y = z = NaN)."""
    arr = np.zeros(len(attempts), dtype=RF_DTYPE)
    for i, a in enumerate(attempts):
        if a.ok and math.isfinite(a.e) and math.isfinite(a.n):
            x, y, z = float(a.e), float(a.n), 0.0
        else:
            x = y = z = math.nan
        arr[i] = (
            x, y, z, _opt(a.cep),
            _opt_int(a.valid_sensors, "valid sensors"),
            _opt_int(a.total_sensors, "total sensors"),
            _opt_int(a.meas_id, "measurement id"),
            _opt(a.center_freq_hz), _opt(a.rho),
        )
    return Cloud(RF_LAYOUT, RF_DTYPE.itemsize, len(attempts), arr.tobytes())


# --- decoding ---------------------------------------------------------------------------------
def _points(
    fields: Sequence[CloudField],
    point_step: int,
    width: int,
    height: int,
    is_bigendian: bool,
    data: bytes,
    required: Sequence[str],
    wanted: Sequence[tuple[str, int]],
) -> tuple[npt.NDArray[np.void], set[str]]:
    """The points as a structured array of the ``wanted`` fields present (checked layout)."""
    if is_bigendian:
        raise MessageError("bad_layout", "big-endian point data is not supported")
    n = int(width) * int(height)
    if point_step <= 0 and n:
        raise MessageError("bad_layout", f"point_step {point_step}")
    if len(data) != n * point_step:
        raise MessageError(
            "bad_layout", f"{len(data)} data bytes for {n} points of {point_step} bytes"
        )
    by_name = {f.name: f for f in fields}
    missing = [r for r in required if r not in by_name]
    if missing:
        raise MessageError("bad_layout", f"missing field(s) {', '.join(missing)}")
    names, formats, offsets = [], [], []
    for name, dt in wanted:
        f = by_name.get(name)
        if f is None:
            continue
        if f.datatype != dt or f.count != 1:
            raise MessageError(
                "bad_layout",
                f"field {name!r} has datatype {f.datatype} x{f.count}, expected {dt} x1",
            )
        if f.offset < 0 or f.offset + _SIZE[dt] > point_step:
            raise MessageError("bad_layout", f"field {name!r} at offset {f.offset} "
                               f"beyond the {point_step}-byte point")
        names.append(name)
        formats.append(_NUMPY[dt])
        offsets.append(f.offset)
    dtype = np.dtype(
        {"names": names, "formats": formats, "offsets": offsets, "itemsize": max(point_step, 1)}
    )
    arr = np.frombuffer(bytes(data), dtype=dtype, count=n) if n else np.zeros(0, dtype=dtype)
    return arr, set(names)


def _get(p: np.void, present: set[str], name: str) -> float:
    return float(p[name]) if name in present else math.nan


def _get_int(p: np.void, present: set[str], name: str) -> int | None:
    if name not in present:
        return None
    v = int(p[name])
    return None if v < 0 else v


def cloud_to_radar_frame(
    t: float,
    fields: Sequence[CloudField],
    point_step: int,
    width: int,
    height: int,
    is_bigendian: bool,
    data: bytes,
) -> tuple[RadarFrame, Counter[str]]:
    """Decode a ``radar/tracks`` cloud stamped ``t``: the frame of its valid reports and the
    dropped points by reason (``nan``, ``out_of_range``, ``bad_value``)."""
    arr, have = _points(fields, point_step, width, height, is_bigendian, data,
                        RADAR_REQUIRED, RADAR_FIELDS)
    dropped: Counter[str] = Counter()
    tracks: list[RadarTrack] = []
    for p in arr:
        e, n, u = float(p["x"]), float(p["y"]), float(p["z"])
        if not (math.isfinite(e) and math.isfinite(n) and math.isfinite(u)):
            dropped["nan"] += 1
            continue
        if max(abs(e), abs(n), abs(u)) > MAX_ABS_ENU_M:
            dropped["out_of_range"] += 1
            continue
        vx, vy, vz = (_get(p, have, k) for k in ("vx", "vy", "vz"))
        fin = [math.isfinite(v) for v in (vx, vy, vz)]
        if any(fin) and not all(fin):
            dropped["nan"] += 1
            continue
        if all(fin) and max(abs(vx), abs(vy), abs(vz)) > MAX_ABS_SPEED_MPS:
            dropped["out_of_range"] += 1
            continue
        prob, rcs, rng, dop = (_get(p, have, k) for k in ("uav_prob", "rcs", "range",
                                                           "radial_velocity"))
        if math.isinf(prob) or math.isinf(rcs) or math.isinf(rng) or math.isinf(dop):
            dropped["nan"] += 1
            continue
        if (math.isfinite(prob) and not 0.0 <= prob <= 1.0) or (math.isfinite(rng) and rng < 0):
            dropped["bad_value"] += 1
            continue
        tracks.append(
            RadarTrack(
                t=t,
                track_id=int(p["track_id"]),
                lat=math.nan,
                lon=math.nan,
                h=math.nan,
                e=e,
                n=n,
                u=u,
                vel_ned=(vy, vx, -vz) if all(fin) else None,
                uav_prob=prob if math.isfinite(prob) else None,
                range_m=rng if math.isfinite(rng) else None,
                rcs_dbsm=rcs if math.isfinite(rcs) else None,
                radial_velocity=dop if math.isfinite(dop) else None,
            )
        )
    return RadarFrame(t=t, tracks=tuple(tracks)), dropped


def cloud_to_rf_attempts(
    t: float,
    fields: Sequence[CloudField],
    point_step: int,
    width: int,
    height: int,
    is_bigendian: bool,
    data: bytes,
) -> tuple[list[RfAttempt], Counter[str]]:
    """Decode an ``rf/fixes`` cloud stamped ``t``: its attempts (failed ones included, as
    ``ok=False``) and the dropped points by reason (``nan``, ``out_of_range``, ``bad_value``)."""
    arr, have = _points(fields, point_step, width, height, is_bigendian, data,
                        RF_REQUIRED, RF_FIELDS)
    dropped: Counter[str] = Counter()
    out: list[RfAttempt] = []
    for p in arr:
        x, y, z = float(p["x"]), float(p["y"]), float(p["z"])
        nan3 = math.isnan(x) and math.isnan(y) and math.isnan(z)
        if not nan3 and not (math.isfinite(x) and math.isfinite(y) and math.isfinite(z)):
            dropped["nan"] += 1
            continue
        if not nan3 and max(abs(x), abs(y), abs(z)) > MAX_ABS_ENU_M:
            dropped["out_of_range"] += 1
            continue
        cep, freq, rho = (_get(p, have, k) for k in ("cep", "center_freq", "rho"))
        if math.isinf(cep) or math.isinf(freq) or math.isinf(rho):
            dropped["nan"] += 1
            continue
        if math.isfinite(cep) and cep < 0.0:
            dropped["bad_value"] += 1
            continue
        mid = _get_int(p, have, "meas_id")
        out.append(
            RfAttempt(
                t=t,
                meas_id=-1 if mid is None else mid,
                ok=not nan3,
                lat=math.nan,
                lon=math.nan,
                e=math.nan if nan3 else x,
                n=math.nan if nan3 else y,
                cep=cep if math.isfinite(cep) else None,
                valid_sensors=_get_int(p, have, "valid_sensors"),
                total_sensors=_get_int(p, have, "total_sensors"),
                center_freq_hz=freq if math.isfinite(freq) else None,
                rho=rho if math.isfinite(rho) else None,
            )
        )
    return out, dropped
