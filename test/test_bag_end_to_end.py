"""Bag end to end: a converted flight played by bag_player into fusion_node and evaluator_node
while bag_recorder records the fusion outputs. The recorded fused track, read back by two
independent readers (rosbags and mcap + mcap-ros2-support), equals the offline core's."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest
from test_graph_flight import write_flight

from uav_fusion.cli import main
from uav_fusion.core.data import load_flight
from uav_fusion.core.estimators import load_profile, run_flight
from uav_fusion.core.site import load_site
from uav_fusion.ros.conversions import time_from_stamp


def _odom_row(m: Any) -> list[float]:
    p, v = m.pose.pose.position, m.twist.twist.linear
    return [time_from_stamp(m.header.stamp), p.x, p.y, p.z, v.x, v.y, v.z]


def _read_rosbags(bag: Path, topic: str) -> np.ndarray:
    from rosbags.rosbag2 import Reader
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_JAZZY)
    rows = []
    with Reader(bag) as rd:
        conns = [c for c in rd.connections if c.topic == topic]
        for c, _ts, raw in rd.messages(connections=conns):
            rows.append(_odom_row(store.deserialize_cdr(raw, c.msgtype)))
    return np.array(rows)


def _read_mcap(bag: Path, topic: str) -> np.ndarray:
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    rows = []
    for f in sorted(bag.glob("*.mcap")):
        with f.open("rb") as fh:
            reader = make_reader(fh, decoder_factories=[DecoderFactory()])
            for _s, ch, _m, msg in reader.iter_decoded_messages(log_time_order=True):
                if ch.topic == topic:
                    rows.append(_odom_row(msg))
    return np.array(rows)


def test_played_bag_recorded_fused_track_equals_the_offline_run(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    flight_dir = write_flight(tmp_path / "flight", seconds=30.0)
    bag = tmp_path / "bag"
    assert main(["convert", str(flight_dir), "--out", str(bag)]) == 0
    rec = tmp_path / "recorded"
    code = main([
        "demo", "--bag", str(bag), "--flight", str(flight_dir), "--rate", "10",
        "--record", str(rec), "--out", str(tmp_path / "report"), "--no-figures", "--quiet",
    ])
    text = capsys.readouterr().out
    assert code == 0, text
    assert "equals the offline run's" in text

    site = load_site()
    offline = run_flight(load_flight(flight_dir, site), load_profile("paper"), site)
    steps = [s for s in offline.steps if s.updated or s.coasted]
    expected = np.array([[s.t, *s.x] for s in steps])
    assert len(expected) > 50

    a = _read_rosbags(rec, "/fusion/odom")
    b = _read_mcap(rec, "/fusion/odom")
    assert a.shape == b.shape == expected.shape
    assert np.array_equal(a, b)  # two independent decoders, same content
    assert np.array_equal(a[:, 0], expected[:, 0])  # stamp <-> float time is exact
    np.testing.assert_allclose(a[:, 1:], expected[:, 1:], rtol=1e-9, atol=1e-9)


def test_record_needs_a_bag(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["demo", "--record", str(tmp_path / "r")]) == 2
    assert "--record goes with --bag" in capsys.readouterr().err
