"""Live ingest under faults, through the stream nodes in-process: the TCP source drops and
comes back, the followed file is rotated and then truncated, a half-written line is completed
later, ten malformed lines in a row, a sensor clock 5 s off the host's. Each ends with the
right counts on /diagnostics and every well-formed line published, in order, stamped with its
sensor time. Plus: bad URLs stop the node naming the parameter. Waits are for events (a
connection accepted, a message received, a counter reached), never fixed sleeps."""

from __future__ import annotations

import socket
import subprocess
import sys
import time
from datetime import UTC, datetime
from pathlib import Path

import pytest
from diagnostic_msgs.msg import DiagnosticStatus
from geometry_msgs.msg import PointStamped, PoseWithCovarianceStamped
from ingest_util import T0, LineServer, StreamHarness, radar_line
from rclpy.context import Context
from rclpy.parameter import Parameter
from sensor_msgs.msg import NavSatFix, PointCloud2

from uav_fusion.core.ingest.transport import UdpReceiver
from uav_fusion.nodes.radar_stream import RadarStream
from uav_fusion.nodes.rf_stream import RfStream
from uav_fusion.nodes.truth_stream import TruthStream
from uav_fusion.ros import conversions as cv
from uav_fusion.ros.params import ParamError

RADAR_TOPICS = {"radar/tracks": PointCloud2, "radar/pose": PoseWithCovarianceStamped}


def _stamps(h: StreamHarness, topic: str = "radar/tracks") -> list[float]:
    return [cv.time_from_stamp(m.header.stamp) for m in h.got[topic]]


def _counts(v: dict[str, str]) -> dict[str, int]:
    """The drop counters of a status."""
    return {k: int(x) for k, x in v.items() if k.startswith("dropped_")}


def test_tcp_source_drops_and_comes_back(ctx: Context) -> None:
    srv = LineServer()
    h = StreamHarness(ctx, RadarStream, RADAR_TOPICS, url=srv.url, reconnect_min_s=0.05,
                      reconnect_max_s=0.2)
    try:
        times = [T0 + 0.25 * k for k in range(10)]
        lines = [radar_line(t) for t in times]
        srv.accept()  # the node connects as soon as it is built
        for ln in lines[:5]:
            srv.send(ln)
        srv.send(lines[5][:30])  # the sensor dies mid-line
        h.spin_until(lambda: len(h.got["radar/tracks"]) == 5)
        srv.drop()
        # the node reconnects by itself; the spin runs while we wait for it
        h.spin_until(lambda: h.node.ingest.transport.stats.disconnects == 1)
        srv.sock.settimeout(0.05)
        end = time.monotonic() + 60.0
        while True:
            try:
                srv.accept()
                break
            except TimeoutError:
                assert time.monotonic() < end
                h.ex.spin_once(timeout_sec=0.01)
        for ln in lines[5:]:
            srv.send(ln)
        h.spin_until(lambda: len(h.got["radar/tracks"]) == len(h.got["radar/pose"]) == 10)
        v = h.settled(lines=10)
        assert _stamps(h) == times
        assert len(h.got["radar/pose"]) == 10
        assert (v["connects"], v["reconnects"], v["disconnects"]) == ("2", "1", "1")
        assert v["records"] == "10" and v["messages_published"] == "30"  # tracks, pose, raw
        assert _counts(v) == {"dropped_truncated": 1}  # the half line cut by the drop
    finally:
        h.close()
        srv.close()


def test_followed_file_rotated_then_truncated(ctx: Context, tmp_path: Path) -> None:
    path = tmp_path / "radar_data.json"
    h = StreamHarness(ctx, RadarStream, RADAR_TOPICS, url=str(path), poll_period_s=0.005)
    try:
        times = [T0 + 0.25 * k for k in range(9)]
        lines = [radar_line(t) for t in times]
        h.spin_until(lambda: h.node.started)
        f = path.open("ab")
        f.writelines(lines[:3])
        f.flush()
        h.spin_until(lambda: len(h.got["radar/tracks"]) == 3)
        # logrotate: rename, the writer finishes its line in the old file, then a new file
        path.rename(tmp_path / "radar_data.json.1")
        f.write(lines[3])
        f.flush()
        f.close()
        f = path.open("ab")
        f.writelines(lines[4:7])
        f.flush()
        h.spin_until(lambda: len(h.got["radar/tracks"]) == 7)
        assert h.node.ingest.transport.stats.rotations == 1
        # copytruncate: the file is cut to nothing and written again, shorter than before
        f.close()
        with path.open("r+b") as g:
            g.truncate(0)
        h.spin_until(lambda: h.node.ingest.transport.stats.truncations == 1)
        with path.open("ab") as g:
            g.writelines(lines[7:9])
        h.spin_until(lambda: len(h.got["radar/tracks"]) == 9)
        v = h.settled(lines=9)
        assert _stamps(h) == times
        assert (v["rotations"], v["truncations"]) == ("1", "1")
        assert v["records"] == "9" and _counts(v) == {}
        assert v["state"] == "following"
    finally:
        h.close()


def test_half_written_line_is_completed_later(ctx: Context, tmp_path: Path) -> None:
    path = tmp_path / "AADM.csv"
    header = (
        b"Meas ID,Algorithm,Center Frequency,Sample Rate,Num Samples,Latitude,Longitude,"
        b"Elevation,RHO,CEP,Total Sensors,Valid Sensors,Overloaded Sensors,Sensor Names,Time,"
        b"Comment\n"
    )
    row = (
        b'1,TDOA,2.44E+09,2.8E+07,16384,35.7300,-78.6980,0,0.93,45.2,4,4,0,"LW2,LW3,LW4,LW5",'
        b"2025-10-07 19:42:20.000,\n"
    )
    path.write_bytes(header)
    h = StreamHarness(ctx, RfStream, {"rf/fix": PointStamped, "rf/fixes": PointCloud2},
                      url=f"file://{path}", poll_period_s=0.005)
    try:
        with path.open("ab") as f:
            f.write(row[:50])  # the server is in the middle of writing the row
            f.flush()
            n = len(header) + 50
            h.spin_until(lambda: h.node.ingest.transport.stats.bytes == n)
            for _ in range(20):  # the half line is held, not decoded
                h.ex.spin_once(timeout_sec=0.01)
            assert h.got["rf/fix"] == [] and h.node.ingest.transport.framer.pending == 50
            f.write(row[50:])
            f.flush()
        h.spin_until(lambda: len(h.got["rf/fix"]) == 1 and len(h.got["rf/fixes"]) == 1)
        v = h.settled(lines=2)
        assert _stamps(h, "rf/fix") == [T0]
        assert v["records"] == "1" and v["headers"] == "1" and _counts(v) == {}
    finally:
        h.close()


def test_ten_malformed_lines_in_a_row(ctx: Context) -> None:
    """Over UDP: every kind of bad line the issue names, ten in a row between good ones."""
    h = StreamHarness(ctx, RadarStream, RADAR_TOPICS, url="udp://127.0.0.1:0",
                      max_line_bytes=4096)
    tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        h.spin_until(lambda: h.node.started)
        udp = h.node.ingest.transport
        assert isinstance(udp, UdpReceiver)  # the url's scheme chose it
        port = udp.port
        good = [radar_line(T0 + k) for k in (0, 1, 10, 11)]
        bad = [
            b"{this is not json\n",
            b"[1, 2, 3]\n",
            b'{"params":{"globalTime":1759866142.0}}\n',  # no trackData
            b'{"params":{},"trackData":[]}\n',  # no time
            b'{"params":{"globalTime":12.5},"trackData":[]}\n',  # not a plausible time
            radar_line(T0 + 1),  # duplicate stamp
            radar_line(T0 + 0.5),  # stamp going back
            radar_line(T0 + 2, alt=float("nan")),  # a non-finite track: the frame stays, empty
            b'{"params":{"globalTime":1759866143.0},"trackData":[{"id":1,"lla":[35.7,-78.7,'
            + b"1" * 5000 + b"]}]}\n",  # longer than max_line_bytes
            b'{"params":{"globalTime":1759866144.0},"trackData":{"id":1}}\n',
        ]
        for k, d in enumerate([*good[:2], *bad, *good[2:]]):
            tx.sendto(d, ("127.0.0.1", port))
            # one datagram in flight at a time: UDP may reorder or drop under load
            def taken(k: int = k) -> bool:
                return h.node.ingest.transport.stats.datagrams == k + 1

            h.spin_until(taken)
        # 14 datagrams, 13 lines (the long one is never a line); the NaN frame is kept empty
        v = h.settled(lines=13)
        clouds = h.got["radar/tracks"]
        h.spin_until(lambda: len(clouds) == 5 and len(h.got["radar/pose"]) == 4)
        assert _stamps(h) == [T0, T0 + 1, T0 + 2, T0 + 10, T0 + 11]
        assert clouds[2].width == 0 and len(h.got["radar/pose"]) == 4
        assert _counts(v) == {
            "dropped_bad_json": 1,
            "dropped_not_object": 1,
            "dropped_no_track_data": 1,
            "dropped_no_time": 1,
            "dropped_bad_time": 1,
            "dropped_duplicate_time": 1,
            "dropped_time_backwards": 1,
            "dropped_track_nonfinite": 1,
            "dropped_too_long": 1,
            "dropped_bad_track_data": 1,
        }
        assert v["dropped"] == "10"
        level, message = h.level_message()
        assert level == int.from_bytes(DiagnosticStatus.WARN, "little") and "dropped" in message
    finally:
        tx.close()
        h.close()


def test_sensor_clock_five_seconds_off(ctx: Context, tmp_path: Path) -> None:
    path = tmp_path / "vehicleOut.txt"
    h = StreamHarness(ctx, TruthStream, {"truth/fix": NavSatFix}, url=str(path),
                      poll_period_s=0.005, clock_offset_warn_s=1.0)
    try:
        sent = []
        with path.open("ab") as f:
            for k in range(5):
                t = time.time() - 5.0  # the vehicle's clock runs 5 s behind the host's
                sent.append(round(t, 6))
                stamp = datetime.fromtimestamp(t, UTC).strftime("%Y-%m-%dT%H:%M:%S.%fZ")
                f.write(f'{k},-78.6980,35.7300,45.0,"(0,0,0)","(1,0,0)",15.8,{stamp},6,22\n'
                        .encode())
                f.flush()
                def published(k: int = k) -> bool:
                    return len(h.got["truth/fix"]) == k + 1

                h.spin_until(published)
        v = h.settled(lines=5)
        off = float(v["clock_offset_s"])
        assert 4.99 < off < 6.0, off  # 5 s plus the time to notice the line
        level, message = h.level_message()
        assert level == int.from_bytes(DiagnosticStatus.WARN, "little")
        assert "sensor clock +5." in message
        assert [round(cv.time_from_stamp(m.header.stamp), 6) for m in h.got["truth/fix"]] == sent
        assert _counts(v) == {}
        # the same offset under a looser threshold is fine
        h.node.set_parameters([Parameter("clock_offset_warn_s", value=10.0)])
        n = len(h.diag)
        h.spin_until(lambda: len(h.diag) > n + 1)
        assert h.level_message()[0] == 0
    finally:
        h.close()


@pytest.mark.parametrize(
    ("url", "why"),
    [
        ("tcp://127.0.0.1", "no port"),
        ("tcp://127.0.0.1:70000", "outside"),
        ("tcp://no-such-host.invalid:5601", "does not resolve"),
        ("gopher://x:1", "unknown scheme"),
        ("/no/such/folder/radar.json", "does not exist"),
        (".", "is a folder"),
    ],
)
def test_bad_url_stops_the_node_naming_the_parameter(ctx: Context, url: str, why: str) -> None:
    with pytest.raises(ParamError) as err:
        RadarStream(context=ctx, parameter_overrides=[Parameter("url", value=url)])
    assert "parameter 'url'" in str(err.value) and why in str(err.value)


def test_udp_port_taken_is_a_bad_url(ctx: Context) -> None:
    taken = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    taken.bind(("127.0.0.1", 0))
    try:
        port = taken.getsockname()[1]
        with pytest.raises(ParamError, match=r"parameter 'url'.*cannot bind"):
            RadarStream(context=ctx, parameter_overrides=[
                Parameter("url", value=f"udp://127.0.0.1:{port}")])
    finally:
        taken.close()


@pytest.mark.processes
def test_bad_url_console_script_exits_2_naming_the_parameter(tmp_path: Path) -> None:
    exe = Path(sys.executable).parent / "rf_stream"
    if not exe.exists():
        pytest.skip("rf_stream is not installed (pip install -e .)")
    bad = str(tmp_path / "missing" / "AADM.csv")
    done = subprocess.run([str(exe), "--ros-args", "-p", f"url:={bad}"], capture_output=True,
                          text=True, timeout=60)
    assert done.returncode == 2
    assert f"parameter 'url' = '{bad}'" in done.stderr + done.stdout
    assert "does not exist" in done.stderr + done.stdout
