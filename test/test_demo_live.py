"""``uav_fusion demo --live`` end to end on a short flight: the emulator feeds the stream nodes
over TCP, UDP and followed files, with RF late; the live table equals the offline run's (with
zero wait: in the arrival order the fusion node wrote; with a reorder window: in order)."""

from __future__ import annotations

from pathlib import Path

import pytest
from test_graph_flight import write_flight

from uav_fusion.cli import main
from uav_fusion.core.ingest.emulator import read_schedule


@pytest.mark.parametrize(
    ("via", "profile", "extra"),
    [
        ("tcp", "tracker", ["--delay", "rf=1.5", "--jitter", "rf=0.5", "--seed", "3"]),
        ("udp", "paper", []),
        ("file", "paper", ["--delay", "rf=1.0", "--window", "2"]),
    ],
)
def test_demo_live_equals_offline(
    via: str, profile: str, extra: list[str], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    flight = write_flight(tmp_path / "flight", seconds=20.0)
    out = tmp_path / "live"
    code = main(["demo", "--live", "--live-via", via, "--profile", profile, "--rate", "20",
                 "--flight", str(flight), "--out", str(out), "--no-figures", "--quiet", *extra])
    text = capsys.readouterr()
    assert code == 0, text.out + text.err
    assert (out / "report.md").is_file()
    zero_wait = "--window" not in extra
    order = " in the node's arrival order" if zero_wait else ""
    assert f"the live table equals the offline run's{order} in every row" in text.out
    assert "stream drops: none;" in text.out
    assert (out / "arrivals.csv").is_file() == zero_wait  # the fusion node's schedule
    rows = read_schedule(out / "emulated.csv")
    rf = [(t, due) for src, _, t, due, _, _ in rows if src == "rf" and t is not None]
    if "rf=1.5" in extra:
        assert all(1.0 - 1e-9 <= due - t <= 2.0 + 1e-9 for t, due in rf)
