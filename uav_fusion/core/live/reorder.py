"""The reorder window: puts items from several streams back into time order before they are
fused (:class:`ReorderBuffer`; the live pipeline's ``reorder_window_s`` > 0).

Each stream is FIFO in its own time, so an item stamped ``t`` is released when nothing earlier
can still come: every stream has delivered something strictly later than ``t``, or the
watermark (the latest stamp seen, or the simulated clock) is ``window_s`` past ``t``. Items of
a grouped source sharing a stamp are released together as one frame. Order of release: time,
then source rank, then arrival. An item arriving after something later was released is
*late*: refused and counted.

Pure Python, no ROS.
"""

from __future__ import annotations

import heapq
import math
from collections import Counter
from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import Generic, TypeVar

T = TypeVar("T")


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
