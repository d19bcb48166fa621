"""The tracker: every radar report of every frame is a candidate; one UAV track is kept.

Components come from the profile: a motion filter (CV or IMM,
:mod:`~uav_fusion.core.estimators.filters`), measurement models that own their R (fixed, polar
radar, CEP-based RF), a robust weight (none, Student-t, Huber), the NIS gate, M-of-N
initiation and a deleter (:mod:`~uav_fusion.core.estimators.components`), and the radar object
table with its UAV score (:mod:`~uav_fusion.core.estimators.objects`).

Per radar frame (all reports share one time):

1. every finite report updates its radar object (its own filter and score), whatever else
   happens to it; non-finite reports are discarded (``invalid``);
2. with a track: the deleter may drop it (``max_coast``); otherwise it is predicted to the
   frame's time once;
3. reports beyond the range gate are discarded (``range_gate``), except, with
   ``far_gate_m``, those inside the far gate: they stay candidates with their horizontal
   position only (R's horizontal block; before such an update the vertical velocity is held
   near zero as for RF fixes, and a track started from such a report takes the RF start's
   height prior, ``rf_init_altitude_m`` and ``rf_init_altitude_std_m``, with no climb);
4. confirmed track: a report is *eligible* when its object's score is at least
   ``follow_min``; of the eligible reports inside the NIS gate the one with the smallest
   ``NIS - 2 score`` (global nearest neighbour with the score as prior log-odds) updates the
   track with ``R / w`` (``w`` the robust weight); the others are ``not_selected``. When no
   eligible report is inside the gate, the most UAV-like eligible report makes the frame's
   ``coasted`` step (a rejection); ineligible reports are discarded (``score``). With
   ``challenge_s`` > 0, before that: when, for ``challenge_s`` seconds, one and the same
   object outside the gate has reached ``init_min`` (with ``init_min_reports`` reports) and
   outscored the followed object by ``challenge_margin``, the radar's track the UAV track
   follows has most likely left the UAV (the radar's own tracker swapped it onto another
   object, while the UAV's evidence, its class and RF support, went to a new track id): the
   track is dropped (``reinit_challenged``) and started again from the reports of the frame
   (step 5);
5. no confirmed track: the object with the highest score that reaches ``init_min`` with at
   least ``init_min_reports`` reports starts a confirmed track from its own filter's state
   (position and velocity); a tentative RF track is confirmed by an eligible report inside
   its gate or superseded by such an object.

An RF fix (``ok`` attempts only) credits every radar object it agrees with, then is gated
and fused with its CEP-based R (or coasts); without any track it starts a tentative track
that needs M of N hits (NIS gate and speed bound) to be confirmed, as in the paper profile.

Every report and fix yields exactly one :class:`TrackerStep` (a :class:`Step` that also
carries its measurement ``z``, the object score and the robust weight), with the statuses of
:mod:`~uav_fusion.core.estimators.paper`, so Table II and every consumer of steps work
unchanged.

Fixed-rate output needs only :attr:`confirmed`, :attr:`last_update_t`, :meth:`best_track`
and :meth:`predict_to` (which predicts a copy of the filter: the track is not changed).
"""

from __future__ import annotations

import math
import struct
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
import numpy.typing as npt

from uav_fusion.core.estimators.components import (
    CepRfR,
    Deleter,
    FixedRadarR,
    FixedRfR,
    HuberWeight,
    MofN,
    NoRobust,
    PolarRadarR,
    RadarAlignment,
    RadarRModel,
    RfRModel,
    RobustWeight,
    StudentTWeight,
    scale_packed,
)
from uav_fusion.core.estimators.filters import CvFilter, ImmFilter, MotionFilter
from uav_fusion.core.estimators.grid import Outputs, StepGrid, step_outputs
from uav_fusion.core.estimators.kalman import PackedR, expand_cov3, expand_upper, pack_r
from uav_fusion.core.estimators.objects import ObjectTable, RadarObject
from uav_fusion.core.estimators.profile import Profile
from uav_fusion.core.estimators.selection import frames_input
from uav_fusion.core.estimators.smoothing import SegmentSmoother
from uav_fusion.core.estimators.steps import (
    COASTED,
    DISCARDED,
    INITIALISED,
    RESET,
    TENTATIVE,
    UPDATED,
    Step,
    nis_gate,
)
from uav_fusion.core.records import RADAR, RF, Flight, RadarFrame, RadarTrack, RfAttempt
from uav_fusion.core.site import Site

FloatArray = npt.NDArray[np.float64]

_pack = struct.Struct("27d").pack
_NAN_STATE = _pack(*(math.nan,) * 27)
# a filter's (x, P) lists with their packed bytes, mode probabilities and effective q
_Packed = tuple[object, object, bytes, tuple[float, ...], tuple[float, float, float]]
# a candidate report of a frame: (index in the frame, report, its object, the object's score,
# z, R, NIS against the track, inside the gate)
_Scored = tuple[int, RadarTrack, RadarObject, float, tuple[float, ...], PackedR, float, bool]


class TrackerStep(Step):
    """A :class:`Step` with the measurement, its object's UAV score, the robust weight, the
    IMM mode probabilities and the track segment (a new one starts at every track start)."""

    __slots__ = ("mode_probs", "q_eff", "score", "segment", "weight", "z")

    def __init__(
        self,
        t: float,
        source: str,
        status: str,
        reason: str | None,
        nis: float | None,
        state: bytes,
        dim: int,
        track_id: int | None,
        seq: int,
        z: tuple[float, ...],
        score: float | None,
        weight: float | None,
        mode_probs: tuple[float, ...],
        segment: int,
        q_eff: tuple[float, float, float],
    ) -> None:
        self.t = t
        self.source = source
        self.status = status
        self.reason = reason
        self.nis = nis
        self._state = state
        self._x = None
        self._P = None
        self.dim = dim
        self.track_id = track_id
        self.seq = seq
        self.z = z
        self.score = score
        self.weight = weight
        self.mode_probs = mode_probs
        self.segment = segment
        self.q_eff = q_eff

    def with_state(self, state: bytes) -> TrackerStep:
        """A copy with another packed state (x then the upper triangle of P)."""
        return TrackerStep(
            self.t,
            self.source,
            self.status,
            self.reason,
            self.nis,
            state,
            self.dim,
            self.track_id,
            self.seq,
            self.z,
            self.score,
            self.weight,
            self.mode_probs,
            self.segment,
            self.q_eff,
        )


@dataclass(frozen=True)
class TrackEstimate:
    """The tracker's UAV track at its last processed time."""

    t: float
    x: FloatArray
    P: FloatArray
    confirmed: bool
    last_update_t: float | None
    radar_object: int | None
    mode_probs: tuple[float, ...]


def radar_model_from_profile(profile: Profile, site: Site) -> RadarRModel:
    if profile.radar_model == "polar":
        return PolarRadarR(
            tuple(float(v) for v in site.radar.enu),  # type: ignore[arg-type]
            profile.radar_sigma_range_m,
            math.radians(profile.radar_sigma_az_deg),
            math.radians(profile.radar_sigma_el_deg),
            profile.radar_floor_m,
            profile.radar_low_el_gain,
            profile.radar_low_el_deg,
        )
    return FixedRadarR(pack_r(profile.r_radar))


def alignment_from_profile(profile: Profile, site: Site) -> RadarAlignment | None:
    """The radar's misalignment correction (``measurement.radar.az_bias_deg`` /
    ``el_bias_deg``), or None when both are 0."""
    if not (profile.radar_az_bias_deg or profile.radar_el_bias_deg):
        return None
    return RadarAlignment(site.radar.enu, profile.radar_az_bias_deg, profile.radar_el_bias_deg)


def rf_model_from_profile(profile: Profile) -> RfRModel:
    fixed = pack_r(profile.r_rf)
    if profile.rf_model == "cep":
        return CepRfR(
            profile.rf_cep_scale,
            profile.rf_floor_m,
            profile.rf_ref_sensors,
            profile.rf_sensor_exponent,
            fixed,
        )
    return FixedRfR(fixed)


def robust_from_profile(profile: Profile) -> RobustWeight:
    if profile.robust == "student_t":
        return StudentTWeight(profile.robust_dof)
    if profile.robust == "huber":
        return HuberWeight(profile.robust_huber_k)
    return NoRobust()


def motion_filter_from_profile(profile: Profile) -> MotionFilter:
    if profile.motion_model == "imm":
        return ImmFilter(profile.imm_q, profile.imm_transition, profile.imm_initial)
    return CvFilter(profile.q)


def radar_gates2(profile: Profile, site: Site) -> tuple[float, float]:
    """The squared 3D range gate (the profile's, else the site's) and the squared far gate
    (``far_gate_m``; 0 without one, or when it is not beyond the 3D gate)."""
    gate = profile.range_gate_m if profile.range_gate_m is not None else site.radar.range_gate_m
    far = profile.far_gate_m
    return float(gate) ** 2, (float(far) ** 2 if far is not None and far > gate else 0.0)


def object_start(obj: RadarObject, profile: Profile, flat: bool) -> tuple[list[float], FloatArray]:
    """A new track's state and covariance from a radar object's own filter; ``flat`` (the
    object reported beyond the 3D range gate): no usable height, so the RF start's height
    prior (``rf_init_altitude_m`` +- ``rf_init_altitude_std_m``) and no climb instead."""
    kf = obj.kf
    assert kf is not None
    x = list(kf.x)
    P = expand_upper(kf.P)
    if flat:
        x[2], x[5] = profile.rf_init_altitude_m, 0.0
        P[2, :] = P[:, 2] = P[5, :] = P[:, 5] = 0.0
        P[2, 2] = profile.rf_init_altitude_std_m**2
        P[5, 5] = profile.vz_hold_sigma_mps**2
    return x, P


class Tracker:
    """Radar + RF UAV tracker over all radar objects (see the module text)."""

    kind = "tracker"
    fixed_rate = True
    reads = "frames"

    def __init__(
        self,
        profile: Profile,
        site: Site,
        grid_hz: float | None = 10.0,
        t0: float | None = None,
        t1: float | None = None,
        smooth: bool = False,
    ) -> None:
        self.profile = profile
        self.site = site
        self.cfg = profile.score
        self.radar_r = radar_model_from_profile(profile, site)
        self._align = alignment_from_profile(profile, site)
        self.rf_r = rf_model_from_profile(profile)
        self.robust = robust_from_profile(profile)
        r_obj = self.radar_r
        self._extra_var = 0.0  # UAV-track R = object R + this on each diagonal element
        if isinstance(r_obj, PolarRadarR):
            # each object's own filter sees the per-report error (its erratic-motion cue
            # would vanish under the UAV track's floor for correlated errors)
            f_obj = min(r_obj.floor_m, self.cfg.object_floor_m)
            self._extra_var = r_obj.floor_m**2 - f_obj**2
            r_obj = replace(r_obj, floor_m=f_obj)
        self._r_obj = r_obj
        self.objects = ObjectTable(self.cfg, r_obj)
        self.deleter = Deleter(profile.max_coast_s, profile.max_consecutive_rejections)
        self._g2 = nis_gate(profile.nis_probability, 2)
        self._g3 = nis_gate(profile.nis_probability, 3)
        self._gate2, self._far2 = radar_gates2(profile, site)  # far: 0 without a far gate
        self._radar_pos = tuple(float(v) for v in site.radar.enu)
        self.filter: MotionFilter | None = None
        self.t: float | None = None
        self.last_update_t: float | None = None
        self.confirmed = False
        self.followed: int | None = None  # radar object id of the last radar update
        self.last_3d_t: float | None = None  # time of the last 3D radar update
        self.last_radar_t: float | None = None  # ... of any radar update (3D or horizontal)
        # the horizontal position after its last update (association.takeover.reach_margin_m)
        self._last_pos = (0.0, 0.0)
        self.consecutive_rejections = 0
        # (object id, since when) of a strong object outside the gate that outscores the
        # followed one (association.takeover.challenge_s)
        self._challenger: tuple[int, float] | None = None
        self.segment = -1
        self._mofn: MofN | None = None
        self._last_hit = (0.0, 0.0, 0.0)
        self._pending_reset: str | None = None
        self._seq = 0
        self.counters: dict[str, int] = {}
        # (x, P, packed bytes, mode probabilities, effective q) of the last step's state
        self._packed: _Packed = (None, None, b"", (), (0.0, 0.0, 0.0))
        # the estimator interface: fixed-rate output, live fixed-lag smoothing
        self._args = (grid_hz, t0, t1, smooth)
        self.grid = StepGrid(profile, grid_hz, t0, t1) if grid_hz is not None else None
        lag = profile.smoother_lag_s
        live = smooth and lag is not None and math.isfinite(lag)
        self.smoother = SegmentSmoother(lag) if live and lag is not None else None

    # --- the estimator interface (uav_fusion.core.estimators.base) ----------------------
    def radar_frame(self, frame: RadarFrame) -> Outputs:
        return self._outputs(self.process_radar_frame(frame))

    def rf_attempt(self, attempt: RfAttempt) -> Outputs:
        return self._outputs(self.process_rf(attempt))

    def advance(self, t: float) -> Outputs:
        return Outputs(grid=self.grid.advance(t)) if self.grid is not None else Outputs()

    def finish(self) -> Outputs:
        out = Outputs(grid=self.grid.finish()) if self.grid is not None else Outputs()
        if self.smoother is not None:
            out.smoothed = self.smoother.finish()
        return out

    def restart(self, reason: str) -> None:
        """A new timeline: a new tracker (the old one's smoothing window is dropped)."""
        del reason
        self.__init__(self.profile, self.site, *self._args)  # type: ignore[misc]

    def measurement(self, step: Step) -> tuple[FloatArray, FloatArray | None] | None:
        z = getattr(step, "z", None)
        if z is None:
            return None
        if step.source == RADAR and len(z) == 3:
            return np.asarray(z, dtype=float), expand_cov3(self.radar_r.r_at(z[0], z[1], z[2]))
        return np.asarray(z, dtype=float), None

    def flight_input(self, flight: Flight) -> list[RadarFrame | RfAttempt]:
        return frames_input(flight, self.profile)

    def status(self) -> dict[str, object]:
        """The followed radar object, its UAV score and probability, and the time since the
        last accepted measurement and the last 3D radar update."""
        best = self.best_track()
        if best is None:
            return {"track": "tentative" if self.active else "none"}
        out: dict[str, object] = {"track": "confirmed"}
        ref = self.t
        if best.last_update_t is not None and ref is not None:
            out["since_last_accepted_s"] = f"{ref - best.last_update_t:.3f}"
        if ref is not None:
            last_3d = self.last_3d_t
            out["since_last_3d_radar_s"] = "-" if last_3d is None else f"{ref - last_3d:.3f}"
        fol = best.radar_object
        obj = self.objects.objects.get(fol) if fol is not None else None
        if obj is not None:
            score = obj.score(self.cfg)
            out["followed_radar_track"] = obj.id
            out["uav_score"] = f"{score:.3f}"
            out["uav_probability"] = f"{1.0 / (1.0 + math.exp(-max(-30.0, min(30.0, score)))):.3f}"
        return out

    def _outputs(self, steps: list[TrackerStep]) -> Outputs:
        out = step_outputs(self.grid, list[Step](steps))
        sm = self.smoother
        if sm is not None:
            for s in steps:
                if s.counted:
                    out.smoothed += sm.push(s)
        return out

    # --- fixed-rate accessors -----------------------------------------------------------
    @property
    def active(self) -> bool:
        return self.filter is not None

    def best_track(self) -> TrackEstimate | None:
        """The confirmed UAV track at its last processed time, or None."""
        f = self.filter
        if f is None or not self.confirmed or self.t is None:
            return None
        x, p = f.mean()
        return TrackEstimate(
            self.t,
            np.array(x, dtype=float),
            expand_upper(p),
            True,
            self.last_update_t,
            self.followed,
            f.mode_probabilities(),
        )

    def predict_to(self, t: float) -> tuple[FloatArray, FloatArray]:
        """The track predicted to ``t`` (IMM: the combined estimate of the mixed
        prediction) without changing the filter. Raises ValueError without a track or for
        ``t`` before the track's time."""
        f = self.filter
        if f is None or self.t is None:
            raise ValueError("predict_to: no track")
        dt = t - self.t
        if dt < 0:
            raise ValueError(f"predict_to: {t} is before the track's time {self.t}")
        c = f.copy()
        c.predict(dt)
        x, p = c.mean()
        return np.array(x, dtype=float), expand_upper(p)

    # --- bookkeeping --------------------------------------------------------------------
    def _count(self, key: str, n: int = 1) -> None:
        c = self.counters
        c[key] = c.get(key, 0) + n

    def _step(
        self,
        t: float,
        source: str,
        status: str,
        reason: str | None,
        nis: float | None,
        z: tuple[float, ...],
        track_id: int | None,
        score: float | None = None,
        weight: float | None = None,
    ) -> TrackerStep:
        f = self.filter
        if f is not None:
            x, p = f.mean()
            # the filters install new lists on every change, so the same two lists are the
            # same state: pack it once for all the steps of a frame that leave it unchanged
            # (the mode probabilities and the effective q change only with them too)
            packed = self._packed
            if x is packed[0] and p is packed[1]:
                state, probs, q = packed[2], packed[3], packed[4]
            else:
                state = _pack(*x, *p)
                probs = f.mode_probabilities()
                q = f.effective_q()
                self._packed = (x, p, state, probs, q)
        else:
            state = _NAN_STATE
            probs = ()
            q = (0.0, 0.0, 0.0)
        seq = self._seq
        self._seq = seq + 1
        if status == DISCARDED:
            c = self.counters
            c[DISCARDED] = c.get(DISCARDED, 0) + 1
            key = f"rejected_{reason}"
            c[key] = c.get(key, 0) + 1
        return TrackerStep(
            t, source, status, reason, nis, state, len(z), track_id, seq, z, score, weight,
            probs, self.segment, q,
        )  # fmt: skip

    def _drop(self, reason: str) -> None:
        if self.filter is not None:
            if self.confirmed:
                self._count(f"reinit_{reason}")
                self._count("reinitialisations")
                self._pending_reset = reason
            else:
                self._count("tentative_dropped")
        self.filter = None
        self.confirmed = False
        self._mofn = None
        self.consecutive_rejections = 0
        self.followed = None
        self._challenger = None

    def _advance(self, t: float) -> bool:
        """Deleter check and prediction to ``t``; False when ``t`` is before the track."""
        if self.filter is None or self.t is None:
            return True
        dt = t - self.t
        if dt < 0:
            return False
        if self.deleter.coast_expired(t, self.last_update_t):
            self._drop("max_coast")
            return True
        self.filter.predict(dt)
        self.t = t
        return True

    def _start(
        self,
        t: float,
        x: list[float],
        P: FloatArray,
        tentative: bool,
    ) -> None:
        f = motion_filter_from_profile(self.profile)
        f.set_state(x, P)
        self.filter = f
        self.t = t
        self.last_update_t = t
        self.consecutive_rejections = 0
        self.confirmed = not tentative
        self.segment += 1
        self.last_3d_t = None
        self.last_radar_t = None
        self._last_pos = (x[0], x[1])

    def _confirmed_status(self) -> tuple[str, str | None]:
        reason = self._pending_reset
        self._pending_reset = None
        status = INITIALISED if reason is None else RESET
        self._count(status)
        return status, reason

    # --- radar --------------------------------------------------------------------------
    def process_radar_frame(self, frame: RadarFrame) -> list[TrackerStep]:
        """One radar frame; returns one step per report, in the frame's order (a report's
        step carries it as corrected for the radar's misalignment, when the profile sets one)."""
        t = frame.t
        c = self.counters
        tracks = frame.tracks
        if tracks:
            n = len(tracks)
            c["measurements"] = c.get("measurements", 0) + n
            c["radar_measurements"] = c.get("radar_measurements", 0) + n
        out: list[TrackerStep | None] = [None] * len(tracks)
        objs: list[tuple[int, RadarTrack, RadarObject, PackedR]] = []
        r_at = self._r_obj.r_at
        update = self.objects.update
        dv = self._extra_var
        isfinite = math.isfinite
        # each report's position, corrected for the radar's misalignment (report index -> z)
        zs: dict[int, tuple[float, float, float]] = {}
        align = self._align.point if self._align is not None else None
        for i, trk in enumerate(tracks):
            e, n_, u = trk.e, trk.n, trk.u
            if not isfinite(trk.t + e + n_ + u):
                z = (e, n_, u)
                out[i] = self._step(t, RADAR, DISCARDED, "invalid", None, z, trk.track_id)
                continue
            if align is not None:
                e, n_, u = align(e, n_, u)
            p3 = zs[i] = (e, n_, u)
            ro = r_at(e, n_, u)
            r = (ro[0] + dv, ro[1], ro[2], ro[3] + dv, ro[4], ro[5] + dv) if dv else ro
            objs.append((i, trk, update(trk, ro, p3), r))
        if not self._advance(t):
            for i, trk, _, _ in objs:
                out[i] = self._step(t, RADAR, DISCARDED, "out_of_order", None, zs[i], trk.track_id)
            return [s for s in out if s is not None]
        cands: list[tuple[int, RadarTrack, RadarObject, float]] = []
        rs: dict[int, PackedR] = {}
        rx, ry, rz = self._radar_pos
        gate2 = self._gate2
        cfg = self.cfg
        skip_coasts = cfg.skip_radar_coasts
        far2 = self._far2
        far: set[int] = set()  # reports beyond the range gate, kept as 2D candidates
        for i, trk, obj, r in objs:
            rs[i] = r
            e, n_, u = zs[i]
            d2 = (e - rx) ** 2 + (n_ - ry) ** 2 + (u - rz) ** 2
            if d2 > gate2:
                if d2 <= far2 and not (obj.coasting and skip_coasts):
                    # inside the far gate: a horizontal-only candidate (R's horizontal
                    # block; the elevation is too poor out there)
                    far.add(i)
                    rs[i] = (r[0], r[1], r[3])
                    cands.append((i, trk, obj, obj.score(cfg)))
                    continue
                out[i] = self._step(t, RADAR, DISCARDED, "range_gate", None, zs[i], trk.track_id)
            elif obj.coasting and skip_coasts:
                out[i] = self._step(t, RADAR, DISCARDED, "coast", None, zs[i], trk.track_id)
            else:
                cands.append((i, trk, obj, obj.score(cfg)))
        if cands:
            for i, step in self._radar_candidates(t, cands, rs, far, zs):
                out[i] = step
        if self.profile.notch_after_s is not None:
            self._notch(t)
        return [s for s in out if s is not None]

    def _notch(self, t: float) -> None:
        """At a radar frame: no radar update for ``update.notch_after_s`` with the track
        within ``update.notch_range_m`` of the radar. The radar would see the UAV there
        unless its radial speed sits in the Doppler notch, so a pseudo-measurement radial
        speed = 0 (sigma ``update.notch_sigma_mps``) is fused (a hover stops the coast's
        drift). No step is made; the next step carries the state."""
        p = self.profile
        f = self.filter
        after = p.notch_after_s
        last = self.last_radar_t
        if f is None or not self.confirmed or after is None or last is None or t - last < after:
            return
        x = f.mean()[0]
        rx, ry, rz = self._radar_pos
        dx, dy, dz = x[0] - rx, x[1] - ry, x[2] - rz
        rng = math.sqrt(dx * dx + dy * dy + dz * dz)
        if not 1.0 < rng <= p.notch_range_m:
            return
        sd = p.notch_sigma_mps
        f.update_linear((0.0, 0.0, 0.0, dx / rng, dy / rng, dz / rng), 0.0, sd * sd)
        self._count("notch")

    def _radar_candidates(
        self,
        t: float,
        cands: list[tuple[int, RadarTrack, RadarObject, float]],
        rs: dict[int, PackedR],
        far: set[int],
        zs: dict[int, tuple[float, float, float]],
    ) -> list[tuple[int, TrackerStep]]:
        cfg = self.cfg
        res: list[tuple[int, TrackerStep]] = []
        f = self.filter
        if f is not None:
            g = self._g3
            scored: list[_Scored] = []
            # the CV filter's kernel directly (what CvFilter.nis calls for a 3D z)
            nis3 = f.kf.nis3 if isinstance(f, CvFilter) else None
            mark = self.objects.mark_fused if self.confirmed else None
            cap = cfg.lost_sigma_m
            if mark is not None and cap > 0:
                p = f.mean()[1]
                if (p[0] if p[0] > p[6] else p[6]) > cap * cap:
                    # a long coast: the gate spans far more than the UAV's neighbourhood, so
                    # an object inside it agrees with nothing in particular (not recorded)
                    mark = None
            fused_nis = cfg.fused_nis
            reach = cfg.reach_margin_m
            g2 = self._g2
            for i, trk, obj, s in cands:
                r = rs[i]
                z: tuple[float, ...]
                if far and i in far:
                    z = zs[i][:2]
                    nis = f.nis(z, r)
                    inside = nis <= g2
                else:
                    z = zs[i]
                    nis = nis3(z[0], z[1], z[2], r) if nis3 is not None else f.nis(z, r)
                    inside = nis <= g
                if inside and reach > 0 and trk.track_id != self.followed:
                    inside = self._reachable(t, z[0], z[1], reach)
                if mark is not None:
                    mark(obj, nis <= fused_nis, t)
                scored.append((i, trk, obj, s, z, r, nis, inside))
            if not self.confirmed:
                # a tentative RF track: only an object strong enough to start a track may
                # confirm it (inside its gate) or supersede it (_initiate)
                strong = [
                    e
                    for e in scored
                    if e[7] and e[3] >= cfg.init_min and e[2].n_reports >= cfg.init_min_reports
                ]
                if strong:
                    best = min(strong, key=lambda e: (e[6] - 2.0 * e[3], e[0]))
                    self.confirmed = True
                    self._pending_reset = None
                    self._count("confirmed")
                    res.append((best[0], self._take_radar(t, f, best, 1.0)))
                    for e in scored:
                        if e is not best:
                            res.append((e[0], self._discard_report(t, e, "not_selected")))
                    return res
                return self._initiate(t, cands, far, zs)
            if cfg.challenge_s > 0 and self._challenged(t, scored):
                # the followed object has been outscored by a strong object outside the
                # gate for challenge_s: the radar's track has most likely left the UAV
                self._drop("challenged")
                return self._initiate(t, cands, far, zs)
            eligible = [e for e in scored if e[3] >= cfg.follow_min]
            in_gate = [e for e in eligible if e[7]]
            if in_gate:
                best = min(in_gate, key=lambda e: (e[6] - 2.0 * e[3], e[0]))
                w = self.robust.weight(best[6], len(best[4]))
                res.append((best[0], self._take_radar(t, f, best, w)))
                for e in scored:
                    if e is not best:
                        why = "not_selected" if e[3] >= cfg.follow_min else "score"
                        res.append((e[0], self._discard_report(t, e, why)))
                return res
            # nothing usable inside the gate: a rejection of the track only when the object
            # it follows, or one strong enough to start a track, disagrees with it
            contra = [
                e
                for e in eligible
                if e[1].track_id == self.followed
                or (e[3] >= cfg.init_min and e[2].n_reports >= cfg.init_min_reports)
            ]
            if contra:
                best = max(contra, key=lambda e: (e[3], -e[0]))
                i, trk, obj, s, z, r, nis, _ = best
                if self.deleter.too_many_rejections(self.consecutive_rejections + 1):
                    # this rejection drops the track: the reports of the frame (the one that
                    # disagreed included) may start the next one at once
                    self._count("rejected_nis")
                    self._drop("max_rejections")
                    return self._initiate(t, cands, far, zs)
                res.append((i, self._rejected(t, RADAR, nis, z, trk.track_id, s)))
                for e in scored:
                    if e is best:
                        continue
                    why = "nis" if e[3] >= cfg.follow_min else "score"
                    res.append((e[0], self._discard_report(t, e, why)))
                return res
            for e in scored:
                why = "nis" if e[3] >= cfg.follow_min else "score"
                res.append((e[0], self._discard_report(t, e, why)))
            return res
        # no confirmed track (none, or a tentative RF track): a strong object starts one
        return self._initiate(t, cands, far, zs)

    def _take_radar(self, t: float, f: MotionFilter, e: _Scored, w: float) -> TrackerStep:
        """Update the track with candidate ``e`` (R / ``w``; a horizontal-only candidate holds
        the climb rate first) and make its ``updated`` step; the track now follows its
        object."""
        _, trk, _, s, z, r, nis, _ = e
        if len(z) == 2:
            self._hold_vz(t, f)
            self._count("updated_radar_horizontal")
        f.update(z, scale_packed(r, 1.0 / w) if w != 1.0 else r)
        step = self._used(t, RADAR, nis, z, trk.track_id, s, w)
        self.followed = trk.track_id
        self.last_radar_t = t
        if len(z) == 3:
            self.last_3d_t = t
        return step

    def _reachable(self, t: float, e: float, n: float, margin: float) -> bool:
        """Whether the UAV could have flown from the track's position at its last update to
        (``e``, ``n``) by ``t``: within ``track.max_speed_mps`` times the time since, plus
        ``margin`` (measurement errors; no limit without a maximum speed)."""
        vmax = self.profile.max_speed_mps
        if vmax is None or self.last_update_t is None:
            return True
        d = vmax * max(0.0, t - self.last_update_t) + margin
        e0, n0 = self._last_pos
        return (e - e0) ** 2 + (n - n0) ** 2 <= d * d

    def _challenged(self, t: float, scored: Sequence[_Scored]) -> bool:
        """Whether a strong object outside the gate (score >= ``init_min`` and at least
        ``challenge_margin`` above the followed object's) has done so for ``challenge_s``."""
        cfg = self.cfg
        lo = cfg.init_min
        n_min = cfg.init_min_reports
        best = None
        for e in scored:  # the strongest object outside the gate (most frames: none)
            if e[7] or e[3] < lo or e[2].n_reports < n_min or e[1].track_id == self.followed:
                continue
            if best is None or e[3] > best[3]:
                best = e
        fol = self.objects.objects.get(self.followed) if self.followed is not None else None
        if best is None or fol is None or best[3] < fol.score(cfg) + cfg.challenge_margin:
            ch = self._challenger
            if (
                best is None
                and ch is not None
                and not any(e[1].track_id == ch[0] for e in scored)
            ):
                # the challenger sent no fresh report this frame (a radar coast): its clock runs on
                return False
            self._challenger = None
            return False
        tid = best[2].id
        ch = self._challenger
        if ch is None or ch[0] != tid:
            self._challenger = (tid, t)
            return False
        return t - ch[1] >= cfg.challenge_s

    def _discard_report(
        self,
        t: float,
        e: _Scored,
        why: str,
    ) -> TrackerStep:
        return self._step(t, RADAR, DISCARDED, why, e[6], e[4], e[1].track_id, e[3])

    def _initiate(
        self,
        t: float,
        cands: list[tuple[int, RadarTrack, RadarObject, float]],
        far: set[int],
        zs: dict[int, tuple[float, float, float]],
    ) -> list[tuple[int, TrackerStep]]:
        cfg = self.cfg
        ok = [
            e
            for e in cands
            if e[3] >= cfg.init_min and e[2].n_reports >= cfg.init_min_reports
        ]
        res: list[tuple[int, TrackerStep]] = []
        best = max(ok, key=lambda e: (e[3], -e[0])) if ok else None
        if best is not None and RADAR in self.profile.init_sources:
            i, trk, obj, s = best
            if self.filter is not None:  # a tentative RF track is superseded
                self._count("reinit_superseded")
                self.filter = None
                self._pending_reset = "superseded"
            flat = i in far
            x, P = object_start(obj, self.profile, flat)
            self._start(t, x, P, tentative=False)
            self.last_update_t = t
            self.followed = trk.track_id
            self.last_3d_t = None if flat else t
            self.last_radar_t = t
            status, reason = self._confirmed_status()
            self._count(f"{status}_{RADAR}")
            res.append((i, self._step(t, RADAR, status, reason, None, zs[i], trk.track_id, s)))
        for e in cands:
            if e is best and res:
                continue
            why = "no_track" if self.filter is None or not self.confirmed else "not_selected"
            if self.filter is not None and not self.confirmed:
                why = "tentative_track"
            res.append(
                (e[0], self._step(t, RADAR, DISCARDED, why, None, zs[e[0]], e[1].track_id, e[3]))
            )
        return res

    def _used(
        self,
        t: float,
        source: str,
        nis: float,
        z: tuple[float, ...],
        track_id: int | None,
        score: float | None,
        weight: float,
    ) -> TrackerStep:
        self._count(UPDATED)
        self._count(f"updated_{source}")
        f = self.filter
        if f is not None:
            m = f.mean()[0]
            self._last_pos = (m[0], m[1])
        self.consecutive_rejections = 0
        self.last_update_t = t
        return self._step(t, source, UPDATED, None, nis, z, track_id, score, weight)

    def _rejected(
        self,
        t: float,
        source: str,
        nis: float,
        z: tuple[float, ...],
        track_id: int | None,
        score: float | None,
    ) -> TrackerStep:
        self._count(COASTED)
        self._count(f"coasted_{source}")
        self._count("rejected_nis")
        self.consecutive_rejections += 1
        step = self._step(t, source, COASTED, "nis", nis, z, track_id, score)
        if self.deleter.too_many_rejections(self.consecutive_rejections):
            self._drop("max_rejections")
        return step

    # --- RF -----------------------------------------------------------------------------
    def process_rf(self, a: RfAttempt) -> list[TrackerStep]:
        """One RF attempt; a failed attempt (no position) gives no step."""
        if not a.ok:
            return []
        t = a.t
        z = (a.e, a.n)
        self._count("measurements")
        self._count("rf_measurements")
        if not math.isfinite(t + a.e + a.n):
            return [self._step(t, RF, DISCARDED, "invalid", None, z, None)]
        max_cep = self.profile.rf_max_cep_m
        coarse = max_cep is not None and a.cep is not None and a.cep > max_cep
        # a fix too coarse to update the track may still be evidence of an emitter at the
        # object it fits best (its gate grows with the CEP)
        if coarse and not (a.cep is not None and a.cep <= self.cfg.rf_support_max_cep_m):
            return [self._step(t, RF, DISCARDED, "cep", None, z, None)]
        r = self.rf_r.r_for(a.cep, a.valid_sensors)
        self.objects.rf_fix(t, a.e, a.n, 0.5 * (r[0] + r[2]))
        if coarse:
            return [self._step(t, RF, DISCARDED, "cep", None, z, None)]
        if not self._advance(t):
            return [self._step(t, RF, DISCARDED, "out_of_order", None, z, None)]
        f = self.filter
        if f is None:
            if RF not in self.profile.init_sources:
                return [self._step(t, RF, DISCARDED, "no_track", None, z, None)]
            return [self._start_rf(t, z, r)]
        if not self.confirmed:
            return [self._tentative_test(t, z, r)]
        self._hold_vz(t, f)
        nis = f.nis(z, r)
        if nis <= self._g2:
            w = self.robust.weight(nis, 2)
            f.update(z, scale_packed(r, 1.0 / w) if w != 1.0 else r)
            return [self._used(t, RF, nis, z, None, None, w)]
        return [self._rejected(t, RF, nis, z, None, None)]

    def _hold_vz(self, t: float, f: MotionFilter) -> None:
        hold = self.profile.vz_hold_after_s
        if hold is not None and (self.last_3d_t is None or t - self.last_3d_t > hold):
            # no 3D measurement for a while: the vertical velocity is unobservable from 2D
            # measurements, hold it near zero instead of letting a stale climb rate run away
            sd = self.profile.vz_hold_sigma_mps
            f.update_scalar(5, 0.0, sd * sd)
            self._count("vz_hold")

    def _start_rf(self, t: float, z: tuple[float, ...], r: PackedR) -> TrackerStep:
        p = self.profile
        x = [z[0], z[1], p.rf_init_altitude_m, 0.0, 0.0, 0.0]
        P = np.zeros((6, 6))
        P[0, 0], P[0, 1], P[1, 0], P[1, 1] = r[0], r[1], r[1], r[2]
        P[2, 2] = p.rf_init_altitude_std_m**2
        P[3, 3] = P[4, 4] = P[5, 5] = p.init_velocity_std_mps**2
        tentative = RF in p.tentative_sources and p.confirm_m > 1
        self._start(t, x, P, tentative=tentative)
        if tentative:
            self._mofn = MofN(p.confirm_m, p.confirm_n)
            self._last_hit = (t, z[0], z[1])
            self._count("tentative_started")
            self._count("tentative_started_rf")
            return self._step(t, RF, TENTATIVE, "start", None, z, None)
        status, reason = self._confirmed_status()
        self._count(f"{status}_{RF}")
        return self._step(t, RF, status, reason, None, z, None)

    def _tentative_test(self, t: float, z: tuple[float, ...], r: PackedR) -> TrackerStep:
        f = self.filter
        m = self._mofn
        assert f is not None and m is not None
        vmax = self.profile.max_speed_mps
        t0, e0, n0 = self._last_hit
        dist = math.hypot(z[0] - e0, z[1] - n0)
        speed_ok = vmax is None or (dist <= vmax * (t - t0) if t > t0 else dist == 0.0)
        nis = f.nis(z, r)
        hit = speed_ok and nis <= self._g2
        if hit:
            f.update(z, r)
            self._last_hit = (t, z[0], z[1])
            self.last_update_t = t
        state = m.record(hit)
        if state == "confirmed":
            self.confirmed = True
            self._mofn = None
            self._pending_reset = None
            self._count("confirmed")
            return self._used(t, RF, nis, z, None, None, 1.0)
        if hit:
            self._count("tentative_hits")
            return self._step(t, RF, TENTATIVE, "hit", nis, z, None)
        reason = "nis" if speed_ok else "speed"
        self._count(f"tentative_miss_{reason}")
        if state == "failed":
            self._drop("unconfirmed")
            return self._start_rf(t, z, r)
        return self._step(t, RF, TENTATIVE, reason, nis, z, None)
