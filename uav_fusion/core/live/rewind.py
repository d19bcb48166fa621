"""Zero-wait fusion: every input is fused the moment it arrives; a late one is fused by
rewinding the estimator and re-filtering what came after it.

:class:`Rewinder` keeps what it fused in the last ``max_lag_s`` (sensor time), in processing
order (time, radar before RF, arrival), and a snapshot of the estimator every
``checkpoint_s`` of sensor time. An input later than something already fused, but at most
``max_lag_s`` behind the latest time fused, is put in its place: the estimator goes back to
the last snapshot before that place and re-filters everything from there, the late input
included. A radar message whose stamp equals a frame already fused joins that frame (the
frame is one scan). So once the late data is in, the estimator's state, its counters and its
re-filtered steps (:attr:`Rewinder.steps`) are exactly those of processing everything in
order.

What was published stays published: the outputs of a re-filtering are passed on only where
they are new: the late input's own steps (for a radar message joining a fused frame, the
steps of its own reports), fixed-rate epochs and track epochs after the last ones
published, smoothed estimates after the last one published. An input older than
``max_lag_s`` behind the latest time fused is refused (the caller counts it as late).

Pure Python, no ROS.
"""

from __future__ import annotations

import copy
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from uav_fusion.core.estimators.base import Estimator
from uav_fusion.core.estimators.grid import Outputs
from uav_fusion.core.estimators.steps import Step
from uav_fusion.core.live.schedule import Arrival, ClockTick
from uav_fusion.core.records import RADAR, RadarFrame, RfAttempt

Item = RadarFrame | RfAttempt
#: Default sensor seconds between two snapshots of the estimator.
CHECKPOINT_S = 1.0
_RANK = {RADAR: 0}


@dataclass
class Fused:
    """One fused input: a radar frame (every message of one stamp) or one RF attempt."""

    t: float
    rank: int
    items: list[Item]

    def frame(self) -> Item:
        """The radar frame of all messages of the stamp, or the RF attempt."""
        first = self.items[0]
        if len(self.items) == 1 or not isinstance(first, RadarFrame):
            return first
        tracks = tuple(trk for f in self.items for trk in f.tracks)  # type: ignore[union-attr]
        return RadarFrame(self.t, tracks, first.line)


@dataclass
class _Checkpoint:
    index: int  # the estimator before ``fused[index]``
    t: float
    estimator: Estimator


@dataclass
class _Published:
    """How far each output has been published."""

    grid_k: int | None = None
    track_t: float = -math.inf
    smoothed_t: float = -math.inf

    def keep_new(self, out: Outputs, steps: bool) -> Outputs:
        """The part of ``out`` not published yet (its steps only when ``steps``)."""
        k0 = self.grid_k
        grid = [g for g in out.grid if k0 is None or g.k > k0]
        if grid:
            self.grid_k = grid[-1].k
        tracks = [e for e in out.tracks if e.t > self.track_t]
        if tracks:
            self.track_t = tracks[-1].t
        smoothed = [s for s in out.smoothed if s[0] > self.smoothed_t]
        if smoothed:
            self.smoothed_t = smoothed[-1][0]
        return Outputs(out.steps if steps else [], grid, tracks, smoothed)


def snapshot(est: Estimator) -> Estimator:
    """An independent copy of ``est`` (its profile and site are shared, not copied)."""
    memo: dict[int, Any] = {id(est.profile): est.profile}
    site = getattr(est, "site", None)
    if site is not None:
        memo[id(site)] = site
    return copy.deepcopy(est, memo)


@dataclass
class Rewinder:
    """Zero-wait fusion with exact late data (see the module text)."""

    estimator: Estimator
    max_lag_s: float = 10.0
    checkpoint_s: float = CHECKPOINT_S
    fused: list[Fused] = field(default_factory=list)
    #: re-filtered inputs and rewinds so far
    rewinds: int = 0
    refiltered: int = 0
    _checkpoints: list[_Checkpoint] = field(default_factory=list)
    _steps: list[list[Step]] = field(default_factory=list)
    _done: list[Step] = field(default_factory=list)  # steps of inputs no longer held
    _published: _Published = field(default_factory=_Published)

    def __post_init__(self) -> None:
        if not (self.max_lag_s >= 0 and math.isfinite(self.max_lag_s)):
            raise ValueError(f"max_lag_s must be finite and >= 0, got {self.max_lag_s}")
        if not self.checkpoint_s > 0:
            raise ValueError(f"checkpoint_s must be > 0, got {self.checkpoint_s}")

    @property
    def latest(self) -> float:
        """The latest time fused (-inf: none)."""
        return self.fused[-1].t if self.fused else -math.inf

    @property
    def steps(self) -> list[Step]:
        """Every step so far, as re-filtered: those of processing every input in order."""
        return self._done + [s for group in self._steps for s in group]

    def fuse(self, source: str, t: float, item: Item) -> Outputs | None:
        """Fuse one input; None when it is more than ``max_lag_s`` behind the latest time
        fused (refused)."""
        rank = _RANK.get(source, 1)
        fused = self.fused
        if not fused or (t, rank) > (fused[-1].t, fused[-1].rank):
            entry = Fused(t, rank, [item])
            self._checkpoint_due(len(fused), t)
            out = self._feed(entry)
            fused.append(entry)
            self._steps.append(out.steps)
            self._trim()
            return self._published.keep_new(out, steps=True)
        if t < self.latest - self.max_lag_s:
            return None
        return self._rewind(source, t, rank, item)

    def advance(self, t: float) -> Outputs:
        """Time passed without input: the fixed-rate epochs up to ``t``."""
        return self._published.keep_new(self.estimator.advance(t), steps=False)

    def finish(self) -> Outputs:
        """The input ended: the estimator's held-back outputs."""
        return self._published.keep_new(self.estimator.finish(), steps=False)

    def restart(self, reason: str) -> None:
        """A new timeline: forget every input and snapshot."""
        self.estimator.restart(reason)
        self.fused.clear()
        self._steps.clear()
        self._done.clear()
        self._checkpoints.clear()
        self._published = _Published()

    # --- internals ------------------------------------------------------------------------
    def _feed(self, entry: Fused) -> Outputs:
        item = entry.frame()
        if isinstance(item, RadarFrame):
            return self.estimator.radar_frame(item)
        return self.estimator.rf_attempt(item)

    def _checkpoint_due(self, index: int, t: float) -> None:
        cps = self._checkpoints
        if not cps or t - cps[-1].t >= self.checkpoint_s:
            cps.append(_Checkpoint(index, t, snapshot(self.estimator)))

    def _rewind(self, source: str, t: float, rank: int, item: Item) -> Outputs | None:
        fused = self.fused
        key = (t, rank)
        pos = 0
        while pos < len(fused) and (fused[pos].t, fused[pos].rank) < key:
            pos += 1
        merge = source == RADAR and pos < len(fused) and (fused[pos].t, fused[pos].rank) == key
        if not merge:  # an RF attempt of an equal stamp goes after those that came before
            while pos < len(fused) and (fused[pos].t, fused[pos].rank) == key:
                pos += 1
        cps = self._checkpoints
        while cps and cps[-1].index > pos:
            cps.pop()
        if not cps:
            return None  # nothing to go back to (the input is older than every snapshot)
        cp = cps[-1]  # the estimator before fused[cp.index]: kept for later rewinds
        self.estimator = snapshot(cp.estimator)
        if merge:
            fused[pos].items.append(item)
        else:
            fused.insert(pos, Fused(t, rank, [item]))
            self._steps.insert(pos, [])
        self.rewinds += 1
        # the late input's own steps are passed on: for a message joining a fused frame, the
        # steps of its reports (the last of the frame's), the others were passed on before
        n_new = len(item.tracks) if merge and isinstance(item, RadarFrame) else None
        out = Outputs()
        for i in range(cp.index, len(fused)):
            entry = fused[i]
            self._checkpoint_due(i, entry.t)
            got = self._feed(entry)
            self._steps[i] = got.steps
            new = self._published.keep_new(got, steps=i == pos)
            if i == pos and n_new is not None:
                new.steps = new.steps[len(new.steps) - n_new :] if n_new else []
            out.add(new)
            if i != pos:
                self.refiltered += 1
        self._trim()
        return out

    def _trim(self) -> None:
        """Forget what no late input can need: everything before the last snapshot taken
        more than ``max_lag_s`` before the latest time fused."""
        cps = self._checkpoints
        horizon = self.latest - self.max_lag_s
        drop = 0
        while drop + 1 < len(cps) and cps[drop + 1].t <= horizon:
            drop += 1
        if not drop:
            return
        first = cps[drop].index
        del cps[:drop]
        del self.fused[:first]
        self._done += [s for group in self._steps[:first] for s in group]
        del self._steps[:first]
        for cp in cps:
            cp.index -= first


@dataclass(frozen=True)
class Published:
    """A step as the subscribers of the per-step topics saw it live, with the position of the
    measurement it fused (``z``; None: not known). Reads like a step
    (:func:`uav_fusion.core.scoring.evaluation.feed_steps`)."""

    step: Step
    z: Any

    @property
    def t(self) -> float:
        return self.step.t

    @property
    def source(self) -> str:
        return self.step.source

    @property
    def status(self) -> str:
        return self.step.status

    @property
    def x(self) -> Any:
        return self.step.x

    @property
    def updated(self) -> bool:
        return self.step.updated

    @property
    def coasted(self) -> bool:
        return self.step.coasted

    @property
    def validated(self) -> bool:
        return self.step.validated


def simulate(
    make: Callable[[], Estimator],
    arrivals: list[Arrival],
    max_lag_s: float = 10.0,
) -> tuple[list[Outputs], Rewinder, list[Published]]:
    """``arrivals`` (source, input) fused in that order by a fresh :class:`Rewinder` (what a
    zero-wait pipeline does live): what it passed on after each arrival (the last entry:
    after the end of the input), the rewinder (its :attr:`Rewinder.steps` are the final,
    re-filtered track), and every step passed on with its measurement's position. An arrival
    beyond ``max_lag_s`` passes nothing on; a :class:`~uav_fusion.core.live.schedule.ClockTick`
    passes on the fixed-rate epochs up to its time."""
    rw = Rewinder(make(), max_lag_s)
    outs = []
    published: list[Published] = []
    for source, item in arrivals:
        if isinstance(item, ClockTick):
            outs.append(rw.advance(item.t))
            continue
        got = rw.fuse(source, item.t, item)
        out = got if got is not None else Outputs()
        for st in out.steps:
            meas = rw.estimator.measurement(st)
            published.append(Published(st, None if meas is None else meas[0]))
        outs.append(out)
    outs.append(rw.finish())
    return outs, rw, published
