"""Per-source live health: input rate, age of the last line, line-to-publish latency and the
host-vs-sensor clock offset, as ``/diagnostics`` key/value pairs (no ROS here).

- **rate**: lines received over the last ``window_s`` wall seconds (or since the first line,
  if that is shorter);
- **age**: wall seconds since the last line (any line, good or bad) and since the last record;
- **latency**: from the moment a line's bytes were read to the moment its messages were
  published (p50, p99 and max over the last ``latency_samples`` lines);
- **clock offset**: host time when a line was read minus the sensor time it carries. Every
  sample also holds the transport delay (and a TDOA server's computing time), so the offset
  reported is the smallest of the last ``window_s`` seconds, the sample with the least delay.
  Its magnitude above ``clock_offset_warn_s`` (> 0) is a warning.
"""

from __future__ import annotations

import math
import time
from collections import deque


class SourceMonitor:
    """Collects the samples of one source (see the module text)."""

    def __init__(
        self,
        *,
        window_s: float = 10.0,
        clock_offset_warn_s: float = 2.0,
        stale_s: float = 0.0,
        latency_samples: int = 2000,
    ) -> None:
        self.window_s = window_s
        self.clock_offset_warn_s = clock_offset_warn_s
        self.stale_s = stale_s
        self.lines = 0
        self.records = 0
        self.messages = 0
        self._t0: float | None = None
        self._line_times: deque[float] = deque()
        self._offsets: deque[tuple[float, float]] = deque()
        self._latency: deque[float] = deque(maxlen=latency_samples)
        self.latency_max = 0.0
        self.last_line: float | None = None
        self.last_record: float | None = None
        self.last_offset = math.nan
        self.started = time.monotonic()

    def line(self, t_mono: float) -> None:
        """A line was read at ``t_mono`` (monotonic seconds)."""
        self.lines += 1
        if self._t0 is None:
            self._t0 = t_mono
        self._line_times.append(t_mono)
        self.last_line = t_mono if self.last_line is None else max(self.last_line, t_mono)
        self._prune(t_mono)

    def record(self, t_mono: float, t_wall: float, sensor_t: float) -> None:
        """A record with sensor time ``sensor_t`` from a line read at ``t_wall``."""
        self.records += 1
        self.last_record = t_mono if self.last_record is None else max(self.last_record, t_mono)
        off = t_wall - sensor_t
        self.last_offset = off
        self._offsets.append((t_mono, off))

    def published(self, t_mono_read: float, messages: int, now: float | None = None) -> None:
        """The messages of a line read at ``t_mono_read`` were published (now)."""
        lat = (time.monotonic() if now is None else now) - t_mono_read
        self.messages += messages
        self._latency.append(lat)
        self.latency_max = max(self.latency_max, lat)

    def _prune(self, now: float) -> None:
        lo = now - self.window_s
        while self._line_times and self._line_times[0] < lo:
            self._line_times.popleft()
        while self._offsets and self._offsets[0][0] < lo:
            self._offsets.popleft()

    # --- what the diagnostics show -----------------------------------------------------
    def rate_hz(self, now: float) -> float:
        self._prune(now)
        if self._t0 is None:
            return 0.0
        span = min(self.window_s, now - self._t0)
        return len(self._line_times) / span if span > 0 else 0.0

    def clock_offset(self, now: float) -> float:
        """The least-delayed offset of the window (NaN without a sample in it)."""
        self._prune(now)
        if not self._offsets:
            return math.nan
        return min(o for _, o in self._offsets)

    def latency_quantiles(self) -> tuple[float, float]:
        """(p50, p99) of the recent latencies in seconds (NaN without a sample)."""
        if not self._latency:
            return math.nan, math.nan
        xs = sorted(self._latency)
        return _quantile(xs, 0.5), _quantile(xs, 0.99)

    def values(self, now: float | None = None) -> list[tuple[str, str]]:
        now = time.monotonic() if now is None else now
        p50, p99 = self.latency_quantiles()
        return [
            ("lines", str(self.lines)),
            ("records", str(self.records)),
            ("messages_published", str(self.messages)),
            ("rate_hz", _fmt(self.rate_hz(now), 4)),
            ("last_line_age_s", _age(now, self.last_line)),
            ("last_record_age_s", _age(now, self.last_record)),
            ("latency_p50_ms", _fmt(p50 * 1e3, 3)),
            ("latency_p99_ms", _fmt(p99 * 1e3, 3)),
            ("latency_max_ms", _fmt(self.latency_max * 1e3, 3) if self._latency else "-"),
            ("clock_offset_s", _fmt(self.clock_offset(now), 6)),
            ("clock_offset_warn_s", _fmt(self.clock_offset_warn_s, 6)),
        ]

    def warnings(self, now: float | None = None) -> list[str]:
        """What is wrong now (empty: nothing)."""
        now = time.monotonic() if now is None else now
        out = []
        off = self.clock_offset(now)
        if self.clock_offset_warn_s > 0 and math.isfinite(off) and (
            abs(off) > self.clock_offset_warn_s
        ):
            out.append(
                f"sensor clock {off:+.3f} s off the host's (more than "
                f"{self.clock_offset_warn_s:g} s)"
            )
        if self.stale_s > 0:
            ref = self.last_line if self.last_line is not None else self.started
            if now - ref > self.stale_s:
                out.append(f"no line for {now - ref:.1f} s")
        return out


def _quantile(xs: list[float], q: float) -> float:
    """Linear-interpolated quantile of sorted ``xs``."""
    if len(xs) == 1:
        return xs[0]
    pos = q * (len(xs) - 1)
    i = math.floor(pos)
    j = min(i + 1, len(xs) - 1)
    return xs[i] + (xs[j] - xs[i]) * (pos - i)


def _fmt(v: float, digits: int) -> str:
    return f"{v:.{digits}g}" if math.isfinite(v) else "-"


def _age(now: float, t: float | None) -> str:
    return "-" if t is None else f"{max(0.0, now - t):.3f}"
