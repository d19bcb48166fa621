"""Vehicle truth log reader on hand-written rows in the real ``*_vehicleOut.txt`` format."""

from __future__ import annotations

import dataclasses
import math
from collections import Counter
from pathlib import Path

import pytest
from readers_util import ReaderFiles, lines

from uav_fusion.core.data import read_truth
from uav_fusion.core.errors import DataError
from uav_fusion.core.site import Site, load_site

T0 = 1759866140.0  # 2025-10-07 19:42:20 UTC = 15:42:20 EDT


def row(
    n: int,
    lon: str,
    lat: str,
    alt: str,
    ts: str,
    fix: str = "6",
    sats: str = "22",
    vel: str = '"(1.25,-0.5,0.1)"',
) -> str:
    return f'{n},{lon},{lat},{alt},"(0.01,1.57,-0.02)",{vel},15.8,{ts},{fix},{sats}'


R1 = row(1, "-78.6980", "35.7300", "45.0", "2025-10-07 15:42:20.000000")
R2 = row(2, "-78.6981", "35.7301", "45.5", "2025-10-07 15:42:20.200000")
NOFIX = row(3, "-999", "-999", "-999", "2025-10-07 15:42:20.400000", fix="1", sats="4")
R4 = row(4, "-78.6982", "35.7302", "46.0", "2025-10-07 15:42:20.600000")


@pytest.fixture(scope="module")
def site() -> Site:
    return load_site()


_FILES = ReaderFiles(read_truth, "t_vehicleOut.txt")
write = _FILES.write
strict_error = _FILES.strict_error


def test_real_format_rows(tmp_path: Path, site: Site) -> None:
    p = write(tmp_path, lines(R1, R2, NOFIX, R4))
    out, rep = read_truth(p, site)
    assert [f.line for f in out] == [1, 2, 4]
    a = out[0]
    assert a.t == T0  # local EDT + 4 h
    assert out[1].t == pytest.approx(T0 + 0.2) and out[2].t == pytest.approx(T0 + 0.6)
    assert (a.lat, a.lon) == (35.73, -78.698)  # lon is the column BEFORE lat
    assert a.h == site.takeoff_h + 45.0
    e, n, u = site.to_enu(35.73, -78.698, site.takeoff_h + 45.0)
    assert (a.e, a.n, a.u) == pytest.approx((float(e), float(n), float(u)), abs=1e-9)
    assert a.vel_ned == (1.25, -0.5, 0.1)
    assert (a.fix_type, a.num_sats) == (6, 22)
    assert rep.rows == 4 and rep.used == 3 and rep.skipped == Counter({"no_fix": 1})
    assert rep.notes == ["fix types: 6×3"]
    # no-fix rows are expected: strict mode counts them too instead of raising
    out2, rep2 = read_truth(p, site, strict=True)
    assert len(out2) == 3 and rep2.skipped == Counter({"no_fix": 1})


def test_fix_type_below_two_is_no_fix(tmp_path: Path, site: Site) -> None:
    p = write(tmp_path, lines(R1, row(2, "-78.6981", "35.7301", "45", "2025-10-07 15:42:21", "1")))
    out, rep = read_truth(p, site)
    assert len(out) == 1 and rep.skipped == Counter({"no_fix": 1})


def test_timestamp_formats(tmp_path: Path, site: Site) -> None:
    p = write(
        tmp_path,
        lines(
            row(1, "-78.698", "35.73", "45", "2025-10-07 15:42:20"),  # fraction omitted at .0
            row(2, "-78.698", "35.73", "45", "2025-10-07 15:42:20.5"),
            row(3, "-78.698", "35.73", "45", "2025-10-07T15:42:21.250000"),
            row(4, "-78.698", "35.73", "45", "2025-10-07T19:42:22Z"),  # zoned: no offset
        ),
    )
    out, rep = read_truth(p, site)
    assert [f.t for f in out] == [T0, T0 + 0.5, T0 + 1.25, T0 + 2.0]
    assert rep.skipped == Counter()


def test_unix_seconds_get_the_offset_and_a_note(tmp_path: Path, site: Site) -> None:
    p = write(tmp_path, lines(row(1, "-78.698", "35.73", "45", "1759851740.5")))
    (f,), rep = read_truth(p, site)
    assert f.t == T0 + 0.5  # read as the file's clock: UTC = file + 4 h
    assert rep.notes[-1] == (
        "1 timestamp(s) are unix seconds; the truth clock offset (-4 h) was applied to them as "
        "to wall-clock times — if the logger wrote true UTC epoch seconds, set "
        "clock_offsets_h.truth to 0"
    )
    utc_site = dataclasses.replace(site, clock_offsets_h={"truth": 0.0})
    (f,), rep = read_truth(p, utc_site)
    assert f.t == 1759851740.5 and not any("unix seconds" in n for n in rep.notes)


def test_clock_offset_from_site(tmp_path: Path, site: Site) -> None:
    est = dataclasses.replace(site, clock_offsets_h={"truth": -5.0})
    (f,), _ = read_truth(write(tmp_path, lines(R1)), est)
    assert f.t == T0 + 3600.0


def test_empty_file(tmp_path: Path, site: Site) -> None:
    p = write(tmp_path, "\n\n")
    out, rep = read_truth(p, site)
    assert out == [] and rep.rows == 0 and rep.notes == ["empty file: no truth rows"]
    err = strict_error(p, site)
    assert str(err) == f"{p}: empty file: no truth rows"


def test_missing_file(tmp_path: Path, site: Site) -> None:
    with pytest.raises(DataError, match=r"file not found$"):
        read_truth(tmp_path / "x_vehicleOut.txt", site)
    with pytest.raises(DataError, match=r"not a regular file$"):
        read_truth(tmp_path, site)


def test_truncated_last_line(tmp_path: Path, site: Site) -> None:
    p = write(tmp_path, lines(R1, R2) + '3,-78.6982,35.7302,46.0,"(0.01,1.5')
    out, rep = read_truth(p, site)
    assert len(out) == 2 and rep.skipped == Counter({"truncated": 1})
    err = strict_error(p, site)
    assert err.line == 3
    assert err.what == (
        "truncated last line (no newline at end of file): 5 fields, expected 10 (line, lon, "
        "lat, alt, (pitch,yaw,roll), (vN,vE,vD), battery_V, local_timestamp, gps_fix_type, "
        "num_sats)"
    )


def test_wrong_column_count(tmp_path: Path, site: Site) -> None:
    unquoted = R2.replace('"', "")  # tuples without quotes split into extra columns
    p = write(tmp_path, lines(R1, unquoted, R4))
    out, rep = read_truth(p, site)
    assert [f.line for f in out] == [1, 3] and rep.skipped == Counter({"bad_columns": 1})
    err = strict_error(p, site)
    assert err.line == 2 and err.what.startswith("14 fields, expected 10 (line, lon, lat")


def test_non_utf8_bytes(tmp_path: Path, site: Site) -> None:
    data = R1.encode() + b"\n" + R2.replace("35.7301", "35.73\xff1").encode("latin-1") + b"\n"
    p = write(tmp_path, data)
    out, rep = read_truth(p, site)
    assert len(out) == 1 and rep.skipped == Counter({"bad_value": 1})
    assert rep.notes[0] == (
        "1 line(s) hold bytes that are not UTF-8 (first: line 2); they were replaced by U+FFFD"
    )
    err = strict_error(p, site)
    assert err.line == 2 and err.what.startswith("byte 0xff at byte ")


def test_time_order_policy(tmp_path: Path, site: Site) -> None:
    back = row(5, "-78.698", "35.73", "45", "2025-10-07 15:42:20.100000")
    dup = row(6, "-78.698", "35.73", "45", "2025-10-07 15:42:20.200000")
    p = write(tmp_path, lines(R1, R2, back, dup, R4))
    out, rep = read_truth(p, site)
    assert [f.line for f in out] == [1, 2, 5]
    assert rep.skipped == Counter({"time_backwards": 1, "duplicate_time": 1})
    err = strict_error(p, site)
    assert (err.line, err.what) == (
        3,
        "time 2025-10-07T19:42:20.100Z is earlier than 2025-10-07T19:42:20.200Z on line 2",
    )


def test_nonfinite_out_of_range_and_bad_values(tmp_path: Path, site: Site) -> None:
    rows = [
        row(2, "-78.698", "35.73", "nan", "2025-10-07 15:42:21"),
        row(3, "-inf", "35.73", "45", "2025-10-07 15:42:22"),
        row(4, "-78.698", "-91", "45", "2025-10-07 15:42:23"),
        row(5, "-78.698", "35.73", "high", "2025-10-07 15:42:24"),
        row(6, "-78.698", "35.73", "45", "2025-10-07 15:42:25", fix="RTK"),
        row(7, "-78.698", "35.73", "45", "15:42:26"),
    ]
    p = write(tmp_path, lines(R1, *rows))
    out, rep = read_truth(p, site)
    assert len(out) == 1
    assert rep.skipped == Counter(
        {"nonfinite": 2, "out_of_range": 1, "bad_value": 2, "bad_time": 1}
    )
    err = strict_error(p, site)
    assert (err.line, err.what) == (2, "lon/lat/alt -78.698, 35.73, nan not finite")
    for i, what in [
        (3, "lat/lon -91.0, -78.698 out of range"),
        (4, "lon/lat/alt '-78.698', '35.73', 'high' not numbers"),
        (5, "gps_fix_type 'RTK' is not an integer"),
        (6, "timestamp '15:42:26' is not a plausible time"),
    ]:
        err = strict_error(write(tmp_path, lines(rows[i - 1]), f"r{i}.txt"), site)
        assert (err.line, err.what) == (1, what)


def test_unreadable_velocity_and_sats(tmp_path: Path, site: Site) -> None:
    p = write(
        tmp_path,
        lines(row(1, "-78.698", "35.73", "45", "2025-10-07 15:42:20", sats="", vel='"None"')),
    )
    (f,), rep = read_truth(p, site)
    assert all(math.isnan(v) for v in f.vel_ned) and f.num_sats == -1
    assert rep.skipped == Counter()
    assert rep.notes[-1] == (
        "2 optional field value(s) unreadable, read as missing (first: line 1: velocity 'None' "
        "is not a (vN,vE,vD) tuple)"
    )
    err = strict_error(p, site)
    assert (err.line, err.what) == (1, "velocity 'None' is not a (vN,vE,vD) tuple")


def test_carriage_return_inside_an_unquoted_field(tmp_path: Path, site: Site) -> None:
    p = write(tmp_path, lines(R1, R2.replace("15.8", "15\r.8"), R4))
    out, rep = read_truth(p, site)
    assert [f.line for f in out] == [1, 3]
    assert rep.rows == 3 and rep.used == 2 and rep.skipped == Counter({"bad_csv": 1})
    err = strict_error(p, site)
    assert err.line == 2 and "carriage return (\\r) inside an unquoted field" in err.what


def test_altitude_alone_at_minus_999_is_no_fix(tmp_path: Path, site: Site) -> None:
    # the logger writes -999 for "no fix"; a row with valid lat/lon but altitude -999 has no
    # usable height: the same rule as the all -999 rows (no_fix in both modes), never a fix
    # 999 m below the take-off point
    alt_only = row(2, "-78.6981", "35.7301", "-999", "2025-10-07 15:42:20.200000")
    p = write(tmp_path, lines(R1, alt_only, R4))
    for strict in (False, True):
        out, rep = read_truth(p, site, strict=strict)
        assert [f.line for f in out] == [1, 3]
        assert rep.skipped == Counter({"no_fix": 1})
        assert all(f.h > site.takeoff_h for f in out)
