"""How the single-UAV track follows the radar: which report of a frame updates it, when the
frame is a rejection, when a challenger takes the track over, and how a track (re)starts.

A component of the :class:`~uav_fusion.core.estimators.tracker.Tracker` (it acts on the
tracker's track and makes its steps). For a radar frame's candidates (reports inside the
range gate, or horizontal only inside the far gate, not coasting; each with its object's UAV
score):

- confirmed track: a report is *eligible* when its object's score is at least ``follow_min``;
  of the eligible reports inside the NIS gate (and, for another radar object than the one
  followed, reachable from the track's last update at ``track.max_speed_mps`` plus
  ``association.takeover.reach_margin_m``, and not a ground object without corroboration:
  :meth:`~uav_fusion.core.estimators.gates.PhysicalGates.refuse_ground`; a report refused
  so is discarded as ``unreachable`` or ``ground``) the one with the
  smallest ``NIS - 2 score``
  (global nearest neighbour with the score as prior log-odds) updates the track with
  ``R / w`` (``w`` the robust weight); the others are ``not_selected``. When no eligible
  report is inside the gate, the followed object, or one strong enough to start a track,
  makes the frame's ``coasted`` step (a rejection); ineligible reports are discarded
  (``score``). Before that, with ``challenge_s`` > 0: when, for ``challenge_s`` seconds, one
  and the same object outside the gate has reached ``init_min`` (with ``init_min_reports``
  reports) and outscored the followed object by ``challenge_margin``, the radar's track has
  most likely left the UAV: the track is dropped (``reinit_challenged``) and started again
  from the frame's reports. The two are compared without their agreement with the fused
  track, which the followed object has because the track follows it. Each report records
  in its object whether it agrees with the track (:meth:`ObjectTable.mark_fused
  <uav_fusion.core.estimators.objects.ObjectTable.mark_fused>`) only while the track knows
  the UAV's horizontal position at least as well as the report does (:func:`informative`):
  after a long coast the gate spans far more than the UAV's neighbourhood, and any report
  inside it would count as agreement;
- no confirmed track: the object with the highest score reaching ``init_min`` with at least
  ``init_min_reports`` reports starts a confirmed track from its own filter's state; a
  tentative RF track is confirmed by a strong report inside its gate or superseded by one.

With ``update.hold_after_s``: no radar update for that long with the track inside
the 3D range gate means the UAV hovers in the Doppler notch, so a radial
speed of 0 is fused at every frame (:meth:`RadarFollower.notch`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import TYPE_CHECKING

from uav_fusion.core.estimators.kalman import CvFilter, MotionFilter, PackedR
from uav_fusion.core.estimators.objects import RadarObject
from uav_fusion.core.estimators.parts import object_start, scale_packed
from uav_fusion.core.estimators.steps import DISCARDED
from uav_fusion.core.records import RADAR, RadarTrack

if TYPE_CHECKING:
    from uav_fusion.core.estimators.steps import TrackerStep
    from uav_fusion.core.estimators.tracker import Tracker

# a candidate report of a frame: (index in the frame, report, its object, the object's score,
# z, R, NIS against the track, inside the gate)
Scored = tuple[int, RadarTrack, RadarObject, float, tuple[float, ...], PackedR, float, bool]
# a frame's candidate before scoring: (index in the frame, report, its object, its score)
Candidate = tuple[int, RadarTrack, RadarObject, float]


def informative(track_var_m2: float, r: PackedR) -> bool:
    """Whether a report's agreement with the track says anything: the track's largest
    horizontal variance (east or north) is at most the report's own (its R, 3D packed or,
    beyond the 3D gate, 2D packed)."""
    r_var = max(r[0], r[3] if len(r) == 6 else r[2])
    return track_var_m2 <= r_var


class RadarFollower:
    """The single-UAV track's radar association (see the module text)."""

    def __init__(self, tracker: Tracker) -> None:
        self.tr = tracker
        #: (object id, since when) of a strong object outside the gate that outscores the
        #: followed one (``association.takeover.challenge_s``)
        self.challenger: tuple[int, float] | None = None

    def notch(self, t: float) -> None:
        """At a radar frame: no radar update for ``update.hold_after_s`` with the track
        inside the 3D range gate. The radar would see the UAV there
        unless its radial speed sits in the Doppler notch, so a pseudo-measurement radial
        speed = 0 (sigma ``update.hold_sigma_mps``) is fused (a hover stops the coast's
        drift). No step is made; the next step carries the state."""
        tr = self.tr
        p = tr.profile
        f = tr.filter
        after = p.hold_after_s
        last = tr.last_radar_t
        if f is None or not tr.confirmed or after is None or last is None or t - last < after:
            return
        x = f.mean()[0]
        rx, ry, rz = tr.front.radar_pos
        dx, dy, dz = x[0] - rx, x[1] - ry, x[2] - rz
        rng = math.sqrt(dx * dx + dy * dy + dz * dz)
        if rng <= 1.0 or rng * rng > tr.front.gate2:
            return
        sd = p.hold_sigma_mps
        f.update_linear((0.0, 0.0, 0.0, dx / rng, dy / rng, dz / rng), 0.0, sd * sd)
        tr._count("notch")

    def frame(
        self,
        t: float,
        cands: list[Candidate],
        rs: dict[int, PackedR],
        far: set[int],
        zs: dict[int, tuple[float, float, float]],
    ) -> list[tuple[int, TrackerStep]]:
        tr = self.tr
        cfg = tr.cfg
        res: list[tuple[int, TrackerStep]] = []
        f = tr.filter
        if f is not None:
            g = tr._g3
            scored: list[Scored] = []
            # the CV filter's kernel directly (what CvFilter.nis calls for a 3D z)
            nis3 = f.kf.nis3 if isinstance(f, CvFilter) else None
            mark = tr.objects.mark_fused if tr.confirmed else None
            p_var = 0.0
            if mark is not None:
                p = f.mean()[1]
                p_var = p[0] if p[0] > p[6] else p[6]
            fused_nis = cfg.fused_nis
            reach = cfg.reach_margin_m
            g2 = tr._g2
            # reports inside the gate that the track may not pass onto, and why
            refused: dict[int, str] = {}
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
                if inside and trk.track_id != tr.followed:
                    if reach > 0 and not self._reachable(t, z[0], z[1], reach):
                        inside = False
                        refused[i] = "unreachable"
                    elif tr.gates.refuse_ground(obj, t):
                        # a ground object no second source confirms (gates.py)
                        inside = False
                        refused[i] = "ground"
                if mark is not None and informative(p_var, r):
                    mark(obj, nis <= fused_nis, t)
                scored.append((i, trk, obj, s, z, r, nis, inside))
            if not tr.confirmed:
                # a tentative RF track: only an object strong enough to start a track may
                # confirm it (inside its gate) or supersede it (_initiate)
                strong = [
                    e
                    for e in scored
                    if e[7] and e[3] >= cfg.init_min and e[2].n_reports >= cfg.init_min_reports
                ]
                if strong:
                    best = min(strong, key=lambda e: (e[6] - 2.0 * e[3], e[0]))
                    tr.confirmed = True
                    tr._pending_reset = None
                    tr._count("confirmed")
                    res.append((best[0], self._take(t, f, best, 1.0)))
                    for e in scored:
                        if e is not best:
                            res.append((e[0], self._discard(t, e, "not_selected")))
                    return res
                return self.initiate(t, cands, far, zs)
            if cfg.challenge_s > 0 and self._challenged(t, scored):
                # the followed object has been outscored by a strong object outside the
                # gate for challenge_s: the radar's track has most likely left the UAV
                tr._drop("challenged")
                return self.initiate(t, cands, far, zs)
            eligible = [e for e in scored if e[3] >= cfg.follow_min]
            in_gate = [e for e in eligible if e[7]]
            if in_gate:
                best = min(in_gate, key=lambda e: (e[6] - 2.0 * e[3], e[0]))
                w = tr.robust.weight(best[6], len(best[4]))
                res.append((best[0], self._take(t, f, best, w)))
                for e in scored:
                    if e is not best:
                        why = "not_selected" if e[3] >= cfg.follow_min else "score"
                        res.append((e[0], self._discard(t, e, refused.get(e[0], why))))
                return res
            # nothing usable inside the gate: a rejection of the track only when the object
            # it follows, or one strong enough to start a track, disagrees with it
            contra = [
                e
                for e in eligible
                if e[1].track_id == tr.followed
                or (e[3] >= cfg.init_min and e[2].n_reports >= cfg.init_min_reports)
            ]
            if contra:
                best = max(contra, key=lambda e: (e[3], -e[0]))
                i, trk, obj, s, z, r, nis, _ = best
                if tr.deleter.too_many_rejections(tr.consecutive_rejections + 1):
                    # this rejection drops the track: the reports of the frame (the one that
                    # disagreed included) may start the next one at once
                    tr._count("rejected_nis")
                    tr._drop("max_rejections")
                    return self.initiate(t, cands, far, zs)
                res.append((i, tr._rejected(t, RADAR, nis, z, trk.track_id, s)))
                for e in scored:
                    if e is best:
                        continue
                    why = "nis" if e[3] >= cfg.follow_min else "score"
                    res.append((e[0], self._discard(t, e, refused.get(e[0], why))))
                return res
            for e in scored:
                why = "nis" if e[3] >= cfg.follow_min else "score"
                res.append((e[0], self._discard(t, e, refused.get(e[0], why))))
            return res
        # no confirmed track (none, or a tentative RF track): a strong object starts one
        return self.initiate(t, cands, far, zs)

    def _take(self, t: float, f: MotionFilter, e: Scored, w: float) -> TrackerStep:
        """Update the track with candidate ``e`` (R / ``w``; a horizontal-only candidate holds
        the climb rate first) and make its ``updated`` step; the track now follows its
        object."""
        tr = self.tr
        _, trk, _, s, z, r, nis, _ = e
        if len(z) == 2:
            tr._hold_vz(t, f)
            tr._count("updated_radar_horizontal")
        elif tr.confirmed:  # measurement.adaptive: the innovation, before the update
            tr.front.innovation(z, f)
        f.update(z, scale_packed(r, 1.0 / w) if w != 1.0 else r)
        step = tr._used(t, RADAR, nis, z, trk.track_id, s, w)
        tr.followed = trk.track_id
        tr.last_radar_t = t
        if len(z) == 3:
            tr.last_3d_t = t
        return step

    def _reachable(self, t: float, e: float, n: float, margin: float) -> bool:
        """Whether the UAV could have flown from the track's position at its last update to
        (``e``, ``n``) by ``t``: within ``track.max_speed_mps`` times the time since, plus
        ``margin`` (measurement errors; no limit without a maximum speed)."""
        tr = self.tr
        vmax = tr.profile.max_speed_mps
        if vmax is None or tr.last_update_t is None:
            return True
        d = vmax * max(0.0, t - tr.last_update_t) + margin
        e0, n0 = tr._last_pos
        return (e - e0) ** 2 + (n - n0) ** 2 <= d * d

    def _challenged(self, t: float, scored: Sequence[Scored]) -> bool:
        """Whether a strong object outside the gate (score >= ``init_min`` and at least
        ``challenge_margin`` above the followed object's) has done so for ``challenge_s``."""
        tr = self.tr
        cfg = tr.cfg
        lo = cfg.init_min
        n_min = cfg.init_min_reports
        best = None
        for e in scored:  # the strongest object outside the gate (most frames: none)
            if e[7] or e[3] < lo or e[2].n_reports < n_min or e[1].track_id == tr.followed:
                continue
            if best is None or e[3] > best[3]:
                best = e
        fol = tr.objects.objects.get(tr.followed) if tr.followed is not None else None
        # compared without the agreement with the fused track: the followed object agrees
        # with the track because the track follows it, and an object outside the gate
        # cannot agree with it
        if (
            best is None
            or fol is None
            or best[2].score(cfg, fused=False) < fol.score(cfg, fused=False) + cfg.challenge_margin
        ):
            ch = self.challenger
            if (
                best is None
                and ch is not None
                and not any(e[1].track_id == ch[0] for e in scored)
            ):
                # the challenger sent no fresh report this frame (a radar coast): its clock runs on
                return False
            self.challenger = None
            return False
        tid = best[2].id
        ch = self.challenger
        if ch is None or ch[0] != tid:
            self.challenger = (tid, t)
            return False
        return t - ch[1] >= cfg.challenge_s

    def _discard(
        self,
        t: float,
        e: Scored,
        why: str,
    ) -> TrackerStep:
        tr = self.tr
        return tr._step(t, RADAR, DISCARDED, why, e[6], e[4], e[1].track_id, e[3])

    def initiate(
        self,
        t: float,
        cands: list[Candidate],
        far: set[int],
        zs: dict[int, tuple[float, float, float]],
    ) -> list[tuple[int, TrackerStep]]:
        tr = self.tr
        cfg = tr.cfg
        refused: dict[int, str] = {}
        ok = []
        for e in cands:
            if e[3] < cfg.init_min or e[2].n_reports < cfg.init_min_reports:
                continue
            why = tr.gates.refuse_start(e[2], t, zs[e[0]][0], zs[e[0]][1])
            if why is None:
                ok.append(e)
            else:  # the UAV cannot be there, or a ground object no second source confirms
                refused[e[0]] = why
                tr._count(f"init_refused_{why}")
        res: list[tuple[int, TrackerStep]] = []
        best = max(ok, key=lambda e: (e[3], -e[0])) if ok else None
        if best is not None and RADAR in tr.profile.init_sources:
            i, trk, obj, s = best
            if tr.filter is not None:  # a tentative RF track is superseded
                tr._count("reinit_superseded")
                tr.filter = None
                tr._pending_reset = "superseded"
            flat = i in far
            x, P = object_start(obj, tr.profile, flat)
            tr._start(t, x, P, tentative=False)
            tr.last_update_t = t
            tr.followed = trk.track_id
            tr.last_3d_t = None if flat else t
            tr.last_radar_t = t
            status, reason = tr._confirmed_status()
            tr._count(f"{status}_{RADAR}")
            res.append((i, tr._step(t, RADAR, status, reason, None, zs[i], trk.track_id, s)))
        for e in cands:
            if e is best and res:
                continue
            why = "no_track" if tr.filter is None or not tr.confirmed else "not_selected"
            if tr.filter is not None and not tr.confirmed:
                why = "tentative_track"
            why = refused.get(e[0], why)
            res.append(
                (e[0], tr._step(t, RADAR, DISCARDED, why, None, zs[e[0]], e[1].track_id, e[3]))
            )
        return res
