"""Reader of the vehicle truth log ``<date>_<time>_vehicleOut.txt``.

No header; ten comma-separated columns, the tuple columns quoted::

    line, lon, lat, alt, "(pitch,yaw,roll)", "(vN,vE,vD)", battery_V, local_timestamp,
    gps_fix_type, num_sats

Note longitude BEFORE latitude. ``alt`` is relative to the take-off point, so the ellipsoidal
height is ``site.takeoff_h + alt``. ``lat``/``lon``/``alt`` are −999 when the logger had no
fix (fix type below 2): such rows are skipped and counted as ``no_fix`` (in both modes; they
are expected, not errors). The timestamp is the vehicle computer's local wall clock,
``YYYY-MM-DD HH:MM:SS[.ffffff]`` (the fraction is absent when it is zero); unix seconds are
also accepted. UTC = file time − ``site.clock_offset_s("truth")`` (default offset −4 h, so
UTC = local + 4 h). A timestamp carrying its own zone (``Z``, ``±HH:MM``) is converted with
that zone and the offset is not applied.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Sequence
from pathlib import Path
from typing import NamedTuple

import numpy as np

from uav_fusion.core.data._source import (
    LinePolicy,
    Source,
    TimeOrder,
    csv_fields,
    parse_clock_time,
    to_float,
    to_int,
    unix_clock_note,
)
from uav_fusion.core.records import LoadReport, TruthFix
from uav_fusion.core.site import Site

COLUMNS = (
    "line",
    "lon",
    "lat",
    "alt",
    "(pitch,yaw,roll)",
    "(vN,vE,vD)",
    "battery_V",
    "local_timestamp",
    "gps_fix_type",
    "num_sats",
)
NO_FIX = -999.0
MIN_FIX_TYPE = 2


def _triple(text: str) -> tuple[float, float, float] | None:
    s = text.strip()
    if not (s.startswith("(") and s.endswith(")")):
        return None
    parts = s[1:-1].split(",")
    if len(parts) != 3:
        return None
    vals = [to_float(p) for p in parts]
    if any(v is None or not math.isfinite(v) for v in vals):
        return None
    return (float(vals[0] or 0.0), float(vals[1] or 0.0), float(vals[2] or 0.0))


class RawFix(NamedTuple):
    """A decoded truth row before the ENU conversion."""

    t: float
    lat: float
    lon: float
    alt: float
    vel: tuple[float, float, float]
    fix: int
    sats: int
    line: int


class TruthLines:
    """Decodes truth rows one at a time, with ``policy``'s bookkeeping and ``order``'s
    time-ordering policy: the file reader and the live stream decoder share it.

    :meth:`decode` returns the fix a row carries (before the ENU conversion, which
    :func:`truth_fixes` does for many at once) or None for a row without a fix (counted as
    ``no_fix``) or one that was skipped (counted by ``policy``). :attr:`kinds` counts the
    timestamp kinds read (``wall``, ``zoned``, ``unix``), :attr:`fix_types` the fix types.
    """

    def __init__(self, policy: LinePolicy, order: TimeOrder, offset_s: float) -> None:
        self.policy = policy
        self.order = order
        self.offset_s = offset_s
        self.kinds: Counter[str] = Counter()
        self.fix_types: Counter[int] = Counter()

    def decode(self, line: int, text: str) -> RawFix | None:
        src = self.policy
        f, not_csv = csv_fields(text)
        if f is None:
            src.bad(line, "bad_csv", str(not_csv))
            return None
        if len(f) != len(COLUMNS):
            src.bad(
                line,
                "bad_columns",
                f"{len(f)} fields, expected {len(COLUMNS)} ({', '.join(COLUMNS)})",
            )
            return None
        lon, lat, alt = to_float(f[1]), to_float(f[2]), to_float(f[3])
        if lon is None or lat is None or alt is None:
            src.bad(
                line,
                "bad_value",
                f"lon/lat/alt {f[1].strip()!r}, {f[2].strip()!r}, {f[3].strip()!r} not numbers",
            )
            return None
        fix = to_int(f[8])
        if fix is None:
            src.bad(line, "bad_value", f"gps_fix_type {f[8].strip()!r} is not an integer")
            return None
        if NO_FIX in (lon, lat, alt) or fix < MIN_FIX_TYPE:
            src.count("no_fix")
            return None
        if not (math.isfinite(lon) and math.isfinite(lat) and math.isfinite(alt)):
            src.bad(line, "nonfinite", f"lon/lat/alt {lon}, {lat}, {alt} not finite")
            return None
        if not (-90.0 <= lat <= 90.0 and -180.0 <= lon <= 180.0):
            src.bad(line, "out_of_range", f"lat/lon {lat}, {lon} out of range")
            return None
        parsed = parse_clock_time(f[7])
        if parsed is None:
            src.bad(line, "bad_time", f"timestamp {f[7].strip()!r} is not a plausible time")
            return None
        t = parsed[0] - (self.offset_s if parsed[1] != "zoned" else 0.0)
        if not self.order.accept(t, line):
            return None
        vel = _triple(f[5])
        if vel is None:
            src.soft(line, f"velocity {f[5].strip()!r} is not a (vN,vE,vD) tuple")
            vel = (math.nan, math.nan, math.nan)
        sats = to_int(f[9])
        if sats is None:
            src.soft(line, f"num_sats {f[9].strip()!r} is not an integer")
            sats = -1
        self.kinds[parsed[1]] += 1
        self.fix_types[fix] += 1
        return RawFix(t, lat, lon, alt, vel, fix, sats, line)


def truth_fixes(site: Site, kept: Sequence[RawFix]) -> list[TruthFix]:
    """Decoded truth rows as ENU fixes (one vectorised conversion for all); the height is
    ``site.takeoff_h`` + the row's relative altitude."""
    lat_a = np.array([k.lat for k in kept], dtype=float)
    lon_a = np.array([k.lon for k in kept], dtype=float)
    h_a = site.takeoff_h + np.array([k.alt for k in kept], dtype=float)
    e_a, n_a, u_a = site.to_enu(lat_a, lon_a, h_a)
    return [
        TruthFix(
            t=k.t,
            lat=k.lat,
            lon=k.lon,
            h=float(h_a[j]),
            e=float(e_a[j]),
            n=float(n_a[j]),
            u=float(u_a[j]),
            vel_ned=k.vel,
            fix_type=k.fix,
            num_sats=k.sats,
            line=k.line,
        )
        for j, k in enumerate(kept)
    ]


def read_truth(
    path: str | Path, site: Site, *, strict: bool = False
) -> tuple[list[TruthFix], LoadReport]:
    """Read one vehicle truth log into UTC, ENU truth fixes.

    Skip reasons (lenient mode): ``no_fix`` (also counted in strict mode, never raised),
    ``bad_csv`` (a carriage return inside an unquoted field, an oversized field),
    ``bad_columns``, ``truncated``, ``bad_value``, ``nonfinite``, ``out_of_range``,
    ``bad_time``, ``time_backwards``, ``duplicate_time``. An unreadable velocity tuple gives
    NaN velocity and an unreadable satellite count −1 (noted; strict mode raises).
    """
    src = Source(path, strict)
    rep = src.report
    rep.rows = len(src.lines)
    if not src.lines:
        src.empty("empty file: no truth rows")
        return [], src.finish()
    offset = site.clock_offset_s("truth")
    dec = TruthLines(src, TimeOrder(src), offset)
    kept = [k for line, text in src.lines if (k := dec.decode(line, text)) is not None]
    out = truth_fixes(site, kept)
    rep.used = len(out)
    if dec.fix_types:
        rep.notes.append(
            "fix types: " + ", ".join(f"{ft}×{c}" for ft, c in sorted(dec.fix_types.items()))
        )
    if dec.kinds["unix"] and offset != 0.0:
        rep.notes.append(unix_clock_note(dec.kinds["unix"], "truth", offset))
    return out, src.finish()
