"""Multi-target scoring: GOSPA per epoch and per-UAV track continuity on a fixed-rate grid.

**GOSPA** (generalised optimal sub-pattern assignment; Rahmathullah, García-Fernández and
Svensson, 2017) between the truth positions ``X`` (m x 3) and the estimated positions ``Y``
(n x 3) of one epoch, with exponent ``p`` (2), cut-off ``c`` (100 m) and ``alpha`` (2)::

    GOSPA = ( min over assignments  sum_(i, j) min(d(x_i, y_j), c)^p
                                  + c^p / alpha * (m + n - 2 |assignment|) ) ^ (1 / p)

The minimum is found with ``scipy.optimize.linear_sum_assignment`` on the (m + n) x (n + m)
padded matrix: ``min(d, c)^p`` for a truth-estimate pair, ``c^p / alpha`` for a truth left
missed (its own dummy column) or an estimate left false (its own dummy row), 0 for
dummy-dummy. With ``alpha = 2`` a pair at ``d >= c`` costs ``c^p`` exactly as one missed plus
one false; such a pair is reported unassigned (missed + false), so every reported pair is
closer than ``c`` and the total splits into (the paper's Proposition 1)::

    localisation = sum of d^p over the assigned pairs (d < c)       [m^p]
    missed       = c^p / alpha * (number of missed truths)           [m^p]
    false        = c^p / alpha * (number of false estimates)         [m^p]
    distance     = (localisation + missed + false) ^ (1 / p)         [m]

These are Stone Soup's conventions for its ``GOSPAMetric`` (``compute_gospa_metric``): its
``distance`` is the p-th root of the sum, its ``localisation``, ``missed`` and ``false`` are the
un-rooted contributions (p-th powers of metres), a pair at exactly ``c`` counts as missed +
false. ``test/test_multiscore.py`` checks all four against Stone Soup on random scenes. With
``alpha < 2`` (allowed: ``0 < alpha <= 2``) pairs at ``d >= c`` stay assigned and add ``c^p``
to the localisation part (the split is then not the paper's).

**Per flight** (:func:`score_flight`) on the tracker's fixed-rate output (one entry per grid
epoch, empty epochs included, ``step_s`` apart): at each epoch the truth set is the UAVs
**airborne** then (truth linearly interpolated; by default more than ``airborne_min_m``, 5 m,
above the UAV's first truth sample, as in :mod:`uav_fusion.core.scoring.fixed_rate`; epochs inside a
truth gap longer than ``max_truth_gap_s`` do not count) and the estimate set is every
published track. GOSPA's optimal assignment then gives, per UAV:

* ``coverage_pct``: airborne epochs with an assigned track (closer than ``c``);
* 3D error mean, p50, p95, max over the assigned epochs;
* ``id_switches``: the track id assigned to the UAV differs from the one at its previous
  assigned epoch (a gap in between does not reset it). GOSPA's assignment is optimal per
  epoch and has no memory: two UAVs a few metres apart, each with its own track a few metres
  off, can be assigned crosswise for one epoch and back at the next (two switches each);
* ``id_switches_kept``: the same count on the CLEAR MOT correspondence (Bernardin and
  Stiefelhagen, 2008), which keeps each UAV's previous track while that track is still
  published and closer than ``c``, and assigns the other UAVs and tracks optimally: a track
  that stays with its UAV through a crossing is no switch, a track that leaves its UAV for
  another is one (for each UAV) once it is more than ``c`` from its UAV or gone;
* ``fragmentations``: over the UAV's airborne epochs, an assigned run is interrupted by
  unassigned epochs and assignment resumes (one per resumption; not-airborne epochs are
  skipped, so landing and taking off again is no fragmentation);
* ``switch_times`` and ``switch_times_kept``: the epochs at which those switches happened
  (so that a benchmark can attribute them, e.g. to the crossings of two UAVs).

and per flight: ``false_track_s``, the number of estimates left unassigned summed over the
epochs times ``step_s``; the mean GOSPA
distance over the epochs and the means of its three parts (p-th powers of metres; the mean
distance is not the root of the summed mean parts). A flight's samples are kept so that
:func:`pool` pools flights exactly (epochs pooled; per-UAV figures by vehicle name).

**A UAV that is not airborne** (on its pad, or in the last metres of a take-off or landing)
is neither required nor forbidden: its epochs are not in its coverage, and with
``excuse_grounded`` (the default) a track that GOSPA's assignment leaves false but that is
closer than ``c`` to such a UAV (its truth defined at the epoch) is **excused**: it leaves the
epoch's false part and the false-track time and is counted in ``excused_track_s`` instead.
Each UAV that is not airborne excuses at most one track (the pairs by minimum total squared
distance, as GOSPA pairs them), so a second track on a landed UAV stays false. Removing
estimates that the optimal assignment left unassigned cannot change that assignment, so the
epoch's GOSPA is the GOSPA of the scene without them. Without the rule
(``excuse_grounded=False``) a track following a UAV through its last 5 m of descent counts
as false although it is on a real UAV (docs/benchmark.md has the figures both ways).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np
import numpy.typing as npt
from scipy.optimize import linear_sum_assignment
from scipy.spatial.distance import cdist

from uav_fusion.core.scoring.continuity import KeptCorrespondence, fragmentations, id_switch_indices
from uav_fusion.core.scoring.metrics import interpolate_truth
from uav_fusion.core.scoring.outcomes import (
    EpochAssignment,
    FlightSamples,
    MultiScore,
    UavSamples,
    UavScore,
)

FloatArray = npt.NDArray[np.float64]
BoolArray = npt.NDArray[np.bool_]
# airborne rule given as a function: (epoch times (K,), interpolated ENU (K, 3), NaN rows
# outside the truth) -> airborne mask (K,)
AirborneFn = Callable[[FloatArray, FloatArray], BoolArray]


@dataclass(frozen=True)
class GospaSettings:
    p: float = 2.0  # exponent, >= 1
    c_m: float = 100.0  # cut-off distance
    alpha: float = 2.0  # 0 < alpha <= 2; 2 gives the localisation / missed / false split

    def __post_init__(self) -> None:
        if not (math.isfinite(self.p) and self.p >= 1.0):
            raise ValueError(f"GOSPA p must be a finite number >= 1, got {self.p}")
        if not (math.isfinite(self.c_m) and self.c_m > 0.0):
            raise ValueError(f"GOSPA cut-off c must be a finite number > 0, got {self.c_m}")
        if not (0.0 < self.alpha <= 2.0):
            raise ValueError(f"GOSPA alpha must be in (0, 2], got {self.alpha}")


@dataclass(frozen=True)
class Gospa:
    """GOSPA of one epoch (see the module docstring for the units of each part)."""

    distance: float  # (localisation + missed + false) ** (1 / p), metres
    localisation: float  # sum of d ** p over the assigned pairs
    missed: float  # c ** p / alpha per missed truth
    false: float  # c ** p / alpha per false estimate
    assignment: tuple[int | None, ...]  # per truth index: its estimate index, or None
    errors_m: tuple[float | None, ...]  # per truth index: distance to its estimate, or None
    n_missed: int
    n_false: int

    @property
    def total(self) -> float:
        """The sum under the root: localisation + missed + false (p-th power of metres)."""
        return self.localisation + self.missed + self.false


def _points(a: npt.ArrayLike, what: str) -> FloatArray:
    arr = np.asarray(a, dtype=float)
    if arr.size == 0:
        return np.zeros((0, 3))
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise ValueError(f"GOSPA {what}: expected an (n, 3) array of positions, got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"GOSPA {what}: positions must be finite")
    return arr


def gospa(
    truths: npt.ArrayLike, estimates: npt.ArrayLike, settings: GospaSettings | None = None
) -> Gospa:
    """GOSPA between truth positions (m x 3) and estimated positions (n x 3) of one epoch."""
    s = settings or GospaSettings()
    X = _points(truths, "truths")
    Y = _points(estimates, "estimates")
    m, n = X.shape[0], Y.shape[0]
    dummy = s.c_m**s.p / s.alpha
    assignment: list[int | None] = [None] * m
    errors: list[float | None] = [None] * m
    localisation = 0.0
    if m and n:
        d = cdist(X, Y)
        cost = np.full((m + n, n + m), np.inf)
        cost[:m, :n] = np.minimum(d, s.c_m) ** s.p
        cost[np.arange(m), n + np.arange(m)] = dummy  # truth i missed
        cost[m + np.arange(n), np.arange(n)] = dummy  # estimate j false
        cost[m:, n:] = 0.0
        rows, cols = linear_sum_assignment(cost)
        for i, j in zip(rows.tolist(), cols.tolist(), strict=True):
            if i >= m or j >= n:
                continue
            if s.alpha == 2.0 and not d[i, j] < s.c_m:
                continue  # costs exactly one missed + one false: reported as such
            assignment[i] = j
            errors[i] = float(d[i, j])
            localisation += float(cost[i, j])
    n_pairs = sum(1 for j in assignment if j is not None)
    n_missed, n_false = m - n_pairs, n - n_pairs
    missed, false = n_missed * dummy, n_false * dummy
    return Gospa(
        distance=float((localisation + missed + false) ** (1.0 / s.p)),
        localisation=localisation,
        missed=missed,
        false=false,
        assignment=tuple(assignment),
        errors_m=tuple(errors),
        n_missed=n_missed,
        n_false=n_false,
    )


# --- the tracker's output ------------------------------------------------------------------


class TrackLike(Protocol):
    """One published track at an epoch: its id and state (position ENU first)."""

    @property
    def track_id(self) -> int: ...

    @property
    def x(self) -> FloatArray: ...


class EpochLike(Protocol):
    """The published tracks at one grid epoch."""

    @property
    def t(self) -> float: ...

    @property
    def tracks(self) -> Sequence[TrackLike]: ...


@dataclass(frozen=True)
class PublishedTrack:
    """A published track: id, state ``x`` (position ENU first; at least 3 values), optionally
    its covariance and UAV probability (not used by the scores)."""

    track_id: int
    x: FloatArray
    P: FloatArray | None = None
    uav_prob: float | None = None


@dataclass(frozen=True)
class EpochTracks:
    t: float
    tracks: tuple[PublishedTrack, ...]


@dataclass(frozen=True)
class UavTruth:
    """One UAV's truth: times (N,), ENU positions (N, 3) and when it is airborne: ``None``
    (more than ``airborne_min_m`` above its first sample), a per-sample mask (N,) (an epoch is
    airborne when both samples around it are) or a function (see :data:`AirborneFn`)."""

    t: FloatArray
    enu: FloatArray
    airborne: BoolArray | AirborneFn | None = None


@dataclass(frozen=True)
class MultiScoreSettings:
    gospa: GospaSettings = field(default_factory=GospaSettings)
    step_s: float = 1.0  # grid step of the tracker's output
    airborne_min_m: float = 5.0  # above the UAV's first truth sample
    max_truth_gap_s: float = 2.0
    # a track left false but within c of a UAV that is not airborne then (on its pad, taking
    # off, landing; one track per such UAV) is excused: neither false nor scored
    excuse_grounded: bool = True

    def __post_init__(self) -> None:
        if not (math.isfinite(self.step_s) and self.step_s > 0.0):
            raise ValueError(f"grid step must be a finite number > 0, got {self.step_s}")


def _check_truth(name: str, tr: UavTruth) -> tuple[FloatArray, FloatArray]:
    t = np.asarray(tr.t, dtype=float)
    enu = np.asarray(tr.enu, dtype=float)
    if t.ndim != 1 or enu.ndim != 2 or enu.shape != (t.size, 3):
        raise ValueError(
            f"truth of {name!r}: expected times (N,) and ENU (N, 3), got {t.shape} and {enu.shape}"
        )
    if not (np.all(np.isfinite(t)) and np.all(np.isfinite(enu))):
        raise ValueError(f"truth of {name!r}: times and positions must be finite")
    if t.size > 1 and not np.all(np.diff(t) > 0):
        raise ValueError(f"truth of {name!r}: times must be strictly increasing")
    return t, enu


def _airborne(
    name: str,
    tr: UavTruth,
    t: FloatArray,
    enu: FloatArray,
    grid_t: FloatArray,
    pos: FloatArray,
    s: MultiScoreSettings,
) -> BoolArray:
    defined = np.isfinite(pos[:, 0])
    if tr.airborne is None:
        if t.size == 0:
            return np.zeros(grid_t.size, dtype=bool)
        with np.errstate(invalid="ignore"):
            return np.asarray(defined & (pos[:, 2] - enu[0, 2] > s.airborne_min_m), dtype=bool)
    if callable(tr.airborne):
        mask = np.asarray(tr.airborne(grid_t, pos), dtype=bool)
        if mask.shape != grid_t.shape:
            raise ValueError(
                f"truth of {name!r}: the airborne function returned shape {mask.shape}, "
                f"expected {grid_t.shape}"
            )
        return np.asarray(defined & mask, dtype=bool)
    m = np.asarray(tr.airborne)
    if m.shape != t.shape:
        raise ValueError(
            f"truth of {name!r}: airborne mask has shape {m.shape}, expected {t.shape}"
        )
    # linear interpolation of the 0/1 mask is exactly 1 only where both neighbours are 1
    mf = interpolate_truth(t, np.column_stack([m.astype(float)] * 3), grid_t, s.max_truth_gap_s)
    with np.errstate(invalid="ignore"):
        return np.asarray(defined & (mf[:, 0] >= 1.0), dtype=bool)


def score_flight(
    truths: Mapping[str, UavTruth],
    outputs: Sequence[EpochLike],
    settings: MultiScoreSettings | None = None,
) -> FlightSamples:
    """Score one flight's fixed-rate multi-track output (see the module docstring)."""
    s = settings or MultiScoreSettings()
    grid_t = np.array([float(e.t) for e in outputs], dtype=float)
    if grid_t.size and not np.all(np.isfinite(grid_t)):
        raise ValueError("tracker output: epoch times must be finite")
    if grid_t.size > 1:
        bad = np.flatnonzero(np.abs(np.diff(grid_t) - s.step_s) > 1e-6)
        if bad.size:
            k = int(bad[0])
            raise ValueError(
                f"tracker output: epochs must be {s.step_s} s apart (one entry per epoch, "
                f"empty ones included); epoch {k + 1} at {grid_t[k + 1]} follows {grid_t[k]}"
            )
    names = list(truths)
    pos: dict[str, FloatArray] = {}
    air: dict[str, BoolArray] = {}
    for name in names:
        t, enu = _check_truth(name, truths[name])
        pos[name] = interpolate_truth(t, enu, grid_t, max_gap_s=s.max_truth_gap_s)
        air[name] = _airborne(name, truths[name], t, enu, grid_t, pos[name], s)

    K = grid_t.size
    dist, loc, mis, fal = np.zeros(K), np.zeros(K), np.zeros(K), np.zeros(K)
    ids: dict[str, list[int | None]] = {name: [] for name in names}
    when: dict[str, list[float]] = {name: [] for name in names}
    errs: dict[str, list[float]] = {name: [] for name in names}
    n_false = n_excused = 0
    assignments: list[EpochAssignment] = []
    kept = KeptCorrespondence(s.gospa.c_m)
    for k, epoch in enumerate(outputs):
        present = [name for name in names if air[name][k]]
        tracks = list(epoch.tracks)
        track_ids = [int(tr.track_id) for tr in tracks]
        if len(set(track_ids)) != len(track_ids):
            raise ValueError(f"tracker output at t = {grid_t[k]}: duplicate track ids {track_ids}")
        Y = np.zeros((len(tracks), 3))
        for j, tr in enumerate(tracks):
            x = np.asarray(tr.x, dtype=float).ravel()
            if x.size < 3 or not np.all(np.isfinite(x[:3])):
                raise ValueError(
                    f"tracker output at t = {grid_t[k]}: track {track_ids[j]} has no finite "
                    f"ENU position (state {x.tolist()})"
                )
            Y[j] = x[:3]
        X = np.array([pos[name][k] for name in present], dtype=float).reshape(-1, 3)
        g = gospa(X, Y, s.gospa)
        dist[k], loc[k], mis[k], fal[k] = g.distance, g.localisation, g.missed, g.false
        pairs: list[tuple[str, int]] = []
        used: set[int] = set()
        for i, name in enumerate(present):
            when[name].append(float(grid_t[k]))
            a, e = g.assignment[i], g.errors_m[i]
            if a is None or e is None or not e < s.gospa.c_m:
                ids[name].append(None)
                continue
            ids[name].append(track_ids[a])
            errs[name].append(e)
            pairs.append((name, track_ids[a]))
            used.add(a)
        excused: tuple[tuple[str, int], ...] = ()
        if s.excuse_grounded:
            grounded = [n for n in names if not air[n][k] and np.isfinite(pos[n][k, 0])]
            # (with alpha < 2 a pair at c or more stays in GOSPA's assignment: not excusable)
            held = {a for a in g.assignment if a is not None}
            left = [j for j in range(len(track_ids)) if j not in used and j not in held]
            if grounded and left:
                G = np.array([pos[n][k] for n in grounded], dtype=float)
                hits = _excuse(G, Y[left], s.gospa.c_m)
                if hits:
                    excused = tuple((grounded[a], track_ids[left[b]]) for a, b in hits)
                    used.update(left[b] for _, b in hits)
                    n_excused += len(hits)
                    unit = s.gospa.c_m**s.gospa.p / s.gospa.alpha
                    fal[k] = max(fal[k] - len(hits) * unit, 0.0)
                    dist[k] = (loc[k] + mis[k] + fal[k]) ** (1.0 / s.gospa.p)
        false_ids = tuple(tid for j, tid in enumerate(track_ids) if j not in used)
        n_false += len(false_ids)
        kept.step(float(grid_t[k]), present, X, track_ids, Y)
        assignments.append(
            EpochAssignment(float(grid_t[k]), tuple(pairs), false_ids, excused)
        )

    sw = {name: id_switch_indices(ids[name]) for name in names}
    uavs = tuple(
        UavSamples(
            name=name,
            epochs=len(ids[name]),
            assigned=len(errs[name]),
            errors=np.asarray(errs[name], dtype=float),
            track_ids=tuple(ids[name]),
            id_switches=len(sw[name]),
            fragmentations=fragmentations(ids[name]),
            times=np.asarray(when[name], dtype=float),
            id_switches_kept=len(kept.switches.get(name, [])),
            switch_times=np.asarray([when[name][k] for k in sw[name]], dtype=float),
            switch_times_kept=np.asarray(kept.switches.get(name, []), dtype=float),
        )
        for name in names
    )
    return FlightSamples(
        step_s=s.step_s,
        distance=dist,
        localisation=loc,
        missed=mis,
        false=fal,
        false_estimates=n_false,
        uavs=uavs,
        assignments=tuple(assignments),
        excused_estimates=n_excused,
        p=s.gospa.p,
    )


def _excuse(G: FloatArray, Y: FloatArray, c_m: float) -> list[tuple[int, int]]:
    """(UAV row of ``G``, track row of ``Y``) pairs: the tracks left false that follow a UAV
    that is not airborne, one per such UAV, closer than the cut-off, by minimum total squared
    distance."""
    D = cdist(G, Y)
    r, c = linear_sum_assignment(np.minimum(D, c_m) ** 2)
    return [(a, b) for a, b in zip(r.tolist(), c.tolist(), strict=True) if D[a, b] < c_m]


def _pct(num: int, den: int) -> float:
    return 100.0 * num / den if den > 0 else math.nan


def _err_stats(err: FloatArray) -> tuple[float, float, float, float]:
    if err.size == 0:
        return (math.nan, math.nan, math.nan, math.nan)
    return (
        float(err.mean()),
        float(np.percentile(err, 50)),
        float(np.percentile(err, 95)),
        float(err.max()),
    )


def _mean(parts: Sequence[FloatArray]) -> float:
    a = np.concatenate(parts) if parts else np.zeros(0)
    return float(a.mean()) if a.size else math.nan


def pool(flights: Sequence[FlightSamples]) -> MultiScore:
    """The figures over one or several flights (epochs pooled; per UAV by vehicle name)."""
    by_name: dict[str, list[UavSamples]] = {}
    for f in flights:
        for u in f.uavs:
            by_name.setdefault(u.name, []).append(u)
    uav_scores: list[UavScore] = []
    for name, us in by_name.items():
        err = np.concatenate([u.errors for u in us])
        mean, p50, p95, mx = _err_stats(err)
        uav_scores.append(
            UavScore(
                name=name,
                flights=len(us),
                epochs=sum(u.epochs for u in us),
                coverage_pct=_pct(sum(u.assigned for u in us), sum(u.epochs for u in us)),
                err_mean_m=mean,
                err_p50_m=p50,
                err_p95_m=p95,
                err_max_m=mx,
                id_switches=sum(u.id_switches for u in us),
                fragmentations=sum(u.fragmentations for u in us),
                id_switches_kept=sum(u.id_switches_kept for u in us),
            )
        )
    all_u = [u for us in by_name.values() for u in us]
    err_all = np.concatenate([u.errors for u in all_u]) if all_u else np.zeros(0)
    mean, p50, p95, mx = _err_stats(err_all)
    uav_epochs = sum(u.epochs for u in all_u)
    return MultiScore(
        flights=len(flights),
        epochs=sum(f.epochs for f in flights),
        uav_epochs=uav_epochs,
        coverage_pct=_pct(sum(u.assigned for u in all_u), uav_epochs),
        err_mean_m=mean,
        err_p50_m=p50,
        err_p95_m=p95,
        err_max_m=mx,
        id_switches=sum(u.id_switches for u in all_u),
        fragmentations=sum(u.fragmentations for u in all_u),
        false_track_s=float(sum(f.false_estimates * f.step_s for f in flights)),
        gospa_mean_m=_mean([f.distance for f in flights]),
        localisation_mean=_mean([f.localisation for f in flights]),
        missed_mean=_mean([f.missed for f in flights]),
        false_mean=_mean([f.false for f in flights]),
        uavs=tuple(uav_scores),
        id_switches_kept=sum(u.id_switches_kept for u in all_u),
        excused_track_s=float(sum(f.excused_estimates * f.step_s for f in flights)),
    )


def epochs_from_published(
    published: Sequence[tuple[float, int, FloatArray]],
    frequency_hz: float,
    t0: float,
    t1: float,
) -> list[EpochTracks]:
    """A fixed-rate multi-track output as a subscriber sees it: every epoch ``k / frequency``
    in ``[t0, t1]`` with the (time, track id, state) messages received for it, and no track at
    the others (an epoch without a confirmed track publishes nothing). A repeated (epoch, id)
    keeps the last message."""
    if not (math.isfinite(frequency_hz) and frequency_hz > 0):
        raise ValueError(f"frequency_hz must be finite and > 0, got {frequency_hz}")
    k0 = math.ceil(t0 * frequency_hz - 1e-9)
    k1 = math.floor(t1 * frequency_hz + 1e-9)
    per: dict[int, dict[int, FloatArray]] = {}
    for t, tid, x in published:
        k = round(t * frequency_hz)
        if k0 <= k <= k1:
            per.setdefault(k, {})[int(tid)] = np.asarray(x, dtype=float)
    return [
        EpochTracks(
            k / frequency_hz,
            tuple(PublishedTrack(tid, x) for tid, x in sorted(per.get(k, {}).items())),
        )
        for k in range(k0, k1 + 1)
    ]
