"""Damaged copies of the bundled flight's files never crash the Dataset-28 readers.

Each example takes a slice of one bundled file (a few hundred lines), damages it (byte flips,
truncation, duplicated / deleted / shuffled lines, garbage lines, NaN / inf, 400-digit
numbers, empty fields, odd Unicode, stray carriage returns) and reads it:

- lenient: a list of records whose accounting adds up (every data line used or skipped
  under one reason, radar tracks counted apart), strictly increasing times, finite ENU;
- strict (on the same damaged file): the same, or a ``DataError`` naming the file and a
  line of it (only an empty file has no line). Any other exception fails the property.
"""

from __future__ import annotations

import itertools
import math
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

from hypothesis import given
from hypothesis import strategies as st
from propkit import count_data_lines, damaged_lines, examples

from uav_fusion.core.data import read_radar_jsonl, read_rf_csv, read_truth
from uav_fusion.core.errors import DataError
from uav_fusion.core.records import LoadReport
from uav_fusion.core.site import load_site

FLIGHT = Path(__file__).resolve().parents[2] / "data" / "default_flight"
SITE = load_site()


def _slice(glob: str, start: int, n: int, keep_first: bool = False) -> list[bytes]:
    (path,) = FLIGHT.glob(glob)
    lines = path.read_bytes().split(b"\n")
    body = lines[start : start + n]
    return ([lines[0]] if keep_first else []) + body


# RF: the header and 150 rows; radar: 200 lines around the first tracks; truth: 200 rows
# across the first fix (some no-fix rows, then fixes)
RF_LINES = _slice("AADM.csv", 1, 150, keep_first=True)
RADAR_LINES = _slice("radar_data_*.json", 225, 200)
TRUTH_LINES = _slice("*_vehicleOut.txt", 300, 200)

Reader = Callable[..., tuple[list[Any], LoadReport]]
SURFACES: dict[str, tuple[Reader, str, list[bytes]]] = {
    "rf": (read_rf_csv, "AADM.csv", RF_LINES),
    "radar": (read_radar_jsonl, "radar_data_2025-10-07_19-40-00.json", RADAR_LINES),
    "truth": (read_truth, "2025-10-07_15-40-00_vehicleOut.txt", TRUTH_LINES),
}


def _times(kind: str, out: list[Any]) -> list[float]:
    return [r.t for r in out]


def _check_records(kind: str, out: list[Any], rep: LoadReport, n_lines: int) -> None:
    """The invariants every successful read keeps, lenient or strict."""
    ts = _times(kind, out)
    assert all(math.isfinite(t) for t in ts)
    assert all(a < b for a, b in itertools.pairwise(ts)), "times not increasing"
    assert rep.used == len(out)
    line_skips = sum(v for k, v in rep.skipped.items() if not k.startswith("track_"))
    data_rows = n_lines - 1 if kind == "rf" and n_lines else n_lines
    assert rep.rows == data_rows, (rep.rows, data_rows)
    assert rep.used + line_skips == rep.rows, rep.summary()
    if kind == "rf":
        for a in out:
            assert a.ok == math.isfinite(a.e) == math.isfinite(a.n)
            assert math.isfinite(a.lat) and math.isfinite(a.lon)
    elif kind == "radar":
        for fr in out:
            for tr in fr.tracks:
                assert all(math.isfinite(v) for v in (tr.lat, tr.lon, tr.h, tr.e, tr.n, tr.u))
                assert tr.t == fr.t
    else:
        for f in out:
            assert all(math.isfinite(v) for v in (f.lat, f.lon, f.h, f.e, f.n, f.u))
            assert f.fix_type >= 2


def _run(kind: str, data: bytes, strict: bool) -> None:
    reader, name, _ = SURFACES[kind]
    with tempfile.TemporaryDirectory() as d:
        p = Path(d) / name
        p.write_bytes(data)
        n_lines = count_data_lines(data)
        try:
            out, rep = reader(p, SITE, strict=strict)
        except DataError as exc:
            assert strict, f"lenient mode raised {exc}"
            assert exc.path == p
            msg = str(exc)
            if exc.line is None:
                assert exc.what.startswith("empty file"), msg
            else:
                assert 1 <= exc.line <= data.count(b"\n") + 1, msg
                assert msg.startswith(f"{p}:{exc.line}: ") and exc.what
            return
        _check_records(kind, out, rep, n_lines)
        if strict:  # strict skips only normal content
            assert set(rep.skipped) <= {"status", "no_fix"}, rep.summary()


def _damaged(kind: str) -> st.SearchStrategy[bytes]:
    return damaged_lines(SURFACES[kind][2])


@examples(ci=80)
@given(data=_damaged("rf"))
def test_rf_csv_survives_damage(data: bytes) -> None:
    _run("rf", data, strict=False)
    _run("rf", data, strict=True)


@examples(ci=80)
@given(data=_damaged("radar"))
def test_radar_jsonl_survives_damage(data: bytes) -> None:
    _run("radar", data, strict=False)
    _run("radar", data, strict=True)


@examples(ci=80)
@given(data=_damaged("truth"))
def test_truth_log_survives_damage(data: bytes) -> None:
    _run("truth", data, strict=False)
    _run("truth", data, strict=True)


def test_undamaged_slices_read_fully_in_strict_mode() -> None:
    # the property's baseline: the slices themselves are clean
    for kind, (reader, name, lines) in SURFACES.items():
        with tempfile.TemporaryDirectory() as d:
            p = Path(d) / name
            p.write_bytes(b"\n".join(lines) + b"\n")
            out, rep = reader(p, SITE, strict=True)
            assert len(out) > 50, (kind, rep.summary())
            _check_records(kind, out, rep, len(lines))
