"""The sensor emulator: its plan (delays, seeded jitter, per-source order, the RF header first,
a segment), files written equal to the flight's, a TCP client that connects late or drops and
comes back loses nothing, the arrival schedule reads back."""

from __future__ import annotations

import socket
import threading
from pathlib import Path

import pytest
from test_graph_flight import write_flight

from uav_fusion.cli import main
from uav_fusion.core.data.flight import flight_files
from uav_fusion.core.errors import ConfigError
from uav_fusion.core.ingest.emulator import (
    Emulator,
    SensorLine,
    TcpServerSink,
    plan,
    read_schedule,
    read_sensor_lines,
    write_schedule,
)
from uav_fusion.core.site import load_site

LIMIT_S = 60.0


@pytest.fixture(scope="module")
def flight(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return write_flight(tmp_path_factory.mktemp("flight") / "f", seconds=20.0)


def _lines(flight: Path) -> dict[str, list[SensorLine]]:
    site = load_site()
    files = flight_files(flight)
    return {s: read_sensor_lines(files[s], s, site) for s in ("radar", "rf", "truth")}


def test_plan_delays_jitter_order_and_segment(flight: Path) -> None:
    lines = _lines(flight)
    base = plan(lines)
    late = plan(lines, delay_s={"rf": 3.0}, jitter_s={"rf": 1.0}, seed=7)
    assert late == plan(lines, delay_s={"rf": 3.0}, jitter_s={"rf": 1.0}, seed=7)  # seeded
    assert late != plan(lines, delay_s={"rf": 3.0}, jitter_s={"rf": 1.0}, seed=8)
    assert len(base) == len(late) == sum(len(v) for v in lines.values())
    rf = [s for s in late if s.source == "rf"]
    assert rf[0].line == 1 and rf[0].sensor_t is None  # the header goes first
    lags = [s.due - s.sensor_t for s in rf if s.sensor_t is not None]
    assert min(lags) >= 2.0 and max(lags) <= 4.0 + 1e-9
    for src in ("radar", "rf", "truth"):  # every source keeps its file order
        mine = [s for s in late if s.source == src]
        assert [s.line for s in mine] == sorted(s.line for s in mine)
    assert [s.due for s in late] == sorted(s.due for s in late)
    t0 = min(s.sensor_t for s in base if s.sensor_t is not None)
    seg = plan(lines, start_s=5.0, duration_s=5.0)
    timed = [s.sensor_t for s in seg if s.sensor_t is not None]
    assert min(timed) >= t0 + 5.0 and max(timed) <= t0 + 10.0
    assert next(s for s in seg if s.source == "rf").line == 1


def test_files_are_written_as_the_sensors_wrote_them(flight: Path, tmp_path: Path,
                                                     capsys: pytest.CaptureFixture[str]) -> None:
    out, sched = tmp_path / "out", tmp_path / "arrivals.csv"
    args = ["emulate", str(flight), "--rate", "0", "--out", str(out), "--schedule", str(sched)]
    assert main(args) == 0
    for f in flight_files(flight).values():
        assert (out / f.name).read_bytes() == f.read_bytes()
    rows = read_schedule(sched)
    assert len(rows) == sum(len(v) for v in _lines(flight).values())
    assert {r[0] for r in rows} == {"radar", "rf", "truth"}
    assert main(args) == 2  # the files exist: never overwritten without --overwrite
    assert "exists already" in capsys.readouterr().err


def test_tcp_client_late_and_reconnecting_loses_nothing(flight: Path, tmp_path: Path) -> None:
    lines = _lines(flight)
    sends = [s for s in plan(lines) if s.source == "radar"]
    sink = TcpServerSink("127.0.0.1", 0)
    emu = Emulator(sends, {"radar": sink}, rate=0.0, wait_s=0.0)
    half = len(sends) // 2
    first = Emulator(sends[:half], {"radar": sink}, rate=0.0, wait_s=0.0)
    first.run()  # nobody connected yet: kept
    c1 = socket.create_connection(("127.0.0.1", sink.port), timeout=LIMIT_S)
    want_first = b"".join(s.data for s in sends[:half])
    got = b""
    while len(got) < len(want_first):
        got += c1.recv(1 << 16)
    assert got == want_first
    c1.close()  # the client goes away
    rest = Emulator(sends[half:], {"radar": sink}, rate=0.0, wait_s=0.0)
    done = threading.Event()

    def run_rest() -> None:
        rest.run()
        done.set()

    threading.Thread(target=run_rest, daemon=True).start()
    assert done.wait(LIMIT_S)
    c2 = socket.create_connection(("127.0.0.1", sink.port), timeout=LIMIT_S)
    want_rest = b"".join(s.data for s in sends[half:])
    got = b""
    while len(got) < len(want_rest):
        got += c2.recv(1 << 16)
    assert got == want_rest
    c2.close()
    emu.close()


def test_schedule_round_trip_and_bad_options(tmp_path: Path, flight: Path) -> None:
    rows = [("rf", 1, None, 1759866140.25, 1.5e9, 12.0),
            ("radar", 2, 1759866140.1, 1759866140.1, 1.5e9 + 0.1, 12.1)]
    write_schedule(tmp_path / "s.csv", rows)
    assert read_schedule(tmp_path / "s.csv") == rows
    assert main(["emulate", str(flight), "--delay", "sonar=3"]) == 2
    assert main(["emulate", str(flight), "--radar", "tcp://127.0.0.1"]) == 2
    with pytest.raises(ConfigError):
        Emulator([], {}, rate=-1.0)
