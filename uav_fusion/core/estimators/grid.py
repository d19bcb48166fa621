"""Fixed-rate output: the estimate the system publishes at every epoch ``k / frequency``.

The filter produces an estimate whenever a measurement arrives, at irregular times. A user
(and the fixed-rate benchmark) wants one at a fixed rate. This module is the one place that
decides what is published at a grid epoch, so the benchmark's scoring and a tracker's live
fixed-rate output cannot disagree:

* the latest snapshot of the confirmed track, predicted to the epoch with the motion model's
  own prediction (for the CV filter :func:`cv_predictor`: exactly the arithmetic the filter
  uses, in one piece from the snapshot's time, never touching the filter);
* ``published`` while the track's last accepted measurement is no older than the maximum
  coast (``max_coast_s``; None: no limit);
* nothing (no track) while the estimator has no track, or only a tentative (unconfirmed) one:
  the estimator publishes confirmed estimates only.

:class:`GridEmitter` is fed :class:`TrackSnapshot` objects as processed time advances and
returns a :class:`GridState` for every epoch it has passed. An epoch ``b`` is emitted once a
snapshot later than ``b`` arrives, or when the caller declares time up to ``b`` processed
(:meth:`GridEmitter.advance`, :meth:`GridEmitter.finish`); the state at ``b`` uses the last
snapshot at or before ``b``. So at an epoch equal to a step's time the published state is that
step's state (the last one, when several steps share the time).

:class:`StepGrid` turns the estimator's :class:`~uav_fusion.core.estimators.paper.Step` stream
into snapshots (track starts and restarts, tentative tracks, dropped tracks, the time of the
last accepted measurement); :func:`grid_from_steps` runs it over a finished run.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np
import numpy.typing as npt

from uav_fusion.core.estimators.kalman import CvKalman
from uav_fusion.core.estimators.steps import (
    COASTED,
    DISCARDED,
    INITIALISED,
    RESET,
    TENTATIVE,
    USED,
    Step,
)
from uav_fusion.core.profiles.model import Profile

FloatArray = npt.NDArray[np.float64]
Predict = Callable[[FloatArray, FloatArray, float], tuple[FloatArray, FloatArray]]
#: The covariance a state is published with (``consider(x, P)``).
Consider = Callable[[FloatArray, FloatArray], FloatArray]

_NAN6 = np.full(6, math.nan)
_NAN66 = np.full((6, 6), math.nan)
# discarded steps whose state is not the track at the step's time (the filter returned before
# predicting): they change nothing and are not snapshots
_NOT_AT_STEP_TIME = frozenset(("out_of_order", "invalid"))


def cv_predictor(q: Sequence[float]) -> Predict:
    """The CV filter's prediction with process noise ``q`` (per axis, m^2/s^3).

    Runs :class:`~uav_fusion.core.estimators.kalman.CvKalman`'s own ``predict`` on a copy of the
    state, so for a state taken from a filter step the result is bit for bit the state that
    filter would hold after predicting by ``dt``.
    """
    kf = CvKalman((float(q[0]), float(q[1]), float(q[2])))

    def predict(x: FloatArray, P: FloatArray, dt: float) -> tuple[FloatArray, FloatArray]:
        kf.set_state(x, P)
        kf.predict(float(dt))
        return kf.x_array(), kf.P_array()

    return predict


def profile_predictor(profile: Profile) -> Predict:
    """The prediction of ``profile``'s motion model (the CV model with its ``q``)."""
    return cv_predictor(profile.q)


@dataclass(frozen=True)
class TrackSnapshot:
    """The estimator's track after processing everything up to time ``t``.

    ``confirmed`` False (a tentative track, or no track at all: ``x`` NaN) publishes nothing.
    ``last_accepted_t`` is the time of the track's last accepted measurement (its start
    included) and ``last_source`` that measurement's source; ``track_id`` numbers the tracks
    of a run (0, 1, ...), -1 without a track.
    """

    t: float
    x: FloatArray
    P: FloatArray
    last_accepted_t: float
    confirmed: bool
    track_id: int
    last_source: str = ""

    @staticmethod
    def none(t: float) -> TrackSnapshot:
        """No track at time ``t``."""
        return TrackSnapshot(float(t), _NAN6, _NAN66, math.nan, False, -1)


@dataclass(frozen=True)
class GridState:
    """What is published at grid epoch ``t = k / frequency``.

    ``has_track``: a confirmed track exists (``x``, ``P`` are its state predicted to ``t``;
    NaN otherwise). ``published``: ``has_track`` and the last accepted measurement is at most
    ``max_coast_s`` old. ``age_s``: ``t`` minus that measurement's time, ``last_source`` its
    source (NaN and "" without a confirmed track).
    """

    k: int
    t: float
    x: FloatArray
    P: FloatArray
    has_track: bool
    published: bool
    age_s: float
    track_id: int
    last_source: str = ""


@dataclass(frozen=True)
class TrackOutput:
    """One confirmed track of a multi-UAV estimator at a time: id, state, covariance, UAV
    probability, emitter."""

    track_id: int
    t: float
    x: FloatArray
    P: FloatArray
    uav_prob: float
    emitter: str | None
    radar_object: int | None
    last_update_t: float


@dataclass(frozen=True)
class GridEpoch:
    """The confirmed tracks of a multi-UAV estimator at one grid time."""

    t: float
    tracks: tuple[TrackOutput, ...]


#: A fixed-lag smoothed estimate: time, state, covariance.
Smoothed = tuple[float, FloatArray, FloatArray]


@dataclass(slots=True)
class Outputs:
    """What an estimator gives for the input it was just handed (or for time passing):

    - ``steps``: one :class:`~uav_fusion.core.estimators.steps.Step` per measurement (the
      paper's filter and the single-UAV tracker; Table II reads them);
    - ``grid``: the fixed-rate output, one :class:`GridState` per epoch passed (for the
      multi-UAV tracker: its most UAV-like track);
    - ``tracks``: every confirmed track at every epoch passed (the multi-UAV tracker);
    - ``smoothed``: estimates that became final in the fixed-lag smoother (profiles with a
      finite ``smoother.lag_s``, when the estimator smooths live).
    """

    steps: list[Step] = field(default_factory=list)
    grid: list[GridState] = field(default_factory=list)
    tracks: list[GridEpoch] = field(default_factory=list)
    smoothed: list[Smoothed] = field(default_factory=list)

    def add(self, other: Outputs) -> None:
        """Append ``other``'s outputs after these."""
        self.steps += other.steps
        self.grid += other.grid
        self.tracks += other.tracks
        self.smoothed += other.smoothed

    def __bool__(self) -> bool:
        return bool(self.steps or self.grid or self.tracks or self.smoothed)


class EpochClock:
    """The grid epochs ``k / frequency_hz`` (unix seconds) an output emits, handed out in
    order: none before ``t0`` (default: the first time asked about) or after ``t1``. Shared by
    the single-track output (:class:`GridEmitter`) and the multi-UAV one
    (:class:`~uav_fusion.core.estimators.multi.MultiGrid`)."""

    def __init__(self, frequency_hz: float, t0: float | None = None, t1: float | None = None):
        if not (math.isfinite(frequency_hz) and frequency_hz > 0):
            raise ValueError(f"frequency_hz must be finite and > 0, got {frequency_hz}")
        self.frequency_hz = float(frequency_hz)
        self._k: int | None = None if t0 is None else self.first_epoch(float(t0))
        self._t1 = math.inf if t1 is None else float(t1)

    def epoch_time(self, k: int) -> float:
        return k / self.frequency_hz

    def first_epoch(self, t: float) -> int:
        """The smallest ``k`` with ``k / frequency >= t``."""
        k = math.ceil(t * self.frequency_hz)
        while self.epoch_time(k - 1) >= t:
            k -= 1
        while self.epoch_time(k) < t:
            k += 1
        return k

    @property
    def bounded(self) -> bool:
        """Whether the output has an end time ``t1``."""
        return math.isfinite(self._t1)

    @property
    def end(self) -> float:
        """The output's end time ``t1`` (inf: none)."""
        return self._t1

    def take(self, t: float, inclusive: bool) -> list[int]:
        """The next epochs before ``t`` (``inclusive``: up to and including ``t``), at most up
        to ``t1``; they are handed out once."""
        k = self._k
        if k is None:
            k = self.first_epoch(t)
        ks: list[int] = []
        hz = self.frequency_hz
        t1 = self._t1
        while True:
            b = k / hz
            if b > t1 or b > t or (b == t and not inclusive):
                break
            ks.append(k)
            k += 1
        self._k = k
        return ks


class GridEmitter(EpochClock):
    """Fixed-rate output from track snapshots (see the module docstring).

    ``frequency_hz``: epochs at ``k / frequency_hz`` (unix seconds); ``max_coast_s``: a track
    is published while its last accepted measurement is at most this old (None: always);
    ``predict(x, P, dt)``: the motion model's prediction; ``t0`` / ``t1``: no epoch before
    ``t0`` (default: the first time fed) or after ``t1``; ``consider(x, P)``: the published
    covariance of a state (:mod:`uav_fusion.core.estimators.consider`; None: ``P``).
    """

    def __init__(
        self,
        frequency_hz: float,
        max_coast_s: float | None,
        predict: Predict,
        t0: float | None = None,
        t1: float | None = None,
        consider: Consider | None = None,
    ) -> None:
        super().__init__(frequency_hz, t0, t1)
        if max_coast_s is not None and not max_coast_s >= 0:
            raise ValueError(f"max_coast_s must be >= 0 or None, got {max_coast_s}")
        self.max_coast_s = math.inf if max_coast_s is None else float(max_coast_s)
        self.predict = predict
        self.consider = consider
        self._snap: TrackSnapshot | None = None

    @property
    def snapshot(self) -> TrackSnapshot | None:
        return self._snap

    def feed(self, snap: TrackSnapshot) -> list[GridState]:
        """A new snapshot: emits every epoch before ``snap.t`` (with the previous snapshot),
        then ``snap`` becomes the current one. Snapshots must not go back in time."""
        t = float(snap.t)
        if not math.isfinite(t):
            raise ValueError(f"snapshot time must be finite, got {t}")
        if self._snap is not None and t < self._snap.t:
            raise ValueError(f"snapshot at {t} is older than the last one ({self._snap.t})")
        # a snapshot at or before epochs already emitted (the output was moved on ahead of
        # the input) emits nothing: it is the state of the epochs still to come
        out = [self.state_at(k) for k in self.take(t, inclusive=False)]
        self._snap = snap
        return out

    def advance(self, t: float) -> list[GridState]:
        """Declare every time up to ``t`` processed: emits every epoch ``<= t``."""
        t = float(t)
        return [self.state_at(k) for k in self.take(t, inclusive=True)]

    def finish(self) -> list[GridState]:
        """Emit the remaining epochs up to ``t1`` (requires a finite ``t1``)."""
        if not math.isfinite(self._t1):
            raise ValueError("finish() needs the emitter's t1")
        return self.advance(self._t1)

    def state_at(self, k: int) -> GridState:
        """The state published at epoch ``k`` from the current snapshot."""
        b = self.epoch_time(k)
        s = self._snap
        if s is None or not s.confirmed:
            return GridState(k, b, _NAN6, _NAN66, False, False, math.nan, -1, "")
        dt = b - s.t
        x, P = (s.x, s.P) if dt == 0.0 else self.predict(s.x, s.P, dt)
        if self.consider is not None:
            P = self.consider(x, P)
        age = b - s.last_accepted_t
        published = age <= self.max_coast_s
        return GridState(k, b, x, P, True, published, age, s.track_id, s.last_source)


class StepGrid:
    """Fixed-rate output of an estimator run, fed its steps one at a time.

    Keeps what a :class:`~uav_fusion.core.estimators.paper.Step` does not say on its own: the
    track a step belongs to (a new one at every ``initialised`` / ``reset`` step and at every
    tentative start), whether that track is confirmed (after an updated, coasted, initialised
    or reset step; not after a ``tentative`` one), and the time of its last accepted
    measurement. Discarded steps keep the track as it is (their state is the track predicted
    to their time) unless they have no track (NaN state); out-of-order and invalid discards
    are skipped.
    """

    def __init__(
        self,
        profile: Profile,
        frequency_hz: float,
        t0: float | None = None,
        t1: float | None = None,
        predict: Predict | None = None,
        consider: Consider | None = None,
    ) -> None:
        self.emitter = GridEmitter(
            frequency_hz,
            profile.max_coast_s,
            predict if predict is not None else profile_predictor(profile),
            t0,
            t1,
            consider,
        )
        self.tracks = 0  # tracks started (tentative ones included)
        self.confirmed_tracks = 0  # tracks that became confirmed
        self._track_id = -1
        self._confirmed = False
        self._last_accepted = math.nan
        self._last_source = ""
        self._last_t = -math.inf

    @property
    def restarts(self) -> int:
        """Confirmed tracks after the first: how often the published track was replaced."""
        return max(0, self.confirmed_tracks - 1)

    def feed_step(self, step: Step) -> list[GridState]:
        t = float(step.t)
        if not math.isfinite(t) or t < self._last_t:
            return []
        status = step.status
        if status == DISCARDED and step.reason in _NOT_AT_STEP_TIME:
            return []
        x = step.x
        if not math.isfinite(float(x[0])):  # no track after this step
            self._track_id = -1
            self._confirmed = False
            self._last_t = t
            return self.emitter.feed(TrackSnapshot.none(t))
        if status in (INITIALISED, RESET) or (status == TENTATIVE and step.reason == "start"):
            self.tracks += 1
            self._track_id = self.tracks - 1
            self._confirmed = False
        elif self._track_id < 0:  # a state without a start seen (a run fed from the middle)
            self.tracks += 1
            self._track_id = self.tracks - 1
        if status in USED or status == COASTED:
            if not self._confirmed:
                self.confirmed_tracks += 1
            self._confirmed = True
        elif status == TENTATIVE:
            self._confirmed = False
        if status in USED:
            self._last_accepted = t
            self._last_source = str(step.source)
        self._last_t = t
        snap = TrackSnapshot(
            t, x, step.P, self._last_accepted, self._confirmed, self._track_id, self._last_source
        )
        return self.emitter.feed(snap)

    def advance(self, t: float) -> list[GridState]:
        """Every step up to time ``t`` has been fed (e.g. a reorder buffer released everything
        up to ``t``): emit the epochs ``<= t``. Live use: call after each release. A step
        older than ``t`` may still come (a clock moved the output on ahead of the input): it
        emits no epoch again, and is the state of the epochs after ``t``."""
        return self.emitter.advance(t)

    def finish(self) -> list[GridState]:
        """The input ended: the epochs up to the output's end time ``t1`` (none without one)."""
        return self.emitter.finish() if self.emitter.bounded else []

    def feed_steps(self, steps: Iterable[Step]) -> list[GridState]:
        out: list[GridState] = []
        for s in steps:
            out.extend(self.feed_step(s))
        return out


def step_outputs(grid: StepGrid | None, steps: list[Step]) -> Outputs:
    """A single-track estimator's outputs for ``steps``: the steps and the epochs of the
    fixed-rate output ``grid`` (None: not kept) they pass."""
    out = Outputs(steps)
    if grid is not None:
        g = out.grid
        for s in steps:
            g += grid.feed_step(s)
    return out


class TrackSource(Protocol):
    """What :class:`MultiGrid` reads: every track a multi-UAV estimator publishes at a time."""

    def outputs(self, t: float | None = None) -> list[TrackOutput]: ...


class MultiGrid(EpochClock):
    """The confirmed tracks at every grid epoch ``k / frequency_hz``, emitted as processed time
    passes it (the same for a live node and an offline run): call :meth:`before` with an
    item's time before feeding the item to the tracker, :meth:`advance` when everything up to
    a time has been processed. Each track the tracker publishes (its ``outputs``;
    :meth:`~uav_fusion.core.estimators.multi.MultiTracker.outputs`)
    is predicted to the epoch, while its last accepted measurement is at most ``max_coast_s``
    old. No epoch before ``t0`` (default: the first time seen) or after
    ``t1``."""

    def __init__(
        self,
        tracker: TrackSource,
        frequency_hz: float,
        t0: float | None = None,
        t1: float | None = None,
        max_coast_s: float | None = None,
    ) -> None:
        super().__init__(frequency_hz, t0, t1)
        self.tracker = tracker
        self.max_coast_s = max_coast_s

    def _epochs(self, ks: list[int]) -> list[GridEpoch]:
        out: list[GridEpoch] = []
        mc = self.max_coast_s
        for k in ks:
            g = self.epoch_time(k)
            tracks = tuple(
                o
                for o in self.tracker.outputs(g)
                if o.t <= g and (mc is None or g - o.last_update_t <= mc)
            )
            out.append(GridEpoch(g, tracks))
        return out

    def before(self, t: float) -> list[GridEpoch]:
        """An item at ``t`` is about to be processed: every epoch before ``t``."""
        return self._epochs(self.take(t, inclusive=False))

    def advance(self, t: float) -> list[GridEpoch]:
        """Everything up to ``t`` has been processed: every epoch up to ``t``."""
        return self._epochs(self.take(t, inclusive=True))
