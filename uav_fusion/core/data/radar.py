"""Reader of the Fortem TrueView radar log ``radar_data_*.json`` (JSON Lines).

One JSON object per line. Kinds of line:

- status: an object with ``error`` (e.g. ``{"error":{"code":200,...}}``) or ``result`` and
  no track data. Skipped and counted as ``status`` (in both modes; not an error).
- track frame: ``{"params":{"globalTime":<unix s>,"gpsWeek":..,"gpsSeconds":..},
  "trackData":[...]}``; ``trackData`` may also sit inside ``params``. Frame time:
  ``params.globalTime``, else a top-level ``globalTime``, else GPS week/seconds (GPS time
  minus the 18 s GPS−UTC leap-second difference valid since 2017). UTC = frame time −
  ``site.clock_offset_s("radar")``. Every track of a frame gets the frame's time.

Track fields: ``id`` (integer), ``lla`` [lat deg, lon deg, alt m] — the altitude is taken as
ellipsoidal height (HAE, WGS84), the radar's GNSS-referenced output —, ``velocityNed``
[n, e, d] m/s, ``catProb`` (class probabilities; index 0 = UAV), ``range`` m,
``radialVelocity`` m/s, ``numInliers``, and RCS in dBsm as ``rcsDbsm`` (or ``rcs``).
A track lacking ``lla`` or with non-finite / out-of-range position is skipped (counted by
reason, prefixed ``track_``) without losing the frame's other tracks. Unreadable optional
fields are read as None (strict mode raises).
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from uav_fusion.core.data._source import T_MAX, T_MIN, LinePolicy, Source, TimeOrder
from uav_fusion.core.records import LoadReport, RadarFrame, RadarTrack
from uav_fusion.core.site import Site

GPS_EPOCH_UNIX = 315964800.0  # 1980-01-06T00:00:00Z
GPS_UTC_LEAP_S = 18.0  # GPS − UTC since 2017-01-01
H_MIN, H_MAX = -500.0, 10000.0  # plausible ellipsoidal heights of a track, metres


def _parse_int(text: str) -> int | float:
    """JSON integers as int, except those beyond the float range (over 300 digits), which
    become ±inf so that every later float conversion and finiteness check holds."""
    if len(text) <= 300:
        return int(text)
    return -math.inf if text.startswith("-") else math.inf


def _is_num(v: Any) -> bool:
    """A JSON number (``bool`` is not one; JSON gives exactly int or float)."""
    return type(v) is float or type(v) is int


def _finite(v: Any) -> float | None:
    """A finite JSON number as float, else None."""
    if (type(v) is float or type(v) is int) and math.isfinite(v):
        return float(v)
    return None


def _frame_time(obj: dict[str, Any], params: dict[str, Any]) -> float | None:
    for holder in (params, obj):
        v = _finite(holder.get("globalTime"))
        if v is not None:
            return v
    week, sec = _finite(params.get("gpsWeek")), _finite(params.get("gpsSeconds"))
    if week is not None and sec is not None:
        return GPS_EPOCH_UNIX + 604800.0 * week + sec - GPS_UTC_LEAP_S
    return None


class _Track:
    __slots__ = ("h", "id", "lat", "lon", "ninl", "prob", "range", "rcs", "rv", "vel")

    def __init__(self) -> None:
        self.id = 0
        self.lat = self.lon = self.h = 0.0
        self.vel: tuple[float, float, float] | None = None
        self.prob: float | None = None
        self.range: float | None = None
        self.rcs: float | None = None
        self.rv: float | None = None
        self.ninl: int | None = None


class RawFrame(NamedTuple):
    """A decoded radar line before the ENU conversion."""

    t: float
    line: int
    tracks: list[_Track]


class RadarLines:
    """Decodes radar lines one at a time, with ``policy``'s bookkeeping and ``order``'s
    time-ordering policy: the file reader and the live stream decoder share it.

    :meth:`decode` returns the frame a line carries (before the ENU conversion, which
    :func:`radar_frames` does for many frames at once) or None for a status line or a line
    that was skipped (counted by ``policy``).
    """

    def __init__(self, policy: LinePolicy, order: TimeOrder, offset_s: float) -> None:
        self.policy = policy
        self.order = order
        self.offset_s = offset_s

    def decode(self, line: int, text: str) -> RawFrame | None:
        src = self.policy
        try:
            obj = json.loads(text, parse_int=_parse_int)
        except json.JSONDecodeError as exc:
            src.bad(line, "bad_json", f"invalid JSON: {exc.msg} at column {exc.colno}")
            return None
        except RecursionError:
            src.bad(line, "bad_json", "invalid JSON: nested too deeply")
            return None
        if not isinstance(obj, dict):
            src.bad(line, "not_object", f"a JSON {type(obj).__name__}, not an object")
            return None
        params = obj.get("params")
        if not isinstance(params, dict):
            params = {}
        if "trackData" in obj:
            tdata = obj["trackData"]
        elif "trackData" in params:
            tdata = params["trackData"]
        elif "error" in obj or "result" in obj:
            src.count("status")
            return None
        else:
            src.bad(line, "no_track_data", "object has neither trackData nor error/result")
            return None
        if tdata is None:
            tdata = []
        if not isinstance(tdata, list):
            src.bad(line, "bad_track_data", f"trackData is a {type(tdata).__name__}, not a list")
            return None
        t_file = _frame_time(obj, params)
        if t_file is None:
            src.bad(
                line, "no_time", "frame has no finite params.globalTime (nor gpsWeek/gpsSeconds)"
            )
            return None
        t = t_file - self.offset_s
        if not T_MIN <= t_file <= T_MAX:
            src.bad(line, "bad_time", f"globalTime {t_file!r} is not a plausible unix time")
            return None
        if not self.order.accept(t, line):
            return None
        tracks = [tr for k, raw in enumerate(tdata) if (tr := _track(src, line, k, raw))]
        return RawFrame(t, line, tracks)


def radar_frames(site: Site, frames: Sequence[RawFrame]) -> list[RadarFrame]:
    """Decoded radar lines as frames of ENU tracks (one vectorised conversion for all)."""
    all_tracks = [tr for _, _, trs in frames for tr in trs]
    lat = np.array([tr.lat for tr in all_tracks], dtype=float)
    lon = np.array([tr.lon for tr in all_tracks], dtype=float)
    h = np.array([tr.h for tr in all_tracks], dtype=float)
    e, n, u = site.to_enu(lat, lon, h)
    out: list[RadarFrame] = []
    j = 0
    for t, line, trs in frames:
        recs = []
        for tr in trs:
            recs.append(
                RadarTrack(
                    t=t,
                    track_id=tr.id,
                    lat=tr.lat,
                    lon=tr.lon,
                    h=tr.h,
                    e=float(e[j]),
                    n=float(n[j]),
                    u=float(u[j]),
                    vel_ned=tr.vel,
                    uav_prob=tr.prob,
                    range_m=tr.range,
                    rcs_dbsm=tr.rcs,
                    radial_velocity=tr.rv,
                    num_inliers=tr.ninl,
                    line=line,
                )
            )
            j += 1
        out.append(RadarFrame(t=t, tracks=tuple(recs), line=line))
    return out


def read_radar_jsonl(
    path: str | Path, site: Site, *, strict: bool = False
) -> tuple[list[RadarFrame], LoadReport]:
    """Read one radar JSON Lines log into UTC frames of ENU tracks.

    Line-level skip reasons (lenient mode): ``status`` (never raised), ``bad_json``,
    ``truncated``, ``not_object``, ``no_track_data``, ``bad_track_data``, ``no_time``,
    ``bad_time``, ``time_backwards``, ``duplicate_time``. Track-level: ``track_bad_value``,
    ``track_no_lla``, ``track_nonfinite``, ``track_out_of_range``.
    """
    src = Source(path, strict)
    rep = src.report
    rep.rows = len(src.lines)
    if not src.lines:
        src.empty("empty file: no radar lines")
        return [], src.finish()
    dec = RadarLines(src, TimeOrder(src), site.clock_offset_s("radar"))
    raw = [f for line, text in src.lines if (f := dec.decode(line, text)) is not None]
    out = radar_frames(site, raw)
    rep.used = len(out)
    rep.notes.append(f"{len(out)} frames, {sum(len(f.tracks) for f in out)} tracks")
    return out, src.finish()


def _track(src: LinePolicy, line: int, k: int, raw: Any) -> _Track | None:
    """One track of a frame, or None (skipped and counted) if its position is unusable."""
    where = f"trackData[{k}]"
    if not isinstance(raw, dict):
        src.bad(line, "track_bad_value", f"{where} is not an object")
        return None
    rid = raw.get("id")
    fid = _finite(rid)
    if fid is None or fid != int(fid):
        src.bad(line, "track_bad_value", f"{where}: id {rid!r} is not an integer")
        return None
    tid = int(fid)
    where = f"{where} (id {tid})"
    lla = raw.get("lla")
    if lla is None:
        src.bad(line, "track_no_lla", f"{where}: no lla")
        return None
    if not (isinstance(lla, list) and len(lla) == 3 and all(_is_num(v) for v in lla)):
        src.bad(line, "track_bad_value", f"{where}: lla {lla!r} is not [lat, lon, alt]")
        return None
    lat, lon, h = (float(v) for v in lla)
    if not (math.isfinite(lat) and math.isfinite(lon) and math.isfinite(h)):
        src.bad(line, "track_nonfinite", f"{where}: lla {lat}, {lon}, {h} not finite")
        return None
    if not (-90.0 <= lat <= 90.0 and -180.0 <= lon <= 180.0 and H_MIN <= h <= H_MAX):
        src.bad(line, "track_out_of_range", f"{where}: lla {lat}, {lon}, {h} out of range")
        return None
    tr = _Track()
    tr.id, tr.lat, tr.lon, tr.h = tid, lat, lon, h

    v = raw.get("velocityNed")
    if v is not None:
        if isinstance(v, list) and len(v) == 3 and all(_is_num(x) and math.isfinite(x) for x in v):
            tr.vel = (float(v[0]), float(v[1]), float(v[2]))
        else:
            src.soft(line, f"{where}: velocityNed {v!r} is not 3 finite numbers")
    cp = raw.get("catProb")
    if cp is not None:
        if isinstance(cp, list) and cp and _is_num(cp[0]) and 0.0 <= cp[0] <= 1.0:
            tr.prob = float(cp[0])
        else:
            src.soft(line, f"{where}: catProb {cp!r} has no probability at index 0")
    tr.range = _opt(src, line, where, raw, "range", lo=0.0)
    rcs_key = "rcsDbsm" if raw.get("rcsDbsm") is not None else "rcs"
    tr.rcs = _opt(src, line, where, raw, rcs_key)
    tr.rv = _opt(src, line, where, raw, "radialVelocity")
    ni = _opt(src, line, where, raw, "numInliers", lo=0.0)
    if ni is not None:
        if ni == int(ni):
            tr.ninl = int(ni)
        else:
            src.soft(line, f"{where}: numInliers {ni!r} is not an integer")
    return tr


def _opt(
    src: LinePolicy, line: int, where: str, raw: dict[str, Any], key: str, lo: float | None = None
) -> float | None:
    v = raw.get(key)
    if v is None:
        return None
    if _is_num(v) and math.isfinite(v) and (lo is None or v >= lo):
        return float(v)
    src.soft(line, f"{where}: {key} {v!r} is not a valid number")
    return None
