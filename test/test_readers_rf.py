"""Keysight RF CSV reader on hand-written rows in the real AADM.csv format."""

from __future__ import annotations

import dataclasses
import math
from collections import Counter
from pathlib import Path

import numpy as np
import pytest
from readers_util import ReaderFiles, lines

from uav_fusion.core.data import read_rf_csv
from uav_fusion.core.errors import DataError
from uav_fusion.core.site import Site, load_site

# The real header, with the stray spaces the real files carry.
HEADER = (
    "Meas ID,Algorithm,Center Frequency,Sample Rate,Num Samples, Latitude,Longitude ,"
    "Elevation,RHO,CEP,Total Sensors,Valid Sensors,Overloaded Sensors,Sensor Names,Time,Comment"
)
T0 = 1759866140.0  # 2025-10-07 19:42:20 UTC


def row(
    mid: int | str,
    lat: str,
    lon: str,
    time: str,
    cep: str = "45.2",
    sensors: str = '"LW2,LW3,LW4,LW5"',
    valid: str = "4",
    comment: str = "",
) -> str:
    return (
        f"{mid},TDOA,2.44E+09,2.8E+07,16384,{lat},{lon},0,0.93,{cep},4,{valid},0,"
        f"{sensors},{time},{comment}"
    )


GOOD = row(1, "35.7300", "-78.6980", "2025-10-07 19:42:20.000")
FAILED = row(2, "0", "0", "2025-10-07 19:42:23.880", cep="", sensors='"LW2,LW3"', valid="2")
GOOD2 = row(3, "35.7310", "-78.6990", "2025-10-07 19:42:27.760", comment="ok")


@pytest.fixture(scope="module")
def site() -> Site:
    return load_site()


_FILES = ReaderFiles(read_rf_csv, "AADM.csv")
write = _FILES.write
strict_error = _FILES.strict_error


def test_real_format_rows(tmp_path: Path, site: Site) -> None:
    p = write(tmp_path, lines(HEADER, GOOD, FAILED, GOOD2))
    out, rep = read_rf_csv(p, site)
    assert [a.meas_id for a in out] == [1, 2, 3]
    assert [a.line for a in out] == [2, 3, 4]
    a, f, b = out
    assert a.t == T0 and f.t == pytest.approx(T0 + 3.88) and b.t == pytest.approx(T0 + 7.76)
    assert a.ok and b.ok and not f.ok
    assert (a.lat, a.lon) == (35.73, -78.698)
    e, n, _ = site.to_enu(35.73, -78.698, site.h0)
    assert a.e == pytest.approx(float(e), abs=1e-9) and a.n == pytest.approx(float(n), abs=1e-9)
    assert math.isnan(f.e) and math.isnan(f.n) and (f.lat, f.lon) == (0.0, 0.0)
    assert (a.cep, a.valid_sensors, a.total_sensors) == (45.2, 4, 4)
    assert (f.cep, f.valid_sensors, f.total_sensors) == (None, 2, 4)
    assert rep.rows == 3 and rep.used == 3 and rep.skipped == Counter()
    assert rep.notes == ["3 attempts, 1 failed (Latitude = Longitude = 0)"]


def test_rf_position_matches_published_geometry(tmp_path: Path, site: Site) -> None:
    lw4 = site.towers["LW4"]
    p = write(tmp_path, lines(HEADER, row(9, str(lw4.lat), str(lw4.lon), "2025-10-07 19:42:20")))
    (a,), _ = read_rf_csv(p, site)
    assert (a.e, a.n) == pytest.approx((-217.7, 629.6), abs=0.1)


def test_clock_offset_is_applied(tmp_path: Path, site: Site) -> None:
    shifted = dataclasses.replace(site, clock_offsets_h={"rf": 1.0})
    p = write(tmp_path, lines(HEADER, GOOD))
    (a,), _ = read_rf_csv(p, shifted)
    assert a.t == T0 - 3600.0  # file clock = UTC + 1 h


def test_zoned_time_ignores_clock_offset(tmp_path: Path, site: Site) -> None:
    shifted = dataclasses.replace(site, clock_offsets_h={"rf": 1.0})
    p = write(tmp_path, lines(HEADER, row(1, "35.73", "-78.698", "2025-10-07T15:42:20-04:00")))
    (a,), _ = read_rf_csv(p, shifted)
    assert a.t == T0


def test_bom_and_crlf(tmp_path: Path, site: Site) -> None:
    p = write(tmp_path, ("\ufeff" + HEADER + "\r\n" + GOOD + "\r\n").encode("utf-8"))
    out, rep = read_rf_csv(p, site)
    assert len(out) == 1 and out[0].t == T0 and rep.skipped == Counter()


def test_empty_file(tmp_path: Path, site: Site) -> None:
    p = write(tmp_path, "")
    out, rep = read_rf_csv(p, site)
    assert out == [] and rep.rows == 0 and rep.notes == ["empty file: no header line"]
    err = strict_error(p, site)
    assert str(err) == f"{p}: empty file: no header line" and err.line is None


def test_header_only(tmp_path: Path, site: Site) -> None:
    out, rep = read_rf_csv(write(tmp_path, HEADER + "\n"), site, strict=True)
    assert out == [] and rep.rows == 0 and rep.used == 0


def test_missing_file(tmp_path: Path, site: Site) -> None:
    p = tmp_path / "nope.csv"
    for strict in (False, True):
        with pytest.raises(DataError) as ei:
            read_rf_csv(p, site, strict=strict)
        assert str(ei.value) == f"{p}: file not found"


def test_truncated_last_line(tmp_path: Path, site: Site) -> None:
    p = write(tmp_path, HEADER + "\n" + GOOD + "\n" + "4,TDOA,2.44E+09,2.8E+07,16384,35.73")
    out, rep = read_rf_csv(p, site)
    assert len(out) == 1 and rep.rows == 2 and rep.skipped == Counter({"truncated": 1})
    err = strict_error(p, site)
    assert err.line == 3
    assert err.what == (
        "truncated last line (no newline at end of file): 6 fields, the header has 16"
    )


def test_complete_last_line_without_newline_is_read(tmp_path: Path, site: Site) -> None:
    out, rep = read_rf_csv(write(tmp_path, HEADER + "\n" + GOOD), site, strict=True)
    assert len(out) == 1 and rep.skipped == Counter()


def test_wrong_column_count_inside_file(tmp_path: Path, site: Site) -> None:
    p = write(tmp_path, lines(HEADER, "5,TDOA,1,2", GOOD, GOOD2 + ",,"))
    out, rep = read_rf_csv(p, site)
    assert [a.meas_id for a in out] == [1, 3]  # trailing empty fields are tolerated
    assert rep.skipped == Counter({"bad_columns": 1})
    err = strict_error(p, site)
    assert (err.line, err.what) == (2, "4 fields, the header has 16")


def test_wrong_header(tmp_path: Path, site: Site) -> None:
    bad = HEADER.replace("Time", "Timestamp").replace("Meas ID", "ID")
    p = write(tmp_path, lines(bad, GOOD, GOOD2))
    out, rep = read_rf_csv(p, site)
    assert out == [] and rep.rows == 2 and rep.skipped == Counter({"bad_header": 2})
    assert rep.notes[0].startswith("line 1: header lacks column(s) 'Meas ID', 'Time'; found: 'ID'")
    assert rep.notes[0].endswith("no row could be read")
    err = strict_error(p, site)
    found = ", ".join(repr(h.strip()) for h in bad.split(","))
    assert err.line == 1
    assert err.what == f"header lacks column(s) 'Meas ID', 'Time'; found: {found}"
    assert found.startswith("'ID', 'Algorithm', 'Center Frequency', 'Sample Rate', 'Num Samples',")
    assert rep.notes == [f"line 1: {err.what}; no row could be read"]


def test_non_utf8_bytes(tmp_path: Path, site: Site) -> None:
    in_comment = row(1, "35.73", "-78.698", "2025-10-07 19:42:20", comment="caf\xe9").encode(
        "latin-1"
    )
    in_latitude = row(2, "35.7\xe9", "-78.698", "2025-10-07 19:42:24").encode("latin-1")
    data = (HEADER + "\n").encode() + in_comment + b"\n" + in_latitude + b"\n"
    p = write(tmp_path, data)
    out, rep = read_rf_csv(p, site)
    assert [a.meas_id for a in out] == [1]  # a bad byte in free text costs nothing
    assert rep.skipped == Counter({"bad_value": 1})
    assert rep.notes[0] == (
        "2 line(s) hold bytes that are not UTF-8 (first: line 2); they were replaced by U+FFFD"
    )
    err = strict_error(p, site)
    col = in_comment.index(b"\xe9") + 1
    assert err.line == 2 and err.what == f"byte 0xe9 at byte {col} is not UTF-8"


def test_time_order_policy(tmp_path: Path, site: Site) -> None:
    back = row(4, "35.73", "-78.698", "2025-10-07 19:42:19.000")
    dup = row(5, "35.73", "-78.698", "2025-10-07 19:42:23.880")
    p = write(tmp_path, lines(HEADER, GOOD, FAILED, back, dup, GOOD2))
    out, rep = read_rf_csv(p, site)
    assert [a.meas_id for a in out] == [1, 2, 3]
    assert rep.skipped == Counter({"time_backwards": 1, "duplicate_time": 1})
    err = strict_error(p, site)
    assert err.line == 4
    assert err.what == (
        "time 2025-10-07T19:42:19.000Z is earlier than 2025-10-07T19:42:23.880Z on line 3"
    )
    p2 = write(tmp_path, lines(HEADER, GOOD, FAILED, dup), "dup.csv")
    err = strict_error(p2, site)
    assert (err.line, err.what) == (4, "time 2025-10-07T19:42:23.880Z repeats line 3")


def test_nonfinite_and_out_of_range(tmp_path: Path, site: Site) -> None:
    rows = [
        row(4, "nan", "-78.698", "2025-10-07 19:42:21"),
        row(5, "35.73", "inf", "2025-10-07 19:42:22"),
        row(6, "95.0", "-78.698", "2025-10-07 19:42:23"),
        row(7, "35.73", "-181", "2025-10-07 19:42:24"),
        row(8, "north", "-78.698", "2025-10-07 19:42:25"),
    ]
    p = write(tmp_path, lines(HEADER, GOOD, *rows))
    out, rep = read_rf_csv(p, site)
    assert [a.meas_id for a in out] == [1]
    assert rep.skipped == Counter({"nonfinite": 2, "out_of_range": 2, "bad_value": 1})
    err = strict_error(p, site)
    assert (err.line, err.what) == (3, "Latitude/Longitude nan, -78.698 not finite")
    p2 = write(tmp_path, lines(HEADER, rows[2]), "r.csv")
    err = strict_error(p2, site)
    assert (err.line, err.what) == (2, "Latitude/Longitude 95.0, -78.698 out of range")


def test_bad_times(tmp_path: Path, site: Site) -> None:
    rows = [
        row(4, "35.73", "-78.698", "yesterday"),
        row(5, "35.73", "-78.698", "12.5"),  # seconds since boot: not plausible
        row(6, "35.73", "-78.698", "2025-13-07 19:42:20"),
        row(7, "35.73", "-78.698", "1759866150.5"),  # unix seconds are accepted
    ]
    p = write(tmp_path, lines(HEADER, GOOD, *rows))
    out, rep = read_rf_csv(p, site)
    assert [a.t for a in out] == [T0, T0 + 10.5]
    assert rep.skipped == Counter({"bad_time": 3})
    err = strict_error(p, site)
    assert (err.line, err.what) == (3, "Time 'yesterday' is not a plausible time")


def test_unreadable_optional_field(tmp_path: Path, site: Site) -> None:
    p = write(tmp_path, lines(HEADER, row(1, "35.73", "-78.698", "2025-10-07 19:42:20", cep="?")))
    (a,), rep = read_rf_csv(p, site)
    assert a.cep is None and rep.skipped == Counter()
    assert rep.notes[-1] == (
        "1 optional field value(s) unreadable, read as missing (first: line 2: CEP '?' is not a "
        "number)"
    )
    err = strict_error(p, site)
    assert (err.line, err.what) == (2, "CEP '?' is not a number")


def test_quoted_field_with_stray_quote_does_not_swallow_rows(tmp_path: Path, site: Site) -> None:
    broken = row(4, "35.73", "-78.698", "2025-10-07 19:42:21", sensors='"LW2,LW3')
    p = write(tmp_path, lines(HEADER, GOOD, broken, GOOD2))
    out, rep = read_rf_csv(p, site)
    assert [a.meas_id for a in out] == [1, 3]
    assert rep.skipped == Counter({"bad_columns": 1})


def test_failed_attempts_are_never_positions(tmp_path: Path, site: Site) -> None:
    p = write(tmp_path, lines(HEADER, FAILED))
    (f,), _ = read_rf_csv(p, site)
    assert not f.ok and np.isnan([f.e, f.n]).all()


def test_carriage_return_inside_an_unquoted_field(tmp_path: Path, site: Site) -> None:
    # a lone \r inside a field (a file written half with Windows line ends) is one bad row
    p = write(tmp_path, lines(HEADER, GOOD, FAILED.replace("TDOA", "TD\rOA"), GOOD2))
    out, rep = read_rf_csv(p, site)
    assert [a.line for a in out] == [2, 4]
    assert rep.rows == 3 and rep.used == 2 and rep.skipped == Counter({"bad_csv": 1})
    err = strict_error(p, site)
    assert str(err) == f"{p}:3: carriage return (\\r) inside an unquoted field at column 5"
    assert (err.path, err.line) == (p, 3)


def test_carriage_return_inside_the_header(tmp_path: Path, site: Site) -> None:
    p = write(tmp_path, lines(HEADER.replace("Latitude", "Lat\ritude"), GOOD, GOOD2))
    out, rep = read_rf_csv(p, site)
    assert out == [] and rep.skipped == Counter({"bad_header": 2})
    assert "header line is not CSV: carriage return" in rep.notes[0]
    assert strict_error(p, site).line == 1
