"""Live multi-target scoring: the evaluator scores fusion/tracks as a set, and the multi-UAV
demo's live graph equals its offline run."""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np
import pytest
import rclpy
from nav_msgs.msg import Odometry
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.utilities import try_shutdown
from sensor_msgs.msg import NavSatFix

from uav_fusion.cli import main
from uav_fusion.core.records import TruthFix
from uav_fusion.core.scoring.gospa import (
    MultiScoreSettings,
    UavTruth,
    epochs_from_published,
    pool,
    score_flight,
)
from uav_fusion.core.site import Site, load_site
from uav_fusion.nodes.evaluator_node import EvaluatorNode
from uav_fusion.ros.conversions import truth_to_navsatfix
from uav_fusion.ros.odometry import state_to_odometry

T0 = 1_760_000_000.0


@pytest.fixture
def ros() -> Iterator[None]:
    rclpy.init()
    try:
        yield
    finally:
        try_shutdown()


def spin_until(ex: SingleThreadedExecutor, cond: Callable[[], bool], timeout: float = 60.0) -> None:
    end = time.monotonic() + timeout  # a deadline that only stops a hung test
    while not cond():
        if time.monotonic() > end:
            raise AssertionError("condition not reached before the deadline")
        ex.spin_once(timeout_sec=0.05)


Arr = np.ndarray


def _truth(site: Site, t: Arr, e: Arr, n: Arr, u: Arr) -> list[TruthFix]:
    lat, lon, h = site.to_geodetic(e, n, u)
    return [
        TruthFix(float(a), float(la), float(lo), float(hh), float(x), float(y), float(z),
                 (0.0, 0.0, 0.0), 6, 18)
        for a, la, lo, hh, x, y, z in zip(t, lat, lon, h, e, n, u, strict=True)
    ]  # fmt: skip


def test_the_evaluator_scores_published_tracks_as_a_set(ros: None, tmp_path: Path) -> None:
    """Two UAVs crossing; three track ids (one swap, one false track): the node's score equals
    score_flight over the same epochs, and malformed track messages are counted, not used."""
    site = load_site()
    frame = site.frame_id
    hz = 2.0
    t = T0 + np.arange(0.0, 60.0, 0.2)
    up = site.to_enu(site.takeoff_lat, site.takeoff_lon, site.takeoff_h)[2] + np.where(
        t > T0 + 5.0, 40.0, 0.0
    )
    a = _truth(site, t, 5.0 * (t - T0 - 30.0), 0.0 * t + 200.0, up)
    b = _truth(site, t, 0.0 * t, 200.0 + 5.0 * (t - T0 - 30.0), up + 10.0 * (t > T0 + 5.0))
    node = EvaluatorNode(
        parameter_overrides=[
            Parameter("output_dir", value=str(tmp_path / "r")),
            Parameter("tracks_topic", value="fusion/tracks"),
            Parameter("tracks_hz", value=hz),
            Parameter("log_period_s", value=0.0),
            Parameter("write_on_shutdown", value=False),
            Parameter("figures", value=False),
        ]
    )
    feeder = Node("multi_live_feeder")
    ex = SingleThreadedExecutor()
    ex.add_node(node)
    ex.add_node(feeder)
    qos = QoSProfile(depth=5000, history=HistoryPolicy.KEEP_LAST,
                     reliability=ReliabilityPolicy.RELIABLE)  # fmt: skip
    pub_a = feeder.create_publisher(NavSatFix, "truth/uav1/fix", qos)
    pub_b = feeder.create_publisher(NavSatFix, "truth/uav2/fix", qos)
    pub_t = feeder.create_publisher(Odometry, "fusion/tracks", qos)
    # the vehicles' truth topics are discovered (parameter vehicles left empty)
    spin_until(ex, lambda: min(p.get_subscription_count() for p in (pub_a, pub_b)) > 0)
    assert sorted(node.vehicle_topics) == ["uav1", "uav2"]
    rows: list[tuple[float, int, np.ndarray]] = []
    for k in range(int(10 * hz), int(55 * hz)):
        g = T0 + k / hz
        pa = np.array([5.0 * (g - T0 - 30.0), 200.0, up[0] + 40.0, 5.0, 0.0, 0.0]) + 3.0
        pb = np.array([0.0, 200.0 + 5.0 * (g - T0 - 30.0), up[0] + 50.0, 0.0, 5.0, 0.0]) - 2.0
        id_a = 1 if g < T0 + 35.0 else 3  # uav1's track changes id after the crossing
        rows.append((g, id_a, pa))
        rows.append((g, 2, pb))
        if 20.0 <= g - T0 < 25.0:
            rows.append((g, 7, pa + np.array([500.0, 0, 0, 0, 0, 0])))  # a false track
    sent = 0
    for fix in a:
        pub_a.publish(truth_to_navsatfix(fix, "gps"))
    for fix in b:
        pub_b.publish(truth_to_navsatfix(fix, "gps"))
    sent += len(a) + len(b)
    for g, tid, x in rows:
        pub_t.publish(state_to_odometry(g, x, np.eye(6), frame, f"track_{tid}"))
    sent += len(rows)
    bad_id = state_to_odometry(T0 + 20.0, rows[0][2], np.eye(6), frame, "uav")
    off_grid = state_to_odometry(T0 + 20.1, rows[0][2], np.eye(6), frame, "track_1")
    wrong_frame = state_to_odometry(T0 + 20.0, rows[0][2], np.eye(6), "map", "track_1")
    for m in (bad_id, off_grid, wrong_frame):
        pub_t.publish(m)
    sent += 3
    spin_until(ex, lambda: sum(node.received.values()) >= sent)
    assert node.dropped["fusion/tracks: bad_track_id"] == 1
    assert node.dropped["fusion/tracks: off_grid"] == 1
    assert node.dropped["fusion/tracks: wrong_frame"] == 1

    got = node.multi_score()
    assert got is not None
    truths = {
        "uav1": UavTruth(t, np.array([(f.e, f.n, f.u) for f in a])),
        "uav2": UavTruth(t, np.array([(f.e, f.n, f.u) for f in b])),
    }
    # the node's truth went through NavSatFix and back: equal to well below a millimetre
    ref = pool([score_flight(truths, epochs_from_published(rows, hz, float(t[0]), float(t[-1])),
                             MultiScoreSettings(step_s=1.0 / hz))])  # fmt: skip
    assert got.gospa_mean_m == pytest.approx(ref.gospa_mean_m, abs=1e-6)
    assert got.false_track_s == ref.false_track_s == pytest.approx(5.0)
    assert [u.id_switches for u in got.uavs] == [1, 0]
    assert [u.id_switches_kept for u in got.uavs] == [u.id_switches_kept for u in ref.uavs]
    assert got.epochs == ref.epochs
    files = node.write_report()
    assert "tracks (fusion/tracks, 2 Hz)" in files.markdown.read_text(encoding="utf-8")
    node.destroy_node()
    feeder.destroy_node()


def test_multi_demo_live_graph_equals_offline(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    argv = ["demo", "--multi", "--multi-seed", "3", "--out", str(tmp_path / "demo"),
            "--quiet", "--no-figures"]  # fmt: skip
    assert main(argv) == 0
    out = capsys.readouterr().out
    assert "the live tracks on fusion/tracks equal the offline run's" in out
    assert "uav1" in out and "uav2" in out
    assert (tmp_path / "demo" / "flight" / "twin_manifest.json").is_file()
