"""How well the tracker's filter could do if it knew which radar report is which UAV
(``uav_fusion analyse oracle``).

The **label oracle** (:class:`LabelOracle`) is the multi-UAV tracker with association taken
from the twin: the same profile's motion filter, radar and RF measurement models, robust
update, NIS gates, deleter, misalignment correction, horizontal-only updates (far gate, below
the ground), climb-rate hold and publication rules, but the twin, generated again in memory
(:mod:`~uav_fusion.core.analysis.labels`), says which object each radar track follows at each
report. A UAV's track takes only reports of radar tracks then following that UAV (of several
in one frame, the one with the smallest NIS), is started from the first of them (whatever its
UAV score: no wait for the classifier) and takes only the fixes of that UAV's own control
link (no wrong emitter links); a UAV keeps one id for the whole flight (a track dropped by
the deleter starts again under the same id). Reports of other objects (birds, clutter, cars,
ghosts) are never used, so it has no false tracks.

What the oracle cannot do better than the tracker is what the sensors themselves allow: the
radar's own report errors (angle noise and glint, its onboard tracker's lag), the epochs
where no radar track follows the UAV, and the RF fixes' errors. Its score is a practical floor
for association on this filter, not a strict one: a tracker that leaves a UAV's worst reports
out can do better on what it keeps, but only by missing those epochs.

**Multi-UAV** (a ``targets: multi`` definition): every flight is run twice and scored exactly
as ``uav_fusion bench`` scores it (:func:`~uav_fusion.core.bench.multi.multi_score_task`),
``tracker`` (as shipped) and ``oracle``. Printed: per flight the mean GOSPA of both, then the
benchmark's pooled multi-UAV table for both.

**Single-UAV** (a ``targets: single`` definition): the tracker issue asks, on every flight,
for a position over at least 99 % of the epochs the radar sees the UAV and for at most 1 % of
them more than 100 m off. Every flight is scored as the benchmark scores it (the fixed-rate
grid, the radar-observable epochs from the twin's labels) twice: ``tracker``
(:func:`~uav_fusion.core.bench.single.score_task`) and ``oracle``, the label oracle with the
single-UAV output rule (a track is published until ``max_coast_s`` after its last update, as
``grid_from_steps`` publishes the tracker's). For each gross epoch of the oracle the UAV's own
radar reports of the last ``window_s`` (5 s; every report of a radar track then following the
UAV, corrected for the radar's misalignment as the filter takes it) are looked at: when their
median horizontal error is above 100 m, the sensor itself had the UAV more than 100 m off,
and no association could have helped. Printed: per flight the observable coverage and gross
share of both and how many of the oracle's gross epochs had the radar's own reports that far
off; then the pooled figures and the number of flights meeting each target.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from uav_fusion.core.analysis.labels import (
    FlightSet,
    KindsByTrack,
    LabelledFlight,
    Progress,
    kind_at,
    labelled_flights,
    vehicle_links,
)
from uav_fusion.core.bench.cache import read_labels
from uav_fusion.core.bench.multi import (
    MultiFlightResult,
    MultiScoreTask,
    markdown_multi,
    multi_score_task,
    pool_multi,
)
from uav_fusion.core.bench.single import ScoreTask, score_task
from uav_fusion.core.estimators.emitters import emitter_key
from uav_fusion.core.estimators.kalman import PackedR
from uav_fusion.core.estimators.multi import MultiTracker, UavTrack, run_multi
from uav_fusion.core.estimators.objects import RadarObject
from uav_fusion.core.estimators.parts import object_start, scale_packed
from uav_fusion.core.estimators.selection import frames_input
from uav_fusion.core.profiles.model import Profile
from uav_fusion.core.profiles.settings import MultiSettings
from uav_fusion.core.records import Flight, RadarFrame, RfAttempt
from uav_fusion.core.scoring.fixed_rate import (
    FlightTruth,
    Grid,
    GridSamples,
    epoch_errors,
    grid_from_published,
    observable_epochs,
    pool,
    score_grid,
)
from uav_fusion.core.site import Site
from uav_fusion.core.twin import radar_model

FloatArray = npt.NDArray[np.float64]
Align = Callable[[float, float, float], tuple[float, float, float]]
# a radar report labelled as a vehicle's: its object, R, measurement, beyond the range gate
_Labelled = tuple[RadarObject, PackedR, tuple[float, ...], bool]


class LabelOracle(MultiTracker):
    """The multi-UAV tracker with association from the twin's labels (module text)."""

    def __init__(
        self,
        profile: Profile,
        site: Site,
        kinds: KindsByTrack,
        objects: dict[int, str],
        emitters: dict[str, str],
        vehicles: list[str],
        settings: MultiSettings | None = None,
    ) -> None:
        super().__init__(profile, site, settings or MultiSettings(emitter_misses=None))
        self.kinds = kinds
        self.vehicle_of_object = objects
        self.vehicle_of_emitter = emitters
        self.ids = {v: i + 1 for i, v in enumerate(vehicles)}
        self.own: dict[str, UavTrack] = {}

    def _track_of(self, vehicle: str) -> UavTrack | None:
        tr = self.own.get(vehicle)
        return tr if tr is not None and tr in self.tracks else None

    def _own(self, vehicle: str, tr: UavTrack) -> UavTrack:
        """``tr`` is ``vehicle``'s track, under the vehicle's id."""
        tr.id = self.ids[vehicle]
        self.own[vehicle] = tr
        return tr

    def process_radar_frame(self, frame: RadarFrame) -> None:
        t = frame.t
        cfg = self.cfg
        front = self.front
        # per vehicle: its labelled reports (object, R, measurement, beyond the range gate)
        mine: dict[str, list[_Labelled]] = {}
        for _, trk, obj, p3, r, d2 in front.reports(frame)[1]:
            lab = kind_at(self.kinds, trk.track_id, t)
            if lab is None or lab[0] != radar_model.UAV:
                continue
            vehicle = self.vehicle_of_object.get(lab[1])
            if vehicle is None:
                continue
            if (d2 > front.gate2 and not d2 <= front.far2) or obj.coasting:
                continue
            e, n_, u = p3
            z: tuple[float, ...] = p3
            far = d2 > front.gate2
            if far or u < -cfg.below_ground_m:
                z, r = (e, n_), (r[0], r[1], r[3])
            mine.setdefault(vehicle, []).append((obj, r, z, far))
        self._advance(t)
        for vehicle, cands in mine.items():
            tr = self._track_of(vehicle)
            if tr is None or not tr.confirmed:
                if tr is not None:
                    self._drop(tr, "superseded")
                obj, _, z, far = cands[0]
                x0, P0 = object_start(obj, self.profile, far or len(z) == 2)
                tr = self._own(vehicle, self._new_track(t, x0, P0, confirmed=True))
                tr.last_radar_t = t
                continue
            scored = []
            for _obj, r, z, _far in cands:
                n = tr.filter.nis(z, r)
                scored.append((n if len(z) == 3 else n * self._g3 / self._g2, r, z))
            n3, r, z = min(scored, key=lambda c: c[0])
            if n3 > self._g3:
                self._reject(tr)
                continue
            dof = len(z)
            w = self.robust.weight(n3 if dof == 3 else n3 * self._g2 / self._g3, dof)
            if dof == 2:
                self._hold_height(tr)
            tr.filter.update(z, r if w == 1.0 else scale_packed(r, 1.0 / w))
            self._accept(tr, t)
            tr.last_radar_t = t

    def process_rf(self, att: RfAttempt) -> None:
        if not att.ok or not math.isfinite(att.t + att.e + att.n):
            return
        max_cep = self.profile.rf_max_cep_m
        if max_cep is not None and att.cep is not None and att.cep > max_cep:
            return
        vehicle = self.vehicle_of_emitter.get(emitter_key(att.center_freq_hz))
        if vehicle is None:
            return
        t = att.t
        self._advance(t)
        r = self.rf_r.r_for(att.cep)
        z = (att.e, att.n)
        tr = self._track_of(vehicle)
        if tr is None:  # as the tracker: an RF start is tentative, confirmed by M of N fixes
            self._own(vehicle, self.emitters.start(t, z, r))
            return
        self.emitters.update(tr, t, z, r)


# --- multi-UAV --------------------------------------------------------------------------------


@dataclass(frozen=True)
class MultiFlightOracle:
    tag: str
    tracker: MultiFlightResult
    oracle: MultiFlightResult

    def line(self) -> str:
        return (
            f"{self.tag}: GOSPA tracker {np.mean(self.tracker.samples.distance):.1f} m, "
            f"oracle {np.mean(self.oracle.samples.distance):.1f} m"
        )


def _oracle_for(
    profile: Profile,
    site: Site,
    kinds: KindsByTrack,
    objects: dict[int, str],
    emitters: dict[str, str],
    flight: Flight,
) -> MultiTracker:
    return LabelOracle(profile, site, kinds, objects, emitters, list(flight.vehicles))


def _run_multi_pair(
    lf: LabelledFlight, profile: Profile, fs: FlightSet
) -> tuple[MultiFlightResult, MultiFlightResult]:
    """The estimators' part: the tracker and the label oracle, each run and scored by the
    benchmark's task."""
    s = fs.definition.settings
    task = MultiScoreTask(
        lf.cached, profile, fs.site, fs.definition.grid_hz, s.airborne_min_m,
        s.observable_window_s, fs.definition.excuse_grounded,
    )  # fmt: skip
    objects, emitters = vehicle_links(lf.cached.folder)
    ours = multi_score_task(task)
    oracle = functools.partial(_oracle_for, profile, fs.site, lf.kinds, objects, emitters)
    best = dataclasses.replace(multi_score_task(task, oracle), profile="oracle")
    return ours, best


def multi_oracle(
    fs: FlightSet, profile: Profile, progress: Progress | None = None
) -> Iterator[MultiFlightOracle]:
    """The multi-UAV tracker and its label oracle, flight by flight."""
    for lf in labelled_flights(fs, progress):
        ours, best = _run_multi_pair(lf, profile, fs)
        yield MultiFlightOracle(lf.tag, ours, best)


def multi_summary(flights: Sequence[MultiFlightOracle]) -> list[str]:
    """The benchmark's pooled multi-UAV table, a row for the tracker and one for the oracle."""
    results = [f.tracker for f in flights] + [f.oracle for f in flights]
    return [markdown_multi(pool_multi(results))]


# --- single-UAV -------------------------------------------------------------------------------


@dataclass(frozen=True)
class SingleOptions:
    coverage_pct: float = 99.0  # target per flight
    gross_pct: float = 1.0  # target per flight
    window_s: float = 5.0  # radar reports looked back at


@dataclass(frozen=True)
class SingleFlightOracle:
    tag: str
    tracker: GridSamples
    oracle: GridSamples
    observable: int  # the oracle grid's radar-observable epochs
    gross: int  # ... the oracle's gross epochs among them
    sensor_off: int  # ... of which the UAV's own radar reports were that far off
    gross_m: float

    @property
    def off_pct(self) -> float:
        return 100.0 * float(self.sensor_off) / max(1, self.observable)

    def line(self) -> str:
        (oc, og), (bc, bg) = observable_figures(self.tracker), observable_figures(self.oracle)
        return (
            f"{self.tag}: observable coverage / gross %: "
            f"tracker {oc:.1f} / {og:.2f}, oracle {bc:.1f} / {bg:.2f}; oracle gross epochs "
            f"with the UAV's radar reports > {self.gross_m:g} m off: "
            f"{self.sensor_off} of {self.gross} ({self.off_pct:.2f} % of observable)"
        )


def _pct(num: int, den: int) -> float:
    return 100.0 * num / den if den > 0 else float("nan")


def uav_report_errors(
    stream: Sequence[RadarFrame | RfAttempt],
    kinds: KindsByTrack,
    uav_object: int,
    truth_t: FloatArray,
    truth_enu: FloatArray,
    align: Align | None,
) -> tuple[FloatArray, FloatArray]:
    """Times and horizontal errors (m) of every report of a radar track then following the
    UAV (twin object ``uav_object``), after ``align`` (the misalignment correction)."""
    ts: list[float] = []
    errs: list[float] = []
    for item in stream:
        if not isinstance(item, RadarFrame):
            continue
        for trk in item.tracks:
            lab = kind_at(kinds, trk.track_id, item.t)
            if lab is None or lab != (radar_model.UAV, uav_object):
                continue
            e, n, _ = (trk.e, trk.n, trk.u) if align is None else align(trk.e, trk.n, trk.u)
            te = float(np.interp(item.t, truth_t, truth_enu[:, 0]))
            tn = float(np.interp(item.t, truth_t, truth_enu[:, 1]))
            ts.append(item.t)
            errs.append(math.hypot(e - te, n - tn))
    return np.asarray(ts, dtype=float), np.asarray(errs, dtype=float)


def sensor_off(
    epoch_t: FloatArray, rep_t: FloatArray, rep_err: FloatArray, window_s: float, limit_m: float
) -> npt.NDArray[np.bool_]:
    """Per epoch: the median error of the reports in ``[t - window_s, t]`` (``rep_t`` sorted)
    is above ``limit_m`` (False without a report there)."""
    out = np.zeros(epoch_t.size, dtype=bool)
    lo = np.searchsorted(rep_t, epoch_t - window_s, side="left")
    hi = np.searchsorted(rep_t, epoch_t, side="right")
    for i, (a, b) in enumerate(zip(lo.tolist(), hi.tolist(), strict=True)):
        if b > a:
            out[i] = float(np.median(rep_err[a:b])) > limit_m
    return out


def observable_figures(s: GridSamples) -> tuple[float, float]:
    """A flight's radar-observable coverage and gross share (of the covered ones), in %."""
    return _pct(s.observable_covered, s.observable), _pct(s.observable_gross, s.observable_covered)


# the single-UAV output rule: published until max_coast_s after the last update
SINGLE_RULE = MultiSettings(emitter_misses=None, output_coast_s=None)


def _run_single_pair(
    lf: LabelledFlight, profile: Profile, fs: FlightSet, truth: FlightTruth
) -> tuple[GridSamples, list[RadarFrame | RfAttempt], Grid, Align | None]:
    """The estimators' part: the tracker scored by the benchmark's task; the label oracle with
    the single-UAV output rule over the same inputs, its fixed-rate grid, and the misalignment
    correction it applied."""
    d = fs.definition
    ours = score_task(ScoreTask(lf.cached, profile, fs.site, d.grid_hz, d.settings)).samples
    objects, emitters = vehicle_links(lf.cached.folder)
    oracle = LabelOracle(
        profile, fs.site, lf.kinds, objects, emitters, list(lf.flight.vehicles), SINGLE_RULE
    )
    t0, t1 = truth.span
    stream = list(frames_input(lf.flight, profile))
    epochs = run_multi(oracle, stream, d.grid_hz, t0, t1)
    pub = [(ep.t, ep.tracks[0]) for ep in epochs if ep.tracks]
    grid = grid_from_published(
        [t for t, _ in pub],
        [o.x.tolist() for _, o in pub],
        [o.P for _, o in pub],
        d.grid_hz,
        t0,
        t1,
        profile.max_coast_s,
    )
    align = oracle.front.align.point if oracle.front.align is not None else None
    return ours, stream, grid, align


def _single_flight(
    lf: LabelledFlight, profile: Profile, fs: FlightSet, opt: SingleOptions
) -> SingleFlightOracle:
    settings = fs.definition.settings
    truth = FlightTruth.from_flight(lf.flight, fs.site)
    ours, stream, grid, align = _run_single_pair(lf, profile, fs, truth)
    labels = read_labels(lf.cached.folder)
    best = score_grid(grid, truth, labels, settings)
    # the oracle's gross epochs, and those where the radar itself had the UAV far off
    ee = epoch_errors(grid, truth, settings)
    obs = observable_epochs(grid.t, ee.airborne, labels, settings.observable_window_s)
    gross = obs & ee.covered & (ee.error_m > settings.gross_error_m)
    tt, enu = lf.flight.truth_arrays()
    rep_t, rep_err = uav_report_errors(
        stream, lf.kinds, radar_model.uav_object_id(0), tt, enu, align
    )
    off = gross & sensor_off(grid.t, rep_t, rep_err, opt.window_s, settings.gross_error_m)
    return SingleFlightOracle(
        lf.tag, ours, best, int(obs.sum()), int(gross.sum()), int(off.sum()),
        settings.gross_error_m,
    )  # fmt: skip


def single_oracle(
    fs: FlightSet,
    profile: Profile,
    options: SingleOptions | None = None,
    progress: Progress | None = None,
) -> Iterator[SingleFlightOracle]:
    """The single-UAV tracker and its label oracle, flight by flight."""
    opt = options or SingleOptions()
    for lf in labelled_flights(fs, progress):
        yield _single_flight(lf, profile, fs, opt)


def single_summary(
    flights: Sequence[SingleFlightOracle], fs: FlightSet, options: SingleOptions | None = None
) -> list[str]:
    """The pooled figures of both and the flights meeting each target (module text)."""
    opt = options or SingleOptions()
    settings = fs.definition.settings
    cov_head = f"cov >= {opt.coverage_pct:g}"
    gross_head = f"gross <= {opt.gross_pct:g}"
    out = [
        "",
        f"{'':8} {'mean m':>7} {'p95 m':>7} {'obs cov %':>9} {'obs gross %':>11} "
        f"{cov_head:>10} {gross_head:>10} {'both':>5}",
    ]
    runs = {"tracker": [f.tracker for f in flights], "oracle": [f.oracle for f in flights]}
    for name, samples in runs.items():
        sc = pool(samples, settings)
        figs = [observable_figures(s) for s in samples]
        ok_c = [c >= opt.coverage_pct for c, _ in figs]
        ok_g = [g <= opt.gross_pct for _, g in figs]
        n = len(samples)
        both = sum(a and b for a, b in zip(ok_c, ok_g, strict=True))
        out.append(
            f"{name:8} {sc.err_mean_m:7.1f} {sc.err_p95_m:7.1f} {sc.observable_coverage_pct:9.2f} "
            f"{sc.observable_gross_pct:11.2f} {sum(ok_c):>5}/{n:<4} {sum(ok_g):>5}/{n:<4} "
            f"{both:>2}/{n}"
        )
    n_gross = sum(f.gross for f in flights)
    n_off = sum(f.sensor_off for f in flights)
    off_flights = sum(f.off_pct > opt.gross_pct for f in flights)
    out.append(
        f"oracle gross epochs where the UAV's own radar reports of the last {opt.window_s:g} s "
        f"were more than {settings.gross_error_m:g} m off (median, horizontal): {n_off} of "
        f"{n_gross}; on {off_flights} flights those alone exceed {opt.gross_pct:g} % of the "
        "observable epochs"
    )
    return out
