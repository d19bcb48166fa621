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

import numpy as np
import numpy.typing as npt

from uav_fusion.core.estimators.kalman import CvKalman
from uav_fusion.core.estimators.profile import Profile
from uav_fusion.core.estimators.steps import (
    COASTED,
    DISCARDED,
    INITIALISED,
    RESET,
    TENTATIVE,
    USED,
    Step,
)

FloatArray = npt.NDArray[np.float64]
Predict = Callable[[FloatArray, FloatArray, float], tuple[FloatArray, FloatArray]]

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
    ``t0`` (default: the first time fed) or after ``t1``.
    """

    def __init__(
        self,
        frequency_hz: float,
        max_coast_s: float | None,
        predict: Predict,
        t0: float | None = None,
        t1: float | None = None,
    ) -> None:
        super().__init__(frequency_hz, t0, t1)
        if max_coast_s is not None and not max_coast_s >= 0:
            raise ValueError(f"max_coast_s must be >= 0 or None, got {max_coast_s}")
        self.max_coast_s = math.inf if max_coast_s is None else float(max_coast_s)
        self.predict = predict
        self._snap: TrackSnapshot | None = None
        self._closed = -math.inf  # every epoch <= this has been emitted

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
        if t <= self._closed:
            raise ValueError(f"snapshot at {t} is not after the emitted grid ({self._closed})")
        out = [self.state_at(k) for k in self.take(t, inclusive=False)]
        self._snap = snap
        return out

    def advance(self, t: float) -> list[GridState]:
        """Declare every time up to ``t`` processed: emits every epoch ``<= t``."""
        t = float(t)
        out = [self.state_at(k) for k in self.take(t, inclusive=True)]
        self._closed = max(self._closed, t)
        return out

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
    ) -> None:
        self.emitter = GridEmitter(
            frequency_hz,
            profile.max_coast_s,
            predict if predict is not None else profile_predictor(profile),
            t0,
            t1,
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
        up to ``t``): emit the epochs ``<= t``. Live use: call after each release."""
        self._last_t = max(self._last_t, float(t))
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


@dataclass(frozen=True)
class Grid:
    """A run's fixed-rate output as arrays (one row per epoch)."""

    frequency_hz: float
    max_coast_s: float | None
    t: FloatArray  # (N,)
    x: FloatArray  # (N, 6)
    P: FloatArray  # (N, 6, 6)
    has_track: npt.NDArray[np.bool_]
    published: npt.NDArray[np.bool_]
    age_s: FloatArray
    track_id: npt.NDArray[np.int64]
    last_source: npt.NDArray[np.str_]  # source of the last accepted measurement ("" none)
    confirmed_tracks: int  # confirmed tracks over the whole run (not only inside the grid)

    @property
    def restarts(self) -> int:
        return max(0, self.confirmed_tracks - 1)

    def __len__(self) -> int:
        return int(self.t.size)

    def write_csv(self, path: str) -> None:
        """One row per epoch: time, published, has_track, track id, age, state, P diagonal."""
        import csv

        with open(path, "w", newline="", encoding="utf-8") as fh:
            w = csv.writer(fh)
            w.writerow(GRID_CSV_HEADER)
            for i in range(len(self)):
                d = np.diag(self.P[i])
                w.writerow(
                    [
                        f"{self.t[i]:.6f}",
                        int(self.published[i]),
                        int(self.has_track[i]),
                        int(self.track_id[i]),
                        "" if not math.isfinite(self.age_s[i]) else f"{self.age_s[i]:.6f}",
                        str(self.last_source[i]),
                    ]
                    + ["" if not math.isfinite(v) else f"{v:.6f}" for v in self.x[i]]
                    + ["" if not math.isfinite(v) else f"{v:.6g}" for v in d]
                )


GRID_CSV_HEADER = (
    *("t", "published", "has_track", "track", "age_s", "last_source"),
    *("x", "y", "z", "vx", "vy", "vz"),
    *("var_x", "var_y", "var_z", "var_vx", "var_vy", "var_vz"),
)


def stack_states(
    states: Sequence[GridState],
    frequency_hz: float,
    max_coast_s: float | None,
    confirmed_tracks: int,
) -> Grid:
    n = len(states)
    return Grid(
        frequency_hz=frequency_hz,
        max_coast_s=max_coast_s,
        t=np.array([s.t for s in states], dtype=float),
        x=np.array([s.x for s in states], dtype=float).reshape(n, 6),
        P=np.array([s.P for s in states], dtype=float).reshape(n, 6, 6),
        has_track=np.array([s.has_track for s in states], dtype=bool),
        published=np.array([s.published for s in states], dtype=bool),
        age_s=np.array([s.age_s for s in states], dtype=float),
        track_id=np.array([s.track_id for s in states], dtype=np.int64),
        last_source=np.array([s.last_source for s in states], dtype=str).reshape(n),
        confirmed_tracks=confirmed_tracks,
    )


def grid_from_steps(
    steps: Iterable[Step],
    profile: Profile,
    frequency_hz: float,
    t0: float,
    t1: float,
    predict: Predict | None = None,
) -> Grid:
    """The fixed-rate output of a run (its steps, in processing order) on ``[t0, t1]``.

    Uses ``profile``'s maximum coast and motion model (``predict`` overrides the latter).
    """
    sg = StepGrid(profile, frequency_hz, t0, t1, predict)
    states = sg.feed_steps(steps)
    states.extend(sg.emitter.finish())
    return stack_states(states, frequency_hz, profile.max_coast_s, sg.confirmed_tracks)


def on_grid(t: float, frequency_hz: float, tol: float = 1.0e-6) -> bool:
    """Is ``t`` (seconds) an epoch ``k / frequency_hz`` (within ``tol`` of an epoch step)?"""
    k = round(t * frequency_hz)
    return abs(t * frequency_hz - k) <= tol


def grid_from_published(
    times: Sequence[float],
    xs: Sequence[Sequence[float]],
    Ps: Sequence[FloatArray],
    frequency_hz: float,
    t0: float,
    t1: float,
    max_coast_s: float | None = None,
) -> Grid:
    """The fixed-rate output as a subscriber sees it: every epoch ``k / frequency`` in
    ``[t0, t1]``, with the published states received (``times``, ``xs``, ``Ps``) and nothing
    at the others. What a message cannot carry is unknown: ages NaN, sources "", one track."""
    if not (math.isfinite(frequency_hz) and frequency_hz > 0):
        raise ValueError(f"frequency_hz must be finite and > 0, got {frequency_hz}")
    em = GridEmitter(frequency_hz, None, lambda x, P, dt: (x, P))
    k0 = em.first_epoch(t0)
    k1 = math.floor(t1 * frequency_hz)
    while em.epoch_time(k1 + 1) <= t1:
        k1 += 1
    while k1 >= k0 and em.epoch_time(k1) > t1:
        k1 -= 1
    n = max(0, k1 - k0 + 1)
    t = np.array([em.epoch_time(k) for k in range(k0, k0 + n)], dtype=float)
    x = np.full((n, 6), math.nan)
    P = np.full((n, 6, 6), math.nan)
    pub = np.zeros(n, dtype=bool)
    for ti, xi, Pi in zip(times, xs, Ps, strict=True):
        i = round(ti * frequency_hz) - k0
        if 0 <= i < n:
            x[i] = np.asarray(xi, dtype=float)
            P[i] = np.asarray(Pi, dtype=float)
            pub[i] = True
    return Grid(
        frequency_hz=float(frequency_hz),
        max_coast_s=max_coast_s,
        t=t,
        x=x,
        P=P,
        has_track=pub.copy(),
        published=pub,
        age_s=np.full(n, math.nan),
        track_id=np.where(pub, 0, -1).astype(np.int64),
        last_source=np.full(n, "", dtype=str),
        confirmed_tracks=1 if pub.any() else 0,
    )
