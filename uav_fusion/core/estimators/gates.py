"""Physical gates: what may (re)start the UAV track, and how far one RF fix may move it.

A statistical gate (NIS) says whether a measurement agrees with the track's covariance; after
a long coast that covariance spans kilometres and the gate agrees with almost anything. These
rules ask instead whether the UAV could be there, and whether a second, independent source
says so:

* **(Re)initialisation from radar.** Once the track has had a confirmed state (the *anchor*:
  the last confirmed update), a radar object may start the next track only when it is
  *reachable* (within ``track.max_speed_mps`` times the time since the anchor, plus
  ``association.takeover.reach_margin_m`` for the errors of both positions) or *corroborated*
  (an RF fix was credited to it within ``track.max_coast_s``, the score's ``rf_tau_s``:
  radar and RF agree). A tentative RF track needs M of N agreeing fixes before it is
  confirmed: several RF fixes agreeing with each other.
* **Ground objects.** After take-off (a confirmed state once stood clearly above the ground)
  an object near the ground and stationary is never the UAV without corroboration, however
  reachable: a parked vehicle, a mast or a reflector sits there for the whole flight. This
  holds for a start and for a confirmed track passing from the object it follows onto
  another one inside its gate (after a coast the gate is wide). The
  object table's own terms decide: "near the ground" is a mean height below
  ``ground_alt_m`` plus two of its reports' mean vertical sigmas; "stationary" is a mean
  Doppler speed below ``stationary_speed_mps`` or, once the object is
  ``tau_s`` old, recent positions that stand still (:class:`~uav_fusion.core.
  estimators.objects.Drift`: a fan or a flag is seen through its moving part, whose Doppler
  velocity its reports carry). The track is airborne once a confirmed state stood more than
  ``ground_alt_m`` plus two of its own vertical sigmas up.
* **RF-only moves.** An RF fix that would move the track further than three of the fix's own
  sigmas is held until a second fix agrees with it (within three sigmas of both fixes plus
  what the UAV can fly between them); then the second one is used. A non-line-of-sight fix
  can be consistent and have a small CEP, but two such fixes from different times rarely
  agree; a UAV that really moved is followed one fix later.
* **RF against the radar.** The UAV carries the emitter. When ``track.confirm_m`` RF fixes
  in a row fall outside the track's gate while agreeing with each other (each within three
  sigmas of both plus what the UAV can fly between them), the radar object the track
  follows is not the UAV: the track is dropped (``rf_disagrees``), the last fix becomes the
  state the next start must be reachable from, and the fixes may start the next track. Any
  fix inside the gate ends the run.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from uav_fusion.core.estimators.kalman import UPPER_INDEX, MotionFilter, PackedR
from uav_fusion.core.estimators.objects import RadarObject
from uav_fusion.core.profiles.settings import ScoreConfig

FloatArray = npt.NDArray[np.float64]

#: A fix moving the track further than this many of its own sigmas needs a second fix.
FAR_SIGMAS = 3.0


@dataclass
class Anchor:
    """The last confirmed state: time and horizontal position."""

    t: float
    e: float
    n: float


@dataclass
class HeldFix:
    """An RF fix held for a second one: time, position, variance per axis."""

    t: float
    e: float
    n: float
    var: float


class PhysicalGates:
    """The rules of the module text for one UAV track."""

    def __init__(self, cfg: ScoreConfig, max_speed_mps: float | None) -> None:
        self.cfg = cfg
        self.vmax = max_speed_mps
        self.margin = cfg.reach_margin_m
        self.tau = cfg.rf_tau_s
        self.anchor: Anchor | None = None
        self.airborne = False
        self.held: HeldFix | None = None
        self.outside: list[HeldFix] = []  # agreeing fixes outside the gate, in a row

    # --- the anchor ---------------------------------------------------------------------
    def confirmed_state(self, t: float, x: list[float], p_uu: float) -> None:
        """A confirmed update: the state ``x`` at ``t`` (its vertical variance ``p_uu``)."""
        self.anchor = Anchor(t, x[0], x[1])
        if x[2] > self.cfg.ground_alt_m + 2.0 * math.sqrt(max(p_uu, 0.0)):
            self.airborne = True

    # --- (re)initialisation -------------------------------------------------------------
    def reachable(self, t: float, e: float, n: float) -> bool:
        """Whether the UAV could have flown from the anchor to (``e``, ``n``) by ``t`` (always,
        without a maximum speed or with ``reach_margin_m`` 0)."""
        a = self.anchor
        if a is None or self.vmax is None or self.margin <= 0.0:
            return True
        d = self.vmax * max(0.0, t - a.t) + self.margin
        return (e - a.e) ** 2 + (n - a.n) ** 2 <= d * d

    def corroborated(self, obj: RadarObject, t: float) -> bool:
        """Whether an RF fix was credited to ``obj`` within ``rf_tau_s`` of ``t``."""
        return obj.rf_recent(t, self.tau)

    def grounded(self, obj: RadarObject) -> bool:
        """Whether ``obj`` is near the ground and stationary (the object table's averages)."""
        cfg = self.cfg
        if obj.up >= cfg.ground_alt_m + 2.0 * obj.sd_up:
            return False
        v = cfg.stationary_speed_mps
        if obj.speed < v:
            return True
        return obj.age_s >= cfg.tau_s and obj.drift.still(v)

    def refuse_start(self, obj: RadarObject, t: float, e: float, n: float) -> str | None:
        """Why ``obj`` (reported at ``e``, ``n``) may not start the track at ``t``, or None."""
        if self.anchor is None or self.corroborated(obj, t):
            return None
        if self.refuse_ground(obj, t):
            return "ground"
        if not self.reachable(t, e, n):
            return "unreachable"
        return None

    def refuse_ground(self, obj: RadarObject, t: float) -> bool:
        """Whether ``obj`` may not become the UAV at ``t`` as a ground object: after take-off,
        near the ground and stationary, and no RF fix credited to it within ``rf_tau_s``.
        Applies to a start and to a confirmed track passing onto another object."""
        return self.airborne and self.grounded(obj) and not self.corroborated(obj, t)

    # --- RF-only moves ------------------------------------------------------------------
    def agrees(self, a: HeldFix, b: HeldFix) -> bool:
        """Whether fix ``b`` agrees with the earlier fix ``a``: within three sigmas of both
        plus what the UAV can fly between them."""
        reach = 0.0 if self.vmax is None else self.vmax * max(0.0, b.t - a.t)
        tol = FAR_SIGMAS * math.sqrt(a.var + b.var) + reach
        return (b.e - a.e) ** 2 + (b.n - a.n) ** 2 <= tol * tol

    def rf_inside(self) -> None:
        """An RF fix inside the track's gate: the run of disagreeing fixes ends."""
        self.outside.clear()

    def rf_outside(self, t: float, e: float, n: float, var: float, needed: int) -> bool:
        """An RF fix outside the track's gate; True once ``needed`` such fixes in a row agree
        with each other (the run then starts again)."""
        fix = HeldFix(t, e, n, var)
        run = self.outside
        if run and not self.agrees(run[-1], fix):
            run.clear()
        run.append(fix)
        if len(run) >= needed:
            run.clear()
            # where the UAV is now: the emitter, not the object the track was on
            self.anchor = Anchor(t, e, n)
            return True
        return False

    def rf_move_allowed(self, t: float, e: float, n: float, var: float, move_m: float) -> bool:
        """Whether a fix at (``e``, ``n``) (variance ``var`` per axis) may move the track by
        ``move_m``: a small move, or a far one that a held fix corroborates. A far fix that
        is not corroborated is held in place of any earlier one."""
        if move_m <= FAR_SIGMAS * math.sqrt(var):
            self.held = None
            return True
        h = self.held
        fix = HeldFix(t, e, n, var)
        if h is not None and t > h.t and self.agrees(h, fix):
            self.held = None
            return True
        self.held = fix
        return False


def rf_move(f: MotionFilter, z: Sequence[float], r: PackedR) -> float:
    """How far (m, horizontally) the update with the 2D fix ``z`` (R ``r``, packed) would
    move the track: ``|K y|`` with ``K = P_h (P_h + R)^-1``."""
    x, p = f.mean()
    pe, pen, pn = p[UPPER_INDEX[0][0]], p[UPPER_INDEX[0][1]], p[UPPER_INDEX[1][1]]
    a, b, d = pe + r[0], pen + r[1], pn + r[2]
    det = a * d - b * b
    if not det > 0.0:
        return math.inf
    ye, yn = z[0] - x[0], z[1] - x[1]
    ve, vn = (d * ye - b * yn) / det, (a * yn - b * ye) / det
    return math.hypot(pe * ve + pen * vn, pen * ve + pn * vn)


def horizontal_nis(x: FloatArray, p: FloatArray, z: Sequence[float], r: PackedR) -> float:
    """The NIS of a 2D fix ``z`` (R ``r``, packed) against the state ``x`` with covariance
    ``p`` (full arrays)."""
    ye, yn = z[0] - x[0], z[1] - x[1]
    a, b, d = p[0, 0] + r[0], p[0, 1] + r[1], p[1, 1] + r[2]
    det = a * d - b * b
    if not det > 0.0:
        return math.inf
    return float((d * ye * ye - 2.0 * b * ye * yn + a * yn * yn) / det)
