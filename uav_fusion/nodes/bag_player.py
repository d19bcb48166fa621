"""``bag_player``: play a rosbag2 bag into the live graph with its recorded timing.

Usage::

    bag_player BAG [--ros-args -p rate:=10.0 -p topics:="['/uav_fusion/radar/pose']" ...]

``BAG`` is a bag directory, a bare ``.mcap`` or a bare ``.db3`` (or parameter ``bag``).
Messages are published as the raw CDR bytes stored in the bag (never decoded); a topic whose
message type is not installed here cannot be published by rclpy and is skipped with a warning.
``/clock`` carries the bag's receive times, so nodes with ``use_sim_time`` follow the bag.
"""

from __future__ import annotations

import importlib
import sys
import threading
import time
from collections import Counter
from collections.abc import Callable, Sequence
from typing import Any

import rclpy
from rcl_interfaces.msg import ParameterDescriptor, ParameterType
from rclpy.node import Node
from rclpy.publisher import Publisher
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock

from uav_fusion.bag.reader import BagReader, BagTopic, qos_reliability, qos_transient_local
from uav_fusion.core.errors import ConfigError, UavFusionError
from uav_fusion.ros.app import EXIT_FAILED, EXIT_OK, App, UsageError, run_app
from uav_fusion.ros.qos import CLOCK_QOS, make_qos


def message_class(msgtype: str) -> Any:
    """The installed Python class of ``pkg/msg/Name``, or None when not installed."""
    pkg, _, name = msgtype.partition("/msg/")
    if not name:
        return None
    try:
        return getattr(importlib.import_module(f"{pkg}.msg"), name, None)
    except ImportError:
        return None


def _abs(topic: str) -> str:
    return topic if topic.startswith("/") else "/" + topic


def _parse_remap(items: Sequence[Any]) -> dict[str, str]:
    """The ``remap`` parameter's ``from:=to`` entries (empty ones skipped), topic names
    made absolute."""
    remap: dict[str, str] = {}
    for item in items:
        if not item:
            continue
        src, sep, dst = str(item).partition(":=")
        if not sep or not src or not dst:
            raise ConfigError(f"bag_player: remap entry '{item}' is not 'from:=to'")
        remap[_abs(src.strip())] = _abs(dst.strip())
    return remap


def _desc(text: str, kind: int) -> ParameterDescriptor:
    return ParameterDescriptor(description=text, type=kind)


#: The longest one wait for :attr:`BagPlayer.hold` lasts (s).
HOLD_MAX_S = 5.0


class BagPlayer(Node):
    """Publishes a bag's messages with recorded spacing divided by ``rate``.

    Construct, then :meth:`start` (a playback thread) and spin the node; :attr:`finished` is set
    when playback ends. :attr:`played` counts published messages per output topic.
    """

    def __init__(self, bag: str | None = None, **kwargs: Any) -> None:
        super().__init__("bag_player", **kwargs)
        self._declare_parameters(bag)
        g = self.get_parameter
        path = str(g("bag").value)
        if not path:
            raise ConfigError("bag_player: no bag given (positional path or -p bag:=PATH)")
        self.rate = float(g("rate").value)
        if not self.rate > 0:
            raise ConfigError(f"bag_player: rate must be > 0, got {self.rate}")
        self.loop = bool(g("loop").value)
        self.loop_count = int(g("loop_count").value)
        self.wait_for_subs = bool(g("wait_for_subscribers").value)
        self.wait_timeout = float(g("wait_timeout").value)
        self.clock_hz = float(g("clock_hz").value)
        depth = int(g("qos_depth").value)
        if depth < 1:
            raise ConfigError(f"bag_player: qos_depth must be >= 1, got {depth}")
        reliability = str(g("qos_reliability").value).strip().lower()
        if reliability not in {"", "reliable", "best_effort"}:
            raise ConfigError(f"bag_player: qos_reliability '{reliability}' is not "
                              "'reliable', 'best_effort' or ''")
        remap = _parse_remap(g("remap").value or [])
        wanted = {_abs(str(t)) for t in (g("topics").value or []) if t}

        self.reader = BagReader(path)
        for w in self.reader.warnings:
            self.get_logger().warning(w)
        unknown = wanted - {_abs(t) for t in self.reader.topics}
        if unknown:
            raise ConfigError(f"bag_player: topics not in {path}: {', '.join(sorted(unknown))}")

        self.skipped: dict[str, str] = {}
        self._pubs: dict[str, Publisher] = {}  # bag topic name -> publisher
        self._out: dict[str, str] = {}  # bag topic name -> output topic
        publish_clock = bool(g("publish_clock").value)
        self._open_publishers(wanted, remap, publish_clock, reliability, depth)
        if not self._pubs:
            raise UavFusionError(f"bag_player: nothing to play in {path}"
                                 + (f" ({'; '.join(self.skipped.values())})" if self.skipped
                                    else ""))
        self._clock_pub = (
            self.create_publisher(Clock, "/clock", CLOCK_QOS)
            if publish_clock else None
        )
        start = self.reader.start_ns + int(float(g("start_offset").value) * 1e9)
        dur = float(g("duration").value)
        self.start_ns = start
        self.end_ns = start + int(dur * 1e9) if dur > 0 else None
        self.played: Counter[str] = Counter()
        #: set by an in-process owner: while it returns True the player waits before the next
        #: message (its consumers have fallen behind; the bag's spacing resumes after the
        #: wait), at most HOLD_MAX_S at a time (a consumer that lost messages never catches up)
        self.hold: Callable[[], bool] | None = None
        self.passes = 0
        self.finished = threading.Event()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.error: str | None = None
        self.ack_wait_s = 0.0
        self.summary = ""
        self._t_begin = 0.0
        self._last_clock: int | None = None

    def _declare_parameters(self, bag: str | None) -> None:
        p = self.declare_parameter
        p("bag", bag or "", _desc("bag directory, .mcap or .db3", ParameterType.PARAMETER_STRING))
        p("rate", 1.0, _desc("playback speed factor (> 0)", ParameterType.PARAMETER_DOUBLE))
        p("topics", [""],
          _desc("bag topics to play (empty: all)", ParameterType.PARAMETER_STRING_ARRAY))
        p("remap", [""], _desc("output renames, each 'from:=to'",
                               ParameterType.PARAMETER_STRING_ARRAY))
        p("start_offset", 0.0, _desc("seconds of bag time to skip", ParameterType.PARAMETER_DOUBLE))
        p("duration", 0.0, _desc("seconds of bag time to play (0: to the end)",
                                 ParameterType.PARAMETER_DOUBLE))
        p("loop", False, _desc("replay from the start when done", ParameterType.PARAMETER_BOOL))
        p("loop_count", 0, _desc("passes when looping (0: until stopped)",
                                 ParameterType.PARAMETER_INTEGER))
        p("wait_for_subscribers", True, _desc(
            "before starting, wait until every played topic has a subscriber",
            ParameterType.PARAMETER_BOOL))
        p("wait_timeout", 10.0, _desc("seconds to wait for subscribers, then play anyway",
                                      ParameterType.PARAMETER_DOUBLE))
        p("qos_reliability", "", _desc("'reliable', 'best_effort' or '' (as recorded)",
                                       ParameterType.PARAMETER_STRING))
        p("qos_depth", 1000, _desc("publisher history depth", ParameterType.PARAMETER_INTEGER))
        p("publish_clock", True, _desc("publish /clock with bag time",
                                       ParameterType.PARAMETER_BOOL))
        p("clock_hz", 50.0, _desc("/clock rate between messages (0: only at messages)",
                                  ParameterType.PARAMETER_DOUBLE))

    def _open_publishers(
        self,
        wanted: set[str],
        remap: dict[str, str],
        publish_clock: bool,
        reliability: str,
        depth: int,
    ) -> None:
        """A publisher per played topic (``wanted``, or every topic with messages); the
        others that cannot be played are listed in :attr:`skipped`, with the reason."""
        for t in self.reader.topics.values():
            if wanted and _abs(t.name) not in wanted:
                continue
            if t.count == 0:
                continue
            if publish_clock and _abs(t.name) == "/clock":
                # two /clock sources would fight; the player's own follows the bag anyway
                self.skipped[t.name] = "recorded /clock replaced by the player's (publish_clock)"
                continue
            if t.serialization_format != "cdr":
                self.skipped[t.name] = f"serialization '{t.serialization_format}' is not cdr"
                continue
            cls = message_class(t.msgtype)
            if cls is None:
                self.skipped[t.name] = f"message type {t.msgtype or '?'} is not installed"
                continue
            out = remap.get(_abs(t.name), _abs(t.name))
            self._pubs[t.name] = self.create_publisher(cls, out, self._qos(t, reliability, depth))
            self._out[t.name] = out
        for name, why in self.skipped.items():
            self.get_logger().warning(
                f"skipping {name} ({self.reader.topics[name].count} messages): {why}")

    @staticmethod
    def _qos(topic: BagTopic, reliability: str, depth: int) -> QoSProfile:
        rel = reliability or qos_reliability(topic.offered_qos) or "reliable"
        return make_qos(
            reliable=rel != "best_effort",
            transient_local=qos_transient_local(topic.offered_qos),
            depth=depth,
        )

    # -- control -----------------------------------------------------------------------------

    def start(self) -> None:
        """Start playback in a background thread."""
        self._thread = threading.Thread(target=self._run, name="bag_player", daemon=True)
        self._thread.start()

    def stop(self, timeout: float = 5.0) -> None:
        """Ask playback to stop and wait for the thread."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout)

    def _run(self) -> None:
        try:
            self._play()
        except Exception as exc:
            if self.context.ok() and not self._stop.is_set():
                self.error = f"{type(exc).__name__}: {exc}"
            else:  # shut down under us (Ctrl-C): report what was played
                self._stop.set()
                self._make_summary()
        finally:
            self.finished.set()

    def _wait_for_subscribers(self) -> None:
        deadline = time.monotonic() + self.wait_timeout
        while not self._stop.is_set():
            lonely = [
                self._out[n] for n, p in self._pubs.items() if p.get_subscription_count() == 0
            ]
            if not lonely:
                return
            if time.monotonic() >= deadline:
                self.get_logger().warning(
                    f"no subscriber after {self.wait_timeout:.1f} s on: {', '.join(lonely)}; "
                    "playing anyway")
                return
            time.sleep(0.02)

    def _make_summary(self) -> bool:
        """Set :attr:`summary`; returns whether playback was interrupted."""
        wall = time.monotonic() - self._t_begin if self._t_begin else 0.0
        interrupted = self._stop.is_set()
        per_topic = ", ".join(f"{t} {n}" for t, n in sorted(self.played.items()))
        skipped = "; skipped " + ", ".join(
            f"{t} ({self.reader.topics[t].count}: {why})" for t, why in self.skipped.items()
        ) if self.skipped else ""
        self.summary = (
            f"played {sum(self.played.values())} messages in {wall:.2f} s at rate {self.rate:g}"
            f" ({self.passes} pass{'es' if self.passes != 1 else ''}"
            f"{', interrupted' if interrupted else ''}): {per_topic or 'nothing'}{skipped}"
        )
        return interrupted

    def _publish_clock(self, stamp_ns: int) -> None:
        if self._clock_pub is not None and stamp_ns != self._last_clock:
            self._last_clock = stamp_ns
            msg = Clock()
            msg.clock.sec, msg.clock.nanosec = divmod(int(stamp_ns), 1_000_000_000)
            self._clock_pub.publish(msg)

    def _play(self) -> None:
        if self.wait_for_subs:
            self._wait_for_subscribers()
        topics = list(self._pubs)
        self.get_logger().info(
            f"playing {self.reader.path} at rate {self.rate:g}: "
            + ", ".join(f"{self._out[t]} {self.reader.topics[t].count}" for t in topics))
        self._t_begin = time.monotonic()
        tick = 1.0 / self.clock_hz if self.clock_hz > 0 else None
        while not self._stop.is_set():
            wall0 = time.monotonic()
            bag0: int | None = None
            for msg in self.reader.messages(topics, self.start_ns, self.end_ns):
                if self._stop.is_set():
                    break
                if bag0 is None:
                    bag0 = msg.timestamp_ns
                target = wall0 + (msg.timestamp_ns - bag0) / 1e9 / self.rate
                while True:
                    now = time.monotonic()
                    if now >= target or self._stop.is_set():
                        break
                    if tick is None:
                        time.sleep(target - now)
                        continue
                    time.sleep(min(target - now, tick))
                    now = time.monotonic()
                    if now < target:
                        self._publish_clock(bag0 + int((now - wall0) * self.rate * 1e9))
                if self._stop.is_set():
                    break  # stopped while waiting: this message is not due yet
                hold = self.hold
                if hold is not None and hold():
                    t_hold = time.monotonic()
                    give_up = t_hold + HOLD_MAX_S
                    while hold() and not self._stop.is_set() and time.monotonic() < give_up:
                        time.sleep(0.005)
                    wall0 += time.monotonic() - t_hold  # the schedule moves by the wait
                    if self._stop.is_set():
                        break
                self._publish_clock(msg.timestamp_ns)
                self._pubs[msg.topic].publish(msg.data)
                self.played[self._out[msg.topic]] += 1
            self.passes += 1
            if not self.loop or (self.loop_count and self.passes >= self.loop_count):
                break
        interrupted = self._make_summary()
        if interrupted:
            return  # main() reports
        t_ack = time.monotonic()
        unacked = [
            self._out[n] for n, pub in self._pubs.items()
            if pub.qos_profile.reliability == ReliabilityPolicy.RELIABLE
            and not pub.wait_for_all_acked(rclpy.duration.Duration(seconds=5.0))
        ]
        if unacked:
            self.get_logger().warning(
                f"not acknowledged by every subscriber within 5 s: {', '.join(unacked)}")
        self.ack_wait_s = time.monotonic() - t_ack
        self.get_logger().info(self.summary)


def main(argv: Sequence[str] | None = None) -> int:
    """Console entry point: ``bag_player [BAG] [--ros-args ...]``; exit 0 when the bag was
    played or playback was stopped by SIGINT/SIGTERM, 1 when playback failed."""

    def build(plain: list[str]) -> App:
        if len(plain) > 1 or any(a.startswith("-") for a in plain):
            raise UsageError("bag_player [BAG] [--ros-args -p name:=value ...]")
        node = BagPlayer(plain[0] if plain else None)

        def on_stop(_executor: Any) -> None:
            interrupted = not node.finished.is_set()
            node.stop()
            if interrupted and node.summary:
                print(f"bag_player: {node.summary}", file=sys.stderr)

        def status() -> int:
            if node.error:
                print(f"bag_player: error: {node.error}", file=sys.stderr)
                return EXIT_FAILED
            return EXIT_OK

        return App("bag_player", [node], start=node.start, finished=node.finished.is_set,
                   on_stop=on_stop, status=status)

    return run_app("bag_player", build, argv)


if __name__ == "__main__":
    sys.exit(main())
