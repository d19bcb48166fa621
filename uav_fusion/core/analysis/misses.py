"""Why the tracker misses a UAV where it should have it: every missed epoch put down to one
cause (``uav_fusion analyse misses``).

**Single-UAV** (a ``targets: single`` definition). Every flight is run and scored as
``uav_fusion bench`` scores it: the definition's grid, its airborne epochs, and among them the
radar-observable ones (a radar report of the UAV within ``observable_window_s``). Two kinds of
radar-observable epoch fall short of the tracker's acceptance (coverage of 99 % and at most
1 % of gross errors on every flight); each is put down to one cause.

An observable epoch with nothing published:

* ``start-up``: before the flight's first tracked airborne epoch (the figure the benchmark
  subtracts for ``observable_after_start_pct``);
* ``re-entry``: within ``reentry_s`` (15 s) of the start of a run of observable epochs, the
  UAV coming back into the radar's view (out of range, in the Doppler notch);
* ``other``.

An observable epoch published more than ``gross_error_m`` (100 m) off the UAV, by the last
update before it:

* ``coast``: the last update is more than ``stale_s`` (5 s) old;
* ``rf``: the last update is an RF fix and the last radar update is more than ``stale_s`` old;
* ``other object: <kind>``: the last radar update came from a radar track that was following
  another object then (ghost, bird, clutter, vehicle), as the twin knows
  (:mod:`~uav_fusion.core.analysis.labels`);
* ``UAV report off, far`` / ``near``: it came from the UAV's own radar track, and that report
  was itself more than 100 m off the UAV (horizontally, for a horizontal-only update beyond
  the range gate), with the UAV beyond / within ``far_m`` (1500 m) of the radar: the radar's
  own error (its onboard tracker's lag after a manoeuvre, angle errors at long range);
* ``UAV report close``: from the UAV's own track, with the report within 100 m: the fused
  track's own error.

Printed: per flight, the counts that are not zero; then the pooled counts with their shares
(the gross epochs as a share of the observable epochs with a position published, as the
benchmark's ``obs gross %``).

**Multi-UAV** (a ``targets: multi`` definition). Every flight is run and scored by the
benchmark's own task (:func:`~uav_fusion.core.bench.multi.multi_score_task`): the
definition's grid over the truth's span, GOSPA's optimal assignment per epoch, a UAV counted
while it is more than ``airborne_min_m`` above its pad, and "the radar sees it" from the
benchmark's labels. Each airborne epoch of a UAV with no track assigned gets one cause, the
first that applies:

* ``start-up, seen`` / ``start-up, unseen``: before the UAV's first assigned epoch, with the
  radar seeing it or not;
* ``low``: the UAV within ``low_m`` (20 m) of its pad's height (landing, a low pass);
* ``beside another UAV``: another airborne UAV within ``near_m`` (100 m, GOSPA's cut-off)
  horizontally (a crossing, two UAVs side by side);
* ``other, seen`` / ``other, unseen``.

Printed: per flight the counts that are not zero, then the pooled counts with their shares,
for all UAVs and for the silent ones (no control link).
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import numpy.typing as npt

from uav_fusion.core.analysis.labels import (
    FlightSet,
    LabelledFlight,
    Progress,
    kind_at,
    labelled_flights,
    prepared_flights,
)
from uav_fusion.core.bench.cache import read_labels, read_vehicle_labels
from uav_fusion.core.bench.multi import (
    MultiFlightResult,
    MultiScoreTask,
    multi_score_task,
    near_labels,
)
from uav_fusion.core.data import load_flight
from uav_fusion.core.estimators.consider import published_cov
from uav_fusion.core.estimators.offline import run_flight
from uav_fusion.core.estimators.steps import UPDATED, TrackerStep
from uav_fusion.core.profiles.model import Profile
from uav_fusion.core.records import RADAR
from uav_fusion.core.scoring.fixed_rate import (
    FlightTruth,
    Grid,
    epoch_errors,
    grid_from_steps,
    observable_epochs,
)
from uav_fusion.core.scoring.gospa import UavTruth

BoolArray = npt.NDArray[np.bool_]
FloatArray = npt.NDArray[np.float64]


# --- single-UAV -------------------------------------------------------------------------------


@dataclass(frozen=True)
class SingleOptions:
    reentry_s: float = 15.0
    stale_s: float = 5.0
    far_m: float = 1500.0


@dataclass(frozen=True)
class SingleFlightMisses:
    tag: str  # "[k/n] <flight id>"
    observable: int
    uncovered: Counter[str]
    gross: Counter[str]

    def line(self) -> str:
        parts = [f"{self.observable} observable"]
        if self.uncovered:
            parts.append(
                "uncovered " + ", ".join(f"{c} {v}" for c, v in sorted(self.uncovered.items()))
            )
        if self.gross:
            parts.append("gross " + ", ".join(f"{c} {v}" for c, v in sorted(self.gross.items())))
        return f"{self.tag}: " + "; ".join(parts)


def uncovered_causes(
    t: FloatArray, obs: BoolArray, covered: BoolArray, first: int, reentry_s: float
) -> list[str]:
    """The cause of each observable epoch with nothing published, in order: ``start-up``
    (index before ``first``, the first tracked airborne epoch), ``re-entry`` (less than
    ``reentry_s`` after the start of its run of observable epochs) or ``other``."""
    out: list[str] = []
    run_start = -np.inf
    for i in range(t.size):
        if not obs[i]:
            continue
        if i == 0 or not obs[i - 1]:
            run_start = float(t[i])
        if covered[i]:
            continue
        if i < first:
            out.append("start-up")
        elif t[i] - run_start < reentry_s:
            out.append("re-entry")
        else:
            out.append("other")
    return out


def gross_cause(
    t: float,
    last_update_t: float | None,
    last_radar_t: float | None,
    kind: str | None,
    report_off_m: float,
    far: bool,
    stale_s: float,
    gross_m: float,
) -> str:
    """The cause of a gross epoch at ``t`` (see the module text): from the last update's time,
    the last radar update's time, the kind of object its radar track followed then, how far
    that report was from the UAV, and whether the UAV is far from the radar."""
    if last_update_t is None or t - last_update_t > stale_s:
        return "coast"
    if last_radar_t is None or t - last_radar_t > stale_s:
        return "rf"
    if kind != "uav":
        return f"other object: {kind}"
    if report_off_m > gross_m:
        return "UAV report off, far" if far else "UAV report off, near"
    return "UAV report close"


def _track_single(
    lf: LabelledFlight, profile: Profile, fs: FlightSet, truth: FlightTruth
) -> tuple[Grid, list[TrackerStep]]:
    """The estimator's part: the single-UAV tracker over the flight, its fixed-rate grid and
    its updates (time order)."""
    result = run_flight(lf.flight, profile, fs.site)
    cons = published_cov(profile, fs.site)
    hz = fs.definition.grid_hz
    grid = grid_from_steps(result.steps, profile, hz, *truth.span, consider=cons)
    ups = [s for s in result.steps if isinstance(s, TrackerStep) and s.status == UPDATED]
    return grid, ups


def _single_flight(
    lf: LabelledFlight, profile: Profile, fs: FlightSet, opt: SingleOptions
) -> SingleFlightMisses:
    settings = fs.definition.settings
    gross_m = settings.gross_error_m
    radar_pos = np.asarray(fs.site.radar.enu, dtype=float)
    truth = FlightTruth.from_flight(lf.flight, fs.site)
    grid, ups = _track_single(lf, profile, fs, truth)
    ee = epoch_errors(grid, truth, settings)
    obs = observable_epochs(
        grid.t, ee.airborne, read_labels(lf.cached.folder), settings.observable_window_s
    )
    tracked = np.flatnonzero(ee.airborne & grid.has_track)
    first = int(tracked[0]) if tracked.size else grid.t.size
    unc = Counter(uncovered_causes(grid.t, obs, ee.covered, first, opt.reentry_s))

    ut = np.array([s.t for s in ups])
    radar_idx = [j for j, s in enumerate(ups) if s.source == RADAR]
    rt_up = ut[radar_idx] if radar_idx else np.zeros(0)
    tt, enu = lf.flight.truth_arrays()
    grs: Counter[str] = Counter()
    for i in np.flatnonzero(obs & ee.covered & (ee.error_m > gross_m)):
        t = float(grid.t[i])
        j = int(np.searchsorted(ut, t, side="right")) - 1
        jr = int(np.searchsorted(rt_up, t, side="right")) - 1
        last = float(ut[j]) if j >= 0 else None
        s = ups[radar_idx[jr]] if jr >= 0 else None
        kind, off = None, 0.0
        if s is not None:
            ka = kind_at(lf.kinds, s.track_id, s.t)
            kind = ka[0] if ka is not None else "unknown"
            p = np.array([np.interp(s.t, tt, enu[:, c]) for c in range(3)])
            z = np.asarray(s.z, dtype=float)
            off = float(np.linalg.norm(z - p[: z.size]))
        far = float(np.linalg.norm(ee.truth_enu[i] - radar_pos)) > opt.far_m
        last_radar = s.t if s is not None else None
        grs[gross_cause(t, last, last_radar, kind, off, far, opt.stale_s, gross_m)] += 1
    return SingleFlightMisses(lf.tag, int(obs.sum()), unc, grs)


def single_misses(
    fs: FlightSet,
    profile: Profile,
    options: SingleOptions | None = None,
    progress: Progress | None = None,
) -> Iterator[SingleFlightMisses]:
    """The single-UAV tracker's misses, flight by flight."""
    opt = options or SingleOptions()
    for lf in labelled_flights(fs, progress):
        yield _single_flight(lf, profile, fs, opt)


def single_summary(flights: Sequence[SingleFlightMisses], profile: str, fs: FlightSet) -> list[str]:
    """The pooled counts and shares (module text)."""
    gross_m = fs.definition.settings.gross_error_m
    n_obs = sum(f.observable for f in flights)
    uncovered: Counter[str] = Counter()
    gross: Counter[str] = Counter()
    for f in flights:
        uncovered.update(f.uncovered)
        gross.update(f.gross)
    n_cov = n_obs - sum(uncovered.values())
    name = fs.definition.name
    out = ["", f"{profile}, {name} {fs.split}: {n_obs} radar-observable epochs"]
    for c, title, of, what in (
        (uncovered, "nothing published", n_obs, "observable"),
        (gross, f"more than {gross_m:.0f} m off", n_cov, "observable and published"),
    ):
        total = sum(c.values())
        out.append(f"  {title}: {total} ({100.0 * total / max(of, 1):.2f} % of {what})")
        for cause, v in c.most_common():
            out.append(f"    {cause}: {v} ({100.0 * v / max(total, 1):.1f} %)")
    return out


# --- multi-UAV --------------------------------------------------------------------------------


@dataclass(frozen=True)
class MultiOptions:
    low_m: float = 20.0
    near_m: float = 100.0


@dataclass(frozen=True)
class MultiFlightMisses:
    tag: str
    causes: Counter[str]  # every UAV's
    silent_causes: Counter[str]  # the silent UAVs'
    epochs: int  # airborne UAV-epochs
    silent_epochs: int

    def line(self) -> str:
        summary = ", ".join(f"{c} {n}" for c, n in self.causes.most_common()) or "none"
        return f"{self.tag}: missed UAV-epochs: {summary}"


def miss_causes(
    covered: BoolArray, seen: BoolArray, low: BoolArray, beside: BoolArray
) -> list[str]:
    """The cause of each uncovered epoch of one UAV's airborne epochs, in order (module text).
    All four arrays are per airborne epoch, in time order."""
    first = np.flatnonzero(covered)
    start = int(first[0]) if first.size else covered.size
    out: list[str] = []
    for i in np.flatnonzero(~covered):
        if i < start:
            out.append("start-up, seen" if seen[i] else "start-up, unseen")
        elif low[i]:
            out.append("low")
        elif beside[i]:
            out.append("beside another UAV")
        else:
            out.append("other, seen" if seen[i] else "other, unseen")
    return out


def _at(tr: UavTruth, t: FloatArray) -> FloatArray:
    return np.column_stack([np.interp(t, tr.t, tr.enu[:, c]) for c in range(3)])


def _track_multi(task: MultiScoreTask) -> MultiFlightResult:
    """The estimator's part: the multi-UAV tracker run and scored by the benchmark's task."""
    return multi_score_task(task)


def _multi_flight(
    tag: str, folder: Path, profile: Profile, fs: FlightSet, task: MultiScoreTask,
    opt: MultiOptions,
) -> MultiFlightMisses:  # fmt: skip
    st = fs.definition.settings
    result = _track_multi(task)
    # the flight is read again for its truth
    flight = load_flight(folder, fs.site)
    truths = {v: UavTruth(*flight.truth_arrays(v)) for v in flight.vehicles}
    labels = read_vehicle_labels(folder)
    silent = {u.name for u in result.uavs if u.silent}
    counts: Counter[str] = Counter()
    silent_counts: Counter[str] = Counter()
    n_epochs = n_silent = 0
    for u in result.samples.uavs:
        tr = truths[u.name]
        pos = _at(tr, u.times)
        low = pos[:, 2] - tr.enu[0, 2] <= opt.low_m
        beside = np.zeros(u.times.size, dtype=bool)
        for name, other in truths.items():
            if name == u.name:
                continue
            op = _at(other, u.times)
            up = op[:, 2] - other.enu[0, 2] > st.airborne_min_m
            d = np.hypot(op[:, 0] - pos[:, 0], op[:, 1] - pos[:, 1])
            beside |= up & (d <= opt.near_m)
        seen = near_labels(
            u.times, np.sort(labels.get(u.name, np.zeros(0))), st.observable_window_s
        )
        c = Counter(miss_causes(u.covered(), seen, low, beside))
        counts.update(c)
        n_epochs += u.epochs
        if u.name in silent:
            silent_counts.update(c)
            n_silent += u.epochs
    return MultiFlightMisses(tag, counts, silent_counts, n_epochs, n_silent)


def multi_misses(
    fs: FlightSet,
    profile: Profile,
    options: MultiOptions | None = None,
    progress: Progress | None = None,
) -> Iterator[MultiFlightMisses]:
    """The multi-UAV tracker's missed UAV-epochs, flight by flight."""
    opt = options or MultiOptions()
    st = fs.definition.settings
    flights = prepared_flights(fs, progress)
    for k, cf in enumerate(flights, 1):
        tag = f"[{k}/{len(flights)}] {cf.flight_id}"
        if progress is not None:
            progress(tag)
        task = MultiScoreTask(
            cf, profile, fs.site, fs.definition.grid_hz, st.airborne_min_m,
            st.observable_window_s,
        )  # fmt: skip
        yield _multi_flight(tag, cf.folder, profile, fs, task, opt)


def multi_summary(flights: Sequence[MultiFlightMisses]) -> list[str]:
    """The pooled counts and shares, for all UAVs and for the silent ones."""
    pooled: Counter[str] = Counter()
    pooled_silent: Counter[str] = Counter()
    for f in flights:
        pooled.update(f.causes)
        pooled_silent.update(f.silent_causes)
    n_epochs = sum(f.epochs for f in flights)
    n_silent = sum(f.silent_epochs for f in flights)
    out: list[str] = []
    for c, title, of in (
        (pooled, f"all UAVs, {len(flights)} flights", n_epochs),
        (pooled_silent, "silent UAVs", n_silent),
    ):
        total = sum(c.values())
        pct = 100.0 * total / max(of, 1)
        out.append("")
        out.append(f"{title}: {total} of {of} airborne UAV-epochs missed ({pct:.2f} %)")
        for cause, n in c.most_common():
            out.append(f"  {n:5d}  {100.0 * n / max(total, 1):5.1f} %  {cause}")
    return out
