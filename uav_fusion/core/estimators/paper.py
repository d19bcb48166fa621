"""The fusion estimator: one CV track fed asynchronously by radar and RF measurements.

For each measurement, in the order given (callers sort by time, then ``seq``):

1. out-of-order check (a measurement older than the track's time is discarded);
2. when a track exists: the state is predicted to the measurement's time (for the continuous
   white-noise acceleration model predicting in pieces equals predicting in one go, so this
   never changes the result) and the coast-time limit is checked;
3. pre-gates, which discard without touching the track: radar range gate (distance from the
   radar's phase centre), optional UAV class-probability threshold;
4. without a track: initialisation from the measurement if its source may start tracks;
5. NIS gate at the profile's chi-square probability for the measurement's dimension:
   accepted -> Joseph-form update; rejected -> coast (the prediction is the estimate);
6. after ``max_consecutive_rejections`` NIS rejections in a row the track is restarted from
   the measurement that hit the limit.

Track confirmation (M-of-N). A track started from a source listed in ``tentative_sources``
(RF fixes, whose errors are heavy-tailed) is *tentative*: it is confirmed once ``confirm_m``
of its first ``confirm_n`` measurements (the one that started it included) were hits. A hit
passes the NIS gate and, while the track is tentative, also the speed plausibility bound: the
horizontal distance from the last hit divided by the time since it must not exceed
``max_speed_mps``. When the track can no longer reach ``confirm_m`` hits it is dropped and the
measurement that made it fail starts a new tentative track. A measurement of a source not in
``tentative_sources`` (radar) decides at once: a hit confirms the track, a miss supersedes it
(the tentative track is dropped and the report starts a confirmed track). A tentative track's
estimates are not published as filter estimates: its steps have status ``tentative``.

Every measurement yields exactly one :class:`~uav_fusion.core.estimators.steps.Step`
(statuses: :mod:`uav_fusion.core.estimators.steps`).

As an :class:`~uav_fusion.core.estimators.base.Estimator` it takes radar frames (the selected
reports; several in one frame are candidates) and RF attempts, and keeps the fixed-rate output
of its steps (:class:`~uav_fusion.core.estimators.grid.StepGrid`); its ``fusion/odom`` is every
filter step, as in the paper.
"""

from __future__ import annotations

import copy
import math
from collections.abc import Sequence
from typing import Any

import numpy as np
import numpy.typing as npt

from uav_fusion.core.estimators.grid import Outputs, StepGrid, step_outputs
from uav_fusion.core.estimators.kalman import CvKalman, PackedR, expand_cov3, pack_r
from uav_fusion.core.estimators.selection import selected_input
from uav_fusion.core.estimators.steps import (
    COASTED,
    DISCARDED,
    INITIALISED,
    NAN_STATE,
    RESET,
    TENTATIVE,
    UPDATED,
    Step,
    nis_gate,
    pack_state,
)
from uav_fusion.core.profiles.model import Profile
from uav_fusion.core.records import (
    RADAR,
    RF,
    Flight,
    Measurement,
    RadarFrame,
    RadarTrack,
    RfAttempt,
)
from uav_fusion.core.site import Site

FloatArray = npt.NDArray[np.float64]

#: how many recent measurements the interface keeps for :meth:`FusionEstimator.measurement`
_RECENT = 1024
_DIMS = {RADAR: 3, RF: 2}
_MEAS_KEY = {RADAR: "radar_measurements", RF: "rf_measurements"}
_UPD_KEY = {RADAR: "updated_radar", RF: "updated_rf"}


class FusionEstimator:
    """Streaming radar + RF fusion (one track). Feed measurements in (t, seq) order."""

    kind = "paper"
    fixed_rate = False  # fusion/odom: every filter step, as in the paper
    reads = "selected"

    def __init__(
        self,
        profile: Profile,
        site: Site,
        grid_hz: float | None = None,
        t0: float | None = None,
        t1: float | None = None,
    ) -> None:
        self.profile = profile
        self.site = site
        self._kf = CvKalman(profile.q)
        assert profile.r_radar is not None and profile.r_rf is not None  # the profile's checks
        self._r: dict[str, PackedR] = {RADAR: pack_r(profile.r_radar), RF: pack_r(profile.r_rf)}
        self.gate_threshold: dict[int, float] = {
            d: nis_gate(profile.nis_probability, d) for d in (2, 3)
        }
        self._g2 = self.gate_threshold[2]
        self._g3 = self.gate_threshold[3]
        self.range_gate_m = (
            profile.range_gate_m if profile.range_gate_m is not None else site.radar.range_gate_m
        )
        self._radar_pos = tuple(float(v) for v in site.radar.enu)
        self._gate2 = float(self.range_gate_m) ** 2
        self._init_sources = frozenset(profile.init_sources)
        self._min_uav_prob = profile.min_uav_prob
        self._max_rej = profile.max_consecutive_rejections
        self._max_coast = profile.max_coast_s
        self._tentative_sources = frozenset(profile.tentative_sources)
        self._confirm_m = profile.confirm_m
        self._confirm_n = profile.confirm_n
        self._max_speed = profile.max_speed_mps
        self.tentative = False  # track started from a tentative source, not yet confirmed
        self._hits = 0  # hits of the tentative track (its start included)
        self._tested = 0  # measurements tested on the tentative track (its start included)
        self._last_hit: tuple[float, float, float] = (0.0, 0.0, 0.0)  # t, east, north
        self.t: float | None = None  # time of the current estimate
        self.active = False
        self.last_used_t: float | None = None
        self.consecutive_rejections = 0
        self._pending_reset: str | None = None
        self.counters: dict[str, int] = {}
        # the estimator interface: the steps' fixed-rate output (None: not kept), the next
        # measurement's seq, and the latest measurements by seq (views read them back)
        self._grid_args = (grid_hz, t0, t1)
        self.grid = StepGrid(profile, grid_hz, t0, t1) if grid_hz is not None else None
        self._seq = 0
        self._recent: dict[int, Measurement] = {}

    def __deepcopy__(self, memo: dict[int, Any]) -> FusionEstimator:
        """A copy for a rewind (:mod:`uav_fusion.core.live.rewind`): the recent measurements
        are never changed, so the copy shares them."""
        for m in self._recent.values():
            memo[id(m)] = m
        new = FusionEstimator.__new__(FusionEstimator)
        memo[id(self)] = new
        for k, v in self.__dict__.items():
            setattr(new, k, copy.deepcopy(v, memo))
        return new

    # --- the estimator interface (uav_fusion.core.estimators.base) ----------------------
    def radar_frame(self, frame: RadarFrame) -> Outputs:
        """The selected reports of one radar frame: candidates of one filter step
        (:meth:`process_frame`; a report's own covariance, when it carries one, is its R)."""
        ms = [self._radar_measurement(trk) for trk in frame.tracks]
        return self._outputs(self.process_frame(ms), ms)

    def rf_attempt(self, attempt: RfAttempt) -> Outputs:
        """One RF attempt: a fix with a finite position is one filter step."""
        a = attempt
        if not (a.ok and math.isfinite(a.e) and math.isfinite(a.n)):
            return Outputs()
        m = Measurement(t=a.t, source=RF, z=np.array((a.e, a.n), float), seq=self._next_seq())
        return self._outputs(self.process(m), [m])

    def advance(self, t: float) -> Outputs:
        return Outputs(grid=self.grid.advance(t)) if self.grid is not None else Outputs()

    def finish(self) -> Outputs:
        return Outputs(grid=self.grid.finish()) if self.grid is not None else Outputs()

    def restart(self, reason: str) -> None:
        self.restart_timeline(reason)
        if self.grid is not None:
            self.grid = StepGrid(self.profile, *self._grid_args)  # type: ignore[arg-type]

    def measurement(self, step: Step) -> tuple[FloatArray, FloatArray | None] | None:
        m = self._recent.get(step.seq)
        if m is None:
            return None
        R = m.R if m.R is not None else (self.profile.r_radar if m.source == RADAR else None)
        return m.z, R

    def status(self) -> dict[str, object]:
        if not self.active:
            return {"track": "none"}
        return {"track": "tentative" if self.tentative else "confirmed"}

    def flight_input(self, flight: Flight) -> list[RadarFrame | RfAttempt]:
        return selected_input(flight, self.profile)[0]

    def _next_seq(self) -> int:
        seq = self._seq
        self._seq = seq + 1
        return seq

    def _radar_measurement(self, trk: RadarTrack) -> Measurement:
        c = trk.cov
        return Measurement(
            t=trk.t,
            source=RADAR,
            z=np.array((trk.e, trk.n, trk.u), dtype=float),
            R=None if c is None else expand_cov3(c),
            track_id=trk.track_id if trk.track_id >= 0 else None,
            uav_prob=trk.uav_prob,
            range_m=trk.range_m,
            seq=self._next_seq(),
        )

    def _outputs(self, steps: list[Step], ms: Sequence[Measurement]) -> Outputs:
        recent = self._recent
        for m in ms:
            recent[m.seq] = m
        if len(recent) > _RECENT:
            for k in list(recent)[: len(recent) - _RECENT // 2]:
                del recent[k]
        return step_outputs(self.grid, steps)

    # --- public API ---------------------------------------------------------------------
    def reset(self, reason: str) -> None:
        """Drop the track; the next usable measurement starts a new one (status ``reset``)."""
        if self.active:
            self._count(f"reinit_{reason}")
            self._count("reinitialisations")
            self._pending_reset = reason
        self.active = False
        self.tentative = False
        self.consecutive_rejections = 0

    def restart_timeline(self, reason: str) -> None:
        """The input's time starts over (a bag loop, a clock jumping back): drop the track
        like :meth:`reset` and forget the current time, so earlier stamps than the last one
        seen are not "out of order"."""
        self.reset(reason)
        self.t = None
        self.last_used_t = None

    def state(self) -> tuple[FloatArray, FloatArray] | None:
        """Current (x, P), or None without a track."""
        if not self.active:
            return None
        return self._kf.x_array(), self._kf.P_array()

    def process(self, m: Measurement) -> list[Step]:
        """Process one measurement; returns the step it produced."""
        c = self.counters
        c["measurements"] = c.get("measurements", 0) + 1
        z = m.z.tolist()
        pre = self._pre(m, z)
        if pre is not None:
            return [pre]
        if not self.active:
            return [self._initialise(m)]
        kf = self._kf
        r = self._r[m.source] if m.R is None else pack_r(m.R)
        if self.tentative:
            return [self._tentative_test(m, z, r)]
        if len(z) == 3:
            g = self._g3
            nis = kf.update3(z[0], z[1], z[2], r, g)
        else:
            g = self._g2
            nis = kf.update2(z[0], z[1], r, g)
        if nis <= g:
            return [self._used(m, nis)]
        return [self._rejected(m, nis)]

    def process_frame(self, ms: Sequence[Measurement]) -> list[Step]:
        """Process the candidate reports of one radar frame (all with the same time).

        Candidates are pre-gated individually; of the survivors the one with the smallest
        NIS inside the gate updates the track (the others are ``not_selected``). If none is
        inside the gate, the smallest-NIS candidate makes the frame's coasted step and the
        others are discarded with reason ``nis``. Without a track, the survivor with the
        highest UAV probability (then lowest ``seq``) starts one.
        """
        if len(ms) == 1:
            return self.process(ms[0])
        if not ms:
            return []
        cands = sorted(ms, key=lambda m: m.seq)
        t0 = cands[0].t
        if any(m.t != t0 for m in cands):
            raise ValueError("process_frame: all candidates of a frame must share one time")
        steps: dict[int, Step] = {}
        survivors: list[Measurement] = []
        zs: dict[int, list[float]] = {}
        for m in cands:
            self._count("measurements")
            z = zs[m.seq] = m.z.tolist()
            pre = self._pre(m, z)
            if pre is None:
                survivors.append(m)
            else:
                steps[m.seq] = pre
        if survivors:
            if not self.active:
                best = max(
                    survivors,
                    key=lambda m: (-1.0 if m.uav_prob is None else m.uav_prob, -m.seq),
                )
                steps[best.seq] = self._initialise(best)
                for m in survivors:
                    if m is not best:
                        steps[m.seq] = self._discard(m, "not_selected")
            else:
                kf = self._kf
                scored = []
                for m in survivors:
                    z = zs[m.seq]
                    r = self._rp(m)
                    n = kf.nis3(z[0], z[1], z[2], r) if m.dim == 3 else kf.nis2(z[0], z[1], r)
                    scored.append((n, m.seq, m, r))
                scored.sort(key=lambda s: (s[0], s[1]))
                n0, _, best, r0 = scored[0]
                if self.tentative:
                    steps[best.seq] = self._tentative_test(best, zs[best.seq], r0)
                    hit = steps[best.seq].status != RESET
                    for n, _, m, _ in scored[1:]:
                        steps[m.seq] = self._discard(m, "not_selected" if hit else "nis", n)
                elif n0 <= self.gate_threshold[best.dim]:
                    self._update(best, zs[best.seq], r0)
                    steps[best.seq] = self._used(best, n0)
                    for n, _, m, _ in scored[1:]:
                        steps[m.seq] = self._discard(m, "not_selected", n)
                else:
                    steps[best.seq] = self._rejected(best, n0)
                    for n, _, m, _ in scored[1:]:
                        steps[m.seq] = self._discard(m, "nis", n)
        return [steps[m.seq] for m in cands]

    # --- internals ----------------------------------------------------------------------
    def _count(self, key: str, n: int = 1) -> None:
        c = self.counters
        c[key] = c.get(key, 0) + n

    def _rp(self, m: Measurement) -> PackedR:
        return self._r[m.source] if m.R is None else pack_r(m.R)

    def _pre(self, m: Measurement, z: list[float]) -> Step | None:
        """Time handling and pre-gates; a Step when the measurement goes no further."""
        src = m.source
        if len(z) != _DIMS.get(src):
            raise ValueError(f"measurement seq {m.seq}: {src!r} with {len(z)} values")
        c = self.counters
        key = _MEAS_KEY[src]
        c[key] = c.get(key, 0) + 1
        t = m.t
        if not math.isfinite(t + sum(z)):
            return self._discard(m, "invalid")
        if self.active:
            dt = t - self.t  # type: ignore[operator]
            if dt < 0:
                return self._discard(m, "out_of_order")
            if (
                self._max_coast is not None
                and self.last_used_t is not None
                and t - self.last_used_t > self._max_coast
            ):
                self.reset("max_coast")
            else:
                self._kf.predict(dt)
                self.t = t
        elif self.t is not None and t < self.t:
            return self._discard(m, "out_of_order")
        if src == RADAR:
            rx, ry, rz = self._radar_pos
            dx = z[0] - rx
            dy = z[1] - ry
            dz = z[2] - rz
            if not dx * dx + dy * dy + dz * dz <= self._gate2:
                return self._discard(m, "range_gate")
            mp = self._min_uav_prob
            if mp is not None and (m.uav_prob is None or m.uav_prob < mp):
                return self._discard(m, "class_prob")
        if not self.active and src not in self._init_sources:
            return self._discard(m, "no_track")
        return None

    def _update(self, m: Measurement, z: list[float], r: PackedR) -> float:
        g = self._g3 if len(z) == 3 else self._g2
        if len(z) == 3:
            return self._kf.update3(z[0], z[1], z[2], r, g)
        return self._kf.update2(z[0], z[1], r, g)

    def _snapshot(self, m: Measurement, status: str, reason: str | None, nis: float | None) -> Step:
        if self.active:
            kf = self._kf
            state = pack_state(*kf.x, *kf.P)
        else:
            state = NAN_STATE
        return Step(m.t, m.source, status, reason, nis, state, len(m.z), m.track_id, m.seq)

    def _discard(self, m: Measurement, reason: str, nis: float | None = None) -> Step:
        self._count(DISCARDED)
        self._count(f"rejected_{reason}")
        return self._snapshot(m, DISCARDED, reason, nis)

    def _used(self, m: Measurement, nis: float) -> Step:
        c = self.counters
        c[UPDATED] = c.get(UPDATED, 0) + 1
        key = _UPD_KEY[m.source]
        c[key] = c.get(key, 0) + 1
        self.consecutive_rejections = 0
        self.last_used_t = m.t
        self.tentative = False
        kf = self._kf
        state = pack_state(*kf.x, *kf.P)
        return Step(m.t, m.source, UPDATED, None, nis, state, len(m.z), m.track_id, m.seq)

    def _rejected(self, m: Measurement, nis: float) -> Step:
        self._count(COASTED)
        self._count(f"coasted_{m.source}")
        self._count("rejected_nis")
        self.consecutive_rejections += 1
        n = self._max_rej
        if n is not None and self.consecutive_rejections >= n:
            self.reset("max_rejections")
            if m.source in self._init_sources:
                return self._initialise(m, nis)
        return self._snapshot(m, COASTED, "nis", nis)

    def _speed_ok(self, m: Measurement, z: list[float]) -> bool:
        """Speed plausibility of a measurement against the tentative track's last hit."""
        vmax = self._max_speed
        t0, e0, n0 = self._last_hit
        dist = math.hypot(z[0] - e0, z[1] - n0)
        dt = m.t - t0
        return dist <= vmax * dt if dt > 0 else dist == 0.0

    def _tentative_test(self, m: Measurement, z: list[float], r: PackedR) -> Step:
        """Test a measurement (the track already predicted to its time) against the
        tentative track: hit or miss, then confirm, go on, supersede or drop (M-of-N)."""
        kf = self._kf
        speed_ok = self._speed_ok(m, z)
        if speed_ok:
            nis = self._update(m, z, r)
        else:
            nis = kf.nis3(z[0], z[1], z[2], r) if len(z) == 3 else kf.nis2(z[0], z[1], r)
        hit = speed_ok and nis <= (self._g3 if len(z) == 3 else self._g2)
        confirming = m.source not in self._tentative_sources
        self._tested += 1
        if hit:
            self._hits += 1
            self._last_hit = (m.t, z[0], z[1])
            if confirming or self._hits >= self._confirm_m:
                self._count("confirmed")
                self._pending_reset = None
                return self._used(m, nis)  # clears ``tentative``
            self.last_used_t = m.t
            self._count("tentative_hits")
            return self._snapshot(m, TENTATIVE, "hit", nis)
        reason = "nis" if speed_ok else "speed"
        self._count(f"tentative_miss_{reason}")
        if confirming:  # a radar report disagrees: it supersedes the tentative track
            self.reset("superseded")
            if m.source in self._init_sources:
                return self._initialise(m, nis)
            return self._discard(m, "no_track", nis)
        if self._hits + (self._confirm_n - self._tested) < self._confirm_m:
            self._count("tentative_dropped")
            self.active = False
            self.tentative = False
            self._pending_reset = "unconfirmed"
            if m.source in self._init_sources:
                return self._initialise(m, nis)
        return self._snapshot(m, TENTATIVE, reason, nis)

    def _initialise(self, m: Measurement, nis: float | None = None) -> Step:
        p = self.profile
        z = m.z
        R = np.asarray(p.r_radar if m.source == RADAR else p.r_rf, float) if m.R is None else m.R
        x = np.zeros(6)
        P = np.zeros((6, 6))
        v = p.init_velocity_std_mps**2
        P[3, 3] = P[4, 4] = P[5, 5] = v
        if m.dim == 3:
            x[:3] = z
            P[:3, :3] = R
        else:
            x[:2] = z
            x[2] = p.rf_init_altitude_m
            P[:2, :2] = R
            P[2, 2] = p.rf_init_altitude_std_m**2
        self._kf.set_state(x, P)
        self.active = True
        self.t = m.t
        self.last_used_t = m.t
        self.consecutive_rejections = 0
        if m.source in self._tentative_sources and self._confirm_m > 1:
            self.tentative = True
            self._hits = self._tested = 1
            self._last_hit = (m.t, float(z[0]), float(z[1]))
            self._count("tentative_started")
            self._count(f"tentative_started_{m.source}")
            return self._snapshot(m, TENTATIVE, "start", nis)
        self.tentative = False
        reason = self._pending_reset
        self._pending_reset = None
        status = INITIALISED if reason is None else RESET
        self._count(status)
        self._count(f"{status}_{m.source}")
        return self._snapshot(m, status, reason, nis)
