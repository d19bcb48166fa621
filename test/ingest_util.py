"""Helpers of the live-ingest tests: a TCP server the test drives line by line, radar lines,
and an in-process harness around one stream node (its outputs and /diagnostics)."""

from __future__ import annotations

import json
import socket
import time
from collections.abc import Callable
from typing import Any

from diagnostic_msgs.msg import DiagnosticArray
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter

from uav_fusion.ros.qos import stream_qos
from uav_fusion.ros.stream import StreamNode

T0 = 1759866140.0  # 2025-10-07T19:42:20Z

#: generous: a loaded 2-core machine must not miss it; the tests wait for events, not this
LIMIT_S = 60.0


def radar_line(t: float, *, track_id: int = 1, alt: float = 150.0, lat: float = 35.7260) -> bytes:
    """One radar frame line (Dataset-28 schema) with one track, ending in a newline."""
    obj = {
        "params": {"globalTime": t},
        "trackData": [
            {
                "id": track_id,
                "lla": [lat, -78.6930, alt],
                "velocityNed": [1.0, 2.0, -0.5],
                "catProb": [0.9, 0.1],
                "range": 400.0,
            }
        ],
    }
    return (json.dumps(obj) + "\n").encode()


class LineServer:
    """A TCP server on 127.0.0.1 (any free port) whose one client the test feeds."""

    def __init__(self) -> None:
        self.sock = socket.create_server(("127.0.0.1", 0))
        self.sock.settimeout(LIMIT_S)
        self.port = int(self.sock.getsockname()[1])
        self.conn: socket.socket | None = None
        self.accepted = 0

    @property
    def url(self) -> str:
        return f"tcp://127.0.0.1:{self.port}"

    def accept(self) -> None:
        """Wait for the client's (next) connection."""
        conn, _ = self.sock.accept()
        self.conn = conn
        self.accepted += 1

    def send(self, data: bytes) -> None:
        assert self.conn is not None
        self.conn.sendall(data)

    def drop(self) -> None:
        """Close the connection (the sensor went away)."""
        assert self.conn is not None
        self.conn.shutdown(socket.SHUT_RDWR)
        self.conn.close()
        self.conn = None

    def close(self) -> None:
        if self.conn is not None:
            self.conn.close()
        self.sock.close()


class StreamHarness:
    """One stream node plus a collector of ``topics`` and ``/diagnostics`` on one executor."""

    def __init__(
        self, ctx: Context, cls: Callable[..., StreamNode], topics: dict[str, type], **params: Any
    ) -> None:
        params.setdefault("diagnostics_period_s", 0.05)
        self.node = cls(
            context=ctx, parameter_overrides=[Parameter(k, value=v) for k, v in params.items()]
        )
        self.io = Node("collector", context=ctx)
        self.got: dict[str, list[Any]] = {t: [] for t in topics}
        qos = stream_qos(10000)
        for topic, typ in topics.items():
            self.io.create_subscription(typ, topic, self.got[topic].append, qos)
        self.diag: list[DiagnosticArray] = []
        self.io.create_subscription(DiagnosticArray, "/diagnostics", self.diag.append, 100)
        self.ex = SingleThreadedExecutor(context=ctx)
        self.ex.add_node(self.node)
        self.ex.add_node(self.io)

    def spin_until(self, cond: Callable[[], bool], limit_s: float = LIMIT_S) -> None:
        end = time.monotonic() + limit_s
        while not cond():
            assert time.monotonic() < end, "condition not reached"
            self.ex.spin_once(timeout_sec=0.02)

    def values(self) -> dict[str, str]:
        """The key/values of the node's latest status on /diagnostics."""
        name = f"{self.node.get_name()}: {self.node.kind} input"
        for arr in reversed(self.diag):
            for st in arr.status:
                if st.name == name:
                    return {kv.key: kv.value for kv in st.values}
        return {}

    def level_message(self) -> tuple[int, str]:
        for arr in reversed(self.diag):
            for st in arr.status:
                if st.name.startswith(self.node.get_name()):
                    return int.from_bytes(st.level, "little") if isinstance(
                        st.level, bytes) else int(st.level), str(st.message)
        return -1, ""

    def settled(self, lines: int) -> dict[str, str]:
        """Spin until /diagnostics reports ``lines`` lines; its values then."""
        self.spin_until(lambda: self.values().get("lines") == str(lines))
        return self.values()

    def close(self) -> None:
        self.node.destroy_node()
        self.io.destroy_node()
