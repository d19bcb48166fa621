"""Fortem radar JSON Lines reader on hand-written lines in the real ``radar_data_*.json`` format."""

from __future__ import annotations

import dataclasses
import json
from collections import Counter
from pathlib import Path
from typing import Any

import pytest
from readers_util import ReaderFiles, lines

from uav_fusion.core.data import read_radar_jsonl
from uav_fusion.core.errors import DataError
from uav_fusion.core.site import Site, load_site

T0 = 1759866140.0  # 2025-10-07 19:42:20 UTC
STATUS = '{"error":{"code":200,"message":"OK"}}'


def track(tid: Any = 7, lla: Any = (35.7301, -78.6981, 130.5), **extra: Any) -> dict[str, Any]:
    d: dict[str, Any] = {
        "id": tid,
        "lla": list(lla) if isinstance(lla, tuple) else lla,
        "velocityNed": [1.0, 2.0, -0.5],
        "catProb": [0.9, 0.05, 0.05],
        "range": 650.2,
        "radialVelocity": -3.1,
        "numInliers": 12,
        "rcsDbsm": -12.5,
    }
    d.update(extra)
    return {k: v for k, v in d.items() if v is not ...}


def frame(t: float, *tracks: dict[str, Any], nested: bool = False) -> str:
    params: dict[str, Any] = {"globalTime": t, "gpsWeek": 2387, "gpsSeconds": 243758.0}
    if nested:
        params["trackData"] = list(tracks)
        return json.dumps({"params": params})
    return json.dumps({"params": params, "trackData": list(tracks)})


@pytest.fixture(scope="module")
def site() -> Site:
    return load_site()


_FILES = ReaderFiles(read_radar_jsonl, "radar_data_1.json")
write = _FILES.write
strict_error = _FILES.strict_error


def test_real_format_lines(tmp_path: Path, site: Site) -> None:
    bird = track(12, (35.7260, -78.6930, 95.0), catProb=[0.1, 0.9], rcsDbsm=..., rcs=-25.0)
    p = write(
        tmp_path,
        lines(
            STATUS,
            frame(T0, track(), bird),
            STATUS,
            frame(T0 + 0.25, track(lla=(35.7302, -78.6982, 131.0)), nested=True),
            frame(T0 + 0.5),
        ),
    )
    out, rep = read_radar_jsonl(p, site)
    assert [f.t for f in out] == [T0, T0 + 0.25, T0 + 0.5]
    assert [f.line for f in out] == [2, 4, 5]
    assert [len(f.tracks) for f in out] == [2, 1, 0]
    a, b = out[0].tracks
    assert (a.t, a.track_id, a.lat, a.lon, a.h) == (T0, 7, 35.7301, -78.6981, 130.5)
    e, n, u = site.to_enu(35.7301, -78.6981, 130.5)
    assert (a.e, a.n, a.u) == pytest.approx((float(e), float(n), float(u)), abs=1e-9)
    assert a.vel_ned == (1.0, 2.0, -0.5) and a.uav_prob == 0.9
    assert (a.range_m, a.radial_velocity, a.num_inliers, a.rcs_dbsm) == (650.2, -3.1, 12, -12.5)
    assert (b.track_id, b.uav_prob, b.rcs_dbsm) == (12, 0.1, -25.0)
    assert out[1].tracks[0].lat == 35.7302  # trackData inside params
    assert rep.rows == 5 and rep.used == 3 and rep.skipped == Counter({"status": 2})
    assert rep.notes == ["3 frames, 3 tracks"]


def test_optional_fields_absent(tmp_path: Path, site: Site) -> None:
    bare = {"id": 3, "lla": [35.73, -78.69, 120.0]}
    (f,), rep = read_radar_jsonl(write(tmp_path, lines(frame(T0, bare))), site, strict=True)
    t = f.tracks[0]
    assert (t.vel_ned, t.uav_prob, t.range_m, t.rcs_dbsm, t.radial_velocity, t.num_inliers) == (
        None,
        None,
        None,
        None,
        None,
        None,
    )
    assert rep.notes == ["1 frames, 1 tracks"]


def test_clock_offset_and_time_fallbacks(tmp_path: Path, site: Site) -> None:
    shifted = dataclasses.replace(site, clock_offsets_h={"radar": 0.5})
    (f,), _ = read_radar_jsonl(write(tmp_path, lines(frame(T0, track()))), shifted)
    assert f.t == T0 - 1800.0 and f.tracks[0].t == T0 - 1800.0
    top = json.dumps({"globalTime": T0, "trackData": [track()]})
    # GPS week 2387, 2025-10-07 19:42:20 UTC = 243758 s of GPS week (incl. 18 s leap) → T0
    gps = json.dumps({"params": {"gpsWeek": 2387, "gpsSeconds": 243758.0}, "trackData": []})
    p = write(tmp_path, lines(top, gps), "r2.json")
    out, rep = read_radar_jsonl(p, site)
    assert [f.t for f in out] == [T0]
    assert rep.skipped == Counter({"duplicate_time": 1})  # both give the same time
    (g,), _ = read_radar_jsonl(write(tmp_path, lines(gps), "r3.json"), site)
    assert g.t == T0


def test_empty_file(tmp_path: Path, site: Site) -> None:
    p = write(tmp_path, "")
    out, rep = read_radar_jsonl(p, site)
    assert out == [] and rep.notes == ["empty file: no radar lines"]
    assert str(strict_error(p, site)) == f"{p}: empty file: no radar lines"


def test_only_status_lines(tmp_path: Path, site: Site) -> None:
    out, rep = read_radar_jsonl(write(tmp_path, lines(STATUS, STATUS)), site, strict=True)
    assert out == [] and rep.skipped == Counter({"status": 2}) and rep.used == 0


def test_missing_file(tmp_path: Path, site: Site) -> None:
    p = tmp_path / "radar_data_0.json"
    with pytest.raises(DataError) as ei:
        read_radar_jsonl(p, site)
    assert str(ei.value) == f"{p}: file not found"


def test_truncated_last_line(tmp_path: Path, site: Site) -> None:
    full = frame(T0 + 0.25, track())
    p = write(tmp_path, lines(frame(T0, track())) + full[:40])
    out, rep = read_radar_jsonl(p, site)
    assert len(out) == 1 and rep.skipped == Counter({"truncated": 1})
    err = strict_error(p, site)
    assert err.line == 2
    assert err.what.startswith("truncated last line (no newline at end of file): invalid JSON: ")


def test_invalid_json_lines(tmp_path: Path, site: Site) -> None:
    p = write(
        tmp_path,
        lines(
            frame(T0, track()),
            '{"params": {"globalTime": 1759866140.25}, "trackData": [',
            "[1, 2, 3]",
            '{"params": {"globalTime": 1759866140.5}}',
            '{"params": {"globalTime": 1759866140.75}, "trackData": {"id": 1}}',
            '{"params": {}, "trackData": []}',
            '{"params": {"globalTime": 12.0}, "trackData": []}',
            frame(T0 + 1.0, track()),
        ),
    )
    out, rep = read_radar_jsonl(p, site)
    assert [f.t for f in out] == [T0, T0 + 1.0]
    assert rep.skipped == Counter(
        {
            "bad_json": 1,
            "not_object": 1,
            "no_track_data": 1,
            "bad_track_data": 1,
            "no_time": 1,
            "bad_time": 1,
        }
    )
    err = strict_error(p, site)
    assert (err.line, err.what) == (2, "invalid JSON: Expecting value at column 57")
    expected = {
        3: "a JSON list, not an object",
        4: "object has neither trackData nor error/result",
        5: "trackData is a dict, not a list",
        6: "frame has no finite params.globalTime (nor gpsWeek/gpsSeconds)",
        7: "globalTime 12.0 is not a plausible unix time",
    }
    text = p.read_text().splitlines()
    for ln, what in expected.items():
        err = strict_error(write(tmp_path, text[ln - 1] + "\n", f"l{ln}.json"), site)
        assert (err.line, err.what) == (1, what)


def test_non_utf8_bytes(tmp_path: Path, site: Site) -> None:
    label = json.dumps({"params": {"globalTime": T0 + 0.25}, "trackData": [track(note="X")]})
    data = lines(frame(T0, track())).encode() + label.replace("X", "\udcff").encode(
        "utf-8", "surrogateescape"
    )
    p = write(tmp_path, data + b"\n" + b'{"params":{"globalTime":1759866140.5},"trackData":\xff]\n')
    out, rep = read_radar_jsonl(p, site)
    # a bad byte inside a string value costs nothing; inside the structure, the line is lost
    assert [f.t for f in out] == [T0, T0 + 0.25]
    assert rep.skipped == Counter({"bad_json": 1})
    assert rep.notes[0] == (
        "2 line(s) hold bytes that are not UTF-8 (first: line 2); they were replaced by U+FFFD"
    )
    err = strict_error(p, site)
    assert err.line == 2 and err.what.startswith("byte 0xff at byte ")


def test_time_order_policy(tmp_path: Path, site: Site) -> None:
    p = write(
        tmp_path,
        lines(
            frame(T0, track()),
            frame(T0 + 0.5, track()),
            STATUS,
            frame(T0 + 0.25, track()),
            frame(T0 + 0.5, track(8)),
            frame(T0 + 0.75, track()),
        ),
    )
    out, rep = read_radar_jsonl(p, site)
    assert [f.t for f in out] == [T0, T0 + 0.5, T0 + 0.75]
    assert rep.skipped == Counter({"status": 1, "time_backwards": 1, "duplicate_time": 1})
    err = strict_error(p, site)
    assert (err.line, err.what) == (
        4,
        "time 2025-10-07T19:42:20.250Z is earlier than 2025-10-07T19:42:20.500Z on line 2",
    )


def test_bad_tracks_skipped_without_losing_the_frame(tmp_path: Path, site: Site) -> None:
    nan_lla = '{"id": 2, "lla": [NaN, -78.69, 100.0]}'
    inf_alt = '{"id": 3, "lla": [35.73, -78.69, Infinity]}'
    good = json.dumps(track(1))
    others = [
        json.dumps({"id": 4}),  # no lla
        json.dumps({"id": 5, "lla": [95.0, -78.69, 100.0]}),
        json.dumps({"id": 6, "lla": [35.73, -78.69, 50000.0]}),
        json.dumps({"id": 7, "lla": [35.73, -78.69]}),
        json.dumps({"id": "seven", "lla": [35.73, -78.69, 100.0]}),
        json.dumps("not a track"),
    ]
    body = ", ".join([nan_lla, good, inf_alt, *others])
    text = '{"params": {"globalTime": 1759866140.0}, "trackData": [' + body + "]}"
    p = write(tmp_path, lines(text))
    (f,), rep = read_radar_jsonl(p, site)
    assert [t.track_id for t in f.tracks] == [1]
    assert rep.skipped == Counter(
        {
            "track_nonfinite": 2,
            "track_no_lla": 1,
            "track_out_of_range": 2,
            "track_bad_value": 3,
        }
    )
    err = strict_error(p, site)
    assert (err.line, err.what) == (1, "trackData[0] (id 2): lla nan, -78.69, 100.0 not finite")
    for tr, what in [
        (others[0], "trackData[0] (id 4): no lla"),
        (others[1], "trackData[0] (id 5): lla 95.0, -78.69, 100.0 out of range"),
        (others[3], "trackData[0] (id 7): lla [35.73, -78.69] is not [lat, lon, alt]"),
        (others[4], "trackData[0]: id 'seven' is not an integer"),
        (others[5], "trackData[0] is not an object"),
    ]:
        one = '{"params": {"globalTime": 1759866140.0}, "trackData": [' + tr + "]}"
        err = strict_error(write(tmp_path, one + "\n", "one.json"), site)
        assert (err.line, err.what) == (1, what)


def test_unreadable_optional_fields(tmp_path: Path, site: Site) -> None:
    odd = track(9, catProb=[1.7], velocityNed=[1, "x", 0], range=-5.0, numInliers=2.5)
    (f,), rep = read_radar_jsonl(write(tmp_path, lines(frame(T0, odd))), site)
    t = f.tracks[0]
    assert (t.uav_prob, t.vel_ned, t.range_m, t.num_inliers) == (None, None, None, None)
    assert t.rcs_dbsm == -12.5 and rep.skipped == Counter()
    assert rep.notes[-1] == (
        "4 optional field value(s) unreadable, read as missing (first: line 1: trackData[0] "
        "(id 9): velocityNed [1, 'x', 0] is not 3 finite numbers)"
    )
    err = strict_error(write(tmp_path, lines(frame(T0, odd)), "s.json"), site)
    assert (err.line, err.what) == (
        1,
        "trackData[0] (id 9): velocityNed [1, 'x', 0] is not 3 finite numbers",
    )


def test_numbers_beyond_the_digit_limit_and_deep_nesting_are_one_bad_line(
    tmp_path: Path, site: Site
) -> None:
    # json.loads raised ValueError (not JSONDecodeError) for an integer of more than 4300
    # digits, and raises RecursionError for deep nesting: each is one bad line, not a crash
    good = '{"params":{"globalTime":1759866140.25},"trackData":[]}'
    later = '{"params":{"globalTime":1759866141.25},"trackData":[]}'
    p = tmp_path / "radar_data_x.json"
    p.write_text("\n".join([good, "9" * 5000, "[" * 100000, later]) + "\n")
    frames, rep = read_radar_jsonl(p, site)
    assert [f.line for f in frames] == [1, 4]
    assert rep.skipped == Counter({"not_object": 1, "bad_json": 1})
    with pytest.raises(DataError, match=r":2: a JSON float, not an object"):
        read_radar_jsonl(p, site, strict=True)


def test_integers_beyond_the_float_range_are_not_finite(tmp_path: Path, site: Site) -> None:
    big = "9" * 400
    lines_ = [
        '{"params":{"globalTime":1759866140.25},"trackData":['
        f'{{"id":1,"lla":[35.73,-78.69,{big}]}},'
        f'{{"id":2,"lla":[35.73,-78.69,120.0],"range":{big},"numInliers":-{big}}}]}}',
        f'{{"params":{{"globalTime":{big}}},"trackData":[]}}',
    ]
    p = tmp_path / "radar_data_x.json"
    p.write_text("\n".join(lines_) + "\n")
    frames, rep = read_radar_jsonl(p, site)
    assert [tr.track_id for tr in frames[0].tracks] == [2]
    assert frames[0].tracks[0].range_m is None and frames[0].tracks[0].num_inliers is None
    assert rep.skipped == Counter({"track_nonfinite": 1, "no_time": 1})
