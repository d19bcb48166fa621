"""One live source: transport, line decoder and monitor together (what a stream node wraps).

The transport's thread only frames bytes into lines and queues them with the time they were
read; :meth:`Ingest.take`, called from the node's own thread, decodes the queued lines into
records (:class:`~uav_fusion.core.ingest.decode.StreamDecoder`) and the node publishes them,
then reports back with :meth:`Ingest.published` (the latency sample). ``notify`` is called
from the transport thread whenever lines were queued, so the node can wake up at once
instead of polling. :meth:`Ingest.status` gives the ``/diagnostics`` content: what the
monitor measures, the transport's counters and every dropped line by reason.
"""

from __future__ import annotations

import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass

from uav_fusion.core.ingest.decode import Record, StreamDecoder
from uav_fusion.core.ingest.monitor import SourceMonitor
from uav_fusion.core.ingest.transport import Endpoint, Transport, open_transport
from uav_fusion.core.site import Site

#: what the ``state`` of a working transport starts with
_WORKING = ("connected", "following", "listening")


@dataclass(frozen=True)
class IngestSettings:
    """How a source is read and watched (the stream nodes' parameters)."""

    max_line_bytes: int = 1 << 20
    reconnect_min_s: float = 0.1
    reconnect_max_s: float = 5.0
    idle_timeout_s: float = 0.0
    poll_s: float = 0.01
    start_at_end: bool = False
    clock_offset_warn_s: float = 2.0
    stale_s: float = 0.0
    window_s: float = 10.0


@dataclass(frozen=True)
class Arrival:
    """The records of one line and when the line was read."""

    records: list[Record]
    t_mono: float
    t_wall: float
    line: int


class Ingest:
    """One live source of ``kind`` (radar, rf, truth) at ``endpoint`` (see the module text)."""

    def __init__(
        self,
        kind: str,
        endpoint: Endpoint,
        site: Site,
        settings: IngestSettings | None = None,
        *,
        notify: Callable[[], None] | None = None,
        warn: Callable[[str], None] | None = None,
    ) -> None:
        self.kind = kind
        self.endpoint = endpoint
        self.settings = s = settings or IngestSettings()
        self.decoder = StreamDecoder(kind, site, warn)
        self.monitor = SourceMonitor(
            window_s=s.window_s, clock_offset_warn_s=s.clock_offset_warn_s, stale_s=s.stale_s
        )
        self._queue: deque[tuple[list[bytes], float, float]] = deque()
        self._lock = threading.Lock()
        self._notify = notify
        self._cut_seen = 0
        self._too_long_seen = 0
        self.started = False
        self.transport: Transport = open_transport(
            endpoint,
            self._on_lines,
            max_line_bytes=s.max_line_bytes,
            reconnect_min_s=s.reconnect_min_s,
            reconnect_max_s=s.reconnect_max_s,
            idle_timeout_s=s.idle_timeout_s,
            poll_s=s.poll_s,
            start_at_end=s.start_at_end,
        )

    # --- transport thread ----------------------------------------------------------------
    def _on_lines(self, lines: list[bytes], t_mono: float, t_wall: float) -> None:
        self._queue.append((lines, t_mono, t_wall))
        if self._notify is not None:
            self._notify()

    # --- node thread ---------------------------------------------------------------------
    def start(self) -> None:
        self.started = True
        self.transport.start()

    def close(self) -> None:
        self.transport.close()

    @property
    def queued(self) -> int:
        """Batches of lines read but not yet decoded."""
        return len(self._queue)

    def take(self, max_lines: int = 10000) -> list[Arrival]:
        """Decode what was read so far (at most about ``max_lines`` lines): one
        :class:`Arrival` per line that gave records, in order."""
        self._sync_transport()
        out: list[Arrival] = []
        n = 0
        dec, mon = self.decoder, self.monitor
        while self._queue and n < max_lines:
            lines, t_mono, t_wall = self._queue.popleft()
            for raw in lines:
                n += 1
                mon.line(t_mono)
                recs = dec.decode(raw)
                if recs:
                    for r in recs:
                        mon.record(t_mono, t_wall, r.t)
                    out.append(Arrival(recs, t_mono, t_wall, dec.line))
        return out

    def published(self, arrival: Arrival, messages: int) -> None:
        """The messages of ``arrival`` went out (its latency sample ends now)."""
        self.monitor.published(arrival.t_mono, messages)

    def _sync_transport(self) -> None:
        """Bring the transport's counts of lost lines into the drop counters."""
        st = self.transport.stats
        pol = self.decoder.policy
        cut, too_long = st.cut_lines, self.transport.too_long
        pol.drop("truncated", "an unfinished line was cut off (disconnect, rotation or "
                 "truncation)", cut - self._cut_seen)
        pol.drop("too_long", f"a line longer than {self.settings.max_line_bytes} bytes",
                 too_long - self._too_long_seen)
        self._cut_seen, self._too_long_seen = cut, too_long

    @property
    def dropped(self) -> dict[str, int]:
        self._sync_transport()
        return dict(self.decoder.policy.dropped)

    def status(self, now: float | None = None) -> tuple[bool, str, list[tuple[str, str]]]:
        """(warn, message, key/value pairs) for ``/diagnostics``."""
        now = time.monotonic() if now is None else now
        self._sync_transport()
        st = self.transport.stats
        pol = self.decoder.policy
        state = st.state if self.started else "not reading yet (waiting for subscribers)"
        values: list[tuple[str, str]] = [
            ("source", str(self.endpoint)),
            ("reading", "true" if self.started and self.transport.is_alive() else "false"),
            ("state", state),
        ]
        values += self.monitor.values(now)
        values += [
            ("connects", str(st.connects)),
            ("reconnects", str(st.reconnects)),
            ("disconnects", str(st.disconnects)),
            ("rotations", str(st.rotations)),
            ("truncations", str(st.truncations)),
            ("bytes", str(st.bytes)),
            ("dropped", str(sum(pol.dropped.values()))),
        ]
        values += [(f"dropped_{k}", str(v)) for k, v in sorted(pol.dropped.items())]
        values += [(f"lines_{k}", str(v)) for k, v in sorted(pol.info.items())]
        if self.decoder.kind == "rf":
            values.append(("headers", str(self.decoder.headers)))
        values += [
            ("optional_unreadable", str(pol.optional_unreadable)),
            ("non_utf8", str(self.decoder.non_utf8)),
            ("last_error", st.last_error or "-"),
        ]
        problems = self.monitor.warnings(now)
        if not state.startswith(_WORKING):
            problems.insert(0, state)
        if pol.dropped:
            problems.append(f"{sum(pol.dropped.values())} line(s) dropped")
        if problems:
            return True, "; ".join(problems), values
        return False, f"{state}; {self.monitor.lines} lines", values
