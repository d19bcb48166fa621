"""``bag_recorder``: record topics of the live graph into a rosbag2 MCAP bag.

Usage::

    bag_recorder [--ros-args -p output:=my_bag -p topics:="['/radar/pose']" ...]

Subscribes with ``raw=True`` (messages are stored as received, never decoded) to the chosen
topics as soon as they appear in the graph, and writes them with
:class:`uav_fusion.bag.writer.BagWriter`. The stored time of a message is the node clock at
reception (the system clock, or ``/clock`` with ``use_sim_time:=true``).

SIGINT and SIGTERM stop it cleanly: it first takes every message DDS has already delivered
(so everything acknowledged to a publisher is in the bag), then closes the bag and writes
``metadata.yaml``.
"""

from __future__ import annotations

import sys
import threading
import time
from collections import Counter
from collections.abc import Callable, Sequence
from datetime import UTC, datetime
from typing import Any

from rcl_interfaces.msg import ParameterDescriptor, ParameterType
from rclpy.executors import Executor
from rclpy.node import Node

from uav_fusion.bag.writer import BagWriter, WrittenBag
from uav_fusion.core.errors import ConfigError, UavFusionError
from uav_fusion.nodes.bag_player import message_class
from uav_fusion.ros.app import App, UsageError, run_app
from uav_fusion.ros.qos import make_qos, qos_words

#: Topics recorded by default (relative names follow the recorder's namespace; see
#: docs/graph.md).
DEFAULT_TOPICS: tuple[str, ...] = (
    "radar/pose",
    "radar/raw",
    "rf/fix",
    "truth/fix",
    "fusion/odom",
    "fusion/odom/updated",
    "fusion/odom/coasted",
    "fusion/accepted/radar",
    "fusion/accepted/rf",
    "/clock",
    "/diagnostics",
)

#: Never recorded with ``all_topics`` (graph bookkeeping, not data).
_GRAPH_TOPICS = {"/rosout", "/parameter_events"}


def _desc(text: str, kind: int) -> ParameterDescriptor:
    return ParameterDescriptor(description=text, type=kind)


class BagRecorder(Node):
    """Records raw messages of chosen topics; call :meth:`close` to finish the bag."""

    def __init__(self, output: str | None = None, **kwargs: Any) -> None:
        super().__init__("bag_recorder", **kwargs)
        p = self.declare_parameter
        p("output", output or "", _desc(
            "bag directory to create (default rosbag2_YYYY_MM_DD-HH_MM_SS)",
            ParameterType.PARAMETER_STRING))
        p("topics", list(DEFAULT_TOPICS), _desc(
            "topics to record (relative names follow the namespace)",
            ParameterType.PARAMETER_STRING_ARRAY))
        p("all_topics", False, _desc("record every topic that appears (not /rosout, "
                                     "/parameter_events)", ParameterType.PARAMETER_BOOL))
        p("max_bag_size", 0, _desc("split: bytes of messages per file (0: no split)",
                                   ParameterType.PARAMETER_INTEGER))
        p("max_bag_duration", 0.0, _desc("split: seconds per file (0: no split)",
                                         ParameterType.PARAMETER_DOUBLE))
        p("qos_reliability", "", _desc(
            "'reliable', 'best_effort' or '' (best effort only if a publisher offers only that)",
            ParameterType.PARAMETER_STRING))
        p("qos_depth", 0, _desc("subscription history depth (0: keep all, so a reliable "
                                "publisher is slowed down rather than a message lost)",
                                ParameterType.PARAMETER_INTEGER))
        p("flush_period", 1.0, _desc(
            "seconds between forced writes to disk (0: only when 1 MiB is buffered); bounds "
            "what a killed recorder loses", ParameterType.PARAMETER_DOUBLE))
        p("discovery_period", 0.2, _desc("seconds between looks for new topics",
                                         ParameterType.PARAMETER_DOUBLE))
        g = self.get_parameter
        out = str(g("output").value) or datetime.now(UTC).strftime("rosbag2_%Y_%m_%d-%H_%M_%S")
        self.all_topics = bool(g("all_topics").value)
        self.wanted = {self.resolve_topic_name(str(t)) for t in g("topics").value or [] if t}
        if not self.wanted and not self.all_topics:
            raise ConfigError("bag_recorder: no topics to record (set topics or all_topics)")
        self.reliability = str(g("qos_reliability").value).strip().lower()
        if self.reliability not in {"", "reliable", "best_effort"}:
            raise ConfigError(f"bag_recorder: qos_reliability '{self.reliability}' is not "
                              "'reliable', 'best_effort' or ''")
        self.depth = int(g("qos_depth").value)
        if self.depth < 0:
            raise ConfigError(f"bag_recorder: qos_depth must be >= 0, got {self.depth}")
        self.writer = BagWriter(
            out,
            max_bytes=int(g("max_bag_size").value),
            max_duration_s=float(g("max_bag_duration").value),
        )
        self.received: Counter[str] = Counter()
        self._subscribed: set[str] = set()
        self._refused: set[str] = set()
        self._lock = threading.Lock()
        self._closed: WrittenBag | None = None
        self.get_logger().info(
            f"recording into {self.writer.path}: "
            + ("all topics" if self.all_topics else ", ".join(sorted(self.wanted))))
        self._discover()
        self._timer = self.create_timer(float(g("discovery_period").value), self._discover)
        flush = float(g("flush_period").value)
        self._flush_timer = self.create_timer(flush, self._flush) if flush > 0 else None

    @property
    def path(self) -> str:
        return str(self.writer.path)

    def _discover(self) -> None:
        for name, types in self.get_topic_names_and_types():
            if name in self._subscribed or name in self._refused:
                continue
            if not (name in self.wanted or (self.all_topics and name not in _GRAPH_TOPICS)):
                continue
            if len(types) != 1:
                self._refuse(name, f"{len(types)} types on one topic: {', '.join(types)}")
                continue
            msgtype = types[0]
            cls = message_class(msgtype)
            if cls is None:
                self._refuse(name, f"message type {msgtype} is not installed")
                continue
            pubs = self.get_publishers_info_by_topic(name)
            offered = [qos_words(i.qos_profile) for i in pubs]
            rel = self.reliability or (
                "best_effort" if offered and all(o["reliability"] == "best_effort"
                                                 for o in offered) else "reliable")
            durable = bool(offered) and all(o["durability"] == "transient_local" for o in offered)
            qos = make_qos(
                reliable=rel != "best_effort", transient_local=durable,
                depth=self.depth or 1000, keep_all=not self.depth,
            )
            try:
                self.writer.add_topic(name, msgtype, qos=offered)
            except UavFusionError as exc:
                self._refuse(name, str(exc))
                continue
            self.create_subscription(cls, name, self._callback(name), qos, raw=True)
            self._subscribed.add(name)
            self.get_logger().info(f"subscribed to {name} [{msgtype}]")

    def _flush(self) -> None:
        with self._lock:
            if self._closed is None:
                self.writer.flush()

    def _refuse(self, name: str, why: str) -> None:
        self._refused.add(name)
        self.get_logger().warning(f"not recording {name}: {why}")

    def _callback(self, topic: str) -> Callable[[bytes], None]:
        def on_message(data: bytes) -> None:
            self._on_message(topic, data)

        return on_message

    def _on_message(self, topic: str, data: bytes) -> None:
        with self._lock:
            if self._closed is not None:
                return
            self.writer.write(topic, self.get_clock().now().nanoseconds, data)
            self.received[topic] += 1

    def close(self) -> WrittenBag:
        """Close the bag (idempotent) and log what it holds."""
        with self._lock:
            if self._closed is None:
                self._closed = self.writer.close()
                per_topic = ", ".join(f"{t} {n}" for t, n in sorted(self.received.items()))
                self.get_logger().info(
                    f"recorded {self._closed.message_count} messages into {self.writer.path} "
                    f"({len(self._closed.files)} file(s)): {per_topic or 'nothing'}")
            return self._closed


def drain(executor: Executor, recorder: BagRecorder, quiet_s: float = 0.3) -> None:
    """Take messages already delivered until none has arrived for ``quiet_s``."""
    last = -1
    quiet_since = time.monotonic()
    while time.monotonic() - quiet_since < quiet_s:
        executor.spin_once(timeout_sec=0.05)
        total = sum(recorder.received.values())
        if total != last:
            last = total
            quiet_since = time.monotonic()


def main(argv: Sequence[str] | None = None) -> int:
    """Console entry point: ``bag_recorder [OUTPUT] [--ros-args ...]``."""

    def build(plain: list[str]) -> App:
        if len(plain) > 1 or any(a.startswith("-") for a in plain):
            raise UsageError("bag_recorder [OUTPUT] [--ros-args -p name:=value ...]")
        recorder = BagRecorder(plain[0] if plain else None)

        def on_stop(executor: Executor | None) -> None:
            try:
                if executor is not None and recorder.context.ok():
                    drain(executor, recorder)
            finally:
                recorder.close()

        return App("bag_recorder", [recorder], on_stop=on_stop)

    return run_app("bag_recorder", build, argv)


if __name__ == "__main__":
    sys.exit(main())
