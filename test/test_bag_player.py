"""bag_player in an in-process executor: timing, /clock, topic selection and remapping, loops,
the real rosbag2 bags of shared/interop, unknown message types and bad input."""

from __future__ import annotations

import contextlib
import functools
import os
import subprocess
import sys
import threading
import time
from collections import Counter
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pytest
import rclpy
from geometry_msgs.msg import PointStamped
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.serialization import deserialize_message, serialize_message
from rclpy.utilities import try_shutdown
from rosgraph_msgs.msg import Clock

from uav_fusion.bag.reader import BagReader
from uav_fusion.bag.writer import BagWriter
from uav_fusion.core.errors import ConfigError, UavFusionError
from uav_fusion.nodes.bag_player import BagPlayer, message_class

REPO = Path(__file__).resolve().parent.parent
INTEROP = REPO.parent / "shared" / "interop" / "rosbag2"
PS = "geometry_msgs/msg/PointStamped"
T0 = 1_760_000_000_000_000_000
# bag times (s): a burst, a long gap, a burst; spacing must survive any rate
OFFSETS = [0.0, 0.05, 0.1, 0.15, 0.2, 0.8, 0.85, 0.9, 0.95, 1.0]


@functools.cache
def point(i: int) -> bytes:
    m = PointStamped()
    m.header.frame_id = "enu_lw1"
    m.point.x = float(i)
    return bytes(serialize_message(m))


def make_bag(path: Path, offsets: list[float], topics: tuple[str, ...] = ("/a",)) -> Path:
    w = BagWriter(path)
    for t in topics:
        w.add_topic(t, PS)
    for i, off in enumerate(offsets):
        w.write(topics[i % len(topics)], T0 + round(off * 1e9), point(i))
    w.close()
    return path


@pytest.fixture
def ros() -> Iterator[None]:
    rclpy.init()
    try:
        yield
    finally:
        try_shutdown()


@dataclass
class Sink:
    """Raw subscriptions recording (topic, wall time, bytes), and /clock values."""

    node: Node
    got: list[tuple[str, float, bytes]] = field(default_factory=list)
    clock: list[int] = field(default_factory=list)

    def counts(self) -> Counter[str]:
        return Counter(t for t, _, _ in self.got)


def sink(topics: dict[str, Any], clock: bool = False) -> Sink:
    s = Sink(Node("sink"))
    qos = QoSProfile(history=HistoryPolicy.KEEP_ALL, reliability=ReliabilityPolicy.RELIABLE)
    for name, cls in topics.items():
        def record(d: bytes, n: str = name) -> None:
            s.got.append((n, time.monotonic(), d))

        s.node.create_subscription(cls, name, record, qos, raw=True)
    if clock:
        def on_clock(m: Clock) -> None:
            s.clock.append(m.clock.sec * 1_000_000_000 + m.clock.nanosec)

        s.node.create_subscription(Clock, "/clock", on_clock, qos)
    return s


def play(s: Sink, bag: Path, expect: int, timeout: float = 30.0, **params: Any) -> BagPlayer:
    """Run a player until it finishes and ``expect`` messages arrived (or ``timeout``)."""
    player = BagPlayer(str(bag), parameter_overrides=[Parameter(k, value=v)
                                                      for k, v in params.items()])
    ex = SingleThreadedExecutor()
    ex.add_node(s.node)
    ex.add_node(player)
    player.start()
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline and (
        not player.finished.is_set() or len(s.got) < expect
    ):
        ex.spin_once(timeout_sec=0.02)
    end = time.monotonic() + 0.2  # anything extra would show up now
    while time.monotonic() < end:
        ex.spin_once(timeout_sec=0.02)
    player.stop()
    ex.shutdown()
    player.destroy_node()
    s.node.destroy_node()
    assert player.error is None
    return player


def spacing(times: list[float]) -> list[float]:
    span = times[-1] - times[0]
    return [(t - times[0]) / span for t in times]


@pytest.mark.parametrize("rate", [1.0, 10.0])
def test_relative_timing_is_preserved(ros: None, tmp_path: Path, rate: float) -> None:
    offsets = [o * rate for o in OFFSETS]  # ~1 s of wall time at either rate
    bag = make_bag(tmp_path / "b", offsets)
    s = sink({"/a": PointStamped})
    player = play(s, bag, len(offsets), rate=rate)
    assert player.played == Counter({"/a": len(offsets)})
    assert [d for _, _, d in s.got] == [point(i) for i in range(len(offsets))]
    arrived = spacing([w for _, w, _ in s.got])
    expected = spacing(offsets)
    # generous: a loaded machine may delay single messages, never reorder the structure
    assert max(abs(a - e) for a, e in zip(arrived, expected, strict=True)) < 0.25
    # the rate is applied: never faster than bag time / rate, and at rate 10 clearly faster
    # than real time (5x margin for a loaded machine)
    wall = s.got[-1][1] - s.got[0][1]
    assert wall >= 0.9 * offsets[-1] / rate
    if rate > 1:
        assert wall < 0.5 * offsets[-1]
    gap = arrived[5] - arrived[4]
    assert gap > 2 * max(arrived[4] - arrived[0], arrived[9] - arrived[5])


def test_clock_follows_bag_time(ros: None, tmp_path: Path) -> None:
    bag = make_bag(tmp_path / "b", OFFSETS)
    s = sink({"/a": PointStamped}, clock=True)
    play(s, bag, len(OFFSETS), rate=2.0, clock_hz=20.0)
    assert s.clock, "no /clock received"
    assert s.clock == sorted(s.clock)
    assert s.clock[0] >= T0 and s.clock[-1] == T0 + round(OFFSETS[-1] * 1e9)
    # ticks between messages: the 0.6 s gap is not silent
    inside_gap = [c for c in s.clock if T0 + 0.2e9 < c < T0 + 0.8e9]
    assert inside_gap


def test_topic_selection_remap_offset_and_duration(ros: None, tmp_path: Path) -> None:
    bag = make_bag(tmp_path / "b", [0.01 * i for i in range(30)], topics=("/a", "/b", "c"))
    s = sink({"/a": PointStamped, "/b": PointStamped, "/out/c": PointStamped, "/c": PointStamped})
    player = play(s, bag, 5, topics=["/b", "c"], remap=["c:=/out/c"], start_offset=0.095,
                  duration=0.1)
    # played: messages with offsets in [0.095, 0.195) -> i = 10..19, only /b (i%3==1), c (==2)
    want_b = [i for i in range(10, 20) if i % 3 == 1]
    want_c = [i for i in range(10, 20) if i % 3 == 2]
    assert s.counts() == Counter({"/b": len(want_b), "/out/c": len(want_c)})
    assert [d for t, _, d in s.got if t == "/b"] == [point(i) for i in want_b]
    assert [d for t, _, d in s.got if t == "/out/c"] == [point(i) for i in want_c]
    assert player.played == Counter({"/b": len(want_b), "/out/c": len(want_c)})


def test_loop_replays_and_time_jumps_back(ros: None, tmp_path: Path) -> None:
    bag = make_bag(tmp_path / "b", [0.0, 0.05, 0.1])
    s = sink({"/a": PointStamped}, clock=True)
    player = play(s, bag, 9, rate=1.0, loop=True, loop_count=3)
    assert player.passes == 3 and player.played == Counter({"/a": 9})
    assert [deserialize_message(d, PointStamped).point.x for _, _, d in s.got] == [0.0, 1.0,
                                                                                  2.0] * 3
    jumps_back = sum(1 for a, b in zip(s.clock, s.clock[1:], strict=False) if b < a)
    assert jumps_back == 2


def test_bad_parameters_are_clear_errors(ros: None, tmp_path: Path) -> None:
    bag = make_bag(tmp_path / "b", [0.0])
    for params, text in (
        ({"rate": 0.0}, "rate must be > 0"),
        ({"remap": ["nonsense"]}, "is not 'from:=to'"),
        ({"topics": ["/nope"]}, "topics not in"),
        ({"qos_reliability": "sometimes"}, "qos_reliability"),
    ):
        with pytest.raises(ConfigError, match=text):
            BagPlayer(str(bag), parameter_overrides=[Parameter(k, value=v)
                                                     for k, v in params.items()])


def test_unknown_message_types_are_skipped_and_reported(ros: None, tmp_path: Path) -> None:
    """A type that is not installed cannot be published by rclpy: the topic is skipped, the
    others play in full."""
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    store = get_typestore(Stores.ROS2_JAZZY)
    store.register(get_types_from_msg("float64 value", "ghost_msgs/msg/Reading"))
    w = BagWriter(tmp_path / "b", typestore=store)
    w.add_topic("/ghost", "ghost_msgs/msg/Reading")
    w.add_topic("/a", PS)
    for i in range(6):
        w.write("/ghost", T0 + i * 10_000_000, b"\x00\x01\x00\x00" + bytes(8))
        w.write("/a", T0 + i * 10_000_000 + 1, point(i))
    w.close()
    assert message_class("ghost_msgs/msg/Reading") is None
    s = sink({"/a": PointStamped})
    player = play(s, tmp_path / "b", 6)
    assert s.counts() == Counter({"/a": 6})
    assert "not installed" in player.skipped["/ghost"]
    with pytest.raises(UavFusionError, match=r"nothing to play.*not installed"):
        BagPlayer(str(tmp_path / "b"), parameter_overrides=[Parameter("topics",
                                                                      value=["/ghost"])])


def test_truncated_bag_plays_its_prefix(ros: None, tmp_path: Path) -> None:
    w = BagWriter(tmp_path / "b")
    w.add_topic("/a", PS)
    for i in range(400):
        w.write("/a", T0 + i * 1_000_000, point(i))
        if i % 50 == 49:
            w.flush()
    w.close()
    f = tmp_path / "b" / "b_0.mcap"
    f.write_bytes(f.read_bytes()[: f.stat().st_size // 2])
    n = BagReader(tmp_path / "b").message_count
    assert 0 < n < 400
    s = sink({"/a": PointStamped})
    play(s, tmp_path / "b", n, rate=10.0)
    assert [d for _, _, d in s.got] == [point(i) for i in range(n)]


@pytest.mark.parametrize("name", ["talker_mcap", "talker_sqlite3", "split_mcap"])
def test_interop_bags_play_in_full(ros: None, name: str) -> None:
    from rcl_interfaces.msg import Log
    from std_msgs.msg import String

    bag = INTEROP / name
    if not bag.is_dir():
        pytest.skip(f"interop bags not present at {INTEROP}")
    reader = BagReader(bag)
    expected = Counter({("/" + t.lstrip("/")): v.count for t, v in reader.topics.items()
                        if v.count})
    stored = Counter(m.data for m in reader.messages())
    # /rosout is remapped: this process's own log messages also go to /rosout
    topics = {("/played/rosout" if t == "/rosout" else t): String for t in expected}
    if "/rosout" in expected:
        topics["/played/rosout"] = Log
    s = sink(topics)
    player = play(s, bag, sum(expected.values()), rate=20.0, remap=["/rosout:=/played/rosout"])
    got = Counter({("/rosout" if t == "/played/rosout" else t): n for t, n in s.counts().items()})
    assert got == expected
    assert Counter(d for _, _, d in s.got) == stored  # byte-exact
    assert sum(player.played.values()) == sum(expected.values())


def run_main(*args: str) -> subprocess.CompletedProcess[str]:
    env = dict(os.environ)
    return subprocess.run(
        [sys.executable, "-m", "uav_fusion.nodes.bag_player", *args],
        capture_output=True, text=True, timeout=60, env=env, check=False,
    )


@pytest.mark.processes
def test_command_line_bad_input_is_an_error_message_not_a_traceback(tmp_path: Path) -> None:
    w = BagWriter(tmp_path / "empty")
    w.add_topic("/a", PS)
    w.close()
    cases = ((tmp_path / "missing", "no such bag"), (tmp_path / "empty", "nothing to play"))
    for bag, text in cases:
        res = run_main(str(bag))
        assert res.returncode == 2, res.stderr
        assert text in res.stderr and "Traceback" not in res.stderr


@pytest.mark.processes
def test_command_line_plays_a_bag(tmp_path: Path) -> None:
    bag = make_bag(tmp_path / "b", [0.0, 0.01, 0.02])
    received: list[bytes] = []
    rclpy.init()
    try:
        node = Node("cli_sink")
        node.create_subscription(PointStamped, "/a", received.append, 10, raw=True)
        ex = SingleThreadedExecutor()
        ex.add_node(node)
        proc = subprocess.Popen(
            [sys.executable, "-m", "uav_fusion.nodes.bag_player", str(bag)],
            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        done = threading.Event()
        out: list[str] = []

        def wait() -> None:
            out.append(proc.communicate(timeout=60)[0])
            done.set()

        threading.Thread(target=wait, daemon=True).start()
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline and not (done.is_set() and len(received) >= 3):
            ex.spin_once(timeout_sec=0.05)
        ex.shutdown()
    finally:
        try_shutdown()
    assert proc.returncode == 0, out
    assert received == [point(0), point(1), point(2)]
    assert "played 3 messages" in out[0]


def test_without_subscribers_it_waits_then_plays_anyway(ros: None, tmp_path: Path) -> None:
    bag = make_bag(tmp_path / "b", [0.0, 0.01])
    s = sink({"/unrelated": PointStamped})
    player = play(s, bag, 0, wait_timeout=0.3)
    assert player.played == Counter({"/a": 2}) and s.got == []


@contextlib.contextmanager
def held_player(s: Sink, bag: Path, hold: Any) -> Iterator[tuple[BagPlayer, Any]]:
    """A player at rate 1 with ``hold``, running; yields it and ``spin(cond)``, which spins
    the executor while ``cond()`` holds (30 s at most)."""
    player = BagPlayer(str(bag), parameter_overrides=[Parameter("rate", value=1.0)])
    player.hold = hold
    ex = SingleThreadedExecutor()
    ex.add_node(s.node)
    ex.add_node(player)

    def spin(cond: Any, limit_s: float = 30.0) -> None:
        deadline = time.monotonic() + limit_s
        while cond() and time.monotonic() < deadline:
            ex.spin_once(timeout_sec=0.02)

    player.start()
    try:
        yield player, spin
    finally:
        player.stop()
        ex.shutdown()
        player.destroy_node()
        s.node.destroy_node()


def test_hold_makes_the_player_wait_for_its_consumers_then_keep_the_spacing(
    ros: None, tmp_path: Path
) -> None:
    """An in-process owner's ``hold`` (its consumers behind): nothing is published while it
    holds, and after it the rest of the bag keeps its spacing instead of bursting out."""
    s = sink({"/a": PointStamped})
    released = threading.Event()
    with held_player(
        s, make_bag(tmp_path / "b", OFFSETS), lambda: len(s.got) >= 3 and not released.is_set()
    ) as (player, spin):
        spin(lambda: len(s.got) < 3)
        assert len(s.got) == 3
        # held for longer than the rest of the bag lasts: nothing more is published
        spin(lambda: True, limit_s=1.2)
        assert player.played["/a"] == 3 and len(s.got) == 3
        t_release = time.monotonic()
        released.set()
        spin(lambda: len(s.got) < len(OFFSETS))
    assert [d for _, _, d in s.got] == [point(i) for i in range(len(OFFSETS))]
    # the schedule moved by the wait: the last message comes the rest of the bag's time after
    # the release (without the move, every remaining message was overdue and burst out)
    assert s.got[-1][1] - t_release >= 0.9 * (OFFSETS[-1] - OFFSETS[3])


def test_a_hold_that_never_ends_delays_each_message_by_at_most_its_limit(
    ros: None, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A consumer that lost messages never catches up: the player gives up each wait after
    HOLD_MAX_S and plays the bag out."""
    import uav_fusion.nodes.bag_player as bp

    monkeypatch.setattr(bp, "HOLD_MAX_S", 0.1)
    s = sink({"/a": PointStamped})
    holds: list[float] = []

    def hold() -> bool:
        holds.append(time.monotonic())
        return True

    bag = make_bag(tmp_path / "b", [0.0, 0.01, 0.02, 0.03])
    with held_player(s, bag, hold) as (player, spin):
        spin(lambda: len(s.got) < 4 or not player.finished.is_set())
    assert player.played["/a"] == 4 and len(s.got) == 4
    # every message was held back for its limit first
    assert s.got[-1][1] - holds[0] >= 4 * 0.1


@pytest.mark.processes
def test_ctrl_c_stops_cleanly_and_reports_what_was_played(tmp_path: Path) -> None:
    import signal

    bag = make_bag(tmp_path / "b", [0.0, 0.01, 60.0])  # the last message is a minute away
    proc = subprocess.Popen(
        [sys.executable, "-m", "uav_fusion.nodes.bag_player", str(bag),
         "--ros-args", "-p", "wait_for_subscribers:=false"],
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        assert proc.stdout is not None
        head = []
        for line in proc.stdout:  # wait until playback has started
            head.append(line)
            if "playing" in line:
                break
        time.sleep(0.5)  # the first two messages are 10 ms apart, the third a minute later
        proc.send_signal(signal.SIGINT)
        out = "".join(head) + proc.communicate(timeout=30)[0]
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 0, out  # a stop by a signal is a clean stop
    assert "Traceback" not in out
    assert "interrupted" in out and "/a 2" in out


def test_a_recorded_clock_is_replaced_by_the_players(ros: None, tmp_path: Path) -> None:
    w = BagWriter(tmp_path / "b")
    w.add_topic("/a", PS)
    w.add_topic("/clock", "rosgraph_msgs/msg/Clock")
    for i in range(4):
        c = Clock()
        c.clock.sec = 5  # a stale recorded clock, far from the bag's time
        w.write("/clock", T0 + i * 10_000_000, bytes(serialize_message(c)))
        w.write("/a", T0 + i * 10_000_000 + 1, point(i))
    w.close()
    s = sink({"/a": PointStamped}, clock=True)
    player = play(s, tmp_path / "b", 4)
    assert "/clock" in player.skipped
    assert s.clock and all(c >= T0 for c in s.clock)
