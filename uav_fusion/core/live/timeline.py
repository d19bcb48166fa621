"""The live input timeline: what a streaming consumer does with stamps before the estimator.

The reorder buffer (:mod:`uav_fusion.core.live.reorder`) puts measurements back into time order.
:class:`Timeline` wraps it with the policy for stamps that cannot simply be ordered:

- **Duplicates.** A message equal to one of the last ``duplicate_memory`` of its stream (same
  stamp, same values) is dropped as ``<source>_duplicate`` (a restarted replay re-sends its
  file from the start).
- **Future stamps.** A stamp more than ``max_future_s`` ahead of the reference (the latest
  stamp seen, or the simulated clock if that is later) is held back until the next message of
  the same stream confirms the jump (a real gap in the data: both are then processed) or
  contradicts it (a lone bad stamp: dropped as ``<source>_future``), so one bad stamp cannot
  drag the reorder watermark ahead and make every later message "late".
- **Late runs.** A message too late for the reorder window is dropped as ``late_<source>``;
  ``late_run_reset`` late messages or repeats in a row mean the input timeline went back (a bag
  loop without a clock, or an earlier jump ahead that was wrong): the old timeline is finished
  and a new one starts (counted in :attr:`Timeline.timeline_resets`).
- **Clock jumps back.** A backwards jump of the simulated clock by more than
  ``clock_jump_back_s`` (a bag loop) does the same (counted in
  :attr:`Timeline.clock_jumps_back`).

Restarting a timeline processes what is buffered, drops held stamps as ``future``, asks the
consumer to restart its estimator (:meth:`TimelineSink.restart`, which must forget the old
time, e.g. :meth:`~uav_fusion.core.estimators.FusionEstimator.restart_timeline`), and empties
the reorder buffer and the duplicate memory.

Pure Python, no ROS: the fusion node feeds it from its subscriptions and passes its simulated
clock (or None) with every call.
"""

from __future__ import annotations

import math
from collections import Counter, deque
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol

from uav_fusion.core.live.reorder import Batch, ReorderBuffer
from uav_fusion.core.records import RADAR, RF, Measurement

#: How many recent messages per stream are remembered to recognise exact repeats.
DUPLICATE_MEMORY = 4096


class TimelineSink(Protocol):
    """What the timeline hands its results to (the fusion node, or a test)."""

    def process(self, batches: Sequence[Batch[Measurement]]) -> None:
        """Released batches, in time order."""

    def failed_attempt(self, source: str, t: float) -> None:
        """A failed attempt (no measurement) of ``source`` entered the timeline at ``t``."""

    def restart(self, reason: str) -> None:
        """The input timeline starts over (``clock_jump_back`` or ``timeline_back``): reset
        the estimator and forget its time."""

    def warn(self, text: str) -> None:
        """A warning for the log (the first of every drop reason, and every reset)."""


@dataclass(frozen=True)
class TimelineConfig:
    """The policy's settings (the fusion node's parameters of the same names)."""

    reorder_window_s: float = 2.0
    max_future_s: float = 30.0
    late_run_reset: int = 50  # 0 = never
    clock_jump_back_s: float = 1.0
    duplicate_memory: int = DUPLICATE_MEMORY
    sources: tuple[str, ...] = (RADAR, RF)
    grouped: tuple[str, ...] = (RADAR,)


class Timeline:
    """Duplicate, future-stamp, late-run and clock-jump policy around a reorder buffer."""

    def __init__(self, config: TimelineConfig, sink: TimelineSink) -> None:
        self.config = config
        self.sink = sink
        self.buffer: ReorderBuffer[Measurement] = self._new_buffer()
        #: drop counters: ``<source>_duplicate``, ``<source>_future``, ``late_<source>``
        self.dropped: Counter[str] = Counter()
        self.held: dict[str, list[tuple[float, Measurement | None]]] = {
            s: [] for s in config.sources
        }
        self._seen: dict[str, set[tuple[float, ...]]] = {s: set() for s in config.sources}
        self._seen_order: dict[str, deque[tuple[float, ...]]] = {
            s: deque() for s in config.sources
        }
        self._last_clock: float | None = None
        self._late_run = 0
        self.clock_jumps_back = 0
        self.timeline_resets = 0

    def _new_buffer(self) -> ReorderBuffer[Measurement]:
        c = self.config
        return ReorderBuffer(c.reorder_window_s, list(c.sources), grouped=list(c.grouped))

    # --- state ----------------------------------------------------------------------------
    @property
    def pending(self) -> int:
        """Items in the reorder buffer."""
        return self.buffer.pending

    @property
    def holding(self) -> bool:
        """True while a far-ahead stamp waits for confirmation."""
        return any(self.held.values())

    # --- input ----------------------------------------------------------------------------
    def check_clock(self, clock: float | None) -> None:
        """Note the simulated clock (None: no clock); a backwards jump restarts the timeline."""
        if clock is None:
            return
        last = self._last_clock
        self._last_clock = clock
        if last is None or last - clock <= self.config.clock_jump_back_s:
            return
        self.clock_jumps_back += 1
        n = self.restart("clock_jump_back")
        self.sink.warn(
            f"simulated clock jumped back {last - clock:.3f} s (from {last:.3f} to "
            f"{clock:.3f}; a bag loop?): processed {n} buffered measurement(s) of the old "
            "timeline, reset the filter and the reorder buffer"
        )

    def admit(self, source: str, t: float, m: Measurement | None, clock: float | None) -> None:
        """One message of ``source`` stamped ``t`` (``m`` None: a failed attempt).

        A measurement that enters the buffer releases what became releasable; a failed
        attempt only moves its stream on (call :meth:`release` after it).
        """
        key = (t, *(m.z.tolist() if m is not None else ()))
        seen = self._seen[source]
        if key in seen:
            self._count(
                f"{source}_duplicate",
                f"{source} message at {t:.3f} repeats one already received: dropped",
            )
            self._note_stale()
            return
        seen.add(key)
        order = self._seen_order[source]
        order.append(key)
        if len(order) > self.config.duplicate_memory:
            seen.discard(order.popleft())
        horizon = self.config.max_future_s
        wm = self.buffer.watermark
        ref = wm if clock is None else max(clock, wm)
        held = self.held[source]
        if not math.isfinite(ref) or t <= ref + horizon:
            if held:  # the stream continued on the old timeline: the held stamp was bad
                self._drop_held(source)
            self._enter(source, t, m, clock)
            return
        if held and t == held[-1][0]:  # another report of the same held frame
            held.append((t, m))
            return
        if held and held[-1][0] < t <= held[-1][0] + horizon:  # confirmed: the data jumped
            self.sink.warn(
                f"{source} stamp {t:.3f} is {t - ref:.1f} s ahead of the latest stamp or "
                f"simulated clock (max_future_s {horizon:g}), confirmed by the next "
                "message: following the jump"
            )
            for ht, hm in held:
                self._enter(source, ht, hm, clock)
            held.clear()
            self._enter(source, t, m, clock)
            return
        if held:
            self._drop_held(source)
        held.append((t, m))

    def release(self, clock: float | None) -> None:
        """Hand everything releasable to the sink."""
        if self.buffer.pending:
            self.sink.process(self.buffer.release(clock))

    def flush(self) -> int:
        """Drop unconfirmed held stamps as ``future`` and process the whole buffer; returns
        the number of items processed."""
        for src, held in self.held.items():
            if held:
                self._drop_held(src)
        n = self.buffer.pending
        self.sink.process(self.buffer.flush())
        return n

    def restart(self, reason: str) -> int:
        """Finish the old timeline and start a new one; returns the items processed."""
        n = self.flush()
        self.sink.restart(reason)
        self.buffer = self._new_buffer()
        for src in self._seen:  # a loop repeats the same messages: they are new again
            self._seen[src].clear()
            self._seen_order[src].clear()
        self._late_run = 0
        return n

    # --- internals ------------------------------------------------------------------------
    def _count(self, key: str, warning: str, n: int = 1) -> None:
        if self.dropped[key] == 0:
            self.sink.warn(warning)
        self.dropped[key] += n

    def _drop_held(self, source: str) -> None:
        held = self.held[source]
        self._count(
            f"{source}_future",
            f"{source} stamp {held[0][0]:.3f} lay far ahead of the stream and was not "
            "confirmed by the next message: dropped",
            n=len(held),
        )
        held.clear()

    def _enter(self, source: str, t: float, m: Measurement | None, clock: float | None) -> None:
        if m is None:
            self.sink.failed_attempt(source, t)
            self.buffer.note(source, t)
            return
        if not self.buffer.push(m.source, m.t, m):
            self._count(
                f"late_{m.source}",
                f"{m.source} measurement at {m.t:.3f} arrived after later ones were processed "
                f"(reorder window {self.buffer.window_s:g} s): dropped",
            )
            self._note_stale()
            return
        self._late_run = 0
        self.release(clock)

    def _note_stale(self) -> None:
        """One more message in a row that was late or a repeat; a long run of them means
        the input timeline went back: start a new one."""
        self._late_run += 1
        limit = self.config.late_run_reset
        if limit and self._late_run >= limit:
            self.timeline_resets += 1
            n = self.restart("timeline_back")
            self.sink.warn(
                f"{limit} messages in a row were late for the reorder window or repeats: the "
                "input timeline went back (a bag loop without /clock, or an earlier jump "
                f"ahead that was wrong); processed {n} buffered measurement(s), reset the "
                "filter and the reorder buffer"
            )
