"""Every radar object, and how UAV-like it is: the evidence behind track-level association.

The radar's onboard tracker gives each report a track id. :class:`ObjectTable` keeps one
:class:`RadarObject` per id for the whole flight (its own small CV filter, so multi-target
tracking is an extension, not a rewrite) and a *UAV score* per object, a sum of log-odds-like
terms from independent cues (no single cue decides; the radar's classifier errs both ways),
in units of the class logit. Every moving average of an object's own cues has the one time
constant ``tau_s``: the time its history needs to say what the object is.

* class history: exponential moving average of the logit of the UAV class probability,
  clipped to ``+-class_clip``, each report's output taken as it is (a model of how a
  particular classifier's output on a young track evolves would be that classifier's
  constants, not the tracker's);
* kinematics: an object whose mean height (moving average of its reports' ENU up) lies
  below the ground by more than ``below_ground_m``, and by more than ``below_ground_sigmas``
  times the mean vertical standard deviation of its reports (from the radar's polar R: a few
  metres close in, tens of metres near the horizon far out, where a UAV's low pass scatters
  below the ground), is a multipath ghost (loses :attr:`ScoreConfig.veto`, all that the
  other cues can give: it can be no UAV); one older than ``tau_s`` whose mean speed stays
  below ``stationary_speed_mps`` is clutter (``-stationary_weight``: a mast, a tower or a
  roof edge stands still at any height; a multirotor that hovers in front of the radar pays
  it too, but sits in the radar's Doppler notch and is seldom reported then). A low object
  is not judged by its height or speed: a car is a large radar target (below), and a parked
  one, like any object near the ground that stands still, is the physical gates' concern
  (:mod:`~uav_fusion.core.estimators.gates`: it never becomes the UAV without RF
  corroboration); a flock's erratic motion is the classifier's to call;
* size: an object whose mean RCS (moving average of its reports' dBsm) is at least
  ``large_rcs_dbsm`` is too large for a small UAV (loses the veto too; a reflector, a
  car); one without RCS reports is not judged. A single report that large is not the UAV's
  whatever its object (:func:`too_large`);
* RF agreement: each RF fix within the 99 % chi-square gate of the predicted horizontal
  position of an object the radar still reports (a report within its longest update
  interval, :data:`~uav_fusion.core.estimators.adaptive.HELD_S`) adds one unit of support,
  decaying with time constant ``rf_tau_s`` (the profile's ``track.max_coast_s``) and capped
  at ``rf_max``, times ``rf_weight`` (an emitter at the object's position is strong
  evidence of a UAV); a fix credits only the object it fits best (smallest gate distance),
  not every object in its gate (clutter beside a UAV, or near a UAV on its pad that the
  radar does not see, would otherwise share the UAV's emitter); a fix too
  coarse to update a track (CEP above the profile's ``measurement.rf.max_cep_m``) still
  counts here when its CEP is at most ``rf_support_max_cep_m`` (0: never; single-UAV
  tracker only); a fix that credits no object at all (an emitter the radar does not see
  yet: a UAV on its pad with its link on) is kept for ``rf_tau_s`` (0: not kept), and an
  object seen for the first time takes the support of the kept fixes inside its gate, as
  if it had been credited when each was made (decayed since). A fix given with its emitter's
  key (the multi-UAV tracker) leaves that key on the objects it credits
  (:attr:`RadarObject.rf_key`, the last one);
* agreement with the fused track: moving average (time constant ``fused_tau_s``) of "this
  object's report had an NIS of at most ``fused_nis`` against the UAV track" (closer than
  the gate: the gate is wide when the track's R allows for correlated errors), times
  ``fused_weight``; the single-UAV tracker records nothing while the track knows the UAV's
  horizontal position less well than the report does (after a long coast the gate spans far
  more than the UAV's neighbourhood, and a first report inside it would count as full
  agreement: :func:`~uav_fusion.core.estimators.follow.informative`);
* age: ``age_weight * min(1, age / tau_s)`` (a track that persists is more likely real; the
  term is full once the object's history has settled).

A *coasted* report is one whose velocity and RCS repeat the same radar track's previous report
exactly: the radar's own tracker had no detection for it and reported its prediction
(:attr:`RadarObject.coasting`). It carries no new measurement, so the fused track does not
take it (it would count the radar's prediction as a fresh measurement
with independent noise), and neither does the object's own filter (its state then stays at
its last report that was not a coast, :attr:`RadarObject.kf_t`).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from uav_fusion.core.estimators.adaptive import HELD_S
from uav_fusion.core.estimators.kalman import CvKalman, PackedR
from uav_fusion.core.profiles.settings import ScoreConfig
from uav_fusion.core.records import RadarTrack

if TYPE_CHECKING:
    from uav_fusion.core.estimators.parts import RadarRModel

RF_GATE_99_2DOF = 9.2103403719761836  # chi2.ppf(0.99, 2)


#: Positions older than this fade from an object's drift fit (s; an exponential weight).
DRIFT_TAU_S = 20.0


def too_large(trk: RadarTrack, cfg: ScoreConfig) -> bool:
    """Whether a report's own RCS is too large for a small UAV: at least ``large_rcs_dbsm``.

    A small multirotor's looks stay below it (the paper's flight: 0.0066-0.549 m^2, at most
    -2.6 dBsm, over 3106 reports), while most looks of a car or a reflector lie above. Such a
    report is not the UAV's, whatever track id the radar gave it: the onboard tracker can
    pass one id back and forth between a UAV and a car beside it. The trackers take it for no
    track (its object still learns from it). A report without an RCS is not judged."""
    rcs = trk.rcs_dbsm
    return rcs is not None and rcs >= cfg.large_rcs_dbsm


class Drift:
    """A straight line fitted to an object's horizontal positions against time (weighted
    least squares by running sums, a position's weight fading as ``exp(-age / DRIFT_TAU_S)``):
    the speed its body moves at, whatever its reports' Doppler velocity says (a fan, a flag or
    a tree is seen by the radar through its moving part, and its reported velocity is that
    part's), and how well the positions' own scatter about the line pins that speed down.
    The fading keeps the fit about the object's recent half minute or so: a reflector
    1.5 km out, whose reports scatter by 35 m across the line of sight, is known to stand
    still after about 40 s of reports, and a radar track id that passes from a reflector onto
    an object moving at 8 m/s shows the motion within 20 s, where a fit over the whole
    history would need minutes (``test/test_gates.py``)."""

    __slots__ = ("k", "se", "see", "sn", "snn", "st", "ste", "stn", "stt", "t0", "w")

    def __init__(self, t0: float) -> None:
        self.t0 = t0  # the time the sums are taken about: the last position's
        self.k = 0  # positions added
        self.w = 0.0  # their summed weight
        self.st = self.stt = 0.0
        self.se = self.ste = self.see = 0.0
        self.sn = self.stn = self.snn = 0.0

    def add(self, t: float, e: float, n: float) -> None:
        d = t - self.t0
        if d != 0.0:
            # fade the sums by the time passed and take them about t (x -> x - d)
            a = math.exp(-d / DRIFT_TAU_S) if d > 0.0 else 1.0
            w, st, se, sn = a * self.w, a * self.st, a * self.se, a * self.sn
            self.stt = a * self.stt - 2.0 * d * st + d * d * w
            self.ste = a * self.ste - d * se
            self.stn = a * self.stn - d * sn
            self.st = st - d * w
            self.w, self.se, self.sn = w, se, sn
            self.see *= a
            self.snn *= a
            self.t0 = t
        self.k += 1
        self.w += 1.0
        self.se += e
        self.see += e * e
        self.sn += n
        self.snn += n * n

    def speed(self) -> tuple[float, float] | None:
        """The fitted horizontal speed and its standard error (per axis, m/s), or None with
        fewer than 3 positions or no time between them."""
        w = self.w
        if self.k < 3 or not w > 2.0:
            return None
        sxx = self.stt - self.st * self.st / w
        if not sxx > 1e-9:
            return None
        v2 = 0.0
        var = 0.0
        for sy, sty, syy in ((self.se, self.ste, self.see), (self.sn, self.stn, self.snn)):
            sxy = sty - self.st * sy / w
            b = sxy / sxx
            ssr = syy - sy * sy / w - b * sxy  # the residuals' weighted sum of squares
            v2 += b * b
            var += (ssr if ssr > 0.0 else 0.0) / (w - 2.0) / sxx
        return math.sqrt(v2), math.sqrt(0.5 * var)

    def still(self, speed_mps: float) -> bool:
        """Whether the fit says the object stands still: slower than ``speed_mps``, known to
        better than half of it."""
        fit = self.speed()
        return fit is not None and fit[0] < speed_mps and fit[1] < 0.5 * speed_mps


def _ema(old: float, new: float, dt: float, tau: float) -> float:
    if tau <= 0:
        return new
    a = math.exp(-dt / tau) if dt > 0 else 1.0
    return a * old + (1.0 - a) * new


class RadarObject:
    """One radar track id: its own CV filter and the running evidence of the UAV score."""

    __slots__ = (
        "class_logit",
        "coasting",
        "drift",
        "first_t",
        "fused",
        "fused_t",
        "id",
        "kf",
        "kf_t",
        "last_t",
        "n_reports",
        "rcs_mean",
        "rcs_seen",
        "rf_key",
        "rf_support",
        "rf_t",
        "sd_up",
        "signature",
        "speed",
        "up",
    )

    def __init__(self, track_id: int, t: float) -> None:
        self.id = track_id
        self.first_t = t
        self.last_t = t
        self.n_reports = 0
        self.kf: CvKalman | None = None
        self.kf_t = t  # the time of the filter's state (its last non-coasted report)
        self.drift = Drift(t)  # its non-coasted reports' positions against time
        self.class_logit = 0.0
        self.speed = 0.0
        self.up = 0.0
        self.sd_up = 0.0  # moving average of the reports' vertical standard deviation
        self.rcs_mean = 0.0
        self.rcs_seen = False  # any report with a finite RCS
        self.rf_support = 0.0
        self.rf_t = t
        self.rf_key: str | None = None  # the emitter of the last RF fix that credited it
        self.fused = 0.0
        self.fused_t: float | None = None
        self.signature: tuple[object, ...] | None = None
        self.coasting = False

    @property
    def age_s(self) -> float:
        return self.last_t - self.first_t

    def rf_support_at(self, t: float, tau: float) -> float:
        if self.rf_support == 0.0:
            return 0.0
        return self.rf_support * math.exp(-(t - self.rf_t) / tau) if tau > 0 else 0.0

    def rf_recent(self, t: float, tau: float) -> bool:
        """Whether an RF fix was credited to the object within ``tau`` of ``t`` (its RF
        support, fading with ``tau`` as time constant, is then still worth counting)."""
        return self.rf_support > 0.0 and tau > 0.0 and t - self.rf_t <= tau

    def below_ground(self, cfg: ScoreConfig) -> bool:
        """Clearly below the ground (see the module text): nothing real flies there."""
        lim = cfg.below_ground_m
        k = cfg.below_ground_sigmas
        if k and k * self.sd_up > lim:
            lim = k * self.sd_up
        return self.up < -lim

    def score(self, cfg: ScoreConfig, fused: bool = True) -> float:
        """The UAV score at the object's last report (see the module text); without the
        agreement with the fused track when ``fused`` is false (the evidence the object
        carries of its own)."""
        s = self.class_logit
        age = self.age_s
        if self.below_ground(cfg):  # a multipath ghost
            s -= cfg.veto
        elif age >= cfg.tau_s and self.speed < cfg.stationary_speed_mps:
            s -= cfg.stationary_weight
        if self.rcs_seen and self.rcs_mean >= cfg.large_rcs_dbsm:
            s -= cfg.veto
        # min(rf_max, rf_support_at(last_t)) and min(1, age / tau_s) as conditionals
        sup = self.rf_support
        if sup != 0.0:
            tau = cfg.rf_tau_s
            sup = sup * math.exp(-(self.last_t - self.rf_t) / tau) if tau > 0 else 0.0
        rf_max = cfg.rf_max
        s += cfg.rf_weight * (sup if sup < rf_max else rf_max)
        if fused:
            s += cfg.fused_weight * self.fused
        full = cfg.tau_s
        if full > 0:
            f = age / full
            s += cfg.age_weight * (f if f < 1.0 else 1.0)
        return s


class ObjectTable:
    """Every radar object of a flight, updated by every report of every frame."""

    def __init__(self, cfg: ScoreConfig, radar_r: RadarRModel) -> None:
        #: the object the last RF fix was credited to, or None
        self.credited: RadarObject | None = None
        self.cfg = cfg
        self.radar_r = radar_r
        self.objects: dict[int, RadarObject] = {}
        # RF fixes that credited no object: (t, e, n, variance, emitter)
        self._orphans: list[tuple[float, float, float, float, str | None]] = []

    def update(
        self,
        trk: RadarTrack,
        r: PackedR | None = None,
        z: tuple[float, float, float] | None = None,
    ) -> RadarObject:
        """Fold one report (with its R, computed here when not given; at the position ``z``
        when given: the report corrected for the radar's misalignment) into its object
        (created on first sight)."""
        cfg = self.cfg
        tid = trk.track_id
        obj = self.objects.get(tid)
        t = trk.t
        if obj is None:
            obj = self.objects[tid] = RadarObject(tid, t)
        dt = t - obj.last_t
        if z is None:
            e = trk.e
            n = trk.n
            u = trk.u
        else:
            e, n, u = z
        if r is None:
            r = self.radar_r.r_at(e, n, u)
        if obj.kf is None and self._orphans:
            self._adopt_orphans(obj, t, e, n, r)
        kf = obj.kf
        n_reports = obj.n_reports
        rcs = trk.rcs_dbsm
        vel = trk.vel_ned
        sig = (vel, rcs)
        old = obj.signature
        coast = old is not None and vel is not None and sig == old
        # one smoothing factor per time constant for this interval (the EMAs below)
        tau = cfg.tau_s
        if kf is None or dt < 0:
            kf = self._start_filter(obj, t, e, n, u, r, rcs)
            dt = 0.0
            a = 0.0 if tau <= 0 else 1.0
        else:
            a = 0.0 if tau <= 0 else (math.exp(-dt / tau) if dt > 0 else 1.0)
            if not coast:
                # a coast is the radar's own prediction: no new measurement for the filter
                kf.predict(t - obj.kf_t)
                kf.update3(e, n, u, r)
                obj.kf_t = t
                obj.drift.add(t, e, n)
        if vel is not None and math.isfinite(vel[0] + vel[1] + vel[2]):
            vn, ve, vd = vel
            spd = math.sqrt(vn * vn + ve * ve + vd * vd)
        else:
            x = kf.x
            spd = math.sqrt(x[3] * x[3] + x[4] * x[4] + x[5] * x[5])
        if n_reports == 0:
            obj.speed = spd
        else:
            self._fold_motion(obj, spd, u, r[5], rcs, a)
        p = trk.uav_prob
        if p is not None and math.isfinite(p):
            self._fold_class(obj, trk, p, dt, n_reports == 0)
        obj.coasting = coast
        obj.signature = sig
        obj.n_reports = n_reports + 1
        obj.last_t = t
        return obj

    def _start_filter(
        self,
        obj: RadarObject,
        t: float,
        e: float,
        n: float,
        u: float,
        r: PackedR,
        rcs: float | None,
    ) -> CvKalman:
        """(Re)start the object's filter at a report (its first, or one older than its last)
        and the running height and RCS at the report's."""
        q = self.cfg.object_q
        kf = obj.kf = CvKalman((q, q, q))
        kf.x = [e, n, u, 0.0, 0.0, 0.0]
        v = 100.0
        kf.P = [
            r[0], r[1], r[2], 0.0, 0.0, 0.0,
            r[3], r[4], 0.0, 0.0, 0.0,
            r[5], 0.0, 0.0, 0.0,
            v, 0.0, 0.0,
            v, 0.0,
            v,
        ]  # fmt: skip
        obj.kf_t = t
        obj.drift = Drift(t)
        obj.drift.add(t, e, n)
        obj.up = u
        obj.sd_up = math.sqrt(r[5])
        if rcs is not None and math.isfinite(rcs):
            obj.rcs_mean = rcs
            obj.rcs_seen = True
        else:
            obj.rcs_mean = 0.0
        return kf

    def _fold_motion(
        self, obj: RadarObject, spd: float, u: float, r_uu: float, rcs: float | None, a: float
    ) -> None:
        """Fold a report after the first into the object's moving averages of speed, height,
        vertical sigma (``r_uu``: the report's vertical variance) and RCS, with the
        smoothing factor ``a`` of the interval."""
        b = 1.0 - a
        obj.speed = a * obj.speed + b * spd
        obj.up = a * obj.up + b * u
        obj.sd_up = a * obj.sd_up + b * math.sqrt(r_uu)
        if rcs is not None and math.isfinite(rcs):
            if obj.rcs_seen:
                obj.rcs_mean = a * obj.rcs_mean + b * rcs
            else:
                obj.rcs_mean = rcs
                obj.rcs_seen = True

    def _fold_class(
        self, obj: RadarObject, trk: RadarTrack, p: float, dt: float, first: bool
    ) -> None:
        """Fold a report's UAV class probability ``p`` (finite) into the object's class
        history (``dt`` since its previous report; ``first``: its first report)."""
        cfg = self.cfg
        # min(max(p, 1e-6), 1 - 1e-6) and max(-c, min(c, logit)) as conditionals
        c = cfg.class_clip
        pc = 1e-6 if p < 1e-6 else p
        if pc > 1.0 - 1e-6:
            pc = 1.0 - 1e-6
        lg = math.log(pc / (1.0 - pc))
        if c < lg:
            lg = c
        if -c > lg:
            lg = -c
        if first:
            obj.class_logit = lg
        else:  # _ema(obj.class_logit, lg, dt, tau_s), inlined
            tau = cfg.tau_s
            if tau <= 0:
                obj.class_logit = lg
            else:
                a = math.exp(-dt / tau) if dt > 0 else 1.0
                obj.class_logit = a * obj.class_logit + (1.0 - a) * lg

    def mark_fused(self, obj: RadarObject, inside: bool, t: float) -> None:
        """Record whether the object's report at ``t`` fell inside the UAV track's gate."""
        v = 1.0 if inside else 0.0
        last = obj.fused_t
        if last is None:
            obj.fused = v
        else:  # _ema(obj.fused, v, t - last, fused_tau_s), inlined
            tau = self.cfg.fused_tau_s
            if tau <= 0:
                obj.fused = v
            else:
                dt = t - last
                a = math.exp(-dt / tau) if dt > 0 else 1.0
                obj.fused = a * obj.fused + (1.0 - a) * v
        obj.fused_t = t

    def rf_fix(self, t: float, e: float, n: float, var_m2: float, key: str | None = None) -> int:
        """Credit the recent object whose predicted position agrees best with an RF fix (of
        the emitter ``key``, when known), if any inside the fix's gate; returns the number of
        objects credited (0 or 1). The object credited is :attr:`credited` (else None)."""
        cfg = self.cfg
        hits = 0
        self.credited = None
        best: tuple[float, RadarObject] | None = None
        for obj in self.objects.values():
            kf = obj.kf
            if kf is None or abs(t - obj.last_t) > HELD_S:
                continue
            dt = t - obj.kf_t  # from the filter's own time (coasts leave it behind)
            x = kf.x
            p = kf.P
            de = e - (x[0] + dt * x[3])
            dn = n - (x[1] + dt * x[4])
            # object position variance (horizontal, with the velocity's share over dt)
            s00 = p[0] + 2 * dt * p[3] + dt * dt * p[15] + var_m2
            s11 = p[6] + 2 * dt * p[9] + dt * dt * p[18] + var_m2
            s01 = p[1] + dt * (p[4] + p[8]) + dt * dt * p[16]
            det = s00 * s11 - s01 * s01
            if det <= 0:
                continue
            d2 = (s11 * de * de - 2.0 * s01 * de * dn + s00 * dn * dn) / det
            if d2 <= RF_GATE_99_2DOF and (best is None or d2 < best[0]):
                best = (d2, obj)
        if best is not None:
            obj = self.credited = best[1]
            obj.rf_support = obj.rf_support_at(t, cfg.rf_tau_s) + 1.0
            obj.rf_t = t
            obj.rf_key = key
            hits += 1
        if hits == 0 and cfg.rf_tau_s > 0:
            keep = t - cfg.rf_tau_s
            self._orphans = [o for o in self._orphans if o[0] >= keep]
            self._orphans.append((t, e, n, var_m2, key))
        return hits

    def _adopt_orphans(self, obj: RadarObject, t: float, e: float, n: float, r: PackedR) -> None:
        """Give a new object the support of the kept fixes that credited nobody and fall
        inside its gate (first report ``e``, ``n`` with R ``r``); those fixes are used up."""
        cfg = self.cfg
        keep = t - cfg.rf_tau_s
        left: list[tuple[float, float, float, float, str | None]] = []
        sup = 0.0
        key: str | None = None
        for o in self._orphans:
            tf, fe, fn, var, k = o
            if tf < keep:
                continue
            s00 = r[0] + var
            s11 = r[3] + var
            s01 = r[1]
            det = s00 * s11 - s01 * s01
            de = fe - e
            dn = fn - n
            q = s11 * de * de - 2.0 * s01 * de * dn + s00 * dn * dn
            if det > 0 and q / det <= RF_GATE_99_2DOF:
                sup += math.exp(-(t - tf) / cfg.rf_tau_s) if cfg.rf_tau_s > 0 else 0.0
                key = k
            else:
                left.append(o)
        self._orphans = left
        if sup:
            obj.rf_support = sup
            obj.rf_t = t
            obj.rf_key = key
