"""``uav_fusion demo`` end to end on a short flight: report written, live equals offline."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
from test_graph_flight import write_flight

from uav_fusion.bag.reader import BagReader
from uav_fusion.cli import main


def test_demo_writes_the_report_and_matches_offline(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    flight = write_flight(tmp_path / "flight", seconds=20.0)
    out = tmp_path / "demo"
    code = main(["demo", "--flight", str(flight), "--out", str(out), "--no-figures", "--quiet"])
    text = capsys.readouterr().out
    assert code == 0, text
    assert (out / "report.md").is_file() and (out / "metrics.csv").is_file()
    assert "KF fused track, all steps (3D)" in text
    assert "equals the offline run's" in text


def test_demo_refuses_a_missing_flight(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["demo", "--flight", str(tmp_path / "nope")]) == 2
    assert "flight folder not found" in capsys.readouterr().err


def test_demo_from_a_bag_equals_the_offline_run(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    flight = write_flight(tmp_path / "flight", seconds=20.0)
    bag = tmp_path / "bag"
    assert main(["convert", str(flight), "--out", str(bag)]) == 0
    out = tmp_path / "demo"
    args = ["demo", "--bag", str(bag), "--flight", str(flight), "--rate", "10"]
    code = main([*args, "--out", str(out), "--no-figures", "--quiet"])
    text = capsys.readouterr().out
    assert code == 0, text
    assert (out / "report.md").is_file()
    assert "equals the offline run's" in text
    # it plays what the graph's nodes take (the paper's filter: radar/pose + rf/fix; the
    # evaluator: radar/raw, rf/fix, truth/fix), not the trackers' radar/tracks and rf/fixes,
    # which nothing would subscribe to
    topics = BagReader(bag).topics
    taken = ("/radar/pose", "/radar/raw", "/rf/fix", "/truth/fix")
    assert "/radar/tracks" in topics and "/rf/fixes" in topics
    played = re.search(r"demo: (\d+) messages played", text)
    assert played is not None, text
    assert int(played.group(1)) == sum(topics[t].count for t in taken)
