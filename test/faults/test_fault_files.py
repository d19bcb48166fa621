"""Fault cases, area "files": damaged Dataset-28 files into each reader and the flight loader.

Each test is one row of docs/faults.md. The damage is applied to copies of a clean synthetic
flight (``short_flight``), so every case also checks that the *undamaged* rows still come
through: a fault costs the damaged row and nothing else.
"""

from __future__ import annotations

import itertools
import json
import shutil
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from uav_fusion.core.data import load_flight, read_radar_jsonl, read_rf_csv, read_truth
from uav_fusion.core.errors import DataError
from uav_fusion.core.estimators import load_profile, run_flight
from uav_fusion.core.scoring.metrics import interpolate_truth
from uav_fusion.core.site import Site, load_site

SITE = load_site()
Reader = Callable[..., tuple[list[Any], Any]]
READERS: dict[str, tuple[str, Reader]] = {
    "rf": ("AADM.csv", read_rf_csv),
    "radar": ("radar_data_test.json", read_radar_jsonl),
    "truth": ("2025-10-07_15_42_00_vehicleOut.txt", read_truth),
}
# index of the first data line (the RF file has a header, the radar file a status line)
FIRST_DATA = {"rf": 1, "radar": 1, "truth": 0}
KINDS = sorted(READERS)


def copy_flight(src: Path, dst: Path) -> Path:
    shutil.copytree(src, dst)
    return dst


def lines_of(folder: Path, kind: str) -> list[str]:
    return (folder / READERS[kind][0]).read_text().splitlines()


def write_lines(folder: Path, kind: str, lines: list[str], end: str = "\n") -> Path:
    p = folder / READERS[kind][0]
    p.write_text("\n".join(lines) + end)
    return p


def read(kind: str, path: Path, strict: bool = False) -> tuple[list[Any], Any]:
    return READERS[kind][1](path, SITE, strict=strict)


def times(records: list[Any]) -> list[float]:
    return [float(r.t) for r in records]


def clean_count(folder: Path, kind: str) -> int:
    recs, _rep = read(kind, folder / READERS[kind][0], strict=True)
    return len(recs)


def replace_field(line: str, index: int, value: str) -> str:
    """Replace one comma field of an unquoted-prefix CSV line (the coordinates come first)."""
    parts = line.split(",")
    parts[index] = value
    return ",".join(parts)


# RF columns: 5 = Latitude, 6 = Longitude; truth columns: 1 = lon, 2 = lat
LAT_FIELD = {"rf": 5, "truth": 2}
LON_FIELD = {"rf": 6, "truth": 1}


def radar_with_lla(line: str, lla: Any) -> str:
    obj = json.loads(line)
    obj["trackData"][0]["lla"] = lla
    return json.dumps(obj)


def radar_raw_lla(line: str, token: str) -> str:
    """Put a literal token (e.g. NaN, Infinity) into the first track's latitude."""
    obj = json.loads(line)
    lat = obj["trackData"][0]["lla"][0]
    text = json.dumps(obj)
    return text.replace(f"[{json.dumps(lat)},", f"[{token},", 1)


@pytest.mark.fault("FILE-01")
@pytest.mark.parametrize("kind", KINDS)
def test_missing_file_is_an_error_in_both_modes(kind: str, tmp_path: Path) -> None:
    for strict in (False, True):
        with pytest.raises(DataError) as err:
            read(kind, tmp_path / READERS[kind][0], strict=strict)
        assert err.value.what == "file not found"
        assert READERS[kind][0] in str(err.value)


@pytest.mark.fault("FILE-02")
def test_missing_flight_folder_and_missing_radar_file(short_flight: Path, tmp_path: Path) -> None:
    with pytest.raises(DataError, match="flight folder not found"):
        load_flight(tmp_path / "nope", SITE)
    f = copy_flight(short_flight, tmp_path / "f")
    (f / READERS["radar"][0]).unlink()
    with pytest.raises(DataError) as err:
        load_flight(f, SITE)
    msg = str(err.value)
    assert "radar_data_*.json" in msg and "AADM.csv" in msg  # the pattern and what is there


@pytest.mark.fault("FILE-03")
@pytest.mark.parametrize("kind", KINDS)
def test_empty_file_reads_nothing_with_a_note_or_raises(kind: str, tmp_path: Path) -> None:
    p = tmp_path / READERS[kind][0]
    p.write_text("\n\n  \n")
    recs, rep = read(kind, p)
    assert recs == [] and rep.used == 0
    assert any(n.startswith("empty file") for n in rep.notes)
    with pytest.raises(DataError, match="empty file"):
        read(kind, p, strict=True)


@pytest.mark.fault("FILE-04")
def test_rf_wrong_header_reads_nothing_and_says_which_columns(
    short_flight: Path, tmp_path: Path
) -> None:
    lines = lines_of(short_flight, "rf")
    lines[0] = lines[0].replace("Latitude", "Lat").replace(",Time,", ",Timestamp,")
    p = write_lines(tmp_path, "rf", lines)
    recs, rep = read("rf", p)
    assert recs == []
    assert rep.skipped["bad_header"] == len(lines) - 1
    assert any("Latitude" in n and "Time" in n for n in rep.notes)
    with pytest.raises(DataError, match=r"header lacks column\(s\)") as err:
        read("rf", p, strict=True)
    assert err.value.line == 1 and "Latitude" in err.value.what and "found:" in err.value.what


@pytest.mark.fault("FILE-05")
def test_rf_partial_header_with_stray_spaces_and_other_case(
    short_flight: Path, tmp_path: Path
) -> None:
    """A header cut after the columns we need is fine if the rows match it; spaces and case
    in names are tolerated; a header cut before Time is a named error."""
    lines = lines_of(short_flight, "rf")
    n = clean_count(short_flight, "rf")
    lines[0] = " meas id , ALGORITHM" + lines[0][len("Meas ID,Algorithm"):]
    p = write_lines(tmp_path, "rf", lines)
    recs, _rep = read("rf", p, strict=True)
    assert len(recs) == n
    cut = lines_of(short_flight, "rf")
    cut[0] = cut[0].split(",Time")[0]  # header stops before Time
    p2 = write_lines(tmp_path, "rf", cut)
    with pytest.raises(DataError, match=r"header lacks column\(s\) 'Time'"):
        read("rf", p2, strict=True)


@pytest.mark.fault("FILE-06")
def test_truth_file_with_a_header_line_skips_only_that_line(
    short_flight: Path, tmp_path: Path
) -> None:
    lines = lines_of(short_flight, "truth")
    n = clean_count(short_flight, "truth")
    header = "line,lon,lat,alt,attitude,velocity,battery_V,local_timestamp,gps_fix_type,num_sats"
    p = write_lines(tmp_path, "truth", [header, *lines])
    recs, rep = read("truth", p)
    assert len(recs) == n and rep.skipped["bad_value"] == 1
    with pytest.raises(DataError, match=r"not a number|not numbers") as err:
        read("truth", p, strict=True)
    assert err.value.line == 1


@pytest.mark.fault("FILE-07")
@pytest.mark.parametrize("kind", KINDS)
def test_truncated_last_line_costs_that_line_only(
    kind: str, short_flight: Path, tmp_path: Path
) -> None:
    lines = lines_of(short_flight, kind)
    n = clean_count(short_flight, kind)
    lines[-1] = lines[-1][: len(lines[-1]) // 3]  # cut mid-row, no final newline
    p = write_lines(tmp_path, kind, lines, end="")
    recs, rep = read(kind, p)
    assert len(recs) == n - 1 and rep.skipped["truncated"] == 1
    with pytest.raises(DataError, match="truncated last line") as err:
        read(kind, p, strict=True)
    assert err.value.line == len(lines)


@pytest.mark.fault("FILE-08")
@pytest.mark.parametrize("kind", KINDS)
def test_non_utf8_bytes_are_replaced_and_noted(
    kind: str, short_flight: Path, tmp_path: Path
) -> None:
    data = (short_flight / READERS[kind][0]).read_bytes().split(b"\n")
    k = FIRST_DATA[kind] + 2
    # a Latin-1 byte in the numeric position field of one row: that row is lost
    if kind == "radar":
        data[k] = data[k].replace(b'"lla": [', b'"lla": [\xb0', 1)
    else:
        f = data[k].split(b",")
        f[LAT_FIELD[kind]] = f[LAT_FIELD[kind]] + b"\xb0"
        data[k] = b",".join(f)
    p = tmp_path / READERS[kind][0]
    p.write_bytes(b"\n".join(data))
    _recs, rep = read(kind, p)
    assert any("not UTF-8 (first: line " + str(k + 1) + ")" in n for n in rep.notes)
    assert rep.n_skipped - rep.skipped["status"] - rep.skipped["no_fix"] == 1
    with pytest.raises(DataError, match=r"byte 0xb0 at byte \d+ is not UTF-8") as err:
        read(kind, p, strict=True)
    assert err.value.line == k + 1


@pytest.mark.fault("FILE-09")
@pytest.mark.parametrize("token", ["nan", "inf", "-inf"])
def test_nonfinite_coordinates_are_skipped_by_reason(
    token: str, short_flight: Path, tmp_path: Path
) -> None:
    for kind in KINDS:
        lines = lines_of(short_flight, kind)
        n = clean_count(short_flight, kind)
        k = FIRST_DATA[kind] + 3
        if kind == "radar":
            lines[k] = radar_raw_lla(lines[k], {"nan": "NaN", "inf": "Infinity"}.get(token,
                                                                                  "-Infinity"))
            reason = "track_nonfinite"
        else:
            lines[k] = replace_field(lines[k], LAT_FIELD[kind], token)
            reason = "nonfinite"
        p = write_lines(tmp_path, kind, lines)
        recs, rep = read(kind, p)
        assert rep.skipped[reason] == 1, (kind, rep.summary())
        if kind != "radar":  # a radar frame keeps its other tracks
            assert len(recs) == n - 1
        with pytest.raises(DataError, match="not finite") as err:
            read(kind, p, strict=True)
        assert err.value.line == k + 1


@pytest.mark.fault("FILE-10")
def test_empty_fields_are_named_errors(short_flight: Path, tmp_path: Path) -> None:
    expect = {"rf": "bad_value", "truth": "bad_value", "radar": "track_bad_value"}
    for kind in KINDS:
        lines = lines_of(short_flight, kind)
        k = FIRST_DATA[kind] + 4
        if kind == "radar":
            lines[k] = radar_with_lla(lines[k], [])
        else:
            lines[k] = replace_field(lines[k], LON_FIELD[kind], "")
        p = write_lines(tmp_path, kind, lines)
        _, rep = read(kind, p)
        assert rep.skipped[expect[kind]] == 1, (kind, rep.summary())
        with pytest.raises(DataError) as err:
            read(kind, p, strict=True)
        assert err.value.line == k + 1
        assert ("''" in err.value.what) or ("[]" in err.value.what), err.value.what


@pytest.mark.fault("FILE-11")
def test_latitude_longitude_out_of_range(short_flight: Path, tmp_path: Path) -> None:
    for kind in KINDS:
        for bad_lat in ("91.0", "-90.5"):
            lines = lines_of(short_flight, kind)
            k = FIRST_DATA[kind] + 5
            if kind == "radar":
                obj = json.loads(lines[k])
                lla = obj["trackData"][0]["lla"]
                lines[k] = radar_with_lla(lines[k], [float(bad_lat), lla[1], lla[2]])
                reason = "track_out_of_range"
            else:
                lines[k] = replace_field(lines[k], LAT_FIELD[kind], bad_lat)
                reason = "out_of_range"
            p = write_lines(tmp_path, kind, lines)
            _, rep = read(kind, p)
            assert rep.skipped[reason] == 1, (kind, rep.summary())
            with pytest.raises(DataError, match="out of range") as err:
                read(kind, p, strict=True)
            assert err.value.line == k + 1
    # longitude beyond 180 in RF
    lines = lines_of(short_flight, "rf")
    lines[3] = replace_field(lines[3], LON_FIELD["rf"], "-181.0")
    _, rep = read("rf", write_lines(tmp_path, "rf", lines))
    assert rep.skipped["out_of_range"] == 1


def _swap_rows(lines: list[str], a: int, b: int) -> list[str]:
    out = list(lines)
    out[a], out[b] = out[b], out[a]
    return out


@pytest.mark.fault("FILE-12")
@pytest.mark.parametrize("kind", KINDS)
def test_time_going_backwards_skips_the_earlier_row(
    kind: str, short_flight: Path, tmp_path: Path
) -> None:
    lines = lines_of(short_flight, kind)
    n = clean_count(short_flight, kind)
    k = FIRST_DATA[kind] + 5
    p = write_lines(tmp_path, kind, _swap_rows(lines, k, k + 1))
    recs, rep = read(kind, p)
    assert rep.skipped["time_backwards"] == 1 and len(recs) == n - 1
    ts = times(recs)
    assert all(b > a for a, b in itertools.pairwise(ts))  # still strictly increasing
    with pytest.raises(DataError, match=rf"is earlier than .* on line {k + 1}") as err:
        read(kind, p, strict=True)
    assert err.value.line == k + 2


@pytest.mark.fault("FILE-13")
@pytest.mark.parametrize("kind", KINDS)
def test_duplicate_timestamps_keep_the_first_row(
    kind: str, short_flight: Path, tmp_path: Path
) -> None:
    lines = lines_of(short_flight, kind)
    n = clean_count(short_flight, kind)
    k = FIRST_DATA[kind] + 6
    lines.insert(k + 1, lines[k])
    p = write_lines(tmp_path, kind, lines)
    recs, rep = read(kind, p)
    assert rep.skipped["duplicate_time"] == 1 and len(recs) == n
    with pytest.raises(DataError, match=rf"repeats line {k + 1}"):
        read(kind, p, strict=True)


def _shift_after(lines: list[str], kind: str, start: int, dt: float, site: Site) -> list[str]:
    """Shift every row from ``start`` on by ``dt`` seconds (a logger paused for minutes)."""
    from datetime import UTC, datetime, timedelta

    out = list(lines)
    for i in range(start, len(out)):
        if kind == "radar":
            obj = json.loads(out[i])
            if "params" in obj:
                obj["params"]["globalTime"] += dt
                out[i] = json.dumps(obj)
            continue
        f = out[i].split(",")
        ti = -2 if kind == "rf" else -3
        fmt = "%Y-%m-%d %H:%M:%S.%f"
        text = f[ti]
        t = datetime.strptime(text, fmt).replace(tzinfo=UTC) + timedelta(seconds=dt)
        new = t.strftime(fmt)
        f[ti] = new[: len(text)] if kind == "rf" else new
        out[i] = ",".join(f)
    return out


@pytest.mark.fault("FILE-14")
def test_gap_of_minutes_is_read_and_the_filter_follows_across_it(
    short_flight: Path, tmp_path: Path
) -> None:
    """Every source pauses for 5 minutes mid-flight: all rows load, and after the gap the
    track is updated again (the covariance grew over the gap, so the first measurement after
    it passes the gate) with errors of the same size as before the gap."""
    f = copy_flight(short_flight, tmp_path / "gap")
    gap = 300.0
    t_cut = 1759866140.0 + 15.0
    for kind in KINDS:
        lines = lines_of(f, kind)
        recs, _ = read(kind, f / READERS[kind][0], strict=True)
        # first line whose time is after t_cut (line index = record index + data offset)
        first = FIRST_DATA[kind] + next(i for i, r in enumerate(recs) if r.t > t_cut)
        if kind == "radar":
            first = next(
                i for i, s in enumerate(lines)
                if "params" in s and json.loads(s)["params"]["globalTime"] > t_cut
            )
        write_lines(f, kind, _shift_after(lines, kind, first, gap, SITE))
    flight = load_flight(f, SITE, strict=True)
    assert not any("WARNING" in n for rep in flight.reports.values() for n in rep.notes)
    res = run_flight(flight, load_profile("paper"), SITE)
    steps = res.steps
    after = [s for s in steps if s.t > t_cut + gap and (s.updated or s.coasted)]
    assert after and after[0].updated, "the first measurement after the gap was not used"
    tt = np.array([x.t for x in flight.truth])
    te = np.array([[x.e, x.n, x.u] for x in flight.truth])
    ok = [s for s in after if s.updated]
    est = np.array([s.x[:3] for s in ok])
    tru = interpolate_truth(tt, te, np.array([s.t for s in ok]))
    err = np.linalg.norm(est - tru, axis=1)
    assert float(np.nanmedian(err)) < 20.0


@pytest.mark.fault("FILE-15")
def test_truth_hours_apart_from_sensors_is_noticed_and_explained(
    short_flight: Path, tmp_path: Path
) -> None:
    """Truth logged in UTC while the site says local time (UTC-4): no overlap; lenient mode
    warns with both spans and the offset to use, strict mode refuses."""
    from dataclasses import replace

    site_utc = replace(SITE, clock_offsets_h={**SITE.clock_offsets_h, "truth": 0.0})
    flight = load_flight(short_flight, site_utc)
    warn = [n for n in flight.reports["truth"].notes if n.startswith("WARNING")]
    assert len(warn) == 2  # radar and RF each disagree with truth
    assert any(
        "do not overlap in time" in w and "lie about +4.0 h from the truth" in w for w in warn
    )
    assert any("try clock_offsets_h.truth: -4" in w for w in warn)
    assert any("WARNING" in n for n in flight.reports["radar"].notes)
    with pytest.raises(DataError, match="do not overlap in time"):
        load_flight(short_flight, site_utc, strict=True)


@pytest.mark.fault("FILE-16")
def test_radar_invalid_json_lines_are_skipped_by_reason(
    short_flight: Path, tmp_path: Path
) -> None:
    lines = lines_of(short_flight, "radar")
    n = clean_count(short_flight, "radar")
    junk = {
        "bad_json": '{"params": {"globalTime": 1759866141.1}, "trackData": [',
        "not_object": "[1, 2, 3]",
        "no_track_data": '{"hello": "world"}',
        "bad_track_data": '{"params": {"globalTime": 1759866141.2}, "trackData": 5}',
        "no_time": '{"trackData": []}',
    }
    bad = lines[:5] + list(junk.values()) + lines[5:]
    p = write_lines(tmp_path, "radar", bad)
    recs, rep = read("radar", p)
    assert len(recs) == n
    for reason in junk:
        assert rep.skipped[reason] == 1, (reason, rep.summary())
    with pytest.raises(DataError, match="invalid JSON") as err:
        read("radar", p, strict=True)
    assert err.value.line == 6 and f"{p.name}:6:" in str(err.value)


@pytest.mark.fault("FILE-17")
def test_seconds_since_boot_and_millisecond_times_are_bad_time(
    short_flight: Path, tmp_path: Path
) -> None:
    lines = lines_of(short_flight, "radar")
    obj = json.loads(lines[3])
    obj["params"]["globalTime"] = 1234.5  # seconds since boot
    lines[3] = json.dumps(obj)
    obj = json.loads(lines[4])
    obj["params"]["globalTime"] = obj["params"]["globalTime"] * 1000.0  # milliseconds
    lines[4] = json.dumps(obj)
    _, rep = read("radar", write_lines(tmp_path, "radar", lines))
    assert rep.skipped["bad_time"] == 2
    rf = lines_of(short_flight, "rf")
    rf[2] = replace_field(rf[2], -2, "1970-01-01 00:20:34.500")
    p = write_lines(tmp_path, "rf", rf)
    with pytest.raises(DataError, match="is not a plausible time"):
        read("rf", p, strict=True)
