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
from pathlib import Path

import numpy as np

from uav_fusion.core.data._source import (
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
    order = TimeOrder(src)
    kinds: Counter[str] = Counter()
    fix_types: Counter[int] = Counter()
    nan3 = (math.nan, math.nan, math.nan)
    kept: list[tuple[float, float, float, float, tuple[float, float, float], int, int, int]] = []
    for line, text in src.lines:
        f, not_csv = csv_fields(text)
        if f is None:
            src.bad(line, "bad_csv", str(not_csv))
            continue
        if len(f) != len(COLUMNS):
            src.bad(
                line,
                "bad_columns",
                f"{len(f)} fields, expected {len(COLUMNS)} ({', '.join(COLUMNS)})",
            )
            continue
        lon, lat, alt = to_float(f[1]), to_float(f[2]), to_float(f[3])
        if lon is None or lat is None or alt is None:
            src.bad(
                line,
                "bad_value",
                f"lon/lat/alt {f[1].strip()!r}, {f[2].strip()!r}, {f[3].strip()!r} not numbers",
            )
            continue
        fix = to_int(f[8])
        if fix is None:
            src.bad(line, "bad_value", f"gps_fix_type {f[8].strip()!r} is not an integer")
            continue
        if NO_FIX in (lon, lat, alt) or fix < MIN_FIX_TYPE:
            rep.skip("no_fix")
            continue
        if not (math.isfinite(lon) and math.isfinite(lat) and math.isfinite(alt)):
            src.bad(line, "nonfinite", f"lon/lat/alt {lon}, {lat}, {alt} not finite")
            continue
        if not (-90.0 <= lat <= 90.0 and -180.0 <= lon <= 180.0):
            src.bad(line, "out_of_range", f"lat/lon {lat}, {lon} out of range")
            continue
        parsed = parse_clock_time(f[7])
        if parsed is None:
            src.bad(line, "bad_time", f"timestamp {f[7].strip()!r} is not a plausible time")
            continue
        t = parsed[0] - (offset if parsed[1] != "zoned" else 0.0)
        if not order.accept(t, line):
            continue
        vel = _triple(f[5])
        if vel is None:
            src.soft(line, f"velocity {f[5].strip()!r} is not a (vN,vE,vD) tuple")
            vel = nan3
        sats = to_int(f[9])
        if sats is None:
            src.soft(line, f"num_sats {f[9].strip()!r} is not an integer")
            sats = -1
        kinds[parsed[1]] += 1
        fix_types[fix] += 1
        kept.append((t, lat, lon, alt, vel, fix, sats, line))

    lat_a = np.array([k[1] for k in kept], dtype=float)
    lon_a = np.array([k[2] for k in kept], dtype=float)
    h_a = site.takeoff_h + np.array([k[3] for k in kept], dtype=float)
    e_a, n_a, u_a = site.to_enu(lat_a, lon_a, h_a)
    out = [
        TruthFix(
            t=k[0],
            lat=k[1],
            lon=k[2],
            h=float(h_a[j]),
            e=float(e_a[j]),
            n=float(n_a[j]),
            u=float(u_a[j]),
            vel_ned=k[4],
            fix_type=k[5],
            num_sats=k[6],
            line=k[7],
        )
        for j, k in enumerate(kept)
    ]
    rep.used = len(out)
    if fix_types:
        rep.notes.append(
            "fix types: " + ", ".join(f"{ft}×{c}" for ft, c in sorted(fix_types.items()))
        )
    if kinds["unix"] and offset != 0.0:
        rep.notes.append(unix_clock_note(kinds["unix"], "truth", offset))
    return out, src.finish()
