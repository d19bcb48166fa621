"""The live pipeline: time order, then the estimator.

A live consumer (the fusion node) hands every decoded message to a :class:`Pipeline`: a radar
frame (:meth:`Pipeline.radar`; a frame without reports only moves the radar stream on) or RF
attempts (:meth:`Pipeline.rf`; a failed attempt only moves the RF stream on). The pipeline
puts them back into the offline run's order and hands them to the estimator
(:mod:`uav_fusion.core.estimators.base`); every call returns the
:class:`~uav_fusion.core.estimators.grid.Outputs` that became final.

**Time order.** Messages of different topics arrive in any interleaving. Each stream is FIFO
in its own time, so an item stamped ``t`` is released when nothing earlier can still come:
every stream has delivered something strictly later than ``t``, or the watermark (the latest
stamp seen, or the simulated clock) is ``reorder_window_s`` past ``t``. Radar items sharing a
stamp are released together as one frame. Order of release: time, then source (radar before
RF), then arrival. An item arriving after something later was released is *late*: dropped
and counted (``late_<source>``), since fusing it would change the filter's past.

**Stamp policy.**

- *Duplicates*: a message equal to one of the last ``duplicate_memory`` of its stream (same
  stamp, same positions) is dropped as ``<source>_duplicate`` (a restarted replay re-sends
  its file from the start).
- *Future stamps*: a stamp more than ``max_future_s`` ahead of the reference (the latest
  stamp, or the simulated clock if later) is held until the next message of its stream
  confirms the jump (both are then processed) or contradicts it (dropped as
  ``<source>_future``), so one bad stamp cannot make every later message "late".
- *Late runs*: ``late_run_reset`` late or repeated messages in a row mean the input's time
  went back (a bag loop without a clock): the old timeline is finished and a new one starts
  (:attr:`Pipeline.timeline_resets`).
- *Clock jumps back*: the simulated clock going back by more than ``clock_jump_back_s`` (a
  bag loop) does the same (:attr:`Pipeline.clock_jumps_back`).

Starting a new timeline processes what is buffered, drops held stamps as ``future``,
restarts the estimator (:meth:`~uav_fusion.core.estimators.base.Estimator.restart`) and
empties the buffer and the duplicate memory.

Pure Python, no ROS.
"""

from __future__ import annotations

import heapq
import math
from collections import Counter, deque
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from typing import Generic, TypeVar

from uav_fusion.core.errors import UavFusionError
from uav_fusion.core.estimators.base import Estimator
from uav_fusion.core.estimators.grid import Outputs
from uav_fusion.core.records import RADAR, RF, RadarFrame, RfAttempt

T = TypeVar("T")

#: How many recent messages per stream are remembered to recognise exact repeats.
DUPLICATE_MEMORY = 4096
#: Without a ``max_coast_s``, how far past the processed time a stalled output is predicted.
STALL_CAP_S = 60.0

Item = RadarFrame | RfAttempt


# --- time order ----------------------------------------------------------------------------
@dataclass(frozen=True)
class Batch(Generic[T]):
    """One release: a single item, or all items of a grouped source sharing one stamp."""

    t: float
    source: str
    items: list[T]


@dataclass(order=True)
class _Entry(Generic[T]):
    t: float
    rank: int
    arrival: int
    source: str = field(compare=False)
    item: T = field(compare=False)


class ReorderBuffer(Generic[T]):
    """Time-ordering buffer over named streams (the module text's "Time order").

    ``sources`` are the streams expected to progress (their order is also the tie-break rank
    for equal stamps); ``grouped`` are the sources whose equal-stamp items form one frame.
    """

    def __init__(self, window_s: float, sources: Iterable[str], grouped: Iterable[str] = ()):
        if not (window_s >= 0.0 and math.isfinite(window_s)):
            raise ValueError(f"window_s must be finite and >= 0, got {window_s}")
        self.window_s = float(window_s)
        self.sources: tuple[str, ...] = tuple(sources)
        if not self.sources:
            raise ValueError("at least one source is needed")
        self._rank = {s: i for i, s in enumerate(self.sources)}
        self.grouped = frozenset(grouped)
        self._heap: list[_Entry[T]] = []
        self._arrivals = 0
        self._latest: dict[str, float] = {}
        self._watermark = -math.inf
        self._released: tuple[float, int] | None = None  # (t, rank) of the last release
        self.late: Counter[str] = Counter()
        self.max_depth = 0
        self.released_count = 0

    def _rank_of(self, source: str) -> int:
        if source not in self._rank:
            raise ValueError(f"unknown source '{source}' (expected one of {self.sources})")
        return self._rank[source]

    def is_late(self, t: float, source: str) -> bool:
        """Would an item (t, source) arrive too late to be processed in order?"""
        if self._released is None:
            return False
        rt, rrank = self._released
        rank = self._rank_of(source)
        if source in self.grouped:  # a frame member must not follow its own frame's release
            return (t, rank) <= (rt, rrank)
        return (t, rank) < (rt, rrank)

    def note(self, source: str, t: float) -> None:
        """Record progress of a stream without an item (e.g. a failed RF attempt)."""
        self._rank_of(source)
        if t > self._latest.get(source, -math.inf):
            self._latest[source] = t
        self._watermark = max(self._watermark, t)

    def push(self, source: str, t: float, item: T) -> bool:
        """Add an item; False (and counted in :attr:`late`) if it arrived too late."""
        rank = self._rank_of(source)
        if not math.isfinite(t):
            raise ValueError(f"item time must be finite, got {t}")
        if self.is_late(t, source):
            self.late[source] += 1
            return False
        heapq.heappush(self._heap, _Entry(t, rank, self._arrivals, source, item))
        self._arrivals += 1
        self.max_depth = max(self.max_depth, len(self._heap))
        self.note(source, t)
        return True

    @property
    def pending(self) -> int:
        return len(self._heap)

    @property
    def watermark(self) -> float:
        return self._watermark

    def release(self, clock: float | None = None) -> list[Batch[T]]:
        """Release every item that can no longer be preceded by a new arrival (``clock``: an
        external time, e.g. the simulated clock, that counts as a watermark too)."""
        wm = self._watermark if clock is None else max(self._watermark, clock)
        bound_window = wm - self.window_s
        complete = all(s in self._latest for s in self.sources)
        bound_streams = min(self._latest[s] for s in self.sources) if complete else -math.inf
        out: list[Batch[T]] = []
        while self._heap:
            head = self._heap[0]
            # strictly before every stream's latest stamp, or at least window_s old
            if not (head.t < bound_streams or head.t <= bound_window):
                break
            out.append(self._pop_batch())
        return out

    def flush(self) -> list[Batch[T]]:
        """Release everything held (end of stream)."""
        out: list[Batch[T]] = []
        while self._heap:
            out.append(self._pop_batch())
        return out

    def _pop_batch(self) -> Batch[T]:
        head = heapq.heappop(self._heap)
        items = [head.item]
        if head.source in self.grouped:
            while self._heap and self._heap[0].source == head.source and self._heap[0].t == head.t:
                items.append(heapq.heappop(self._heap).item)
        self._released = (head.t, head.rank)
        self.released_count += len(items)
        return Batch(head.t, head.source, items)


# --- the pipeline --------------------------------------------------------------------------
@dataclass(frozen=True)
class PipelineConfig:
    """The stamp policy's settings (the fusion node's parameters of the same names)."""

    reorder_window_s: float = 2.0
    max_future_s: float = 30.0
    late_run_reset: int = 50  # 0 = never
    clock_jump_back_s: float = 1.0
    duplicate_memory: int = DUPLICATE_MEMORY


def _ignore(_text: str) -> None:
    return None


def frame_key(frame: RadarFrame) -> tuple[float, ...]:
    """What makes a radar message a repeat: its stamp and every report's position."""
    return (frame.t, *(v for trk in frame.tracks for v in (trk.e, trk.n, trk.u)))


class Pipeline:
    """Time order and stamp policy, then the estimator (see the module text)."""

    sources = (RADAR, RF)

    def __init__(
        self,
        estimator: Estimator,
        config: PipelineConfig | None = None,
        warn: Callable[[str], None] = _ignore,
    ) -> None:
        self.estimator = estimator
        self.config = config or PipelineConfig()
        self.warn = warn
        self.buffer: ReorderBuffer[Item] = self._new_buffer()
        #: drops: ``<source>_duplicate``, ``<source>_future``, ``late_<source>``, and
        #: ``<source>_refused`` (the estimator raised on the input)
        self.dropped: Counter[str] = Counter()
        #: inputs without anything to fuse: ``rf_failed_attempt``, ``radar_empty_frame``
        self.empty: Counter[str] = Counter()
        self.held: dict[str, list[tuple[float, Item]]] = {s: [] for s in self.sources}
        self._seen: dict[str, set[tuple[float, ...]]] = {s: set() for s in self.sources}
        self._seen_order: dict[str, deque[tuple[float, ...]]] = {s: deque() for s in self.sources}
        self._last_clock: float | None = None
        self._late_run = 0
        self.clock_jumps_back = 0
        self.timeline_resets = 0
        #: the latest time handed to the estimator (-inf: none yet)
        self.processed_t = -math.inf
        self._out = Outputs()

    def _new_buffer(self) -> ReorderBuffer[Item]:
        return ReorderBuffer(self.config.reorder_window_s, self.sources, grouped=(RADAR,))

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
    def radar(self, frame: RadarFrame, clock: float | None = None) -> Outputs:
        """One radar message (a frame; without reports it only moves the radar stream on)."""
        self.check_clock(clock)
        self._admit(RADAR, frame.t, frame, frame_key(frame), clock)
        self._release(clock)
        return self._take()

    def rf(self, attempts: Sequence[RfAttempt], clock: float | None = None) -> Outputs:
        """One RF message (its attempts; a failed one only moves the RF stream on)."""
        self.check_clock(clock)
        for a in attempts:
            key = (a.t, a.e, a.n) if a.ok else (a.t,)
            self._admit(RF, a.t, a, key, clock)
        self._release(clock)
        return self._take()

    def tick(self, clock: float | None) -> Outputs:
        """Time passes without input (a timer): follow the simulated clock."""
        self.check_clock(clock)
        self._release(clock)
        return self._take()

    def flush(self) -> Outputs:
        """End of input: drop unconfirmed held stamps as ``future``, process the whole buffer
        and finish the estimator's smoothing windows."""
        self._flush()
        self._out.add(self.estimator.finish())
        return self._take()

    def stall(self, t: float) -> Outputs:
        """The inputs stalled: the fixed-rate output predicted up to ``t``, forward from the
        processed time and at most ``max_coast_s`` (60 s without one) past it."""
        if not math.isfinite(self.processed_t) or self.pending or self.holding:
            return Outputs()
        cap = self.estimator.profile.max_coast_s
        target = min(t, self.processed_t + (cap if cap is not None else STALL_CAP_S))
        if target <= self.processed_t:
            return Outputs()
        return self.estimator.advance(target)

    def check_clock(self, clock: float | None) -> None:
        """Note the simulated clock (None: no clock); a backwards jump restarts the timeline."""
        if clock is None:
            return
        last = self._last_clock
        self._last_clock = clock
        if last is None or last - clock <= self.config.clock_jump_back_s:
            return
        self.clock_jumps_back += 1
        n = self._restart("clock_jump_back")
        self.warn(
            f"simulated clock jumped back {last - clock:.3f} s (from {last:.3f} to "
            f"{clock:.3f}; a bag loop?): processed {n} buffered measurement(s) of the old "
            "timeline, reset the filter and the reorder buffer"
        )

    # --- internals ------------------------------------------------------------------------
    def _take(self) -> Outputs:
        out = self._out
        self._out = Outputs()
        return out

    def _admit(
        self, source: str, t: float, item: Item, key: tuple[float, ...], clock: float | None
    ) -> None:
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
            self._enter(source, t, item, clock)
            return
        if held and t == held[-1][0]:  # another report of the same held frame
            held.append((t, item))
            return
        if held and held[-1][0] < t <= held[-1][0] + horizon:  # confirmed: the data jumped
            self.warn(
                f"{source} stamp {t:.3f} is {t - ref:.1f} s ahead of the latest stamp or "
                f"simulated clock (max_future_s {horizon:g}), confirmed by the next "
                "message: following the jump"
            )
            for ht, hm in held:
                self._enter(source, ht, hm, clock)
            held.clear()
            self._enter(source, t, item, clock)
            return
        if held:
            self._drop_held(source)
        held.append((t, item))

    def _enter(self, source: str, t: float, item: Item, clock: float | None) -> None:
        if isinstance(item, RadarFrame) and not item.tracks:
            self.empty["radar_empty_frame"] += 1
            self.buffer.note(source, t)
            return
        if isinstance(item, RfAttempt) and not item.ok:
            self.empty["rf_failed_attempt"] += 1
            self.buffer.note(source, t)
            return
        if not self.buffer.push(source, t, item):
            self._count(
                f"late_{source}",
                f"{source} measurement at {t:.3f} arrived after later ones were processed "
                f"(reorder window {self.buffer.window_s:g} s): dropped",
            )
            self._note_stale()
            return
        self._late_run = 0
        self._release(clock)

    def _release(self, clock: float | None) -> None:
        if self.buffer.pending:
            self._process(self.buffer.release(clock))

    def _flush(self) -> int:
        for src, held in self.held.items():
            if held:
                self._drop_held(src)
        n = self.buffer.pending
        self._process(self.buffer.flush())
        return n

    def _process(self, batches: Sequence[Batch[Item]]) -> None:
        est = self.estimator
        out = self._out
        for b in batches:
            try:
                if b.source == RADAR:
                    frames = b.items
                    frame = frames[0]
                    if len(frames) > 1:  # several messages of one scan: one frame
                        tracks = tuple(trk for f in frames for trk in f.tracks)  # type: ignore[union-attr]
                        frame = RadarFrame(b.t, tracks, frame.line)
                    out.add(est.radar_frame(frame))  # type: ignore[arg-type]
                else:
                    for a in b.items:
                        out.add(est.rf_attempt(a))  # type: ignore[arg-type]
            except UavFusionError as exc:  # the estimator refused the input: count, go on
                self.dropped[f"{b.source}_refused"] += len(b.items)
                self.warn(f"estimator refused {b.source} at {b.t:.3f}: {exc}")
                continue
            if b.t > self.processed_t:
                self.processed_t = b.t

    def _restart(self, reason: str) -> int:
        """Finish the old timeline and start a new one; returns the items processed."""
        n = self._flush()
        self._out.add(self.estimator.finish())
        self.estimator.restart(reason)
        self.processed_t = -math.inf
        self.buffer = self._new_buffer()
        for src in self._seen:  # a loop repeats the same messages: they are new again
            self._seen[src].clear()
            self._seen_order[src].clear()
        self._late_run = 0
        return n

    def _count(self, key: str, warning: str, n: int = 1) -> None:
        if self.dropped[key] == 0:
            self.warn(warning)
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

    def _note_stale(self) -> None:
        """One more message in a row that was late or a repeat; a long run of them means
        the input timeline went back: start a new one."""
        self._late_run += 1
        limit = self.config.late_run_reset
        if limit and self._late_run >= limit:
            self.timeline_resets += 1
            n = self._restart("timeline_back")
            self.warn(
                f"{limit} messages in a row were late for the reorder window or repeats: the "
                "input timeline went back (a bag loop without /clock, or an earlier jump "
                f"ahead that was wrong); processed {n} buffered measurement(s), reset the "
                "filter and the reorder buffer"
            )
