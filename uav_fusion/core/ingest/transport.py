"""Where live lines come from: a TCP connection (client, reconnecting with backoff), UDP
datagrams, or a file that grows (followed across rotation and truncation).

Each transport is a thread that reads bytes, frames them into lines
(:class:`~uav_fusion.core.ingest.framing.LineFramer`) and hands every batch of complete lines
to a sink with the time they were read (``time.monotonic()`` and ``time.time()``). Nothing here
decodes a line. A transport never stops on bad input; its counters (:class:`TransportStats`)
say what happened: connections, drops, rotations, truncations, lines discarded as too long,
unfinished lines lost when a stream was cut. A bad address or path is refused at
construction with :class:`~uav_fusion.core.errors.ConfigError`.

URLs (:func:`parse_url`): ``tcp://HOST:PORT`` (connect to a server), ``udp://HOST:PORT``
(bind and receive; HOST may be empty or ``0.0.0.0``), ``file:///abs/path``, ``file:rel/path``
or a plain path (follow the file).
"""

from __future__ import annotations

import errno
import os
import socket
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import BinaryIO

from uav_fusion.core.errors import ConfigError
from uav_fusion.core.ingest.framing import LineFramer

#: ``sink(lines, t_monotonic, t_wall)``: complete lines (bytes, without line ends) and when
#: they were read.
Sink = Callable[[list[bytes], float, float], None]

SCHEMES = ("tcp", "udp", "file")


@dataclass(frozen=True)
class Endpoint:
    """A parsed source URL."""

    scheme: str  # tcp | udp | file
    host: str = ""
    port: int = 0
    path: str = ""

    def __str__(self) -> str:
        if self.scheme == "file":
            return f"file://{self.path}"
        return f"{self.scheme}://{self.host}:{self.port}"


def parse_url(url: str, *, what: str = "url") -> Endpoint:
    """``tcp://host:port``, ``udp://host:port``, ``file:///path``, ``file:path`` or a path.

    Raises ConfigError naming ``what`` for anything else (unknown scheme, a missing or
    out-of-range port, an empty host for TCP, an empty path)."""
    text = url.strip()
    if not text:
        raise ConfigError(f"{what}: empty; give tcp://HOST:PORT, udp://HOST:PORT or a file path")
    scheme, sep, rest = text.partition("://")
    if not sep:
        if text.startswith("file:"):
            return _file_endpoint(text[len("file:"):], what, url)
        if ":" in text.split("/")[0] and text.split(":")[0] in ("tcp", "udp"):
            raise ConfigError(f"{what} {url!r}: write {text.split(':')[0]}://HOST:PORT")
        return _file_endpoint(text, what, url)
    scheme = scheme.lower()
    if scheme not in SCHEMES:
        raise ConfigError(
            f"{what} {url!r}: unknown scheme {scheme!r}; use tcp://, udp:// or file://"
        )
    if scheme == "file":
        return _file_endpoint(rest, what, url)
    host, colon, port_text = rest.rstrip("/").rpartition(":")
    if not colon:
        raise ConfigError(f"{what} {url!r}: no port; write {scheme}://HOST:PORT")
    host = host.strip("[]")
    try:
        port = int(port_text)
    except ValueError:
        raise ConfigError(f"{what} {url!r}: port {port_text!r} is not a number") from None
    lo = 0 if scheme == "udp" else 1
    if not lo <= port <= 65535:
        raise ConfigError(f"{what} {url!r}: port {port} is outside {lo}..65535")
    if scheme == "tcp" and not host:
        raise ConfigError(f"{what} {url!r}: no host; write tcp://HOST:PORT")
    return Endpoint(scheme, host, port)


def _file_endpoint(path: str, what: str, url: str) -> Endpoint:
    if not path.strip():
        raise ConfigError(f"{what} {url!r}: no file path")
    return Endpoint("file", path=path)


@dataclass
class TransportStats:
    """What a transport did (read by other threads; plain counters)."""

    state: str = "starting"
    bytes: int = 0
    lines: int = 0
    connects: int = 0
    disconnects: int = 0
    rotations: int = 0
    truncations: int = 0
    datagrams: int = 0
    #: unfinished lines lost when the stream was cut (disconnect, rotation, truncation)
    cut_lines: int = 0
    last_error: str = ""
    extra: dict[str, int] = field(default_factory=dict)

    @property
    def reconnects(self) -> int:
        return max(0, self.connects - 1)


class Transport(threading.Thread):
    """Base of the three transports: a daemon thread with a stop flag, a framer, stats."""

    def __init__(self, sink: Sink, *, max_line_bytes: int, name: str) -> None:
        super().__init__(name=name, daemon=True)
        self.sink = sink
        self.framer = LineFramer(max_line_bytes)
        self.stats = TransportStats()
        self._stop_flag = threading.Event()

    @property
    def too_long(self) -> int:
        return self.framer.too_long

    def stop(self) -> None:
        self._stop_flag.set()

    def close(self, timeout_s: float = 2.0) -> None:
        """Stop and wait for the thread (at most ``timeout_s``)."""
        self.stop()
        if self.is_alive():
            self.join(timeout_s)

    def _emit(self, data: bytes) -> None:
        t_mono, t_wall = time.monotonic(), time.time()
        self.stats.bytes += len(data)
        lines = self.framer.feed(data)
        if lines:
            self.stats.lines += len(lines)
            self.sink(lines, t_mono, t_wall)

    def _cut(self) -> None:
        if self.framer.cut():
            self.stats.cut_lines += 1


class TcpClient(Transport):
    """Connects to ``host:port`` and reads lines; reconnects after a drop or a refused
    connection, waiting ``reconnect_min_s`` at first and twice as long after each failed
    attempt up to ``reconnect_max_s`` (a successful connection resets the wait). With
    ``idle_timeout_s`` > 0 a connection silent that long is dropped and made again (a peer
    that vanished without closing). The host name must resolve at construction."""

    def __init__(
        self,
        host: str,
        port: int,
        sink: Sink,
        *,
        max_line_bytes: int,
        reconnect_min_s: float = 0.1,
        reconnect_max_s: float = 5.0,
        connect_timeout_s: float = 2.0,
        idle_timeout_s: float = 0.0,
        poll_s: float = 0.1,
    ) -> None:
        super().__init__(sink, max_line_bytes=max_line_bytes, name=f"tcp {host}:{port}")
        try:
            socket.getaddrinfo(host, port, type=socket.SOCK_STREAM)
        except (OSError, UnicodeError) as exc:
            raise ConfigError(
                f"tcp://{host}:{port}: host {host!r} does not resolve ({exc})"
            ) from None
        self.host, self.port = host, port
        self.reconnect_min_s = max(0.0, reconnect_min_s)
        self.reconnect_max_s = max(self.reconnect_min_s, reconnect_max_s)
        self.connect_timeout_s = connect_timeout_s
        self.idle_timeout_s = idle_timeout_s
        self.poll_s = poll_s
        self.stats.state = "connecting"

    def run(self) -> None:
        wait = self.reconnect_min_s
        stop = self._stop_flag
        while not stop.is_set():
            try:
                sock = socket.create_connection((self.host, self.port), self.connect_timeout_s)
            except OSError as exc:
                self.stats.last_error = _why(exc)
                self.stats.state = f"connecting (retry in {wait:g} s)"
                if stop.wait(wait):
                    break
                wait = min(self.reconnect_max_s, max(wait * 2.0, 0.01))
                continue
            self.stats.connects += 1
            self.stats.state = "connected"
            wait = self.reconnect_min_s
            try:
                self._read(sock)
            finally:
                sock.close()
                self._cut()
            if stop.is_set():
                break
            self.stats.disconnects += 1
            self.stats.state = f"disconnected (retry in {wait:g} s)"
            if stop.wait(wait):
                break
        self.stats.state = "stopped"

    def _read(self, sock: socket.socket) -> None:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_KEEPALIVE, 1)
        sock.settimeout(self.poll_s)
        last = time.monotonic()
        while not self._stop_flag.is_set():
            try:
                data = sock.recv(1 << 16)
            except TimeoutError:
                if self.idle_timeout_s > 0 and time.monotonic() - last > self.idle_timeout_s:
                    self.stats.last_error = f"silent for {self.idle_timeout_s:g} s"
                    return
                continue
            except OSError as exc:
                self.stats.last_error = _why(exc)
                return
            if not data:
                self.stats.last_error = "closed by the peer"
                return
            last = time.monotonic()
            self._emit(data)


class UdpReceiver(Transport):
    """Binds ``host:port`` (port 0: any free port, see :attr:`port`) and reads datagrams;
    a datagram holds one or more lines, its last line complete with or without ``\\n``.
    Binding fails at construction (ConfigError) when the port is taken or not allowed."""

    def __init__(
        self, host: str, port: int, sink: Sink, *, max_line_bytes: int, poll_s: float = 0.1
    ) -> None:
        super().__init__(sink, max_line_bytes=max_line_bytes, name=f"udp {host}:{port}")
        self.sock = socket.socket(socket.AF_INET6 if ":" in host else socket.AF_INET,
                                  socket.SOCK_DGRAM)
        try:
            self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 22)
            self.sock.bind((host or "0.0.0.0", port))
        except (OSError, OverflowError) as exc:
            self.sock.close()
            raise ConfigError(f"udp://{host}:{port}: cannot bind ({_why(exc)})") from None
        self.sock.settimeout(poll_s)
        self.host = host
        self.port = int(self.sock.getsockname()[1])
        self.stats.state = f"listening on {self.port}"

    def run(self) -> None:
        try:
            while not self._stop_flag.is_set():
                try:
                    data = self.sock.recv(1 << 16)
                except TimeoutError:
                    continue
                except OSError as exc:
                    self.stats.last_error = _why(exc)
                    if self._stop_flag.wait(0.1):
                        break
                    continue
                self.stats.datagrams += 1
                t_mono, t_wall = time.monotonic(), time.time()
                self.stats.bytes += len(data)
                lines = self.framer.feed(data) + self.framer.flush_datagram()
                if lines:
                    self.stats.lines += len(lines)
                    self.sink(lines, t_mono, t_wall)
        finally:
            self.sock.close()
            self.stats.state = "stopped"


class FileFollower(Transport):
    """Follows a file as it grows, like ``tail -F``.

    - The file may not exist yet (waits for it); its folder must.
    - ``start_at_end``: skip what the file holds when it is first opened (default: read it).
    - **Rotation** (the path names another file: renamed and created anew): the old file is
      read to its end first (a writer may still finish its last line there, for up to
      ``rotate_grace_s``), then the new file is read from its start.
    - **Truncation** (the file became shorter than what was read): read again from the start.
    - A half-written last line waits until its ``\\n`` arrives.

    The file is polled every ``poll_s`` while nothing new is there.
    """

    def __init__(
        self,
        path: str | Path,
        sink: Sink,
        *,
        max_line_bytes: int,
        poll_s: float = 0.01,
        start_at_end: bool = False,
        rotate_grace_s: float = 1.0,
    ) -> None:
        p = Path(path).expanduser()
        super().__init__(sink, max_line_bytes=max_line_bytes, name=f"file {p}")
        if p.is_dir():
            raise ConfigError(f"{p}: is a folder, not a file")
        if not p.parent.is_dir():
            raise ConfigError(f"{p}: folder {p.parent} does not exist")
        if p.exists() and not os.access(p, os.R_OK):
            raise ConfigError(f"{p}: not readable")
        self.path = p
        self.poll_s = poll_s
        self.start_at_end = start_at_end
        self.rotate_grace_s = rotate_grace_s
        self.stats.state = "waiting for the file"

    def run(self) -> None:
        f: BinaryIO | None = None
        ident: tuple[int, int] | None = None
        first = True
        rotated_at: float | None = None
        stop = self._stop_flag
        try:
            while not stop.is_set():
                if f is None:
                    try:
                        f = self.path.open("rb")
                    except FileNotFoundError:
                        self.stats.state = "waiting for the file"
                        stop.wait(self.poll_s)
                        continue
                    except OSError as exc:
                        self.stats.last_error = _why(exc)
                        self.stats.state = "cannot open the file"
                        stop.wait(max(self.poll_s, 0.5))
                        continue
                    st = os.fstat(f.fileno())
                    ident = (st.st_dev, st.st_ino)
                    if first and self.start_at_end:
                        f.seek(0, os.SEEK_END)
                    first = False
                    self.stats.connects += 1
                    self.stats.state = "following"
                if self._drain(f):
                    continue
                size = -1
                try:
                    st = os.stat(self.path)
                    now_ident: tuple[int, int] | None = (st.st_dev, st.st_ino)
                    size = st.st_size
                except FileNotFoundError:
                    now_ident = None  # renamed away, the new one not there yet
                except OSError:
                    now_ident = ident
                if now_ident is not None and now_ident != ident:
                    # rotated: give a writer that still holds the old file time to finish
                    # its last line there, then switch
                    now = time.monotonic()
                    if rotated_at is None:
                        rotated_at = now
                    if self.framer.pending and now - rotated_at < self.rotate_grace_s:
                        stop.wait(self.poll_s)
                        continue
                    rotated_at = None
                    self._cut()
                    f.close()
                    f = None
                    self.stats.rotations += 1
                    continue
                if 0 <= size < f.tell():
                    self.stats.truncations += 1
                    self._cut()
                    f.seek(0)
                    continue
                stop.wait(self.poll_s)
        finally:
            if f is not None:
                f.close()
            self.stats.state = "stopped"

    def _drain(self, f: BinaryIO) -> bool:
        """Read what is there now (at most 1 MiB); True if anything was read."""
        got = False
        for _ in range(16):
            data = f.read(1 << 16)
            if not data:
                break
            got = True
            self._emit(data)
        return got


def _why(exc: BaseException) -> str:
    if isinstance(exc, OSError) and exc.errno is not None:
        return f"{errno.errorcode.get(exc.errno, exc.errno)}: {exc.strerror}"
    return str(exc) or type(exc).__name__


def open_transport(
    endpoint: Endpoint,
    sink: Sink,
    *,
    max_line_bytes: int,
    reconnect_min_s: float = 0.1,
    reconnect_max_s: float = 5.0,
    idle_timeout_s: float = 0.0,
    poll_s: float = 0.01,
    start_at_end: bool = False,
) -> Transport:
    """The transport for ``endpoint`` (not started)."""
    if endpoint.scheme == "tcp":
        return TcpClient(
            endpoint.host, endpoint.port, sink, max_line_bytes=max_line_bytes,
            reconnect_min_s=reconnect_min_s, reconnect_max_s=reconnect_max_s,
            idle_timeout_s=idle_timeout_s,
        )
    if endpoint.scheme == "udp":
        return UdpReceiver(endpoint.host, endpoint.port, sink, max_line_bytes=max_line_bytes)
    return FileFollower(
        endpoint.path, sink, max_line_bytes=max_line_bytes, poll_s=poll_s,
        start_at_end=start_at_end,
    )
