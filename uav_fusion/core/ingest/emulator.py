"""The sensor emulator: a flight folder written out line by line as the sensors would, at
real time or faster, into files, to TCP clients or as UDP datagrams.

Each source's lines (radar JSON Lines, the RF server's CSV with its header, the truth log)
are sent unchanged, in file order, at their sensor time divided by ``rate`` after the start,
plus a per-source delay and jitter: ``due = sensor time + delay + U(-jitter, +jitter)`` in
sensor seconds (seeded), never before the sensor time and never before the source's previous
line (a stream keeps its order), so RF can arrive seconds late as from a TDOA server. A line
without a time of its own (the RF header, radar status lines, lines the decoder refuses) goes
with the next timed line of its source. The sensor time of a line is what the stream nodes'
decoder reads from it (:class:`~uav_fusion.core.ingest.decode.StreamDecoder`).

Outputs (:func:`open_sink`): ``file:PATH`` (created; appended to and flushed line by line),
``tcp://HOST:PORT`` (a server: every connected client gets every line; while none is
connected, lines are kept and sent to the next client, so a client that reconnects loses
nothing), ``udp://HOST:PORT`` (one datagram per line, sent there).

The arrival schedule (:func:`write_schedule`, CSV) records every line sent:
``source,line,sensor_t,due_t,sent_unix,sent_mono`` -- the source, its 1-based line in the
file, its sensor time (UTC s; empty for an untimed line), when it was due on the sensor
clock (UTC s, rate-independent: sensor time + delay + jitter), and when it was actually
written (``time.time()`` and ``time.monotonic()``, the latter comparable between processes
of one Linux host).
"""

from __future__ import annotations

import contextlib
import csv
import math
import select
import socket
import threading
import time
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Protocol

import numpy as np

from uav_fusion.core.errors import ConfigError
from uav_fusion.core.ingest.decode import KINDS, StreamDecoder
from uav_fusion.core.ingest.transport import Endpoint, parse_url
from uav_fusion.core.site import Site

SCHEDULE_COLUMNS = ("source", "line", "sensor_t", "due_t", "sent_unix", "sent_mono")
SOURCE_RANK = {k: i for i, k in enumerate(KINDS)}


@dataclass(frozen=True)
class SensorLine:
    """One line of a sensor file (with its line end) and the sensor time it carries."""

    source: str
    line: int
    sensor_t: float | None
    data: bytes


@dataclass(frozen=True, order=True)
class Send:
    """One line to write: when (``due``, sensor clock), and what."""

    due: float
    rank: int
    line: int
    source: str = field(compare=False)
    sensor_t: float | None = field(compare=False)
    data: bytes = field(compare=False, repr=False)


def read_sensor_lines(path: str | Path, kind: str, site: Site) -> list[SensorLine]:
    """The lines of one sensor file with the sensor time each carries (None: none)."""
    data = Path(path).read_bytes()
    parts = data.split(b"\n")
    if parts and parts[-1] == b"":
        parts.pop()
    dec = StreamDecoder(kind, site)
    out: list[SensorLine] = []
    for k, raw in enumerate(parts, 1):
        line = raw[3:] if k == 1 and raw.startswith(b"\xef\xbb\xbf") else raw
        recs = dec.decode(line.rstrip(b"\r"))
        out.append(SensorLine(kind, k, recs[0].t if recs else None, raw + b"\n"))
    return out


def plan(
    lines: Mapping[str, Sequence[SensorLine]],
    *,
    delay_s: Mapping[str, float] | None = None,
    jitter_s: Mapping[str, float] | None = None,
    seed: int = 0,
    start_s: float = 0.0,
    duration_s: float | None = None,
) -> list[Send]:
    """Every line to send, in sending order (see the module text). ``start_s`` and
    ``duration_s`` cut a segment of the flight (sensor seconds from its first timed line);
    the RF header is always sent first."""
    delay_s = delay_s or {}
    jitter_s = jitter_s or {}
    times = [ln.sensor_t for ls in lines.values() for ln in ls if ln.sensor_t is not None]
    if not times:
        return []
    t_first = min(times)
    lo = t_first + start_s
    hi = math.inf if duration_s is None else lo + duration_s
    out: list[Send] = []
    for source, ls in lines.items():
        if source not in SOURCE_RANK:
            raise ValueError(f"unknown source {source!r}")
        rng = np.random.default_rng([seed, SOURCE_RANK[source]])
        delay = float(delay_s.get(source, 0.0))
        jitter = float(jitter_s.get(source, 0.0))
        # the timed lines of the segment: their due times
        dues: list[float | None] = [None] * len(ls)
        prev = -math.inf
        for i, ln in enumerate(ls):
            if ln.sensor_t is None or not lo <= ln.sensor_t <= hi:
                continue
            j = float(rng.uniform(-jitter, jitter)) if jitter > 0 else 0.0
            prev = max(prev, ln.sensor_t, ln.sensor_t + delay + j)
            dues[i] = prev
        kept_dues = [d for d in dues if d is not None]
        if not kept_dues:
            continue
        # an untimed line goes with the next timed line of its source (the last one's, at the
        # end); the RF header with the first row sent
        nxt: float | None = None
        timed_after = [False] * len(ls)
        for i in range(len(ls) - 1, -1, -1):
            if ls[i].sensor_t is not None:
                nxt = dues[i]
            elif nxt is not None or (i + 1 < len(ls) and timed_after[i + 1]):
                dues[i] = nxt
            timed_after[i] = ls[i].sensor_t is not None or (
                i + 1 < len(ls) and timed_after[i + 1]
            )
        last: float | None = None
        for i, ln in enumerate(ls):
            if ln.sensor_t is not None:
                last = dues[i]
            elif not timed_after[i]:
                dues[i] = last
        if source == "rf" and ls[0].sensor_t is None:
            dues[0] = kept_dues[0]
        for ln, d in zip(ls, dues, strict=True):
            if d is not None:
                out.append(Send(d, SOURCE_RANK[source], ln.line, source, ln.sensor_t, ln.data))
    out.sort()
    return out


# --- where lines go -------------------------------------------------------------------------


class Sink(Protocol):
    name: str
    lines: int

    def ready(self) -> bool: ...

    def write(self, data: bytes) -> None: ...

    def close(self) -> None: ...


class FileSink:
    """Writes lines into a new file, flushed line by line."""

    def __init__(self, path: str | Path, *, overwrite: bool = False) -> None:
        self.path = Path(path)
        self.name = f"file://{self.path}"
        if not self.path.parent.is_dir():
            raise ConfigError(f"{self.path}: folder {self.path.parent} does not exist")
        if self.path.exists() and not overwrite:
            raise ConfigError(f"{self.path}: exists already (use --overwrite)")
        self._f: IO[bytes] = self.path.open("wb")
        self.lines = 0

    def ready(self) -> bool:
        return True

    def write(self, data: bytes) -> None:
        self._f.write(data)
        self._f.flush()
        self.lines += 1

    def close(self) -> None:
        self._f.close()


class TcpServerSink:
    """A TCP server: every connected client gets every line; with none connected, lines are
    kept and go to the next client that connects (see the module text)."""

    def __init__(self, host: str, port: int, *, send_timeout_s: float = 10.0) -> None:
        try:
            self.server = socket.create_server((host or "0.0.0.0", port))
        except OSError as exc:
            raise ConfigError(f"tcp://{host}:{port}: cannot listen ({exc.strerror or exc})") \
                from None
        self.server.settimeout(0.1)
        self.port = int(self.server.getsockname()[1])
        self.name = f"tcp://{host}:{self.port}"
        self.send_timeout_s = send_timeout_s
        self.clients: list[socket.socket] = []
        self.backlog: list[bytes] = []
        self.accepted = 0
        self.lines = 0
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._accept, name=self.name, daemon=True)
        self._thread.start()

    def _accept(self) -> None:
        while not self._stop.is_set():
            try:
                conn, _ = self.server.accept()
            except TimeoutError:
                continue
            except OSError:
                break
            conn.settimeout(self.send_timeout_s)
            conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            with self._lock:
                try:
                    for data in self.backlog:
                        conn.sendall(data)
                except OSError:
                    conn.close()
                    continue
                self.backlog.clear()
                self.clients.append(conn)
                self.accepted += 1

    def ready(self) -> bool:
        with self._lock:
            return bool(self.clients)

    def write(self, data: bytes) -> None:
        with self._lock:
            self.lines += 1
            for c in list(self.clients):
                if _closed(c):
                    self._drop(c)
                    continue
                try:
                    c.sendall(data)
                except OSError:
                    self._drop(c)
            if not self.clients:
                self.backlog.append(data)

    def _drop(self, c: socket.socket) -> None:
        self.clients.remove(c)
        c.close()

    def close(self) -> None:
        self._stop.set()
        self._thread.join(2.0)
        with self._lock:
            for c in self.clients:
                c.close()
            self.clients.clear()
        self.server.close()


def _closed(c: socket.socket) -> bool:
    """Has the peer closed (readable with nothing to read)?"""
    try:
        readable, _, _ = select.select([c], [], [], 0)
        if not readable:
            return False
        return c.recv(1, socket.MSG_PEEK | socket.MSG_DONTWAIT) == b""
    except (OSError, ValueError):
        return True


class UdpSink:
    """Sends every line as one datagram to ``host:port``."""

    MAX = 65507

    def __init__(self, host: str, port: int) -> None:
        if port == 0:
            raise ConfigError(f"udp://{host}:{port}: the emulator sends to a port; give one")
        self.addr = (host or "127.0.0.1", port)
        self.name = f"udp://{self.addr[0]}:{port}"
        self.sock = socket.socket(socket.AF_INET6 if ":" in self.addr[0] else socket.AF_INET,
                                  socket.SOCK_DGRAM)
        self.lines = 0
        self.too_long = 0

    def ready(self) -> bool:
        return True

    def write(self, data: bytes) -> None:
        if len(data) > self.MAX:
            self.too_long += 1
            return
        # nobody listening (ICMP refused): the datagram is gone, as on a network
        with contextlib.suppress(OSError):
            self.sock.sendto(data, self.addr)
        self.lines += 1

    def close(self) -> None:
        self.sock.close()


def open_sink(url: str | Endpoint, *, overwrite: bool = False, what: str = "url") -> Sink:
    """The sink for ``url`` (see the module text); ConfigError naming ``what`` if bad."""
    ep = url if isinstance(url, Endpoint) else parse_url(url, what=what)
    if ep.scheme == "file":
        return FileSink(ep.path, overwrite=overwrite)
    if ep.scheme == "tcp":
        return TcpServerSink(ep.host, ep.port)
    return UdpSink(ep.host, ep.port)


# --- running --------------------------------------------------------------------------------


@dataclass
class EmulationResult:
    """What a run sent."""

    sent: dict[str, int]
    wall_s: float
    #: how late lines were written against their due time (wall seconds): p50, max
    lag_p50_s: float
    lag_max_s: float
    stopped: bool


class Emulator:
    """Sends a :func:`plan` through one sink per source at ``rate`` (0: as fast as the sinks
    take them), after waiting up to ``wait_s`` for every TCP sink to have a client."""

    def __init__(
        self,
        sends: Sequence[Send],
        sinks: Mapping[str, Sink],
        *,
        rate: float = 1.0,
        wait_s: float = 30.0,
        on_send: Callable[[Send, float, float], None] | None = None,
        log: Callable[[str], None] | None = None,
    ) -> None:
        if rate < 0 or not math.isfinite(rate):
            raise ConfigError(f"rate must be >= 0, got {rate}")
        missing = {s.source for s in sends} - set(sinks)
        if missing:
            raise ConfigError(f"no output for source(s) {', '.join(sorted(missing))}")
        self.sends = list(sends)
        self.sinks = dict(sinks)
        self.rate = rate
        self.wait_s = wait_s
        self.on_send = on_send
        self.log = log or (lambda _text: None)
        self.rows: list[tuple[str, int, float | None, float, float, float]] = []

    def wait_ready(self, stop: threading.Event) -> bool:
        """Wait for the sinks' clients; False if some have none after ``wait_s``."""
        end = time.monotonic() + self.wait_s
        while not all(s.ready() for s in self.sinks.values()):
            if time.monotonic() > end or stop.is_set():
                return False
            stop.wait(0.01)
        return True

    def run(self, stop: threading.Event | None = None) -> EmulationResult:
        stop = stop or threading.Event()
        if not self.wait_ready(stop):
            waiting = [s.name for s in self.sinks.values() if not s.ready()]
            self.log(f"no client after {self.wait_s:g} s on {', '.join(waiting)}; sending "
                     "anyway (lines are kept for the first client)")
        sent = dict.fromkeys(self.sinks, 0)
        lags: list[float] = []
        t0 = self.sends[0].due if self.sends else 0.0
        wall0 = time.monotonic()
        for s in self.sends:
            if stop.is_set():
                break
            if self.rate > 0:
                target = wall0 + (s.due - t0) / self.rate
                dt = target - time.monotonic()
                if dt > 0 and stop.wait(dt):
                    break
                lags.append(max(0.0, time.monotonic() - target))
            self.sinks[s.source].write(s.data)
            t_mono, t_unix = time.monotonic(), time.time()
            sent[s.source] += 1
            self.rows.append((s.source, s.line, s.sensor_t, s.due, t_unix, t_mono))
            if self.on_send is not None:
                self.on_send(s, t_mono, t_unix)
        wall = time.monotonic() - wall0
        lags.sort()
        return EmulationResult(
            sent=sent,
            wall_s=wall,
            lag_p50_s=lags[len(lags) // 2] if lags else 0.0,
            lag_max_s=lags[-1] if lags else 0.0,
            stopped=stop.is_set(),
        )

    def close(self) -> None:
        for s in self.sinks.values():
            s.close()


def write_schedule(
    path: str | Path, rows: Iterable[tuple[str, int, float | None, float, float, float]]
) -> None:
    """The arrival schedule as CSV (columns :data:`SCHEDULE_COLUMNS`; floats exact)."""
    with Path(path).open("w", newline="", encoding="utf-8") as f:
        w = csv.writer(f)
        w.writerow(SCHEDULE_COLUMNS)
        for source, line, t, due, unix, mono in rows:
            w.writerow([source, line, "" if t is None else repr(t), repr(due), repr(unix),
                        repr(mono)])


def read_schedule(path: str | Path) -> list[tuple[str, int, float | None, float, float, float]]:
    """The rows :func:`write_schedule` wrote."""
    out = []
    with Path(path).open(newline="", encoding="utf-8") as f:
        r = csv.reader(f)
        head = next(r, None)
        if head is None or tuple(head) != SCHEDULE_COLUMNS:
            raise ConfigError(f"{path}: not an arrival schedule (header {head})")
        for row in r:
            out.append((row[0], int(row[1]), float(row[2]) if row[2] else None,
                        float(row[3]), float(row[4]), float(row[5])))
    return out
