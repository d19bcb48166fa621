"""Multi-UAV baseline: a Stone Soup multi-target tracker over the same inputs as ours.

    python scripts/multi_baseline.py FLIGHT_FOLDER [...] [--profile tracker] [--grid-hz 1]
        [--radar-min-uav-prob P] [--jpda [--jpda-pd PD] [--jpda-max-hypotheses K]]
    python scripts/multi_baseline.py --split test [--definition multi] [--cache DIR] [...]

``--split`` takes the flights of that half of a benchmark definition from the cache, as
``uav_fusion bench`` names them for the current twin (a cache may also hold the folders of
older twin versions, which a glob would pick up too).

For every flight, the multi-UAV tracker (:func:`uav_fusion.core.estimators.multi.run_multi`)
and the Stone Soup baseline (:func:`run_stonesoup`) run over the same time-ordered radar
frames and RF fixes (``frames_input``) and give their confirmed tracks on the same grid
(the span of the flight's truth). Printed per flight: the wall time of each run
(``time.perf_counter`` around the run only; inputs built beforehand), the ratio Stone Soup /
ours, the number of distinct confirmed track ids on the grid, and per vehicle the share of
its airborne epochs (more than 5 m above its first truth sample) with a track within 100 m
(coverage), the track-epochs farther than 100 m from every vehicle (false-track epochs), and
the multi-target scores of :mod:`uav_fusion.core.scoring.gospa` (mean GOSPA, id switches).

The baseline (Stone Soup's ``MultiTargetTracker`` driven scan by scan; a scan is one radar
frame, or one RF fix):

* state ``[e, ve, n, vn, u, vu]`` (Stone Soup's order; converted to ours, ``[e, n, u, ve,
  vn, vu]``, on output); motion ``CombinedLinearGaussianTransitionModel`` of one
  ``ConstantVelocity(q)`` per axis with the profile's ``motion.q``: the continuous white-noise
  acceleration model with spectral density ``q`` per axis, as ours (``Q = q [[T^3/3, T^2/2],
  [T^2/2, T]]``; checked to 1e-12 by the tests);
* radar reports as 3D position detections, each with its own ``LinearGaussian`` measurement
  model whose R is the profile's polar radar model at the report's position (the R our tracker
  updates with), after the profile's misalignment correction
  (the site file's calibration: the corrected reports ours takes);
  RF fixes as 2D (east, north) detections with R from the CEP model. Reports
  beyond the range gate (the profile's ``far_gate_m`` when it has one: ours updates in 3D
  only out to ``range_gate_m`` and horizontally out to ``far_gate_m``, and this baseline has
  no horizontal-only mode; on the multi-UAV tune half, class filter 0.7, a 1000 m gate gave
  55.6 m GOSPA, 1500 m and 2500 m 49.6 m; ``--range-gate-m``), coasted reports
  (as the tracker does: velocity and RCS repeating the same radar track's
  previous report) and fixes with a CEP above
  ``rf.max_cep_m`` are dropped, as ours does; no UAV score or classifier: every other radar
  report is a detection (``--radar-min-uav-prob P``: a variant that also drops the reports
  whose own class probability from the radar, ``catProb``, is below ``P``);
* ``KalmanPredictor`` / ``KalmanUpdater`` (linear);
* ``DistanceHypothesiser`` with the ``Mahalanobis`` measure: Stone Soup's distance is the
  square root of the NIS and a detection is a hypothesis when it is strictly less than
  ``missed_distance``, so the gate is ``sqrt(chi2.ppf(nis_probability, dim))`` with ``dim`` 3
  for a radar scan and 2 for an RF scan (:class:`GateByDimension` picks the hypothesiser by
  the detections' dimension); the same gate as ours (NIS <= chi2 quantile);
* ``GNNWith2DAssignment``: one-to-one assignment minimising the summed Mahalanobis distances
  (ours: the summed NIS plus a velocity term) with the missed-detection hypothesis at the gate;
* ``MultiMeasurementInitiator``: every detection no confirmed track took starts a holding
  track (``SimpleMeasurementInitiator``: measured components and their covariance from the
  detection and its R, the rest from the prior: velocity 0 +- half ``max_speed_mps``,
  altitude ``rf_init_altitude_m`` +- as much for a 2D fix); at each later
  scan the holding tracks are associated (the same GNN) with the detections the confirmed
  tracks left, and a holding track with ``min_points = confirm_m`` updates (its first
  detection included) becomes a confirmed track. Holding tracks are dropped by
  :class:`MofNDeleter`: once ``confirm_m`` updates among its first ``confirm_n`` scans are out
  of reach. So M-of-N with every scan after the first detection a test (ours counts only the
  fixes of the track's emitter, and starts radar tracks from radar objects directly);
* ``UpdateTimeDeleter(max_coast_s)``: a confirmed track without an update for more than
  ``max_coast_s`` is deleted.

``--jpda``: the confirmed tracks use ``MultiTargetMixtureTracker`` with ``JPDAwithEHM`` (exact
JPDA marginals by efficient hypothesis management, per cluster of tracks sharing detections)
over ``PDAHypothesiser`` hypotheses (detection probability ``--jpda-pd``; clutter density
non-parametric: the gate volume over the detections inside it; gate ``nis_probability``, the
squared Mahalanobis distance against the chi-square quantile as ours), capped to the
``--jpda-max-hypotheses`` most probable detections per track (:class:`CappedHypothesiser`).
A track counts as updated at a scan when a detection hypothesis outweighs the missed one
(Stone Soup's rule). The initiator stays as above (GNN).

On the grid, every confirmed track is predicted to the epoch (without changing it) and output
while its last update is at most ``max_coast_s`` old, with Stone Soup's track id mapped to a
stable integer, ``uav_prob`` 1 (the baseline has no classifier) and no emitter.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass
from datetime import datetime, timedelta
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
from scipy.stats import chi2
from stonesoup.base import Property
from stonesoup.dataassociator.neighbour import GNNWith2DAssignment
from stonesoup.dataassociator.probability import JPDAwithEHM
from stonesoup.deleter.base import Deleter
from stonesoup.deleter.time import UpdateTimeDeleter
from stonesoup.hypothesiser.base import Hypothesiser
from stonesoup.hypothesiser.distance import DistanceHypothesiser
from stonesoup.hypothesiser.probability import PDAHypothesiser
from stonesoup.initiator.simple import MultiMeasurementInitiator
from stonesoup.measures import Mahalanobis
from stonesoup.models.measurement.linear import LinearGaussian
from stonesoup.models.transition.linear import (
    CombinedLinearGaussianTransitionModel,
    ConstantVelocity,
)
from stonesoup.predictor.kalman import KalmanPredictor
from stonesoup.tracker.simple import MultiTargetMixtureTracker, MultiTargetTracker
from stonesoup.types.array import CovarianceMatrix, StateVector
from stonesoup.types.detection import Detection
from stonesoup.types.multihypothesis import MultipleHypothesis
from stonesoup.types.state import GaussianState
from stonesoup.types.track import Track
from stonesoup.types.update import Update
from stonesoup.updater.kalman import KalmanUpdater

from uav_fusion.core.bench.cache import cached_flights
from uav_fusion.core.bench.definition import load_definition
from uav_fusion.core.data import load_flight
from uav_fusion.core.estimators import Profile, load_profile
from uav_fusion.core.estimators.grid import GridEpoch, TrackOutput
from uav_fusion.core.estimators.multi import MultiTracker, run_multi
from uav_fusion.core.estimators.parts import (
    RadarFront,
    alignment_from_site,
    packed_to_array,
    rf_model_from_profile,
)
from uav_fusion.core.estimators.selection import frames_input
from uav_fusion.core.records import Flight, RadarFrame, RfAttempt
from uav_fusion.core.scoring.gospa import MultiScoreSettings, UavTruth, pool, score_flight
from uav_fusion.core.scoring.metrics import interpolate_truth
from uav_fusion.core.site import Site, load_site
from uav_fusion.resources import DEFAULT_SITE, config_path

FloatArray = npt.NDArray[np.float64]

#: Stone Soup's state order [e, ve, n, vn, u, vu] -> ours [e, n, u, ve, vn, vu]
SS_TO_OURS = np.array([0, 2, 4, 1, 3, 5])
RADAR_MAPPING = (0, 2, 4)
RF_MAPPING = (0, 2)
_EPOCH = datetime(1970, 1, 1)


def to_datetime(t: float) -> datetime:
    """Stone Soup's timestamps: datetimes (microsecond resolution) from our seconds."""
    return _EPOCH + timedelta(seconds=t)


def to_seconds(ts: datetime) -> float:
    return (ts - _EPOCH).total_seconds()


# --- Stone Soup components ------------------------------------------------------------------


def transition_model(q: Sequence[float]) -> CombinedLinearGaussianTransitionModel:
    """Constant velocity per axis with spectral density ``q[i]`` (state [e, ve, n, vn, u, vu])."""
    return CombinedLinearGaussianTransitionModel([ConstantVelocity(float(v)) for v in q])


def radar_measurement_model(R: FloatArray) -> LinearGaussian:
    return LinearGaussian(ndim_state=6, mapping=RADAR_MAPPING, noise_covar=CovarianceMatrix(R))


def rf_measurement_model(R: FloatArray) -> LinearGaussian:
    return LinearGaussian(ndim_state=6, mapping=RF_MAPPING, noise_covar=CovarianceMatrix(R))


class GateByDimension(Hypothesiser):  # type: ignore[misc]
    """Delegates to the hypothesiser of the detections' dimension (one gate per dimension:
    3D radar, 2D RF); a scan holds detections of one dimension only."""

    hypothesisers: dict[int, Hypothesiser] = Property(doc="Hypothesiser per detection dimension")
    default_dim: int = Property(default=3, doc="Dimension used for a scan without detections")

    def hypothesise(
        self, track: Track, detections: set[Detection], timestamp: datetime, **kwargs: Any
    ) -> MultipleHypothesis:
        dims = {d.state_vector.shape[0] for d in detections}
        if len(dims) > 1:
            raise ValueError(f"one scan mixes detection dimensions {sorted(dims)}")
        dim = dims.pop() if dims else self.default_dim
        return self.hypothesisers[dim].hypothesise(track, detections, timestamp, **kwargs)


class MofNDeleter(Deleter):  # type: ignore[misc]
    """Holding-track deleter of an M-of-N confirmation: deletes a track (every scan appends a
    state to it: an update or a prediction) once ``m`` updates among its first ``n`` states
    are out of reach. With ``MultiMeasurementInitiator(min_points=m)``, which confirms a
    holding track at ``m`` updates before asking its deleter, this is M-of-N with the starting
    detection counted as a hit."""

    m: int = Property(doc="Updates needed")
    n: int = Property(doc="... among this many scans")

    def check_for_deletion(self, track: Track, **kwargs: Any) -> bool:
        states = len(track)
        hits = sum(1 for s in track if isinstance(s, Update))
        return bool(hits + max(0, self.n - states) < self.m)


class CappedHypothesiser(Hypothesiser):  # type: ignore[misc]
    """Keeps the missed-detection hypothesis and the ``max_detections`` most probable
    detection hypotheses of each track (caps JPDA's joint hypotheses at
    ``(max_detections + 1)`` per track), renormalised."""

    hypothesiser: Hypothesiser = Property(doc="Probability hypothesiser to cap")
    max_detections: int = Property(default=3, doc="Detection hypotheses kept per track")

    def hypothesise(
        self, track: Track, detections: set[Detection], timestamp: datetime, **kwargs: Any
    ) -> MultipleHypothesis:
        hyps = self.hypothesiser.hypothesise(track, detections, timestamp, **kwargs)
        missed = [h for h in hyps if not h]
        found = sorted((h for h in hyps if h), key=lambda h: h.probability, reverse=True)
        return MultipleHypothesis(missed + found[: self.max_detections], normalise=True)


@dataclass
class Baseline:
    """The Stone Soup tracker and what turns our records into its detections."""

    tracker: MultiTargetTracker | MultiTargetMixtureTracker
    predictor: KalmanPredictor
    profile: Profile
    site: Site
    min_radar_uav_prob: float | None = None  # drop reports whose own class probability is lower
    range_gate_m: float | None = None  # radar gate (None: the profile's far or range gate)

    def __post_init__(self) -> None:
        p = self.profile
        # the UAV track's radar R as the trackers start it: with measurement.adaptive, the
        # allowance for correlated errors at its starting value (the baseline cannot adapt it)
        self.radar_r = RadarFront(p, self.site, p.score).radar_r
        self.align = alignment_from_site(self.site)
        self.rf_r = rf_model_from_profile(p)
        gate = p.range_gate_m if p.range_gate_m is not None else self.site.radar.range_gate_m
        if p.far_gate_m is not None:  # no horizontal-only mode here: 3D out to the far gate
            gate = max(gate, p.far_gate_m)
        if self.range_gate_m is not None:
            gate = self.range_gate_m
        self.gate2 = float(gate) ** 2
        self.radar_pos = tuple(float(v) for v in self.site.radar.enu)
        self.signatures: dict[int, tuple[object, object]] = {}
        self.dropped: dict[str, int] = {}

    def _drop(self, reason: str) -> None:
        self.dropped[reason] = self.dropped.get(reason, 0) + 1

    def radar_detections(self, frame: RadarFrame) -> set[Detection]:
        """One detection per usable report of a frame (each with its own R), corrected for the
        radar's misalignment as ours is."""
        if self.align is not None:
            frame = self.align.frame(frame)
        ts = to_datetime(frame.t)
        rx, ry, rz = self.radar_pos
        out: set[Detection] = set()
        for trk in frame.tracks:
            if not math.isfinite(trk.t + trk.e + trk.n + trk.u):
                self._drop("invalid")
                continue
            sig = (trk.vel_ned, trk.rcs_dbsm)
            prev = self.signatures.get(trk.track_id)
            self.signatures[trk.track_id] = sig
            coasting = prev is not None and trk.vel_ned is not None and sig == prev
            if (trk.e - rx) ** 2 + (trk.n - ry) ** 2 + (trk.u - rz) ** 2 > self.gate2:
                self._drop("range_gate")
                continue
            if coasting:
                self._drop("coast")
                continue
            pmin = self.min_radar_uav_prob
            if pmin is not None and not (trk.uav_prob is not None and trk.uav_prob >= pmin):
                self._drop("class")
                continue
            R = packed_to_array(self.radar_r.r_at(trk.e, trk.n, trk.u))
            out.add(
                Detection(
                    StateVector([trk.e, trk.n, trk.u]),
                    timestamp=ts,
                    measurement_model=radar_measurement_model(R),
                    metadata={"radar_track": trk.track_id},
                )
            )
        return out

    def rf_detection(self, att: RfAttempt) -> Detection | None:
        if not att.ok or not math.isfinite(att.t + att.e + att.n):
            self._drop("rf_invalid")
            return None
        max_cep = self.profile.rf_max_cep_m
        if max_cep is not None and att.cep is not None and att.cep > max_cep:
            self._drop("rf_cep")
            return None
        R = packed_to_array(self.rf_r.r_for(att.cep))
        return Detection(
            StateVector([att.e, att.n]),
            timestamp=to_datetime(att.t),
            measurement_model=rf_measurement_model(R),
        )


@dataclass(frozen=True)
class JpdaSettings:
    """JPDA instead of GNN for the confirmed tracks (the initiator keeps GNN)."""

    prob_detect: float = 0.9
    max_detections: int = 3  # detection hypotheses per track


def build_baseline(
    profile: Profile,
    site: Site,
    min_radar_uav_prob: float | None = None,
    jpda: JpdaSettings | None = None,
    range_gate_m: float | None = None,
) -> Baseline:
    """The Stone Soup multi-target tracker with the profile's parameters (module text);
    ``min_radar_uav_prob``: also drop radar reports whose own UAV class probability is lower
    (or missing); ``jpda``: JPDA (module text) instead of GNN for the confirmed tracks."""
    if profile.motion_model != "cv":
        raise ValueError(f"the baseline needs a CV motion profile, {profile.name!r} is not one")
    p = profile
    predictor = KalmanPredictor(transition_model(p.q))
    updater = KalmanUpdater(measurement_model=None)
    hyp = GateByDimension(
        {
            dim: DistanceHypothesiser(
                predictor,
                updater,
                Mahalanobis(),
                missed_distance=math.sqrt(float(chi2.ppf(p.nis_probability, dim))),
            )
            for dim in (2, 3)
        }
    )
    associator = GNNWith2DAssignment(hyp)
    vs = p.init_velocity_std_mps**2
    prior = GaussianState(
        StateVector([0.0, 0.0, 0.0, 0.0, p.rf_init_altitude_m, 0.0]),
        CovarianceMatrix(np.diag([0.0, vs, 0.0, vs, p.rf_init_altitude_std_m**2, vs])),
    )
    initiator = MultiMeasurementInitiator(
        prior_state=prior,
        deleter=MofNDeleter(m=p.confirm_m, n=p.confirm_n),
        data_associator=associator,
        updater=updater,
        min_points=p.confirm_m,
    )
    max_coast = p.max_coast_s if p.max_coast_s is not None else math.inf
    deleter = UpdateTimeDeleter(timedelta(seconds=min(max_coast, 1e9)))
    tracker: MultiTargetTracker | MultiTargetMixtureTracker
    if jpda is None:
        tracker = MultiTargetTracker(
            initiator=initiator,
            deleter=deleter,
            detector=None,
            data_associator=associator,
            updater=updater,
        )
    else:
        pda = PDAHypothesiser(
            predictor,
            updater,
            clutter_spatial_density=None,  # non-parametric: gate volume / detections in it
            prob_detect=jpda.prob_detect,
            prob_gate=p.nis_probability,
        )
        tracker = MultiTargetMixtureTracker(
            initiator=initiator,
            deleter=deleter,
            detector=None,
            data_associator=JPDAwithEHM(CappedHypothesiser(pda, jpda.max_detections)),
            updater=updater,
        )
    tracker.detector_iter = None
    return Baseline(tracker, predictor, profile, site, min_radar_uav_prob, range_gate_m)


def _last_update_t(track: Track) -> float:
    for s in reversed(track.states):
        if isinstance(s, Update):
            return to_seconds(s.timestamp)
    return -math.inf


def baseline_outputs(b: Baseline, ids: dict[str, int], g: float) -> tuple[TrackOutput, ...]:
    """Every confirmed track predicted to ``g`` while its last update is at most
    ``max_coast_s`` old, by stable id."""
    max_coast = b.profile.max_coast_s
    ts = to_datetime(g)
    out: list[TrackOutput] = []
    for tr in b.tracker.tracks:
        last = _last_update_t(tr)
        if max_coast is not None and g - last > max_coast:
            continue
        if tr.timestamp > ts:
            continue
        st = b.predictor.predict(tr.state, timestamp=ts) if tr.timestamp < ts else tr.state
        x = np.asarray(st.state_vector, dtype=float).ravel()[SS_TO_OURS]
        P = np.asarray(st.covar, dtype=float)[np.ix_(SS_TO_OURS, SS_TO_OURS)]
        tid = ids.setdefault(tr.id, len(ids) + 1)
        out.append(TrackOutput(tid, g, x, P, 1.0, None, None, last))
    out.sort(key=lambda o: o.track_id)
    return tuple(out)


def run_baseline_stream(
    b: Baseline,
    stream: Sequence[RadarFrame | RfAttempt],
    grid_hz: float,
    t_start: float,
    t_end: float,
) -> list[GridEpoch]:
    """Feed ``stream`` (time order) scan by scan through the Stone Soup tracker; grid epochs
    as :func:`run_multi` takes them (each epoch once processed time reaches it)."""
    if not grid_hz > 0:
        raise ValueError(f"grid rate must be > 0, got {grid_hz}")
    step = 1.0 / grid_hz
    n_epochs = math.floor((t_end - t_start) * grid_hz + 1e-9) + 1 if t_end >= t_start else 0
    ids: dict[str, int] = {}
    out: list[GridEpoch] = []
    k = 0

    def emit(until: float) -> None:
        nonlocal k
        while k < n_epochs and t_start + k * step <= until:
            g = t_start + k * step
            out.append(GridEpoch(g, baseline_outputs(b, ids, g)))
            k += 1

    for item in stream:
        emit(item.t if item.t < t_end else t_end)
        if isinstance(item, RadarFrame):
            dets = b.radar_detections(item)
        else:
            d = b.rf_detection(item)
            if d is None:
                continue
            dets = {d}
        b.tracker.update_tracker(to_datetime(item.t), dets)
    emit(t_end)
    return out


def run_stonesoup(
    flight: Flight,
    profile: Profile,
    site: Site,
    grid_hz: float,
    t_start: float,
    t_end: float,
) -> list[GridEpoch]:
    """The Stone Soup baseline over a flight's radar frames and RF fixes: its confirmed
    tracks at every grid time ``t_start + k / grid_hz`` up to ``t_end`` (as ``run_multi``)."""
    stream = list(frames_input(flight, profile))
    return run_baseline_stream(build_baseline(profile, site), stream, grid_hz, t_start, t_end)


# --- simple figures ----------------------------------------------------------------------------


@dataclass(frozen=True)
class Figures:
    confirmed: int  # distinct track ids on the grid
    coverage: dict[str, tuple[int, int]]  # vehicle -> (covered, airborne epochs)
    false_epochs: int  # track-epochs farther than `radius_m` from every vehicle
    track_epochs: int
    gospa_mean_m: float
    id_switches: int
    epochs: int
    id_switches_kept: int = 0


def figures(
    flight: Flight,
    epochs: Sequence[GridEpoch],
    radius_m: float = 100.0,
    excuse_grounded: bool = True,
) -> Figures:
    grid_t = np.array([e.t for e in epochs], dtype=float)
    pos: dict[str, FloatArray] = {}
    air: dict[str, npt.NDArray[np.bool_]] = {}
    truths: dict[str, UavTruth] = {}
    for v in flight.vehicles:
        t, enu = flight.truth_arrays(v)
        if t.size < 2:
            continue
        truths[v] = UavTruth(t=t, enu=enu)
        pos[v] = interpolate_truth(t, enu, grid_t, max_gap_s=2.0)
        with np.errstate(invalid="ignore"):
            air[v] = np.isfinite(pos[v][:, 0]) & (pos[v][:, 2] - enu[0, 2] > 5.0)
    cov = {v: [0, int(air[v].sum())] for v in pos}
    false_epochs = 0
    n_tr = 0
    for k, ep in enumerate(epochs):
        xs = np.array([o.x[:3] for o in ep.tracks], dtype=float).reshape(-1, 3)
        n_tr += xs.shape[0]
        near_any = np.zeros(xs.shape[0], dtype=bool)
        for v, p in pos.items():
            if not np.isfinite(p[k, 0]):
                continue
            d = np.linalg.norm(xs - p[k], axis=1) if xs.size else np.zeros(0)
            near = d <= radius_m
            near_any |= near
            if air[v][k] and near.any():
                cov[v][0] += 1
        false_epochs += int((~near_any).sum())
    ids = {o.track_id for ep in epochs for o in ep.tracks}
    gospa_m, switches, kept = math.nan, 0, 0
    if truths and epochs:
        step = float(np.median(np.diff(grid_t))) if grid_t.size > 1 else 1.0
        settings = MultiScoreSettings(step_s=step, excuse_grounded=excuse_grounded)
        sc = pool([score_flight(truths, epochs, settings)])
        gospa_m, switches, kept = sc.gospa_mean_m, sc.id_switches, sc.id_switches_kept
    return Figures(
        len(ids),
        {v: (c[0], c[1]) for v, c in cov.items()},
        false_epochs,
        n_tr,
        gospa_m,
        switches,
        len(epochs),
        kept,
    )


def truth_span(flight: Flight, stream: Sequence[RadarFrame | RfAttempt]) -> tuple[float, float]:
    spans = [flight.truth_arrays(v)[0] for v in flight.vehicles]
    ts = [float(x) for t in spans for x in (t[:1].tolist() + t[-1:].tolist())]
    if not ts:
        ts = [item.t for item in stream]
    if not ts:
        raise ValueError("the flight has neither truth nor measurements")
    return min(ts), max(ts)


def _fmt_cov(f: Figures) -> str:
    parts = []
    for v, (c, n) in f.coverage.items():
        pct = 100.0 * c / n if n else math.nan
        parts.append(f"{v} {pct:.1f} % of {n}")
    return ", ".join(parts) or "-"


def compare(
    folder: Path,
    profile: Profile,
    site: Site,
    grid_hz: float,
    min_radar_uav_prob: float | None = None,
    jpda: JpdaSettings | None = None,
    range_gate_m: float | None = None,
    excuse_grounded: bool = True,
) -> dict[str, Any]:
    flight = load_flight(folder, site)
    stream = list(frames_input(flight, profile))
    t0, t1 = truth_span(flight, stream)
    mt = MultiTracker(profile, site)
    c = time.perf_counter()
    ours = run_multi(mt, stream, grid_hz, t0, t1)
    t_ours = time.perf_counter() - c
    b = build_baseline(profile, site, min_radar_uav_prob, jpda, range_gate_m)
    c = time.perf_counter()
    base = run_baseline_stream(b, stream, grid_hz, t0, t1)
    t_ss = time.perf_counter() - c
    fo = figures(flight, ours, excuse_grounded=excuse_grounded)
    fb = figures(flight, base, excuse_grounded=excuse_grounded)
    name = folder.name
    print(f"{name}: {len(stream)} scans, {len(ours)} epochs at {grid_hz:g} Hz")
    for label, f, dt in (("ours", fo, t_ours), ("stonesoup", fb, t_ss)):
        print(
            f"  {label:9s} {dt:8.3f} s  confirmed {f.confirmed:4d}  coverage {_fmt_cov(f)}  "
            f"false-track epochs {f.false_epochs} of {f.track_epochs}  "
            f"GOSPA {f.gospa_mean_m:.1f} m  id switches {f.id_switches} "
            f"({f.id_switches_kept} on kept correspondences)"
        )
    ratio = t_ss / t_ours if t_ours > 0 else math.inf
    print(f"  time ratio stonesoup / ours {ratio:.1f}; baseline dropped {b.dropped}")
    sys.stdout.flush()
    return {"flight": name, "t_ours": t_ours, "t_ss": t_ss, "ours": fo, "ss": fb}


def _pct_cell(fs: Sequence[Figures]) -> str:
    c = sum(x[0] for f in fs for x in f.coverage.values())
    n = sum(x[1] for f in fs for x in f.coverage.values())
    return f"{100.0 * c / n:.1f}" if n else "-"


def print_table(rows: Sequence[dict[str, Any]]) -> None:
    """Markdown table: one row per flight, then all flights (times summed, coverage pooled
    over the airborne epochs, counts summed, GOSPA averaged over the epochs)."""
    print()
    print(
        "| flight | ours s | Stone Soup s | ratio | coverage % ours / SS | "
        "false-track epochs ours / SS | confirmed ids ours / SS | GOSPA m ours / SS | "
        "ID switches (kept corr.) ours / SS |"
    )
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|")

    def line(
        name: str, t_o: float, t_s: float, fo: Sequence[Figures], fb: Sequence[Figures]
    ) -> None:
        ratio = t_s / t_o if t_o > 0 else math.inf
        g_o = sum(f.gospa_mean_m * f.epochs for f in fo) / max(1, sum(f.epochs for f in fo))
        g_b = sum(f.gospa_mean_m * f.epochs for f in fb) / max(1, sum(f.epochs for f in fb))
        print(
            f"| {name} | {t_o:.2f} | {t_s:.2f} | {ratio:.1f} | "
            f"{_pct_cell(fo)} / {_pct_cell(fb)} | {sum(f.false_epochs for f in fo)} / "
            f"{sum(f.false_epochs for f in fb)} | {sum(f.confirmed for f in fo)} / "
            f"{sum(f.confirmed for f in fb)} | {g_o:.1f} / {g_b:.1f} | "
            f"{sum(f.id_switches for f in fo)} ({sum(f.id_switches_kept for f in fo)}) / "
            f"{sum(f.id_switches for f in fb)} ({sum(f.id_switches_kept for f in fb)}) |"
        )

    for r in rows:
        line(r["flight"], r["t_ours"], r["t_ss"], [r["ours"]], [r["ss"]])
    if len(rows) > 1:
        line(
            f"all {len(rows)}",
            sum(r["t_ours"] for r in rows),
            sum(r["t_ss"] for r in rows),
            [r["ours"] for r in rows],
            [r["ss"] for r in rows],
        )


def split_folders(ap: argparse.ArgumentParser, args: argparse.Namespace) -> list[Path]:
    """The cache folders of ``args.split`` of ``args.definition`` for the current twin; an
    error naming the first that is missing (not generated yet)."""
    site_file = Path(args.site) if args.site else config_path(DEFAULT_SITE)
    flights = cached_flights(load_definition(args.definition), args.split, args.cache, site_file)
    missing = [cf.folder for cf in flights if not cf.folder.is_dir()]
    if missing:
        ap.error(
            f"{missing[0]}: not in the cache ({len(missing)} of {len(flights)} flights of the "
            f"{args.split} half missing); generate them with `uav_fusion bench --definition "
            f"{args.definition} --split {args.split} --cache {args.cache}`"
        )
    return [cf.folder for cf in flights]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0] if __doc__ else None)
    ap.add_argument("folders", nargs="*", type=Path, help="flight folders (or --split)")
    ap.add_argument(
        "--split",
        choices=("tune", "test"),
        help="instead of folders: this half of --definition's flights, from --cache",
    )
    ap.add_argument("--definition", default="multi", help="with --split (default: multi)")
    ap.add_argument(
        "--cache",
        type=Path,
        default=Path("out/bench_cache"),
        help="with --split: the flight cache (default: out/bench_cache)",
    )
    ap.add_argument("--profile", default="tracker", help="tracker profile (default: tracker)")
    ap.add_argument("--grid-hz", type=float, default=1.0, help="output grid rate (default: 1)")
    ap.add_argument("--site", default=None, help="site YAML (default: the shipped site)")
    ap.add_argument(
        "--radar-min-uav-prob",
        type=float,
        default=None,
        help="baseline only: drop radar reports whose own UAV class probability (catProb) is "
        "below this or missing (default: keep every report)",
    )
    ap.add_argument(
        "--jpda",
        action="store_true",
        help="baseline: JPDA (Stone Soup's JPDAwithEHM, PDA hypotheses) instead of GNN",
    )
    ap.add_argument("--jpda-pd", type=float, default=0.9, help="JPDA detection probability")
    ap.add_argument(
        "--jpda-max-hypotheses",
        type=int,
        default=3,
        help="JPDA: detection hypotheses kept per track (the most probable; default 3)",
    )
    ap.add_argument(
        "--range-gate-m",
        type=float,
        default=None,
        help="baseline only: its radar range gate (3D detections; default: the profile's "
        "far_gate_m, else its range_gate_m: ours updates in 3D out to range_gate_m and "
        "horizontally out to far_gate_m)",
    )
    ap.add_argument(
        "--strict-grounded",
        action="store_true",
        help="GOSPA: a track on a UAV that is not airborne counts as false (default: excused; "
        "uav_fusion.core.scoring.gospa)",
    )
    args = ap.parse_args(argv)
    jpda = JpdaSettings(args.jpda_pd, args.jpda_max_hypotheses) if args.jpda else None
    if jpda is not None and not (0.0 < jpda.prob_detect < 1.0 and jpda.max_detections >= 1):
        ap.error("--jpda-pd must lie in (0, 1) and --jpda-max-hypotheses be >= 1")
    if args.range_gate_m is not None and not (
        math.isfinite(args.range_gate_m) and args.range_gate_m > 0
    ):
        ap.error(f"--range-gate-m must be > 0, got {args.range_gate_m}")
    if not (math.isfinite(args.grid_hz) and args.grid_hz > 0):
        ap.error(f"--grid-hz must be > 0, got {args.grid_hz}")
    profile = load_profile(args.profile)
    if not profile.uses_tracker:
        ap.error(f"{profile.name!r} is not a tracker profile (estimator: tracker)")
    site = load_site(args.site)
    if args.split and args.folders:
        ap.error("give flight folders or --split, not both")
    folders = split_folders(ap, args) if args.split else list(args.folders)
    if not folders:
        ap.error("give flight folders or --split")
    rows = [
        compare(
            folder,
            profile,
            site,
            args.grid_hz,
            args.radar_min_uav_prob,
            jpda,
            args.range_gate_m,
            not args.strict_grounded,
        )
        for folder in folders
    ]
    print_table(rows)
    return 0


if __name__ == "__main__":
    sys.exit(main())
