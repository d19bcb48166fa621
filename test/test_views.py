"""The views: fusion/path, fusion/markers, fusion/fix and the per-input diagnostics, on a
recording of the bundled flight (bag_player -> fusion_node + evaluator_node -> bag_recorder,
``uav_fusion demo --bag --record``), read back with mcap + mcap-ros2-support. Also: every topic
and type that config/foxglove_layout.json and config/uav_fusion.rviz name is in that recording
and decodes."""

from __future__ import annotations

import json
import math
from collections import defaultdict
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml

from uav_fusion.cli import main
from uav_fusion.core.site import load_site
from uav_fusion.ros.conversions import time_from_stamp

ROOT = Path(__file__).resolve().parents[1]

pytestmark = pytest.mark.slow

#: RViz display class -> the message type it shows
RVIZ_TYPES = {
    "rviz_default_plugins/MarkerArray": "visualization_msgs/msg/MarkerArray",
    "rviz_default_plugins/Path": "nav_msgs/msg/Path",
    "rviz_default_plugins/Odometry": "nav_msgs/msg/Odometry",
    "rviz_default_plugins/PoseWithCovariance": "geometry_msgs/msg/PoseWithCovarianceStamped",
    "rviz_default_plugins/PointStamped": "geometry_msgs/msg/PointStamped",
}


@pytest.fixture(scope="module")
def recording(tmp_path_factory: pytest.TempPathFactory) -> dict[str, list[tuple[str, Any]]]:
    """topic -> [(schema name, decoded message)] of a recording of the bundled flight."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    tmp = tmp_path_factory.mktemp("views")
    rec = tmp / "rec"
    code = main([
        "demo", "--bag", str(ROOT / "bags" / "default_flight"), "--flight",
        str(ROOT / "data" / "default_flight"), "--rate", "40", "--record", str(rec),
        "--out", str(tmp / "report"), "--no-figures", "--quiet", "--no-check",
    ])
    assert code == 0
    out: dict[str, list[tuple[str, Any]]] = defaultdict(list)
    for f in sorted(rec.glob("*.mcap")):
        with f.open("rb") as fh:
            reader = make_reader(fh, decoder_factories=[DecoderFactory()])
            for schema, ch, _m, msg in reader.iter_decoded_messages(log_time_order=True):
                out[ch.topic].append((schema.name if schema else "", msg))
    return dict(out)


def _xyz(p: Any) -> tuple[float, float, float]:
    return (p.x, p.y, p.z)


def test_fix_is_the_fused_position_in_wgs84(recording: dict[str, list[tuple[str, Any]]]) -> None:
    site = load_site()
    odom = [m for _, m in recording["/fusion/odom"]]
    fixes = [m for s, m in recording["/fusion/fix"] if s == "sensor_msgs/msg/NavSatFix"]
    assert len(fixes) == len(odom) > 1000
    for o, f in zip(odom, fixes, strict=True):
        assert (f.header.stamp.sec, f.header.stamp.nanosec) == (
            o.header.stamp.sec, o.header.stamp.nanosec)
    pos = np.array([_xyz(o.pose.pose.position) for o in odom])
    lat, lon, h = site.to_geodetic(pos[:, 0], pos[:, 1], pos[:, 2])
    np.testing.assert_allclose([f.latitude for f in fixes], lat, rtol=0, atol=1e-12)
    np.testing.assert_allclose([f.longitude for f in fixes], lon, rtol=0, atol=1e-12)
    np.testing.assert_allclose([f.altitude for f in fixes], h, rtol=0, atol=1e-6)
    f, o = fixes[-1], odom[-1]
    assert f.position_covariance_type == 3  # KNOWN
    cov = np.asarray(o.pose.covariance).reshape(6, 6)[:3, :3]
    np.testing.assert_array_equal(np.asarray(f.position_covariance).reshape(3, 3), cov)
    assert f.header.frame_id == "uav"


def test_path_holds_every_fused_position_in_order(
    recording: dict[str, list[tuple[str, Any]]],
) -> None:
    odom = [m for _, m in recording["/fusion/odom"]]
    paths = [m for s, m in recording["/fusion/path"] if s == "nav_msgs/msg/Path"]
    assert paths
    last = paths[-1]
    assert last.header.frame_id == "enu_lw1" and len(last.poses) == len(odom)
    got = np.array([_xyz(p.pose.position) for p in last.poses])
    want = np.array([_xyz(o.pose.pose.position) for o in odom])
    np.testing.assert_array_equal(got, want)
    assert [time_from_stamp(p.header.stamp) for p in last.poses] == [
        time_from_stamp(o.header.stamp) for o in odom]
    # earlier paths are prefixes of the last one (the path only grows)
    mid = paths[len(paths) // 2]
    assert 0 < len(mid.poses) <= len(last.poses)
    assert _xyz(mid.poses[-1].pose.position) == _xyz(last.poses[len(mid.poses) - 1].pose.position)


def test_markers_show_track_ellipsoid_reports_towers_and_gate(
    recording: dict[str, list[tuple[str, Any]]],
) -> None:
    site = load_site()
    arrays = [m for s, m in recording["/fusion/markers"]
              if s == "visualization_msgs/msg/MarkerArray"]
    assert arrays
    last = {(mk.ns, mk.id): mk for mk in arrays[-1].markers}
    assert {ns for ns, _ in last} == {
        "towers", "tower_names", "radar_gate", "radar_accepted", "radar_rejected", "rf_fixes",
        "track", "track_covariance"}
    assert all(mk.header.frame_id == "enu_lw1" for mk in last.values())
    odom = recording["/fusion/odom"][-1][1]
    assert _xyz(last[("track", 0)].pose.position) == _xyz(odom.pose.pose.position)
    # the ellipsoid: 2-sigma diameters along the eigenvectors of the position covariance
    ell = last[("track_covariance", 0)]
    cov = np.asarray(odom.pose.covariance).reshape(6, 6)[:3, :3]
    q = ell.pose.orientation
    x, y, z, w = q.x, q.y, q.z, q.w
    rot = np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])
    radii = np.array([ell.scale.x, ell.scale.y, ell.scale.z]) / (2 * 2.0)
    np.testing.assert_allclose(rot @ np.diag(radii**2) @ rot.T, cov, rtol=1e-6, atol=1e-6)
    # towers: one cylinder and one name each; the gate: a circle of the range gate's radius
    assert sum(ns == "towers" for ns, _ in last) == len(site.towers)
    names = {mk.text for (ns, _), mk in last.items() if ns == "tower_names"}
    assert names == set(site.towers)
    gate = last[("radar_gate", 0)]
    r = [math.dist((p.x, p.y), site.radar.enu[:2]) for p in gate.points]
    np.testing.assert_allclose(r, site.radar.range_gate_m, rtol=1e-9)
    # accepted radar reports: the latest ones the fusion node published as accepted
    acc = [_xyz(m.pose.pose.position) for _, m in recording["/fusion/accepted/radar"]]
    shown = [_xyz(p) for p in last[("radar_accepted", 0)].points]
    assert 0 < len(shown) <= 200 and shown == acc[-len(shown):]
    assert last[("radar_rejected", 0)].points  # the twin's radar has outliers and clutter
    rf = last[("rf_fixes", 0)]
    assert len(rf.points) == len(rf.colors) > 0


def test_diagnostics_carry_rate_and_stamp_delay_per_input(
    recording: dict[str, list[tuple[str, Any]]],
) -> None:
    statuses: dict[str, Any] = {}
    for _, arr in recording["/diagnostics"]:
        for st in arr.status:
            statuses[st.name] = st
    for topic in ("radar/pose", "rf/fix"):
        st = statuses[f"fusion_node: {topic} input"]
        vals = {kv.key: kv.value for kv in st.values}
        assert {"Actual frequency (Hz)", "Events since startup", "Earliest timestamp delay",
                "Latest timestamp delay"} <= set(vals)
        assert 0 < int(vals["Events since startup"]) <= len(recording[f"/{topic}"])


def _foxglove_topics(doc: Any) -> set[str]:
    """Every topic the layout names (keys and values that are topic paths)."""
    found: set[str] = set()

    def walk(x: Any) -> None:
        if isinstance(x, dict):
            for k, v in x.items():
                walk(k)
                walk(v)
        elif isinstance(x, list):
            for v in x:
                walk(v)
        elif isinstance(x, str) and x.startswith("/") and " " not in x:
            found.add(x.split(".", 1)[0])  # "/fusion/odom.pose.pose.position.x" -> topic

    walk(doc)
    return found - {"/move_base_simple/goal", "/clicked_point", "/initialpose"}  # publish tool


def test_foxglove_layout_and_rviz_config_name_recorded_topics_that_decode(
    recording: dict[str, list[tuple[str, Any]]],
) -> None:
    layout = json.loads((ROOT / "config" / "foxglove_layout.json").read_text())
    fox = _foxglove_topics(layout["configById"])
    assert {"/fusion/markers", "/fusion/path", "/fusion/fix", "/truth/fix",
            "/diagnostics"} <= fox
    rviz = yaml.safe_load((ROOT / "config" / "uav_fusion.rviz").read_text())
    man = rviz["Visualization Manager"]
    assert man["Global Options"]["Fixed Frame"] == "enu_lw1"
    rviz_topics = {d["Topic"]["Value"]: RVIZ_TYPES[d["Class"]]
                   for d in man["Displays"] if "Topic" in d}
    for topic in fox | set(rviz_topics):
        assert recording.get(topic), f"{topic} is not in the recording"
        types = {s for s, _ in recording[topic]}
        assert len(types) == 1, (topic, types)
        assert all(m is not None for _, m in recording[topic])  # every message decoded
        if topic in rviz_topics:
            assert types == {rviz_topics[topic]}, topic


def test_ellipsoid_orientation_round_trips_a_rotation() -> None:
    from uav_fusion.ros.visualization import ellipsoid_pose, rotation_to_quaternion

    rng = np.random.default_rng(3)
    for _ in range(200):
        q, _r = np.linalg.qr(rng.normal(size=(3, 3)))
        if np.linalg.det(q) < 0:
            q[:, 0] = -q[:, 0]
        x, y, z, w = rotation_to_quaternion(q)
        assert abs(x * x + y * y + z * z + w * w - 1.0) < 1e-9
        back = np.array([
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ])
        np.testing.assert_allclose(back, q, atol=1e-9)
    d, _ = ellipsoid_pose([[4.0, 0.0, 0.0], [0.0, 9.0, 0.0], [0.0, 0.0, 1.0]], 2.0)
    assert sorted(d) == [4.0, 8.0, 12.0]  # diameters 2 * 2 sigma


def test_layers_never_share_a_namespace() -> None:
    from uav_fusion.ros.visualization import TrackLayer, Visualization

    vis = Visualization("enu_lw1", [TrackLayer()])
    vis.add(TrackLayer(namespace="track_7"))  # a second track: its own namespaces
    with pytest.raises(ValueError, match="track"):
        vis.add(TrackLayer())
