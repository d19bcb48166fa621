"""What the three stream nodes (``radar_stream``, ``rf_stream``, ``truth_stream``) share: the
parameters, the live source (:class:`uav_fusion.core.ingest.stream.Ingest`), waking up as
soon as lines arrive, publishing, and ``/diagnostics``.

The transport reads in its own thread; when lines are queued it triggers a guard condition,
so the executor decodes and publishes them at once (a 0.1 s timer is the safety net). Stamps
are the sensor times the lines carry. Before the transport starts, the node waits up to
``wait_for_subscribers_s`` until its streams have subscribers (DDS drops what is published
before matching; a TCP or file source simply waits, a UDP sender's datagrams would be lost).

A bad ``url`` (unknown scheme, no port, a port out of range or taken, a host that does not
resolve, a file path whose folder does not exist or that is a folder) stops the node with a
message naming the parameter, exit status 2 (:mod:`uav_fusion.ros.app`).
"""

from __future__ import annotations

import contextlib
import time
from collections import Counter
from collections.abc import Sequence
from typing import Any

from diagnostic_msgs.msg import DiagnosticArray
from rclpy.node import Node
from rclpy.publisher import Publisher

from uav_fusion.core.errors import ConfigError
from uav_fusion.core.ingest.decode import Record
from uav_fusion.core.ingest.stream import Ingest, IngestSettings
from uav_fusion.core.ingest.transport import parse_url
from uav_fusion.core.site import load_site
from uav_fusion.ros.app import run_node
from uav_fusion.ros.diagnostics import make_status
from uav_fusion.ros.params import Param, ParamError, declare_all, not_empty
from uav_fusion.ros.qos import DIAGNOSTICS_QOS, stream_qos

#: the emulator's default endpoints (``uav_fusion emulate``), so that both start bare
DEFAULT_URLS = {
    "radar": "tcp://127.0.0.1:5601",
    "rf": "tcp://127.0.0.1:5602",
    "truth": "tcp://127.0.0.1:5603",
}


def stream_params(kind: str, *, clock_offset_warn_s: float, stale_s: float) -> list[Param]:
    """The parameters every stream node declares."""
    return [
        Param(
            "url", DEFAULT_URLS[kind],
            "where the lines come from: tcp://HOST:PORT (connect), udp://HOST:PORT (bind), "
            "file:///path or a path (follow the file)",
            check=not_empty,
        ),
        Param("site_file", "", "site YAML ('' = bundled Lake Wheeler site)"),
        Param("frame_id", "", "ENU frame id of published positions ('' = the site's frame_id)"),
        Param("qos_depth", 1000, "history depth of the reliable streams", lo=1, hi=1000000),
        Param(
            "max_line_bytes", 1 << 20, "a longer line is dropped (counted as too_long)",
            lo=64, hi=1 << 26,
        ),
        Param(
            "reconnect_min_s", 0.1,
            "tcp: wait before reconnecting after a drop; doubled after each failed attempt",
            lo=0.001, hi=3600.0,
        ),
        Param("reconnect_max_s", 5.0, "tcp: longest wait between attempts", lo=0.001,
              hi=3600.0),
        Param(
            "idle_timeout_s", 0.0,
            "tcp: reconnect when the connection is silent this long (0 = never)",
            lo=0.0, hi=86400.0,
        ),
        Param("poll_period_s", 0.01, "file: seconds between looks at a file with nothing new",
              lo=0.001, hi=10.0),
        Param("start_at_end", False, "file: skip what the file already holds when first opened"),
        Param(
            "clock_offset_warn_s", clock_offset_warn_s,
            "warn when the host clock minus the sensor time (least-delayed line of the rate "
            "window) exceeds this in magnitude (0 = never)",
            lo=0.0, hi=1e9, read_only=False,
        ),
        Param(
            "stale_s", stale_s, "warn when no line came for this many seconds (0 = never)",
            lo=0.0, hi=1e9, read_only=False,
        ),
        Param("rate_window_s", 10.0, "wall seconds of the rate and clock-offset window",
              lo=0.1, hi=3600.0),
        Param(
            "diagnostics_period_s", 1.0, "wall seconds between /diagnostics messages",
            lo=0.05, hi=3600.0,
        ),
        Param(
            "wait_for_subscribers_s", 0.0,
            "before reading, wait this long for subscribers of the streams (0 = do not wait)",
            lo=0.0, hi=3600.0,
        ),
    ]


class StreamNode(Node):
    """Base of the stream nodes: subclasses publish the records (:meth:`publish_records`)."""

    def __init__(
        self,
        name: str,
        kind: str,
        *,
        clock_offset_warn_s: float,
        stale_s: float,
        extra: Sequence[Param] = (),
        **kwargs: Any,
    ) -> None:
        super().__init__(name, **kwargs)
        self.kind = kind
        self.p = declare_all(
            self,
            [*stream_params(kind, clock_offset_warn_s=clock_offset_warn_s, stale_s=stale_s),
             *extra],
        )
        p = self.p
        if float(p["reconnect_max_s"]) < float(p["reconnect_min_s"]):
            raise ParamError(
                f"{name}: parameter 'reconnect_max_s' = {p['reconnect_max_s']!r} is below "
                f"reconnect_min_s = {p['reconnect_min_s']!r}"
            )
        self.site = load_site(str(p["site_file"]) or None)
        self.frame_id: str = str(p["frame_id"]) or self.site.frame_id
        self.qos = stream_qos(int(p["qos_depth"]))
        url = str(p["url"])
        settings = IngestSettings(
            max_line_bytes=int(p["max_line_bytes"]),
            reconnect_min_s=float(p["reconnect_min_s"]),
            reconnect_max_s=float(p["reconnect_max_s"]),
            idle_timeout_s=float(p["idle_timeout_s"]),
            poll_s=float(p["poll_period_s"]),
            start_at_end=bool(p["start_at_end"]),
            clock_offset_warn_s=float(p["clock_offset_warn_s"]),
            stale_s=float(p["stale_s"]),
            window_s=float(p["rate_window_s"]),
        )
        self._gc = self.create_guard_condition(self._on_data)
        try:
            endpoint = parse_url(url, what="url")
            self.ingest = Ingest(
                kind, endpoint, self.site, settings, notify=self._wake,
                warn=self.get_logger().warning,
            )
        except ConfigError as exc:
            raise ParamError(f"{name}: parameter 'url' = {url!r}: {exc}") from None
        self.pub_diag = self.create_publisher(DiagnosticArray, "/diagnostics", DIAGNOSTICS_QOS)
        #: messages published per topic (resolved name)
        self.sent: Counter[str] = Counter()
        self.started = False
        self._created = time.monotonic()
        self._poll = self.create_timer(0.1, self._on_poll)
        self._diag_timer = self.create_timer(
            float(p["diagnostics_period_s"]), self.publish_diagnostics
        )
        self.add_on_set_parameters_callback(self._on_params)
        if float(p["wait_for_subscribers_s"]) == 0.0:
            self.start_reading()

    # --- to implement --------------------------------------------------------------------
    def publish_records(self, records: Sequence[Record]) -> int:
        """Publish the records of one line; the number of messages sent."""
        raise NotImplementedError

    def send(self, pub: Publisher, msg: Any) -> int:
        """Publish ``msg`` on ``pub`` and count it; 1."""
        pub.publish(msg)
        self.sent[pub.topic_name] += 1
        return 1

    def stream_groups(self) -> list[tuple[Publisher, ...]]:
        """Groups of publishers of which one needs a subscriber before reading starts (one
        stream in several encodings: radar/pose or radar/tracks)."""
        return []

    # --- running -------------------------------------------------------------------------
    def _wake(self) -> None:
        # the node may be being destroyed (its poll timer is gone too)
        with contextlib.suppress(Exception):
            self._gc.trigger()

    def _subscribers_ready(self) -> bool:
        return all(
            any(p.get_subscription_count() > 0 for p in group) for group in self.stream_groups()
        )

    def _on_poll(self) -> None:
        if not self.started:
            waited = time.monotonic() - self._created
            wait_s = float(self.p["wait_for_subscribers_s"])
            if wait_s > 0 and not self._subscribers_ready():
                if waited < wait_s:
                    return
                self.get_logger().warning(
                    f"no subscriber after {wait_s:g} s; reading {self.ingest.endpoint} anyway"
                )
            self.start_reading()
        self._on_data()

    def start_reading(self) -> None:
        """Start the transport (normally done by the poll timer, see the module text)."""
        if not self.started:
            self.started = True
            self.ingest.start()
            self.get_logger().info(f"reading {self.kind} lines from {self.ingest.endpoint}")

    def _on_data(self) -> None:
        ing = self.ingest
        for arrival in ing.take():
            n = self.publish_records(arrival.records)
            ing.published(arrival, n)

    def drain(self) -> None:
        """Publish what was read but not yet published (at a stop)."""
        while self.ingest.queued:
            self._on_data()

    def _on_params(self, params: list[Any]) -> Any:
        from rcl_interfaces.msg import SetParametersResult

        mon = self.ingest.monitor
        for par in params:
            if par.name == "clock_offset_warn_s":
                mon.clock_offset_warn_s = float(par.value)
            elif par.name == "stale_s":
                mon.stale_s = float(par.value)
        return SetParametersResult(successful=True)

    def status(self) -> Any:
        warn, message, values = self.ingest.status()
        return make_status(f"{self.get_name()}: {self.kind} input", message, values, warn=warn)

    def publish_diagnostics(self) -> None:
        arr = DiagnosticArray()
        arr.header.stamp = self.get_clock().now().to_msg()
        arr.status = [self.status()]
        self.pub_diag.publish(arr)

    def destroy_node(self) -> None:
        ingest = getattr(self, "ingest", None)
        if ingest is not None:
            ingest.close()
        super().destroy_node()


def run_stream(factory: Any, args: Sequence[str] | None, name: str) -> int:
    """``main()`` body of a stream node: spin until stopped; publish what was read, then a
    last ``/diagnostics``, at the stop."""

    def on_stop(node: Node, _executor: Any) -> None:
        assert isinstance(node, StreamNode)
        node.ingest.transport.stop()
        if node.context.ok():
            node.drain()
            node.publish_diagnostics()

    return run_node(factory, args, on_stop=on_stop, name=name)
