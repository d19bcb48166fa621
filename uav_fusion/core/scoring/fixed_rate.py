"""Fixed-rate scoring: what the system publishes at every grid epoch, against truth.

Table II (:mod:`uav_fusion.core.scoring.evaluation`) scores the estimates the filter
happens to make, at the measurement times. A user sees the fixed-rate output instead
(:mod:`uav_fusion.core.estimators.grid`): at every epoch ``k / frequency`` either a
published track state or nothing. This module scores that output over the **airborne
epochs**: grid epochs where the truth, linearly interpolated, is more than
``airborne_min_m`` (5 m) above the take-off point (epochs inside a truth gap longer than
``max_truth_gap_s`` are not scored).

Per flight, and pooled over flights (:func:`pool`):

* ``coverage_pct``: airborne epochs with a published track;
* ``fresh_coverage_pct``: airborne epochs with a published track whose last accepted
  measurement is at most ``fresh_age_s`` (1 s) old;
* 3D error mean, p50, p95, max over the covered (published) airborne epochs;
* ``gross_pct``: covered epochs whose error exceeds ``gross_error_m`` (100 m);
* the same coverage and gross share over the **radar-observable** epochs: airborne epochs with
  a radar report of the UAV within ``observable_window_s`` (2 s); the twin knows which reports
  are the UAV's (``bench_labels.json``); without labels these figures are NaN;
  ``observable_after_start_pct`` is that coverage counted from the flight's first airborne
  epoch with a confirmed track on (the radar-observable epochs before it are the start-up:
  the time the tracker takes to find the UAV, against the ones it loses later);
* NEES ``e^T P^-1 e`` of the published position covariance (``P``'s position block) on the
  covered epochs: ANEES (its mean; 3 for an honest covariance) and the share inside the
  two-sided ``nees_probability`` (95 %) chi-square(3) bounds (95 % for an honest one); an
  output without a covariance (the radar's own track, :mod:`~uav_fusion.core.bench.
  radar_baseline`) has neither;
* ``ttf_s``: time from the first airborne epoch to the first airborne epoch with a confirmed
  track (0 when one existed already; NaN when none ever did);
* ``restarts``: confirmed tracks of the run after the first one (the published track was
  replaced by a new one: an estimator reset);
* what the gross errors are (per flight): ``gross_vertical_pct``, the share of gross epochs
  whose vertical error exceeds the horizontal one, ``gross_age_p50_s``, the median age of
  the last accepted measurement at them (a long coast on the CV prediction), and
  ``gross_rf_pct``, the share of them whose last accepted measurement was an RF fix;
* ``longest_gross_s``: the longest **gross episode**, a run of consecutive covered airborne
  epochs whose error exceeds ``episode_error_m`` (300 m), in seconds (epochs x grid step;
  an epoch without a published track or not airborne ends it; 0 without one). Pooled: the
  longest of any flight, and ``flight_mean_max_m``, the largest per-flight mean error.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import asdict, dataclass, field

import numpy as np
import numpy.typing as npt
from scipy.stats import chi2

from uav_fusion.core.estimators.grid import Consider, GridEmitter, GridState, Predict, StepGrid
from uav_fusion.core.estimators.steps import Step
from uav_fusion.core.profiles.model import Profile
from uav_fusion.core.records import RF, Flight
from uav_fusion.core.scoring.metrics import interpolate_truth
from uav_fusion.core.site import Site

FloatArray = npt.NDArray[np.float64]


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
    consider: Consider | None = None,
) -> Grid:
    """The fixed-rate output of a run (its steps, in processing order) on ``[t0, t1]``.

    Uses ``profile``'s maximum coast and motion model (``predict`` overrides the latter);
    ``consider``: the published covariance of a state (the estimator's
    :func:`~uav_fusion.core.estimators.consider.consider_for`; None: the filter's).
    """
    sg = StepGrid(profile, frequency_hz, t0, t1, predict, consider)
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



@dataclass(frozen=True)
class ScoreSettings:
    airborne_min_m: float = 5.0  # truth above the take-off point
    fresh_age_s: float = 1.0
    gross_error_m: float = 100.0
    observable_window_s: float = 2.0
    max_truth_gap_s: float = 2.0
    nees_probability: float = 0.95  # two-sided bounds of the per-epoch NEES
    episode_error_m: float = 300.0  # a gross episode: consecutive epochs with a larger error

    def nees_bounds(self, dof: int = 3) -> tuple[float, float]:
        a = (1.0 - self.nees_probability) / 2.0
        return float(chi2.ppf(a, dof)), float(chi2.ppf(1.0 - a, dof))


@dataclass(frozen=True)
class FlightTruth:
    """Truth of one flight: times, ENU positions, height above the take-off point."""

    t: FloatArray
    enu: FloatArray
    above_takeoff: FloatArray

    @staticmethod
    def from_flight(flight: Flight, site: Site) -> FlightTruth:
        fixes = sorted(flight.truth, key=lambda f: f.t)
        t = np.array([f.t for f in fixes], dtype=float)
        enu = np.array([(f.e, f.n, f.u) for f in fixes], dtype=float).reshape(-1, 3)
        above = np.array([f.h - site.takeoff_h for f in fixes], dtype=float)
        if t.size:  # one sample per time
            keep = np.concatenate(([True], np.diff(t) > 0))
            t, enu, above = t[keep], enu[keep], above[keep]
        return FlightTruth(t, enu, above)

    @property
    def span(self) -> tuple[float, float]:
        if self.t.size == 0:
            return (math.nan, math.nan)
        return float(self.t[0]), float(self.t[-1])


@dataclass(frozen=True)
class GridSamples:
    """One flight's per-epoch outcomes (kept so flights can be pooled exactly)."""

    epochs: int  # airborne epochs
    covered: int  # ... with a published track
    fresh: int  # ... published and last accepted measurement <= fresh_age_s old
    errors: FloatArray  # 3D error of each covered epoch
    nees: FloatArray  # NEES of each covered epoch
    vertical: FloatArray  # |vertical error| of each covered epoch
    ages: FloatArray  # age of the last accepted measurement at each covered epoch
    rf_last: npt.NDArray[np.bool_]  # ... that measurement was an RF fix
    observable: int  # radar-observable epochs (-1: no labels)
    observable_covered: int
    observable_gross: int
    ttf_s: float
    restarts: int
    observable_startup: int = 0  # radar-observable epochs before the first tracked one
    longest_gross_s: float = 0.0  # the longest gross episode (s)
    #: the grid index of each covered epoch (two runs on one grid compare epoch by epoch)
    epoch_index: npt.NDArray[np.int64] = field(default_factory=lambda: np.zeros(0, np.int64))


@dataclass(frozen=True)
class GridScore:
    """The figures of one flight or of a pool of flights (percentages in %)."""

    flights: int
    epochs: int
    coverage_pct: float
    fresh_coverage_pct: float
    err_mean_m: float
    err_p50_m: float
    err_p95_m: float
    err_max_m: float
    gross_pct: float
    observable_epochs: int
    observable_coverage_pct: float
    observable_gross_pct: float
    anees: float
    nees_in95_pct: float
    ttf_s: float  # pooled: mean over the flights that had a confirmed track
    no_track_flights: int  # flights without any confirmed track while airborne
    restarts: int  # pooled: total
    # what the gross errors are: the share of them whose vertical error exceeds the
    # horizontal one, and the median age of the last accepted measurement at them
    gross_vertical_pct: float
    gross_age_p50_s: float
    gross_rf_pct: float  # share of gross epochs whose last accepted measurement was RF
    # radar-observable coverage from each flight's first tracked airborne epoch on
    observable_after_start_pct: float = math.nan
    # the longest gross episode (error > episode_error_m) of any flight, and the largest
    # per-flight mean error
    longest_gross_s: float = math.nan
    flight_mean_max_m: float = math.nan

    def as_dict(self) -> dict[str, float | int]:
        return asdict(self)


def _pct(num: int, den: int) -> float:
    return 100.0 * num / den if den > 0 else math.nan


def nees(err: FloatArray, P_pos: FloatArray) -> FloatArray:
    """``e^T P^-1 e`` per row: ``err`` (N, 3), ``P_pos`` (N, 3, 3); NaN for a row whose
    covariance is not finite (an output that has none)."""
    out = np.full(err.shape[0], math.nan)
    ok = np.all(np.isfinite(P_pos), axis=(1, 2))
    if not ok.any():
        return out
    sol = np.linalg.solve(P_pos[ok], err[ok][:, :, None])[:, :, 0]
    out[ok] = np.einsum("ij,ij->i", err[ok], sol)
    return out


@dataclass(frozen=True)
class EpochErrors:
    """Per grid epoch: airborne?, covered (airborne and published)?, truth, 3D error, NEES
    (error and NEES NaN where not covered)."""

    airborne: npt.NDArray[np.bool_]
    covered: npt.NDArray[np.bool_]
    truth_enu: FloatArray
    error_m: FloatArray
    nees: FloatArray


def epoch_errors(
    grid: Grid, truth: FlightTruth, settings: ScoreSettings | None = None
) -> EpochErrors:
    """The grid's epochs against truth (see the module docstring for airborne and covered)."""
    s = settings or ScoreSettings()
    ref = interpolate_truth(truth.t, truth.enu, grid.t, max_gap_s=s.max_truth_gap_s)
    above = np.full(grid.t.size, math.nan)
    if truth.t.size >= 2:
        above = interpolate_truth(
            truth.t,
            np.column_stack([truth.above_takeoff] * 3),
            grid.t,
            max_gap_s=s.max_truth_gap_s,
        )[:, 0]
    with np.errstate(invalid="ignore"):
        airborne = np.isfinite(ref[:, 0]) & (above > s.airborne_min_m)
    cov = airborne & grid.published
    d = grid.x[cov, :3] - ref[cov]
    err = np.full(grid.t.size, math.nan)
    err[cov] = np.sqrt(np.sum(d * d, axis=1))
    ne = np.full(grid.t.size, math.nan)
    ne[cov] = nees(d, grid.P[cov][:, :3, :3])
    return EpochErrors(airborne, cov, ref, err, ne)


def observable_epochs(
    t: FloatArray, airborne: npt.NDArray[np.bool_], uav_report_t: FloatArray, window_s: float
) -> npt.NDArray[np.bool_]:
    """The radar-observable epochs: airborne, with a radar report of the UAV (times
    ``uav_report_t``, any order) within ``window_s`` of the epoch."""
    rt = np.sort(np.asarray(uav_report_t, dtype=float))
    lo = np.searchsorted(rt, t - window_s, side="left")
    hi = np.searchsorted(rt, t + window_s, side="right")
    return np.asarray(airborne & (hi > lo), dtype=bool)


def score_grid(
    grid: Grid,
    truth: FlightTruth,
    uav_report_t: FloatArray | None = None,
    settings: ScoreSettings | None = None,
) -> GridSamples:
    """Score one flight's fixed-rate output (see the module docstring)."""
    s = settings or ScoreSettings()
    ee = epoch_errors(grid, truth, s)
    airborne, cov = ee.airborne, ee.covered
    fresh = cov & (grid.age_s <= s.fresh_age_s)
    err = ee.error_m[cov]
    ne = ee.nees[cov]
    vertical = np.abs(grid.x[cov, 2] - ee.truth_enu[cov, 2])
    gross = err > s.gross_error_m

    air_idx = np.flatnonzero(airborne)
    tracked = np.flatnonzero(airborne & grid.has_track)
    n_start = 0
    if uav_report_t is None:
        n_obs, n_obs_cov, n_obs_gross = -1, 0, 0
    else:
        obs = observable_epochs(grid.t, airborne, uav_report_t, s.observable_window_s)
        n_obs = int(np.count_nonzero(obs))
        n_obs_cov = int(np.count_nonzero(obs & cov))
        gross_all = np.zeros(grid.t.size, dtype=bool)
        gross_all[np.flatnonzero(cov)] = gross
        n_obs_gross = int(np.count_nonzero(obs & gross_all))
        first = int(tracked[0]) if tracked.size else grid.t.size
        n_start = int(np.count_nonzero(obs[:first]))

    over = np.zeros(grid.t.size, dtype=bool)
    over[np.flatnonzero(cov)] = err > s.episode_error_m
    ttf = math.nan
    if air_idx.size:
        t_air = grid.t[air_idx[0]]
        if tracked.size:
            ttf = float(grid.t[tracked[0]] - t_air)
    return GridSamples(
        epochs=int(air_idx.size),
        covered=int(np.count_nonzero(cov)),
        fresh=int(np.count_nonzero(fresh)),
        errors=np.asarray(err, dtype=float),
        nees=ne,
        vertical=np.asarray(vertical, dtype=float),
        ages=np.asarray(grid.age_s[cov], dtype=float),
        rf_last=np.asarray(grid.last_source[cov] == RF, dtype=bool),
        observable=n_obs,
        observable_covered=n_obs_cov,
        observable_gross=n_obs_gross,
        ttf_s=ttf,
        restarts=grid.restarts,
        observable_startup=n_start,
        longest_gross_s=longest_run(over) / grid.frequency_hz,
        epoch_index=np.flatnonzero(cov).astype(np.int64),
    )


def longest_run(flags: npt.NDArray[np.bool_]) -> int:
    """The length of the longest run of consecutive true values (0 without one)."""
    x = np.concatenate(([0], np.asarray(flags, dtype=np.int8), [0]))
    d = np.diff(x)
    starts, ends = np.flatnonzero(d == 1), np.flatnonzero(d == -1)
    return int((ends - starts).max()) if starts.size else 0


def pool(samples: Sequence[GridSamples], settings: ScoreSettings | None = None) -> GridScore:
    """The figures over one or several flights (epochs pooled; ttf averaged; restarts summed)."""
    s = settings or ScoreSettings()
    epochs = sum(x.epochs for x in samples)
    covered = sum(x.covered for x in samples)
    fresh = sum(x.fresh for x in samples)
    err = np.concatenate([x.errors for x in samples]) if samples else np.zeros(0)
    ne = np.concatenate([x.nees for x in samples]) if samples else np.zeros(0)
    ne = ne[np.isfinite(ne)]  # an output without a covariance has no NEES
    labelled = [x for x in samples if x.observable >= 0]
    n_obs = sum(x.observable for x in labelled)
    n_obs_cov = sum(x.observable_covered for x in labelled)
    n_obs_gross = sum(x.observable_gross for x in labelled)
    n_obs_start = sum(x.observable_startup for x in labelled)
    vert = np.concatenate([x.vertical for x in samples]) if samples else np.zeros(0)
    ages = np.concatenate([x.ages for x in samples]) if samples else np.zeros(0)
    rf_last = np.concatenate([x.rf_last for x in samples]) if samples else np.zeros(0, bool)
    gross = err > s.gross_error_m
    n_gross = int(np.count_nonzero(gross))
    horiz2 = err[gross] ** 2 - vert[gross] ** 2  # horizontal error squared
    lo, hi = s.nees_bounds(3)
    ttfs = [x.ttf_s for x in samples if math.isfinite(x.ttf_s)]
    nan = math.nan
    return GridScore(
        flights=len(samples),
        epochs=epochs,
        coverage_pct=_pct(covered, epochs),
        fresh_coverage_pct=_pct(fresh, epochs),
        err_mean_m=float(err.mean()) if err.size else nan,
        err_p50_m=float(np.percentile(err, 50)) if err.size else nan,
        err_p95_m=float(np.percentile(err, 95)) if err.size else nan,
        err_max_m=float(err.max()) if err.size else nan,
        gross_pct=_pct(n_gross, int(err.size)),
        observable_epochs=n_obs if labelled else -1,
        observable_coverage_pct=_pct(n_obs_cov, n_obs) if labelled else nan,
        observable_gross_pct=_pct(n_obs_gross, n_obs_cov) if labelled else nan,
        anees=float(ne.mean()) if ne.size else nan,
        nees_in95_pct=_pct(int(np.count_nonzero((ne >= lo) & (ne <= hi))), int(ne.size)),
        ttf_s=float(np.mean(ttfs)) if ttfs else nan,
        no_track_flights=sum(1 for x in samples if x.epochs > 0 and not math.isfinite(x.ttf_s)),
        restarts=sum(x.restarts for x in samples),
        gross_vertical_pct=_pct(int(np.count_nonzero(vert[gross] ** 2 > horiz2)), n_gross),
        gross_age_p50_s=float(np.median(ages[gross])) if n_gross else nan,
        gross_rf_pct=_pct(int(np.count_nonzero(rf_last[gross])), n_gross),
        observable_after_start_pct=(
            _pct(n_obs_cov, n_obs - n_obs_start) if labelled else nan
        ),
        longest_gross_s=max((x.longest_gross_s for x in samples), default=nan),
        flight_mean_max_m=max(
            (float(x.errors.mean()) for x in samples if x.errors.size), default=nan
        ),
    )


# columns of the printed table: (GridScore field, header, format)
TABLE_COLUMNS: tuple[tuple[str, str, str], ...] = (
    ("coverage_pct", "cov %", ".1f"),
    ("fresh_coverage_pct", "fresh %", ".1f"),
    ("err_mean_m", "mean m", ".1f"),
    ("err_p50_m", "p50 m", ".1f"),
    ("err_p95_m", "p95 m", ".1f"),
    ("err_max_m", "max m", ".0f"),
    ("gross_pct", "gross %", ".1f"),
    ("observable_coverage_pct", "obs cov %", ".1f"),
    ("observable_gross_pct", "obs gross %", ".1f"),
    ("anees", "ANEES", ".1f"),
    ("nees_in95_pct", "NEES in 95 % %", ".1f"),
    ("ttf_s", "first track s", ".1f"),
    ("restarts", "restarts", "d"),
)


def format_value(v: float | int, fmt: str) -> str:
    if isinstance(v, float) and not math.isfinite(v):
        return "-"
    return format(v, fmt)
