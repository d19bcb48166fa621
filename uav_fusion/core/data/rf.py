"""Reader of the Keysight N6854A geolocation CSV (``AADM.csv`` / ``AADM_rerun.csv``).

Header (names may carry stray spaces, matched without case)::

    Meas ID,Algorithm,Center Frequency,Sample Rate,Num Samples,Latitude,Longitude,Elevation,
    RHO,CEP,Total Sensors,Valid Sensors,Overloaded Sensors,Sensor Names,Time,Comment

Required columns: Meas ID, Latitude, Longitude, Time. CEP, Total Sensors, Valid Sensors,
Center Frequency (Hz) and RHO are kept when present. ``Time`` is the file clock (UTC for
these files) such as
``2025-10-07 19:42:20.000``; UTC = file time − ``site.clock_offset_s("rf")``.

A failed attempt (Latitude = Longitude = 0) is kept as ``RfAttempt(ok=False)`` with NaN
east/north: it counts as an attempt, never as a position. RF fixes are 2D; their east/north
are computed at the ENU origin's height ``site.h0`` (the filter uses only e, n). Reading them
at h0 rather than at the flight height (up to 200 m above) moves e, n by at most 0.07 m at
2.1 km from the origin: nothing against RF errors of tens of metres.
"""

from __future__ import annotations

import math
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
)
from uav_fusion.core.errors import DataError
from uav_fusion.core.records import LoadReport, RfAttempt
from uav_fusion.core.site import Site

REQUIRED = ("Meas ID", "Latitude", "Longitude", "Time")
OPTIONAL = ("CEP", "Total Sensors", "Valid Sensors", "Center Frequency", "RHO")


def column_key(name: str) -> str:
    """A header name as matched: spaces collapsed, lower case."""
    return " ".join(name.split()).lower()


#: The Keysight server's header (what a stream without a header line is read with).
AADM_HEADER = (
    "Meas ID,Algorithm,Center Frequency,Sample Rate,Num Samples,Latitude,Longitude,Elevation,"
    "RHO,CEP,Total Sensors,Valid Sensors,Overloaded Sensors,Sensor Names,Time,Comment"
)


class RawAttempt(NamedTuple):
    """A decoded RF row before the ENU conversion."""

    t: float
    meas_id: int
    lat: float
    lon: float
    cep: float | None
    total: int | None
    valid: int | None
    line: int
    freq: float | None
    rho: float | None


def header_problem(header: list[str] | None, not_csv: str | None) -> str | None:
    """Why a header row cannot be used (not CSV, a required column missing), or None."""
    if header is None:
        return f"header line is not CSV: {not_csv}"
    col = {column_key(h) for h in header if h.strip()}
    missing = [c for c in REQUIRED if column_key(c) not in col]
    if missing:
        found = ", ".join(repr(h.strip()) for h in header)
        return f"header lacks column(s) {', '.join(repr(m) for m in missing)}; found: {found}"
    return None


class RfLines:
    """Decodes RF rows one at a time against a header, with ``policy``'s bookkeeping and
    ``order``'s time-ordering policy: the file reader and the live stream decoder share it.

    ``header`` must pass :func:`header_problem`. :meth:`decode` returns the attempt a row
    carries (before the ENU conversion, which :func:`rf_attempts` does for many at once) or
    None for a row that was skipped (counted by ``policy``).
    """

    def __init__(
        self, policy: LinePolicy, order: TimeOrder, offset_s: float, header: list[str]
    ) -> None:
        self.policy = policy
        self.order = order
        self.offset_s = offset_s
        self.set_header(header)

    def set_header(self, header: list[str]) -> None:
        col = {column_key(h): i for i, h in enumerate(header) if h.strip()}
        self.i_id, self.i_lat, self.i_lon, self.i_time = (col[column_key(c)] for c in REQUIRED)
        self.i_cep, self.i_tot, self.i_val, self.i_freq, self.i_rho = (
            col.get(column_key(c)) for c in OPTIONAL
        )
        self.n_cols = len(header)

    def decode(self, line: int, text: str) -> RawAttempt | None:
        src = self.policy
        f, not_csv = csv_fields(text)
        if f is None:
            src.bad(line, "bad_csv", str(not_csv))
            return None
        n_cols = self.n_cols
        if len(f) != n_cols and not (len(f) > n_cols and not any(x.strip() for x in f[n_cols:])):
            src.bad(line, "bad_columns", f"{len(f)} fields, the header has {n_cols}")
            return None
        i_id, i_lat, i_lon, i_time = self.i_id, self.i_lat, self.i_lon, self.i_time
        meas_id = to_int(f[i_id])
        if meas_id is None:
            src.bad(line, "bad_value", f"Meas ID {f[i_id].strip()!r} is not an integer")
            return None
        lat, lon = to_float(f[i_lat]), to_float(f[i_lon])
        if lat is None or lon is None:
            src.bad(
                line,
                "bad_value",
                f"Latitude/Longitude {f[i_lat].strip()!r}, {f[i_lon].strip()!r} not numbers",
            )
            return None
        if not (math.isfinite(lat) and math.isfinite(lon)):
            src.bad(line, "nonfinite", f"Latitude/Longitude {lat}, {lon} not finite")
            return None
        if not (-90.0 <= lat <= 90.0 and -180.0 <= lon <= 180.0):
            src.bad(line, "out_of_range", f"Latitude/Longitude {lat}, {lon} out of range")
            return None
        parsed = parse_clock_time(f[i_time])
        if parsed is None:
            src.bad(line, "bad_time", f"Time {f[i_time].strip()!r} is not a plausible time")
            return None
        t = parsed[0] - (self.offset_s if parsed[1] != "zoned" else 0.0)
        if not self.order.accept(t, line):
            return None
        cep = _opt_float(src, line, f, self.i_cep, "CEP")
        tot = _opt_int(src, line, f, self.i_tot, "Total Sensors")
        val = _opt_int(src, line, f, self.i_val, "Valid Sensors")
        freq = _opt_float(src, line, f, self.i_freq, "Center Frequency")
        rho = _opt_float(src, line, f, self.i_rho, "RHO")
        return RawAttempt(t, meas_id, lat, lon, cep, tot, val, line, freq, rho)


def rf_attempts(site: Site, kept: Sequence[RawAttempt]) -> list[RfAttempt]:
    """Decoded RF rows as attempts with ENU east/north (one vectorised conversion for all);
    a failed attempt (Latitude = Longitude = 0) gets NaN."""
    lat_a = np.array([k.lat for k in kept], dtype=float)
    lon_a = np.array([k.lon for k in kept], dtype=float)
    ok_a = ~((lat_a == 0.0) & (lon_a == 0.0))
    e_a = np.full(lat_a.size, np.nan)
    n_a = np.full(lat_a.size, np.nan)
    if ok_a.any():
        e, n, _ = site.to_enu(lat_a[ok_a], lon_a[ok_a], np.full(int(ok_a.sum()), site.h0))
        e_a[ok_a], n_a[ok_a] = e, n
    return [
        RfAttempt(
            t=k.t,
            meas_id=k.meas_id,
            ok=bool(ok_a[j]),
            lat=k.lat,
            lon=k.lon,
            e=float(e_a[j]),
            n=float(n_a[j]),
            cep=k.cep,
            valid_sensors=k.valid,
            total_sensors=k.total,
            line=k.line,
            center_freq_hz=k.freq,
            rho=k.rho,
        )
        for j, k in enumerate(kept)
    ]


def read_rf_csv(
    path: str | Path, site: Site, *, strict: bool = False
) -> tuple[list[RfAttempt], LoadReport]:
    """Read one Keysight RF CSV into RF attempts (failed ones included) in UTC.

    Skip reasons (lenient mode): ``bad_header`` (every row, when the header lacks a
    required column or is not CSV), ``bad_csv`` (a carriage return inside an unquoted
    field, a field beyond the ``csv`` module's size limit), ``bad_columns``, ``truncated``,
    ``bad_value``, ``bad_time``, ``nonfinite``, ``out_of_range``, ``time_backwards``,
    ``duplicate_time``.
    """
    src = Source(path, strict)
    rep = src.report
    if not src.lines:
        src.empty("empty file: no header line")
        return [], src.finish()

    hline, htext = src.lines[0]
    header, bad_header = csv_fields(htext)
    rows = src.lines[1:]
    rep.rows = len(rows)
    what = header_problem(header, bad_header)
    if header is None or what is not None:
        if strict:
            raise DataError(src.path, hline, str(what))
        rep.skipped["bad_header"] += len(rows)
        rep.notes.append(f"line {hline}: {what}; no row could be read")
        return [], src.finish()

    dec = RfLines(src, TimeOrder(src), site.clock_offset_s("rf"), header)
    kept = [k for line, text in rows if (k := dec.decode(line, text)) is not None]
    out = rf_attempts(site, kept)
    rep.used = len(out)
    n_failed = sum(1 for a in out if not a.ok)
    rep.notes.append(f"{len(out)} attempts, {n_failed} failed (Latitude = Longitude = 0)")
    return out, src.finish()


def _opt_float(
    src: LinePolicy, line: int, f: list[str], i: int | None, name: str
) -> float | None:
    if i is None or i >= len(f) or not f[i].strip():
        return None
    x = to_float(f[i])
    if x is None:
        src.soft(line, f"{name} {f[i].strip()!r} is not a number")
        return None
    return x if math.isfinite(x) else None


def _opt_int(src: LinePolicy, line: int, f: list[str], i: int | None, name: str) -> int | None:
    if i is None or i >= len(f) or not f[i].strip():
        return None
    x = to_int(f[i])
    if x is None:
        src.soft(line, f"{name} {f[i].strip()!r} is not an integer")
    return x
