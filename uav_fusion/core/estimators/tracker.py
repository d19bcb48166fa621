"""The single-UAV tracker: every radar report of every frame is a candidate; one UAV track.

It composes the parts it shares with the multi-UAV tracker (:mod:`~uav_fusion.core.estimators.
parts`: the radar front-end with the radar object table and its UAV score, the measurement
models, the robust weight, the NIS gates, the deleter and M-of-N confirmation) and its own
radar association (:class:`~uav_fusion.core.estimators.follow.RadarFollower`).

Per radar frame (all reports share one time):

1. every finite report updates its radar object (:class:`~uav_fusion.core.estimators.parts.
   RadarFront`); non-finite reports are discarded (``invalid``);
2. with a track: the deleter may drop it (``max_coast``); otherwise it is predicted to the
   frame's time once;
3. reports beyond the range gate are discarded (``range_gate``), except, with ``far_gate_m``,
   those inside the far gate: they stay candidates with their horizontal position only (R's
   horizontal block; the climb rate is held near zero before such an update, and a track
   started from one takes the RF start's height prior); reports repeating their radar
   track's last velocity and RCS are coasts (``coast``: the radar's own prediction, no
   measurement); a report whose own RCS is too large for a small UAV is not the UAV's
   (``large_rcs``: :func:`~uav_fusion.core.estimators.objects.too_large`);
4. the follower decides which candidate updates the track, or starts one
   (:mod:`~uav_fusion.core.estimators.follow`), a restart only where the physical gates allow
   (:mod:`~uav_fusion.core.estimators.gates`).

An RF fix (``ok`` attempts only) credits the radar object it agrees with best (and, credited to
the followed object, registers the radar: :mod:`~uav_fusion.core.estimators.registration`),
then is gated and fused with its CEP-based R (or coasts; or, if it would move the track far,
is held for a second fix: the physical gates); without any track it starts a tentative track that
needs M of N hits (NIS gate and speed bound) to be confirmed, as in the paper profile.

Every report and fix yields exactly one :class:`~uav_fusion.core.estimators.steps.
TrackerStep`, with the statuses of :mod:`~uav_fusion.core.estimators.steps`, so Table II and
every consumer of steps work unchanged. As an estimator
(:mod:`~uav_fusion.core.estimators.base`) it also keeps the fixed-rate output of its steps
and, live, their fixed-lag smoothing.
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from uav_fusion.core.estimators.adaptive import observe_rf_fix, rf_status
from uav_fusion.core.estimators.consider import published_cov
from uav_fusion.core.estimators.follow import RadarFollower
from uav_fusion.core.estimators.gates import PhysicalGates, horizontal_nis, rf_move
from uav_fusion.core.estimators.grid import Outputs, StepGrid, step_outputs
from uav_fusion.core.estimators.kalman import (
    UPPER_INDEX,
    MotionFilter,
    PackedR,
    expand_cov3,
    expand_upper,
)
from uav_fusion.core.estimators.objects import RadarObject, too_large
from uav_fusion.core.estimators.parts import (
    MofN,
    RadarFront,
    TrackParts,
    motion_filter_from_profile,
    rf_start,
    scale_packed,
)
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
    TrackerStep,
)
from uav_fusion.core.profiles.model import Profile
from uav_fusion.core.records import RADAR, RF, Flight, RadarFrame, RadarTrack, RfAttempt
from uav_fusion.core.site import Site

FloatArray = npt.NDArray[np.float64]

_pack = struct.Struct("27d").pack
_NAN_STATE = _pack(*(math.nan,) * 27)
# a filter's (x, P) lists with their packed bytes, mode probabilities and effective q
_Packed = tuple[object, object, bytes, tuple[float, ...], tuple[float, float, float]]


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
        self.front = RadarFront(profile, site, self.cfg)
        self.objects = self.front.objects
        self.radar_r = self.front.radar_r
        parts = TrackParts(profile)
        self.rf_r = parts.rf_r
        self.rf_adaptive = parts.rf_adaptive
        self.robust = parts.robust
        self.deleter = parts.deleter
        self._g2 = parts.g2
        self._g3 = parts.g3
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
        self.follow = RadarFollower(self)
        self.gates = PhysicalGates(self.cfg, profile.max_speed_mps)
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
        # the fixed-rate output's published covariance: the radar's elevation error as a
        # consider term
        cons = published_cov(profile, site)
        self.grid = (
            StepGrid(profile, grid_hz, t0, t1, consider=cons) if grid_hz is not None else None
        )
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
        """The followed radar object, its UAV score and probability, the time since the
        last accepted measurement and the last 3D radar update, and the radar's registration."""
        best = self.best_track()
        sensors = {**self.front.status(), **rf_status(self.rf_adaptive)}
        if best is None:
            return {"track": "tentative" if self.active else "none", **sensors}
        out: dict[str, object] = {"track": "confirmed", **sensors}
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
        self.follow.challenger = None

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
        if not tentative:
            self.gates.confirmed_state(t, x, float(P[2, 2]))

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
        bad, reports = self.front.reports(frame)
        for i in bad:
            trk = tracks[i]
            z = (trk.e, trk.n, trk.u)
            out[i] = self._step(t, RADAR, DISCARDED, "invalid", None, z, trk.track_id)
        if not self._advance(t):
            for i, trk, _, p3, _, _ in reports:
                out[i] = self._step(t, RADAR, DISCARDED, "out_of_order", None, p3, trk.track_id)
            return [s for s in out if s is not None]
        cands: list[tuple[int, RadarTrack, RadarObject, float]] = []
        # each report's position, corrected for the radar's misalignment (report index -> z)
        zs: dict[int, tuple[float, float, float]] = {}
        rs: dict[int, PackedR] = {}
        gate2 = self.front.gate2
        cfg = self.cfg
        far2 = self.front.far2
        far: set[int] = set()  # reports beyond the range gate, kept as 2D candidates
        for i, trk, obj, p3, r, d2 in reports:
            zs[i] = p3
            rs[i] = r
            if d2 > gate2 and d2 > far2:
                out[i] = self._step(t, RADAR, DISCARDED, "range_gate", None, p3, trk.track_id)
            elif obj.coasting:
                out[i] = self._step(t, RADAR, DISCARDED, "coast", None, p3, trk.track_id)
            elif too_large(trk, cfg):
                out[i] = self._step(t, RADAR, DISCARDED, "large_rcs", None, p3, trk.track_id)
            elif d2 > gate2:
                # inside the far gate: a horizontal-only candidate (R's horizontal block; the
                # elevation is too poor out there)
                far.add(i)
                rs[i] = (r[0], r[1], r[3])
                cands.append((i, trk, obj, obj.score(cfg)))
            else:
                cands.append((i, trk, obj, obj.score(cfg)))
        if cands:
            for i, step in self.follow.frame(t, cands, rs, far, zs):
                out[i] = step
        if self.profile.hold_after_s is not None:
            self.follow.notch(t)
        return [s for s in out if s is not None]

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
            m, pm = f.mean()
            self._last_pos = (m[0], m[1])
            if self.confirmed:
                self.gates.confirmed_state(t, m, pm[UPPER_INDEX[2][2]])
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
        r = self.rf_r.r_for(a.cep)
        var = 0.5 * (r[0] + r[2])
        self.objects.rf_fix(t, a.e, a.n, var)
        obj = self.objects.credited
        if obj is not None and self.confirmed and obj.id == self.followed:
            self.front.register(t, a.e, a.n, var, obj)
        if coarse:
            if self.confirmed and self.t is not None and t >= self.t:
                self._coarse_check(t, z, r, var)
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
        gates = self.gates
        if nis <= self._g2:
            gates.rf_inside()
            if not gates.rf_move_allowed(t, a.e, a.n, var, rf_move(f, z, r)):
                # far from the track: held until a second fix agrees (gates.py)
                self._count("rf_held")
                return [self._step(t, RF, DISCARDED, "held", nis, z, None)]
            w = self.robust.weight(nis, 2)
            # measurement.adaptive (adaptive.py), before the fix's update
            ad_radar, ad_rf = self.front.adaptive, self.rf_adaptive
            observe_rf_fix(ad_radar, ad_rf, self.last_3d_t, t, f, z, nis, a.cep)
            f.update(z, scale_packed(r, 1.0 / w) if w != 1.0 else r)
            return [self._used(t, RF, nis, z, None, None, w)]
        if gates.rf_outside(t, a.e, a.n, var, max(2, self.profile.confirm_m)):
            # agreeing fixes outside the gate, in a row: the track is not on the UAV
            self._drop("rf_disagrees")
            if RF in self.profile.init_sources:
                return [self._start_rf(t, z, r)]
            return [self._step(t, RF, DISCARDED, "no_track", None, z, None)]
        return [self._rejected(t, RF, nis, z, None, None)]

    def _coarse_check(self, t: float, z: tuple[float, ...], r: PackedR, var: float) -> None:
        """A fix too coarse to update the track still says whether the track is near the
        emitter: it joins the run of agreeing fixes outside the gate (gates.py)."""
        x, p = self.predict_to(t)
        if horizontal_nis(x, p, z, r) <= self._g2:
            self.gates.rf_inside()
        elif self.gates.rf_outside(t, z[0], z[1], var, max(2, self.profile.confirm_m)):
            self._drop("rf_disagrees")

    def _hold_vz(self, t: float, f: MotionFilter) -> None:
        hold = self.profile.hold_after_s
        if hold is not None and (self.last_3d_t is None or t - self.last_3d_t > hold):
            # no 3D measurement for a while: the vertical velocity is unobservable from 2D
            # measurements, hold it near zero instead of letting a stale climb rate run away
            sd = self.profile.hold_sigma_mps
            f.update_scalar(5, 0.0, sd * sd)
            self._count("vz_hold")

    def _start_rf(self, t: float, z: tuple[float, ...], r: PackedR) -> TrackerStep:
        p = self.profile
        x, P = rf_start(z, r, p)
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
        speed_ok = dist <= vmax * (t - t0) if t > t0 else dist == 0.0
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
