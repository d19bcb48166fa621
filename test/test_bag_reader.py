"""Bag reading and writing without a ROS graph: our writer's bags, the real rosbag2 bags in
shared/interop, damaged input, two independent readers, and the flight converter."""

from __future__ import annotations

import functools
import itertools
import math
import shutil
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml
from geometry_msgs.msg import PointStamped
from rclpy.serialization import deserialize_message, serialize_message

from uav_fusion.bag.reader import BagReader, parse_qos, qos_reliability, qos_transient_local
from uav_fusion.bag.writer import BagWriter
from uav_fusion.core.errors import ConfigError, DataError

REPO = Path(__file__).resolve().parent.parent
INTEROP = REPO.parent / "shared" / "interop" / "rosbag2"
PS = "geometry_msgs/msg/PointStamped"


@functools.cache
def point(i: int) -> bytes:
    """Serialized once per i: CDR padding bytes from rclpy are not initialised, so the same
    message serialized twice can differ in its padding."""
    m = PointStamped()
    m.header.frame_id = "enu_lw1"
    m.header.stamp.sec = 1_760_000_000 + i
    m.point.x, m.point.y, m.point.z = float(i), -2.5 * i, 0.125
    return bytes(serialize_message(m))


def make_bag(
    path: Path,
    n: int = 50,
    step_ns: int = 100_000_000,
    flush_every: int = 0,
    max_bytes: int = 0,
    max_duration_s: float = 0.0,
) -> Path:
    w = BagWriter(path, max_bytes=max_bytes, max_duration_s=max_duration_s)
    w.add_topic("/a", PS)
    w.add_topic("/b", PS)
    for i in range(n):
        w.write("/a" if i % 3 else "/b", 1_000_000_000 + i * step_ns, point(i))
        if flush_every and i % flush_every == flush_every - 1:
            w.flush()
    w.close()
    return path


def interop(name: str) -> Path:
    p = INTEROP / name
    if not p.is_dir():
        pytest.skip(f"interop bags not present at {INTEROP}")
    return p


# --- our own bags -------------------------------------------------------------------------


def test_written_bag_reads_back_in_order_with_counts(tmp_path: Path) -> None:
    bag = make_bag(tmp_path / "b")
    r = BagReader(bag)
    assert r.backend == "rosbags" and r.warnings == []
    assert {t: v.count for t, v in r.topics.items()} == {"/a": 33, "/b": 17}
    msgs = list(r.messages())
    assert [m.timestamp_ns for m in msgs] == sorted(m.timestamp_ns for m in msgs)
    assert [m.data for m in msgs] == [point(i) for i in range(50)]
    assert r.start_ns == 1_000_000_000 and r.end_ns == 1_000_000_000 + 49 * 100_000_000
    # topic and time filters
    only_b = list(r.messages(["/b"], start_ns=1_000_000_000 + 10 * 100_000_000))
    assert [deserialize_message(m.data, PointStamped).point.x for m in only_b] == [
        float(i) for i in range(12, 50, 3)
    ]


def test_metadata_is_rosbag2_v9_mcap_with_jazzy_hashes(tmp_path: Path) -> None:
    from rosbags.typesys import Stores, get_typestore

    bag = make_bag(tmp_path / "b")
    info = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert info["version"] == 9 and info["storage_identifier"] == "mcap"
    assert info["message_count"] == 50
    assert info["relative_file_paths"] == ["b_0.mcap"]
    assert [f["message_count"] for f in info["files"]] == [50]
    jazzy = get_typestore(Stores.ROS2_JAZZY)
    for t in info["topics_with_message_count"]:
        assert t["topic_metadata"]["type_description_hash"] == jazzy.hash_rihs01(PS)


@pytest.mark.parametrize(
    ("max_bytes", "max_duration_s", "files"), [(600, 0.0, 5), (0, 1.0, 5)]
)
def test_split_bags_hold_every_message(
    tmp_path: Path, max_bytes: int, max_duration_s: float, files: int
) -> None:
    # 50 msgs x ~60 B; 5 s of bag time
    bag = make_bag(tmp_path / "s", n=50, max_bytes=max_bytes, max_duration_s=max_duration_s)
    info = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert len(info["relative_file_paths"]) == files
    assert sum(f["message_count"] for f in info["files"]) == 50
    assert sorted(p.name for p in bag.glob("*.mcap")) == info["relative_file_paths"]
    r = BagReader(bag)
    assert r.message_count == 50 and r.warnings == []
    assert [m.data for m in r.messages()] == [point(i) for i in range(50)]


def test_two_independent_readers_agree(tmp_path: Path) -> None:
    """rosbags' deserializer and mcap + mcap-ros2-support decode the same content."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory
    from rosbags.rosbag2 import Reader
    from rosbags.typesys import Stores, get_typestore
    from rosbags.typesys.stores.ros2_jazzy import (
        geometry_msgs__msg__PointStamped as RosbagsPointStamped,
    )

    bag = make_bag(tmp_path / "b")
    store = get_typestore(Stores.ROS2_JAZZY)
    a: list[tuple[str, int, float]] = []
    with Reader(bag) as rd:
        for c, ts, raw in rd.messages():
            m = store.deserialize_cdr(raw, c.msgtype)
            assert isinstance(m, RosbagsPointStamped)
            a.append((c.topic, ts, m.point.x))
    b = []
    with (bag / "b_0.mcap").open("rb") as fh:
        reader = make_reader(fh, decoder_factories=[DecoderFactory()])
        for _s, ch, msg, dec in reader.iter_decoded_messages():
            b.append((ch.topic, msg.log_time, dec.point.x))
            assert dec.header.frame_id == "enu_lw1" and dec.point.z == 0.125
    assert a == b and len(a) == 50


def test_writer_refuses_existing_path_and_unknown_types(tmp_path: Path) -> None:
    (tmp_path / "x").mkdir()
    with pytest.raises(ConfigError, match="exists already"):
        BagWriter(tmp_path / "x")
    w = BagWriter(tmp_path / "y")
    with pytest.raises(DataError, match="no_such_pkg/msg/Thing"):
        w.add_topic("/t", "no_such_pkg/msg/Thing")
    with pytest.raises(DataError, match="before add_topic"):
        w.write("/t", 1, b"\x00\x01\x00\x00")
    w.close()


def test_writer_registers_installed_types_missing_from_the_store(tmp_path: Path) -> None:
    """A type absent from rosbags' Jazzy store is defined from the installed .msg files."""
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_JAZZY)
    del store.fielddefs[PS]
    w = BagWriter(tmp_path / "b", typestore=store)
    w.add_topic("/p", PS)
    w.write("/p", 5, point(1))
    w.close()
    assert PS in store.fielddefs
    assert get_typestore(Stores.ROS2_JAZZY).hash_rihs01(PS) == store.hash_rihs01(PS)
    assert BagReader(tmp_path / "b").message_count == 1


def test_empty_bag_is_readable_and_says_so(tmp_path: Path) -> None:
    w = BagWriter(tmp_path / "e")
    w.add_topic("/a", PS)
    w.close()
    r = BagReader(tmp_path / "e")
    assert r.message_count == 0 and list(r.messages()) == []
    assert any("no readable messages" in w for w in r.warnings)


# --- bad input ------------------------------------------------------------------------------


def test_missing_path_and_wrong_files_are_clear_errors(tmp_path: Path) -> None:
    with pytest.raises(DataError, match="no such bag"):
        BagReader(tmp_path / "nope")
    (tmp_path / "d").mkdir()
    with pytest.raises(DataError, match=r"no \.mcap or \.db3"):
        BagReader(tmp_path / "d")
    (tmp_path / "f.txt").write_text("hello")
    with pytest.raises(DataError, match="not a bag"):
        BagReader(tmp_path / "f.txt")
    (tmp_path / "junk.mcap").write_bytes(b"not an mcap file at all")
    r = BagReader(tmp_path / "junk.mcap")
    assert r.message_count == 0 and any("stopped after 0 messages" in w for w in r.warnings)


def test_truncated_mcap_plays_its_readable_prefix(tmp_path: Path) -> None:
    # many small chunks (flush), then cut in the middle of one: earlier chunks stay readable
    bag = make_bag(tmp_path / "b", n=3000, flush_every=100)
    whole = BagReader(bag)
    assert whole.message_count == 3000 and whole.warnings == [] and whole.backend == "rosbags"
    f = bag / "b_0.mcap"
    data = f.read_bytes()
    f.write_bytes(data[: len(data) * 2 // 3])
    r = BagReader(bag)
    assert 0 < r.message_count < 3000
    got = [m.data for m in r.messages()]
    assert got == [point(i) for i in range(len(got))]  # an exact prefix
    text = " ".join(r.warnings)
    assert "readable prefix" in text and "metadata.yaml" in text


@pytest.mark.parametrize("damage", ["missing", "not yaml", "wrong shape", "missing file"])
def test_bad_metadata_falls_back_to_the_storage_files(tmp_path: Path, damage: str) -> None:
    bag = make_bag(tmp_path / "b")
    meta = bag / "metadata.yaml"
    if damage == "missing":
        meta.unlink()
    elif damage == "not yaml":
        meta.write_text("rosbag2_bagfile_information: [unclosed\n  version: 9\n")
    elif damage == "wrong shape":
        meta.write_text("rosbag2_bagfile_information:\n  version: 9\n")
    else:
        doc = yaml.safe_load(meta.read_text())
        doc["rosbag2_bagfile_information"]["relative_file_paths"] = ["gone.mcap"]
        meta.write_text(yaml.safe_dump(doc))
    r = BagReader(bag)
    assert r.message_count == 50
    assert [m.data for m in r.messages()] == [point(i) for i in range(50)]
    assert r.warnings, "the damage must be reported"
    if damage == "not yaml":
        assert "metadata.yaml:3" in r.warnings[0] or "metadata.yaml:2" in r.warnings[0]


def test_count_mismatch_with_metadata_is_warned(tmp_path: Path) -> None:
    bag = make_bag(tmp_path / "b")
    meta = bag / "metadata.yaml"
    doc = yaml.safe_load(meta.read_text())
    doc["rosbag2_bagfile_information"]["topics_with_message_count"][0]["message_count"] = 99
    meta.write_text(yaml.safe_dump(doc))
    r = BagReader(bag)
    assert r.message_count == 50
    assert any("differ from metadata.yaml" in w and "/a: 33 of 99" in w for w in r.warnings)


def test_qos_parsing_handles_v4_strings_and_v9_lists() -> None:
    v4 = "- history: 3\n  depth: 0\n  reliability: 2\n  durability: 1\n"
    assert qos_reliability(parse_qos(v4)) == "best_effort"
    assert qos_transient_local(parse_qos(v4))
    v9 = [{"reliability": "reliable", "durability": "volatile"}]
    assert qos_reliability(parse_qos(v9)) == "reliable" and not qos_transient_local(parse_qos(v9))
    assert parse_qos("") == () and parse_qos("[: bad") == () and qos_reliability(()) is None


# --- real rosbag2 bags -----------------------------------------------------------------------


@pytest.mark.parametrize(
    ("name", "total", "backend"),
    [("talker_mcap", 20, "mcap"), ("talker_sqlite3", 20, "sqlite3"), ("split_mcap", 6074, None)],
)
def test_interop_bags_yield_every_message(name: str, total: int, backend: str | None) -> None:
    bag = interop(name)
    r = BagReader(bag)
    meta = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    expected = {
        t["topic_metadata"]["name"]: t["message_count"] for t in meta["topics_with_message_count"]
    }
    assert r.message_count == total
    assert {t: v.count for t, v in r.topics.items()} == expected
    msgs = list(r.messages())
    assert len(msgs) == total
    assert all(b.timestamp_ns >= a.timestamp_ns for a, b in itertools.pairwise(msgs))
    if backend is not None:  # rosbags yields nothing here: the fallback must have been used
        assert r.backend == backend
        assert any("rosbags reader yields 0" in w for w in r.warnings)


def test_interop_talker_content_is_the_same_from_mcap_and_sqlite() -> None:
    a = BagReader(interop("talker_mcap"))
    b = BagReader(interop("talker_sqlite3"))
    assert [(m.topic, m.timestamp_ns, m.data) for m in a.messages()] == [
        (m.topic, m.timestamp_ns, m.data) for m in b.messages()
    ]


def test_interop_bare_storage_files(tmp_path: Path) -> None:
    for name, suffix in (("talker_mcap", "talker.mcap"), ("talker_sqlite3", "talker.db3")):
        src = interop(name) / suffix
        dst = tmp_path / suffix
        shutil.copy(src, dst)
        r = BagReader(dst)
        assert r.message_count == 20 and r.warnings == []
        assert r.topics["/topic"].msgtype == "std_msgs/msg/String"


# --- converter -------------------------------------------------------------------------------


def test_convert_flight_writes_what_the_replay_nodes_publish(tmp_path: Path) -> None:
    from geometry_msgs.msg import PoseWithCovarianceStamped
    from sensor_msgs.msg import NavSatFix
    from test_graph_flight import write_flight

    from uav_fusion.bag.convert import convert_flight
    from uav_fusion.core.data import load_flight
    from uav_fusion.core.estimators import load_profile
    from uav_fusion.core.estimators.selection import raw_radar_reports, selected_radar
    from uav_fusion.core.site import load_site
    from uav_fusion.ros.conversions import time_from_stamp

    site = load_site()
    flight = load_flight(write_flight(tmp_path / "f", seconds=20.0), site)
    res = convert_flight(flight, site, tmp_path / "bag", namespace="uav")
    prof = load_profile("paper")
    selected = [m for group in selected_radar(flight, prof, site) for m in group]
    raw = raw_radar_reports(flight, prof)
    assert 0 < len(selected) < len(raw)
    r = BagReader(tmp_path / "bag")
    assert {t: v.count for t, v in r.topics.items()} == {
        "/uav/radar/pose": len(selected),
        "/uav/radar/raw": len(raw),
        "/uav/radar/tracks": len(flight.radar),
        "/uav/rf/fix": len(flight.rf),
        "/uav/rf/fixes": len(flight.rf),
        "/uav/truth/fix": len(flight.truth),
    }
    # every report of every frame and every attempt with its quality, decoded losslessly
    from sensor_msgs.msg import PointCloud2

    from uav_fusion.ros.conversions import msg_to_radar_frame, msg_to_rf_attempts

    frames = [
        msg_to_radar_frame(deserialize_message(m.data, PointCloud2), site.frame_id)
        for m in r.messages(["/uav/radar/tracks"])
    ]
    for (got, dropped), fr in zip(frames, flight.radar, strict=True):
        assert not dropped and got.t == fr.t
        def key(x: Any) -> tuple[Any, ...]:
            return (x.track_id, x.e, x.n, x.u, x.vel_ned, x.uav_prob, x.rcs_dbsm)

        assert [key(x) for x in got.tracks] == [key(x) for x in fr.tracks]
    attempts = [
        msg_to_rf_attempts(deserialize_message(m.data, PointCloud2), site.frame_id)[0][0]
        for m in r.messages(["/uav/rf/fixes"])
    ]
    for got_a, a in zip(attempts, flight.rf, strict=True):
        assert (got_a.t, got_a.ok, got_a.cep, got_a.valid_sensors, got_a.center_freq_hz) == (
            a.t, a.ok, a.cep, a.valid_sensors, a.center_freq_hz,
        )
    assert res.radar_cov is not None and prof.r_radar is not None
    assert np.array_equal(res.radar_cov, prof.r_radar)
    poses = [
        deserialize_message(m.data, PoseWithCovarianceStamped)
        for m in r.messages(["/uav/radar/pose"])
    ]
    for msg, m in zip(poses, selected, strict=True):
        assert msg.header.frame_id == site.frame_id
        assert math.isclose(time_from_stamp(msg.header.stamp), m.t, abs_tol=1e-9)
        p = msg.pose.pose.position
        assert (p.x, p.y, p.z) == tuple(float(v) for v in m.z)
        assert np.allclose(np.reshape(msg.pose.covariance, (6, 6))[:3, :3], prof.r_radar)
    fixes = [deserialize_message(m.data, NavSatFix) for m in r.messages(["/uav/truth/fix"])]
    assert [f.latitude for f in fixes] == [f.lat for f in flight.truth]
    assert {f.header.frame_id for f in fixes} == {"gps"}
    # stored receive times are the sensor times, in order across topics
    stamps = [m.timestamp_ns for m in r.messages()]
    assert stamps == sorted(stamps)
    first = next(iter(r.messages(["/uav/truth/fix"])))
    assert first.timestamp_ns == round(flight.truth[0].t * 1e9)
    meta = yaml.safe_load((tmp_path / "bag" / "metadata.yaml").read_text())
    custom = meta["rosbag2_bagfile_information"]["custom_data"]
    assert custom["uav_fusion.profile"] == "paper"
    assert custom["uav_fusion.radar_selection"] == prof.radar_selection


def test_convert_command_errors_are_clear(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from uav_fusion.cli import main

    assert main(["convert", str(tmp_path / "nothing"), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert "flight folder not found" in err and "Traceback" not in err
    (tmp_path / "o").mkdir()
    assert main(["convert", str(tmp_path), "--out", str(tmp_path / "o")]) == 2
    assert "exists already" in capsys.readouterr().err


def test_bundled_bag_matches_the_bundled_flight(tmp_path: Path) -> None:
    """bags/default_flight is the converter's output for data/default_flight with the current
    paper profile; regenerate it after either changes:
    ``uav_fusion convert data/default_flight --out bags/default_flight``."""
    from geometry_msgs.msg import PoseWithCovarianceStamped

    from uav_fusion.bag.convert import convert_flight
    from uav_fusion.core.data import load_flight
    from uav_fusion.core.site import load_site

    bundled = REPO / "bags" / "default_flight"
    flight_dir = REPO / "data" / "default_flight"
    if not (bundled / "metadata.yaml").is_file() or not flight_dir.is_dir():
        pytest.skip("no bundled bag or flight in this checkout")
    site = load_site()
    convert_flight(load_flight(flight_dir, site), site, tmp_path / "fresh")
    old, new = BagReader(bundled), BagReader(tmp_path / "fresh")
    hint = "stale bag: run 'uav_fusion convert data/default_flight --out bags/default_flight'"
    assert old.warnings == [], old.warnings
    assert {t: v.count for t, v in old.topics.items()} == {
        t: v.count for t, v in new.topics.items()
    }, hint
    assert [(m.topic, m.timestamp_ns) for m in old.messages()] == [
        (m.topic, m.timestamp_ns) for m in new.messages()
    ], hint
    for a, b in zip(old.messages(["/radar/pose"]), new.messages(["/radar/pose"]), strict=True):
        pa = deserialize_message(a.data, PoseWithCovarianceStamped)
        pb = deserialize_message(b.data, PoseWithCovarianceStamped)
        assert list(pa.pose.covariance) == list(pb.pose.covariance), hint
        assert pa.pose.pose.position == pb.pose.pose.position, hint


@pytest.mark.parametrize("compression", ["ZSTD", "LZ4"])
def test_chunk_compressed_mcap_from_another_writer(tmp_path: Path, compression: str) -> None:
    """A bare .mcap written by mcap-ros2-support (compressed chunks, its own schema text)."""
    from mcap.writer import CompressionType
    from mcap_ros2.writer import Writer

    path = tmp_path / "other.mcap"
    with path.open("wb") as fh:
        w = Writer(fh, chunk_size=2000, compression=getattr(CompressionType, compression))
        schema = w.register_msgdef(
            "geometry_msgs/msg/Point", "float64 x\nfloat64 y\nfloat64 z\n"
        )
        for i in range(300):
            w.write_message("/p", schema, {"x": float(i), "y": 0.0, "z": -1.0}, log_time=i)
        w.finish()
    r = BagReader(path)
    assert r.message_count == 300 and r.warnings == []
    assert r.topics["/p"].msgtype == "geometry_msgs/msg/Point"
    from geometry_msgs.msg import Point

    xs = [deserialize_message(m.data, Point).x for m in r.messages()]
    assert xs == [float(i) for i in range(300)]
