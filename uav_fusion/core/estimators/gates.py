"""Physical gates: what may (re)start the UAV track, and how far one RF fix may move it.

A statistical gate (NIS) says whether a measurement agrees with the track's covariance; after
a long coast that covariance spans kilometres and the gate agrees with almost anything. These
rules ask instead whether the UAV could be there, and whether a second, independent source
says so:

* **(Re)initialisation from radar.** Once the track has had a confirmed state (the *anchor*:
  the last confirmed update), a radar object may start the next track only when it is
  *reachable* (within ``track.max_speed_mps`` times the time since the anchor, plus
  ``association.takeover.reach_margin_m`` for the errors of both positions) or *corroborated*
  (an RF fix was credited to it within ``association.rf.tau_s``: radar and RF agree). A
  tentative RF track needs M of N agreeing fixes before it is confirmed: several RF fixes
  agreeing with each other.
* **Ground objects.** After take-off (a confirmed state once stood clearly above the ground)
  an object near the ground and stationary is never the UAV without corroboration, however
  reachable: a parked vehicle, a mast or a reflector sits there for the whole flight. The
  object table's own terms decide: "near the ground" is a mean height below
  ``ground_alt_m`` plus two of its reports' mean vertical sigmas, never having stood clearly
  above it (:attr:`RadarObject.aloft`); "stationary" is a mean speed below
  ``stationary_speed_mps``. The track is airborne once a confirmed state stood more than
  ``ground_alt_m`` plus two of its own vertical sigmas up.
* **RF-only moves.** An RF fix that would move the track further than three of the fix's own
  sigmas is held until a second fix agrees with it (within three sigmas of both fixes plus
  what the UAV can fly between them); then the second one is used. A non-line-of-sight fix
  can be consistent and have a small CEP, but two such fixes from different times rarely
  agree; a UAV that really moved is followed one fix later.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

from uav_fusion.core.estimators.kalman import UPPER_INDEX, MotionFilter, PackedR
from uav_fusion.core.estimators.objects import RadarObject
from uav_fusion.core.profiles.settings import ScoreConfig

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
        return obj.rf_support > 0.0 and self.tau > 0.0 and t - obj.rf_t <= self.tau

    def grounded(self, obj: RadarObject) -> bool:
        """Whether ``obj`` is near the ground and stationary (the object table's averages)."""
        cfg = self.cfg
        low = not obj.aloft and obj.up < cfg.ground_alt_m + 2.0 * obj.sd_up
        return low and obj.speed < cfg.stationary_speed_mps

    def refuse_start(self, obj: RadarObject, t: float, e: float, n: float) -> str | None:
        """Why ``obj`` (reported at ``e``, ``n``) may not start the track at ``t``, or None."""
        if self.anchor is None or self.corroborated(obj, t):
            return None
        if self.airborne and self.grounded(obj):
            return "ground"
        if not self.reachable(t, e, n):
            return "unreachable"
        return None

    # --- RF-only moves ------------------------------------------------------------------
    def rf_move_allowed(self, t: float, e: float, n: float, var: float, move_m: float) -> bool:
        """Whether a fix at (``e``, ``n``) (variance ``var`` per axis) may move the track by
        ``move_m``: a small move, or a far one that a held fix corroborates. A far fix that
        is not corroborated is held in place of any earlier one."""
        if move_m <= FAR_SIGMAS * math.sqrt(var):
            self.held = None
            return True
        h = self.held
        if h is not None and t > h.t:
            reach = 0.0 if self.vmax is None else self.vmax * (t - h.t)
            tol = FAR_SIGMAS * math.sqrt(var + h.var) + reach
            if (e - h.e) ** 2 + (n - h.n) ** 2 <= tol * tol:
                self.held = None
                return True
        self.held = HeldFix(t, e, n, var)
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
