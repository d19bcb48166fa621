"""The live stream decoders equal the file readers, line by line, bit for bit; bad lines are
counted by reason and never raise; the framer's half lines, long lines and line ends."""

from __future__ import annotations

from pathlib import Path

import pytest
from test_graph_flight import write_flight

from uav_fusion.core.data import read_radar_jsonl, read_rf_csv, read_truth
from uav_fusion.core.ingest.decode import StreamDecoder
from uav_fusion.core.ingest.framing import LineFramer
from uav_fusion.core.records import RadarFrame, RfAttempt
from uav_fusion.core.site import load_site
from uav_fusion.resources import DEFAULT_FLIGHT, data_path


def _stream(kind: str, path: Path, chunk: int) -> tuple[list[object], StreamDecoder]:
    """Decode ``path`` as a stream arriving in ``chunk``-byte pieces."""
    site = load_site()
    dec = StreamDecoder(kind, site)
    framer = LineFramer(1 << 20)
    data = path.read_bytes()
    out: list[object] = []
    for i in range(0, len(data), chunk):
        for line in framer.feed(data[i : i + chunk]):
            out.extend(dec.decode(line))
    assert framer.pending == 0
    return out, dec


@pytest.mark.parametrize("which", ["bundled", "synthetic"])
def test_stream_decoding_equals_the_file_readers(which: str, tmp_path: Path) -> None:
    folder = data_path(DEFAULT_FLIGHT) if which == "bundled" else write_flight(tmp_path / "f")
    site = load_site()
    files = {
        "radar": (next(folder.glob("radar_data_*.json")), read_radar_jsonl),
        "rf": (folder / "AADM.csv", read_rf_csv),
        "truth": (next(folder.glob("*vehicleOut.txt")), read_truth),
    }
    for kind, (path, reader) in files.items():
        offline, rep = reader(path, site)
        live, dec = _stream(kind, path, chunk=997)  # lines split across reads
        # every field bit for bit (repr: exact floats, NaN equal to NaN), line numbers too
        assert repr(live) == repr(offline), kind
        assert dict(dec.policy.dropped) == {
            k: v for k, v in rep.skipped.items() if k not in ("status", "no_fix")
        }
        assert dict(dec.policy.info) == {
            k: v for k, v in rep.skipped.items() if k in ("status", "no_fix")
        }


def test_bad_lines_are_counted_by_reason_and_never_raise() -> None:
    dec = StreamDecoder("radar", load_site())
    good = (
        b'{"params":{"globalTime":1759866140.0},'
        b'"trackData":[{"id":1,"lla":[35.72,-78.69,100.0]}]}'
    )
    lines = [
        b"{not json",
        b"[1, 2]",
        b'{"params":{}}',
        b'{"trackData":[]}',
        b'{"params":{"globalTime":12.5},"trackData":[]}',
        good,
        good,  # the same stamp again
        good.replace(b"140.0", b"139.0"),  # back in time
        good.replace(b"140.0", b"141.0").replace(b"100.0", b"NaN"),
        b'{"error":{"code":200,"message":"OK"}}',
        b"\xff\xfe not utf-8",
    ]
    out = [r for line in lines for r in dec.decode(line)]
    assert len(out) == 2  # the good frame, and the frame whose only track was not finite
    assert isinstance(out[1], RadarFrame) and out[1].tracks == ()
    assert dict(dec.policy.dropped) == {
        "bad_json": 2,
        "not_object": 1,
        "no_track_data": 1,
        "no_time": 1,
        "bad_time": 1,
        "duplicate_time": 1,
        "time_backwards": 1,
        "track_nonfinite": 1,
    }
    assert dict(dec.policy.info) == {"status": 1}
    assert dec.non_utf8 == 1


def test_rf_stream_takes_a_header_when_it_comes_and_assumes_aadm_without() -> None:
    dec = StreamDecoder("rf", load_site())
    row = "7,TDOA,2.44E+09,2.8E+07,16384,35.73,-78.698,0,0.93,45.2,4,4,0,\"LW2,LW3\",{t},"
    a = dec.decode(row.format(t="2025-10-07 19:42:20.000").encode())
    assert isinstance(a[0], RfAttempt) and a[0].meas_id == 7 and a[0].cep == 45.2
    # another column order, announced by a header line
    assert dec.decode(b"Time,Latitude,Longitude,Meas ID") == []
    b = dec.decode(b"2025-10-07 19:42:24.000,35.731,-78.699,8")
    assert isinstance(b[0], RfAttempt) and b[0].meas_id == 8 and b[0].cep is None
    assert dec.decode(b"Meas ID,Foo") == []  # a header without the required columns
    assert dec.policy.dropped["bad_header"] == 1 and dec.headers == 1


def test_framer_half_lines_long_lines_crlf_and_bom() -> None:
    f = LineFramer(16)
    assert f.feed(b"\xef\xbb") == []
    assert f.feed(b"\xbfab") == []
    assert f.feed(b"c\r\nde") == [b"abc"]
    assert f.pending == 2
    assert f.feed(b"f\n" + b"x" * 40) == [b"def"]
    assert f.too_long == 1 and f.pending == 0
    assert f.feed(b"yyy\nok\n") == [b"ok"]  # the rest of the long line is skipped
    assert f.too_long == 1
    assert f.feed(b"half") == [] and f.cut() is True
    assert f.feed(b"new\n") == [b"new"]
    assert f.feed(b"a\nb") == [b"a"] and f.flush_datagram() == [b"b"]
