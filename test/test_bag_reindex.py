"""``uav_fusion bag reindex``: a recorder killed with SIGKILL (a real separate process) leaves
a bag that, once reindexed, opens in rosbags, in the mcap seeking reader and in the bag player
and holds every message up to the last flushed chunk; a file cut in the middle of a chunk
keeps its whole chunks; a complete bag's lost metadata.yaml comes back as it was."""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import time
import uuid
from collections.abc import Iterator
from pathlib import Path

import pytest
import rclpy
import yaml
from geometry_msgs.msg import PointStamped
from mcap.reader import SeekingReader
from mcap.stream_reader import StreamReader
from rclpy.context import Context
from rclpy.duration import Duration
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import QoSProfile
from rosbags.rosbag2 import Reader
from rosbags.typesys import Stores, get_typestore
from rosbags.typesys.store import Typestore
from rosbags.typesys.stores.ros2_jazzy import (
    geometry_msgs__msg__PointStamped as RosbagsPointStamped,
)

from uav_fusion.bag.reader import BagReader
from uav_fusion.bag.reindex import reindex
from uav_fusion.bag.writer import BagWriter
from uav_fusion.cli import main
from uav_fusion.core.errors import DataError
from uav_fusion.nodes.bag_player import BagPlayer

BIN = Path(sys.executable).parent
ROOT = Path(__file__).resolve().parents[1]
PS = "geometry_msgs/msg/PointStamped"
T0 = 1_760_000_000_000_000_000
LIMIT_S = 60.0


def point(i: int) -> bytes:
    store = get_typestore(Stores.ROS2_JAZZY)
    m = store.types[PS](
        header=store.types["std_msgs/msg/Header"](
            stamp=store.types["builtin_interfaces/msg/Time"](sec=i, nanosec=0), frame_id="f"),
        point=store.types["geometry_msgs/msg/Point"](x=float(i), y=0.0, z=0.0),
    )
    return bytes(store.serialize_cdr(m, PS))


def readable(bag: Path) -> int:
    """Messages a streaming reader gets from every .mcap of the bag (sub-folders too); a
    part the recorder moves while this reads is read again."""
    while True:
        n = 0
        try:
            for f in sorted(bag.rglob("*.mcap")):
                with f.open("rb") as fh:
                    try:
                        for rec in StreamReader(fh).records:
                            n += type(rec).__name__ == "Message"
                    except Exception:  # the cut end of an open part
                        pass
        except FileNotFoundError:
            continue
        return n


def point_x(store: Typestore, raw: bytes | memoryview, msgtype: str) -> float:
    """``point.x`` of a PointStamped as rosbags decodes it."""
    m = store.deserialize_cdr(raw, msgtype)
    assert isinstance(m, RosbagsPointStamped)
    return m.point.x


def xs_rosbags(bag: Path) -> list[float]:
    store = get_typestore(Stores.ROS2_JAZZY)
    with Reader(bag) as r:
        return [point_x(store, raw, c.msgtype) for c, _t, raw in r.messages()]


def xs_seeking(bag: Path) -> list[float]:
    store = get_typestore(Stores.ROS2_JAZZY)
    out = []
    files = sorted(bag.glob("*.mcap"), key=lambda p: int(p.stem.rsplit("_", 1)[1]))
    for f in files:
        with f.open("rb") as fh:
            for _s, _c, m in SeekingReader(fh).iter_messages():
                out.append(point_x(store, m.data, PS))
    return out


@pytest.fixture
def ctx() -> Iterator[Context]:
    c = Context()
    rclpy.init(context=c)
    yield c
    rclpy.shutdown(context=c)


@pytest.mark.processes
def test_recorder_killed_then_reindexed(ctx: Context, tmp_path: Path) -> None:
    """bag_recorder (own process) records a split bag; batch A reaches the disk, batch B is
    sent, SIGKILL. After reindex every reader reads one unbroken prefix of A + B, A whole."""
    topic = f"/k{uuid.uuid4().hex[:8]}/points"
    bag = tmp_path / "rec"
    exe = BIN / "bag_recorder"
    if not exe.exists():
        pytest.skip("bag_recorder is not installed (pip install -e .)")
    proc = subprocess.Popen(
        [str(exe), str(bag), "--ros-args", "-p", f"topics:=['{topic}']",
         "-p", "flush_period:=0.2", "-p", "max_bag_size:=30000"],
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    node = Node("source", context=ctx)
    pub = node.create_publisher(PointStamped, topic, QoSProfile(depth=5000))
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(node)
    try:
        end = time.monotonic() + LIMIT_S
        while pub.get_subscription_count() == 0:
            assert time.monotonic() < end, "the recorder never subscribed"
            ex.spin_once(timeout_sec=0.05)
        n_a, n_b = 2000, 2000

        def send(lo: int, hi: int) -> None:
            for i in range(lo, hi):
                m = PointStamped()
                m.header.stamp.sec = 1000 + i
                m.point.x = float(i)
                pub.publish(m)

        send(0, n_a)
        assert pub.wait_for_all_acked(Duration(seconds=LIMIT_S))
        # batch A is on disk once the recorder's flush timer has closed its chunk
        end = time.monotonic() + LIMIT_S
        while readable(bag) < n_a:
            assert time.monotonic() < end, f"only {readable(bag)} of {n_a} flushed"
            ex.spin_once(timeout_sec=0.05)
        send(n_a, n_a + n_b)
        os.kill(proc.pid, signal.SIGKILL)
        assert proc.wait(timeout=LIMIT_S) == -signal.SIGKILL
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        node.destroy_node()
    on_disk = readable(bag)
    assert not (bag / "metadata.yaml").exists()
    assert any(p.is_dir() for p in bag.iterdir())  # the open part, in its own folder
    with pytest.raises(Exception):  # noqa: B017 - rosbags refuses the killed bag
        xs_rosbags(bag)

    rep = reindex(bag)
    k = rep.message_count
    assert n_a <= k <= n_a + n_b and k == on_disk
    want = [float(i) for i in range(k)]
    assert xs_rosbags(bag) == want
    assert xs_seeking(bag) == want
    assert not any(p.is_dir() for p in bag.iterdir())
    reader = BagReader(bag)
    assert reader.message_count == k and reader.warnings == []
    meta = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert meta["message_count"] == k and len(meta["files"]) == len(list(bag.glob("*.mcap")))
    assert meta["topics_with_message_count"][0]["topic_metadata"]["type_description_hash"] \
        .startswith("RIHS01_")

    # and the bag player plays all of it
    got: list[float] = []
    sink = Node("sink", context=ctx)

    def on_point(m: PointStamped) -> None:
        got.append(m.point.x)

    sink.create_subscription(PointStamped, topic, on_point, QoSProfile(depth=10000))
    player = BagPlayer(str(bag), context=ctx, parameter_overrides=[
        Parameter("rate", value=1000.0), Parameter("publish_clock", value=False)])
    ex2 = SingleThreadedExecutor(context=ctx)
    ex2.add_node(sink)
    ex2.add_node(player)
    player.start()
    end = time.monotonic() + LIMIT_S
    while len(got) < k:
        assert time.monotonic() < end, f"the player delivered {len(got)} of {k}"
        ex2.spin_once(timeout_sec=0.02)
    player.stop()
    player.destroy_node()
    sink.destroy_node()
    assert got == want


def test_file_cut_mid_chunk_keeps_its_whole_chunks(tmp_path: Path) -> None:
    w = BagWriter(tmp_path / "b")
    w.add_topic("/a", PS)
    for i in range(450):
        w.write("/a", T0 + i * 1_000_000, point(i))
        if i % 100 == 99:
            w.flush()  # chunks of 100 messages on disk
    part = tmp_path / "b" / "b_0" / "b_0.mcap"
    assert w._writer is not None
    w._writer.storage.bio.flush()  # what a kill leaves: the flushed chunks and no more
    data = part.read_bytes()
    w.abort()
    bag = tmp_path / "cut"
    (bag / "cut_0").mkdir(parents=True)
    # cut inside the fourth chunk: three chunks (300 messages) stay whole
    chunks, pos = [], 8  # after the magic: opcode (1 byte), length (8 bytes), content
    while pos + 9 <= len(data):
        if data[pos] == 0x06:
            chunks.append(pos)
        pos += 9 + int.from_bytes(data[pos + 1 : pos + 9], "little")
    assert len(chunks) == 4
    (bag / "cut_0" / "cut_0.mcap").write_bytes(data[: chunks[3] + 500])
    rep = reindex(bag)
    assert rep.message_count == 300
    assert rep.files[0].status == "recovered" and rep.files[0].lost_bytes > 0
    assert xs_rosbags(bag) == [float(i) for i in range(rep.message_count)]


def test_a_complete_part_in_its_own_folder_moves_up_and_the_folder_goes(tmp_path: Path) -> None:
    """Killed just after a split, the recorder leaves the part it had closed in its folder,
    whole: reindex moves it up beside the others and removes the emptied folder."""
    w = BagWriter(tmp_path / "b")
    w.add_topic("/a", PS)
    for i in range(50):
        w.write("/a", T0 + i * 1_000_000, point(i))
    w.close()
    bag = tmp_path / "split"
    (bag / "split_0").mkdir(parents=True)
    shutil.copy(tmp_path / "b" / "b_0.mcap", bag / "split_0" / "split_0.mcap")
    rep = reindex(bag)
    assert rep.message_count == 50 and rep.files[0].status == "complete"
    assert not any(p.is_dir() for p in bag.iterdir())
    assert xs_rosbags(bag) == [float(i) for i in range(50)]


def test_lost_metadata_of_a_complete_bag_comes_back(tmp_path: Path,
                                                    capsys: pytest.CaptureFixture[str]) -> None:
    bag = tmp_path / "default_flight"
    shutil.copytree(ROOT / "bags" / "default_flight", bag)
    old = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    (bag / "metadata.yaml").unlink()
    assert main(["bag", "reindex", str(bag)]) == 0
    assert "each read all 13826 messages" in capsys.readouterr().out
    new = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    for key in ("message_count", "files", "starting_time", "duration", "relative_file_paths",
                "storage_identifier", "version"):
        assert new[key] == old[key], key
    assert new["topics_with_message_count"] == old["topics_with_message_count"]
    before = (bag / "default_flight_0.mcap").read_bytes()
    assert reindex(bag).files[0].status == "complete"  # a complete file is left as it is
    assert (bag / "default_flight_0.mcap").read_bytes() == before


def test_reindex_refuses_what_is_not_a_bag(tmp_path: Path) -> None:
    with pytest.raises(DataError, match="no such bag folder"):
        reindex(tmp_path / "nope")
    (tmp_path / "f.mcap").write_bytes(b"")
    with pytest.raises(DataError, match="not a folder"):
        reindex(tmp_path / "f.mcap")
    (tmp_path / "empty").mkdir()
    with pytest.raises(DataError, match=r"no \.mcap file"):
        reindex(tmp_path / "empty")
    # killed before its first flush: not one whole record; the file is kept, set aside
    (tmp_path / "early" / "early_0").mkdir(parents=True)
    (tmp_path / "early" / "early_0" / "early_0.mcap").write_bytes(b"\x89MCAP0\r\n\x01\x10")
    with pytest.raises(DataError, match="no file holds a whole record"):
        reindex(tmp_path / "early")
    assert [p.name for p in (tmp_path / "early").iterdir()] == ["early_0.mcap.unreadable"]
