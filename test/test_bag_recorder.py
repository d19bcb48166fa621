"""bag_recorder: every message sent is in the bag, the bag reads the same with two independent
readers, its type hashes are the live graph's, and SIGINT/SIGTERM close it cleanly."""

from __future__ import annotations

import math
import signal
import subprocess
import sys
import time
import uuid
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
import rclpy
import yaml
from geometry_msgs.msg import PointStamped
from rclpy.duration import Duration
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.publisher import Publisher
from rclpy.qos import HistoryPolicy, QoSProfile
from rclpy.utilities import try_shutdown
from sensor_msgs.msg import NavSatFix

from uav_fusion.bag.reader import BagReader
from uav_fusion.core.errors import ConfigError
from uav_fusion.nodes.bag_recorder import BagRecorder


@pytest.fixture
def ros() -> Iterator[None]:
    rclpy.init()
    try:
        yield
    finally:
        try_shutdown()


def point_msg(i: int) -> PointStamped:
    m = PointStamped()
    m.header.frame_id = "enu_lw1"
    m.header.stamp.sec, m.header.stamp.nanosec = 1_760_000_000 + i // 4, (i % 4) * 250_000_000
    m.point.x, m.point.y = 10.0 * i, -0.5 * i
    m.point.z = math.nan if i % 7 == 0 else 0.0  # failed RF attempts are NaN
    return m


def fix_msg(i: int) -> NavSatFix:
    m = NavSatFix()
    m.header.frame_id = "gps"
    m.latitude, m.longitude, m.altitude = 35.7 + i * 1e-6, -78.69 - i * 1e-6, 120.0 + i
    m.status.status = 2
    return m


def wait_matched(ex: SingleThreadedExecutor, pubs: list[Publisher], timeout: float = 10.0) -> None:
    deadline = time.monotonic() + timeout
    while any(p.get_subscription_count() == 0 for p in pubs):
        assert time.monotonic() < deadline, "recorder never subscribed"
        ex.spin_once(timeout_sec=0.02)


def record(
    tmp_path: Path, n_points: int, n_fixes: int, **params: Any
) -> tuple[Path, Node, str]:
    """Record from a source node; topics live under a fresh namespace, so endpoints of an
    earlier test still being torn down in DDS can never match."""
    ns = f"/t{uuid.uuid4().hex[:8]}"
    out = tmp_path / "rec"
    rec = BagRecorder(str(out), namespace=ns, parameter_overrides=[
        Parameter("topics", value=[f"{ns}/rf/fix", "truth/fix"]),  # absolute and relative
        *[Parameter(k, value=v) for k, v in params.items()],
    ])
    src = Node("source")
    qos = QoSProfile(depth=1000)
    p_pub = src.create_publisher(PointStamped, f"{ns}/rf/fix", qos)
    f_pub = src.create_publisher(NavSatFix, f"{ns}/truth/fix", qos)
    ex = SingleThreadedExecutor()
    ex.add_node(rec)
    ex.add_node(src)
    wait_matched(ex, [p_pub, f_pub])
    for i in range(max(n_points, n_fixes)):
        if i < n_points:
            p_pub.publish(point_msg(i))
        if i < n_fixes:
            f_pub.publish(fix_msg(i))
        if i % 50 == 0:
            ex.spin_once(timeout_sec=0)
    deadline = time.monotonic() + 20
    while sum(rec.received.values()) < n_points + n_fixes and time.monotonic() < deadline:
        ex.spin_once(timeout_sec=0.02)
    rec.close()
    ex.shutdown()
    rec.destroy_node()
    return out, src, ns


def test_every_message_is_recorded_and_readers_agree(ros: None, tmp_path: Path) -> None:
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory
    from rosbags.rosbag2 import Reader
    from rosbags.typesys import Stores, get_typestore
    from rosbags.typesys.stores.ros2_jazzy import (
        geometry_msgs__msg__PointStamped as RosbagsPointStamped,
    )
    from rosbags.typesys.stores.ros2_jazzy import sensor_msgs__msg__NavSatFix as RosbagsNavSatFix

    out, src, ns = record(tmp_path, 600, 60)
    rf, truth = f"{ns}/rf/fix", f"{ns}/truth/fix"
    r = BagReader(out)
    assert r.warnings == []
    assert {t: v.count for t, v in r.topics.items()} == {rf: 600, truth: 60}

    # reader 1: rosbags with its Jazzy type store
    store = get_typestore(Stores.ROS2_JAZZY)
    a: list[tuple[str, Any]] = []
    with Reader(out) as rd:
        for c, _ts, raw in rd.messages():
            m = store.deserialize_cdr(raw, c.msgtype)
            if c.topic == rf:
                assert isinstance(m, RosbagsPointStamped)
                a.append((c.topic, (m.point.x, m.point.y, m.point.z)))
            else:
                assert isinstance(m, RosbagsNavSatFix)
                a.append((c.topic, (m.latitude, m.longitude, m.altitude)))
    # reader 2: mcap + mcap-ros2-support, decoding from the definitions stored in the file
    b: list[tuple[str, Any]] = []
    for f in sorted(out.glob("*.mcap")):
        with f.open("rb") as fh:
            for _s, ch, _msg, m in make_reader(
                fh, decoder_factories=[DecoderFactory()]
            ).iter_decoded_messages(log_time_order=True):
                b.append((ch.topic, (m.point.x, m.point.y, m.point.z) if ch.topic == rf
                          else (m.latitude, m.longitude, m.altitude)))
    def key(item: tuple[str, Any]) -> str:
        return repr(item)  # NaN-safe comparison

    assert sorted(map(key, a)) == sorted(map(key, b))
    sent_points = [(p.point.x, p.point.y, p.point.z) for p in map(point_msg, range(600))]
    assert [key((rf, v)) for v in sent_points] == [key(x) for x in a if x[0] == rf]

    # type hashes stored in the bag are the live graph's
    info = yaml.safe_load((out / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    stored = {t["topic_metadata"]["name"]: t["topic_metadata"]["type_description_hash"]
              for t in info["topics_with_message_count"]}
    for topic in (rf, truth):
        live = {str(i.topic_type_hash) for i in src.get_publishers_info_by_topic(topic)}
        assert live == {stored[topic]}
    assert info["message_count"] == 660 and info["version"] == 9


def test_split_by_size_keeps_every_message(ros: None, tmp_path: Path) -> None:
    out, _, _ = record(tmp_path, 300, 0, max_bag_size=4000)
    info = yaml.safe_load((out / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert len(info["relative_file_paths"]) > 2
    r = BagReader(out)
    assert r.message_count == 300 and r.warnings == []


def test_all_topics_records_data_topics_but_not_graph_bookkeeping(
    ros: None, tmp_path: Path
) -> None:
    topic = f"/t{uuid.uuid4().hex[:8]}/anything"
    rec = BagRecorder(str(tmp_path / "all"), parameter_overrides=[
        Parameter("all_topics", value=True)])
    src = Node("source_all")
    pub = src.create_publisher(PointStamped, topic, QoSProfile(depth=100))
    ex = SingleThreadedExecutor()
    ex.add_node(rec)
    ex.add_node(src)
    wait_matched(ex, [pub])
    for i in range(20):
        pub.publish(point_msg(i))
    deadline = time.monotonic() + 10
    while rec.received[topic] < 20 and time.monotonic() < deadline:
        ex.spin_once(timeout_sec=0.02)
    rec.close()
    ex.shutdown()
    r = BagReader(tmp_path / "all")
    assert r.topics[topic].count == 20
    assert "/rosout" not in r.topics and "/parameter_events" not in r.topics


def test_bad_parameters(ros: None, tmp_path: Path) -> None:
    (tmp_path / "exists").mkdir()
    with pytest.raises(ConfigError, match="exists already"):
        BagRecorder(str(tmp_path / "exists"))
    with pytest.raises(ConfigError, match="qos_reliability"):
        BagRecorder(str(tmp_path / "x"), parameter_overrides=[
            Parameter("qos_reliability", value="maybe")])


@pytest.mark.processes
@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_signal_closes_the_bag_with_every_acknowledged_message(
    ros: None, tmp_path: Path, sig: signal.Signals
) -> None:
    out = tmp_path / "rec"
    topic = f"/t{uuid.uuid4().hex[:8]}/rf/fix"
    proc = subprocess.Popen(
        [sys.executable, "-m", "uav_fusion.nodes.bag_recorder", str(out),
         "--ros-args", "-p", f'topics:=["{topic}"]'],
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        node = Node("source")
        # keep-all: nothing is overwritten before the recorder has acknowledged it
        pub = node.create_publisher(PointStamped, topic,
                                    QoSProfile(history=HistoryPolicy.KEEP_ALL, depth=1))
        deadline = time.monotonic() + 30
        while pub.get_subscription_count() == 0:
            assert time.monotonic() < deadline, "recorder never subscribed"
            assert proc.poll() is None, proc.communicate()[0]
            time.sleep(0.02)
        n = 2000
        for i in range(n):
            pub.publish(point_msg(i))
        assert pub.wait_for_all_acked(Duration(seconds=20))
        proc.send_signal(sig)
        log = proc.communicate(timeout=30)[0]
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 0, log
    assert "Traceback" not in log
    assert f"recorded {n} messages" in log
    r = BagReader(out)
    assert r.warnings == [] and r.backend == "rosbags"
    assert r.topics[topic].count == n
