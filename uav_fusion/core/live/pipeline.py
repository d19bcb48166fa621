"""The live pipeline: time order, then the estimator.

A live consumer (the fusion node) hands every decoded message to a :class:`Pipeline`: a radar
frame (:meth:`Pipeline.radar`; a frame without reports only moves the radar stream on) or RF
attempts (:meth:`Pipeline.rf`; a failed attempt only moves the RF stream on). Every call
returns the :class:`~uav_fusion.core.estimators.grid.Outputs` that became final. Two ways to
order the inputs:

- **Zero wait** (``reorder_window_s`` = 0, the default): every input is fused the moment it
  arrives; one later than something already fused, but at most ``max_lag_s`` behind the
  latest time fused, is fused by rewinding the estimator and re-filtering what came after it
  (:mod:`uav_fusion.core.live.rewind`), so once the late data is in, the track is exactly the
  one of processing everything in order. An input older than that is dropped as late.
- **Reorder window** (``reorder_window_s`` > 0): inputs wait in a reorder buffer until
  nothing earlier can still come (:mod:`uav_fusion.core.live.reorder`), at most
  ``reorder_window_s`` of sensor time; an input later than that is dropped as late. Nothing
  is ever fused out of order, at the price of that wait.

**Stamp policy** (both ways):

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
restarts the estimator and forgets every input and repeat.

Pure Python, no ROS.
"""

from __future__ import annotations

import math
from collections import Counter, deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TypeVar

from uav_fusion.core.errors import UavFusionError
from uav_fusion.core.estimators.base import Estimator
from uav_fusion.core.estimators.grid import Outputs
from uav_fusion.core.live.reorder import Batch, ReorderBuffer
from uav_fusion.core.live.rewind import Rewinder
from uav_fusion.core.records import RADAR, RF, RadarFrame, RfAttempt

T = TypeVar("T")

#: How many recent messages per stream are remembered to recognise exact repeats.
DUPLICATE_MEMORY = 4096
#: Without a ``max_coast_s``, how far past the processed time a stalled output is predicted.
STALL_CAP_S = 60.0

Item = RadarFrame | RfAttempt


# --- the pipeline --------------------------------------------------------------------------
@dataclass(frozen=True)
class PipelineConfig:
    """The stamp policy's settings (the fusion node's parameters of the same names)."""

    reorder_window_s: float = 0.0  # 0: zero wait (rewind late inputs up to max_lag_s)
    max_lag_s: float = 10.0
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
        self.config = config or PipelineConfig()
        self.warn = warn
        c = self.config
        #: zero wait: late inputs re-filtered (None: a reorder window orders the inputs)
        self.rewinder = Rewinder(estimator, c.max_lag_s) if c.reorder_window_s <= 0 else None
        self._estimator = estimator
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
        self._watermark = -math.inf
        self.clock_jumps_back = 0
        self.timeline_resets = 0
        #: the latest time handed to the estimator (-inf: none yet)
        self.processed_t = -math.inf
        self._out = Outputs()

    def _new_buffer(self) -> ReorderBuffer[Item]:
        window = max(self.config.reorder_window_s, 0.0)
        return ReorderBuffer(window, self.sources, grouped=(RADAR,))

    # --- state ----------------------------------------------------------------------------
    @property
    def estimator(self) -> Estimator:
        """The estimator (zero wait: the one a rewind went back to)."""
        rw = self.rewinder
        return rw.estimator if rw is not None else self._estimator

    @property
    def pending(self) -> int:
        """Items waiting in the reorder buffer."""
        return self.buffer.pending

    @property
    def holding(self) -> bool:
        """True while a far-ahead stamp waits for confirmation."""
        return any(self.held.values())

    @property
    def watermark(self) -> float:
        """The latest stamp seen on any stream."""
        return max(self._watermark, self.buffer.watermark)

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
        self._finish()
        return self._take()

    def stall(self, t: float) -> tuple[Outputs, float | None]:
        """Time has come to ``t`` without input (the inputs stalled, or the node's clock moves
        the output on): the fixed-rate output predicted up to ``t``, forward from the
        processed time and at most ``max_coast_s`` (60 s without one) past it; nothing while
        measurements are held. Returns the outputs and the time the output was moved to (None:
        not moved), which an arrival schedule records."""
        if not math.isfinite(self.processed_t) or self.pending or self.holding:
            return Outputs(), None
        cap = self.estimator.profile.max_coast_s
        target = min(t, self.processed_t + (cap if cap is not None else STALL_CAP_S))
        if target <= self.processed_t:
            return Outputs(), None
        rw = self.rewinder
        out = rw.advance(target) if rw is not None else self._estimator.advance(target)
        return out, target

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
        wm = self.watermark
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
            self._note(source, t)
            return
        if isinstance(item, RfAttempt) and not item.ok:
            self.empty["rf_failed_attempt"] += 1
            self._note(source, t)
            return
        rw = self.rewinder
        if rw is not None:
            self._watermark = max(self._watermark, t)
            try:
                got = rw.fuse(source, t, item)
            except UavFusionError as exc:  # the estimator refused the input: count, go on
                self.dropped[f"{source}_refused"] += 1
                self.warn(f"estimator refused {source} at {t:.3f}: {exc}")
                return
            if got is None:
                self._late(source, t, f"more than max_lag_s {rw.max_lag_s:g} s behind")
                return
            self._late_run = 0
            self._out.add(got)
            self.processed_t = max(self.processed_t, t)
            return
        if not self.buffer.push(source, t, item):
            self._late(source, t, f"reorder window {self.buffer.window_s:g} s")
            return
        self._late_run = 0
        self._release(clock)

    def _note(self, source: str, t: float) -> None:
        """A stream moved on without anything to fuse."""
        if self.rewinder is not None:
            self._watermark = max(self._watermark, t)
        else:
            self.buffer.note(source, t)

    def _late(self, source: str, t: float, why: str) -> None:
        self._count(
            f"late_{source}",
            f"{source} measurement at {t:.3f} arrived after later ones were processed "
            f"({why}): dropped",
        )
        self._note_stale()

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

    def _finish(self) -> None:
        rw = self.rewinder
        self._out.add(rw.finish() if rw is not None else self._estimator.finish())

    def _process(self, batches: Sequence[Batch[Item]]) -> None:
        est = self._estimator
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
        self._finish()
        rw = self.rewinder
        if rw is not None:
            rw.restart(reason)
        else:
            self._estimator.restart(reason)
        self.processed_t = -math.inf
        self._watermark = -math.inf
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
                f"{limit} messages in a row were late or repeats: the input timeline went "
                "back (a bag loop without /clock, or an earlier jump ahead that was wrong); "
                f"processed {n} buffered measurement(s), reset the filter and the reorder buffer"
            )
