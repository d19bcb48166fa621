"""Several UAVs at once: every confirmed UAV track with a stable id and a UAV probability.

It composes the parts it shares with the single-UAV tracker
(:mod:`~uav_fusion.core.estimators.parts`: the radar front-end with the radar object table and
its UAV score, the measurement models, the robust weight, the NIS gates, the deleter and M-of-N
confirmation) and routes RF fixes by emitter (:mod:`~uav_fusion.core.estimators.emitters`).
Its own settings are the profile's ``multi`` section (``config/profiles/README.md``); a
``settings`` argument given to :class:`MultiTracker` replaces them.

Per radar frame (one time for all reports):

1. every finite report updates its radar object; the candidates are the reports inside the
   range gate (horizontal only between it and the far gate, or below the ground), not
   coasting, with an RCS of a small UAV (:func:`~uav_fusion.core.estimators.objects.
   too_large`), of objects scoring at least ``follow_min`` (or at
   least ``emitter_follow_min`` for the track carrying the emitter whose fix last credited
   the object: a young radar track on an emitting UAV);
2. every track is predicted to the frame's time (the deleter drops a track whose last
   accepted measurement is older than ``max_coast_s``);
3. tracks and candidates are assigned one to one (Hungarian assignment on the position NIS
   plus ``velocity_weight`` times the NIS of the radar's reported velocity against the
   track's; pairs
   outside the NIS gate forbidden; the UAV score is not in the cost: it tells a UAV from
   clutter, not one UAV from another); an assigned report updates its track (robust
   weight); a confirmed track whose own radar object reported outside its gate counts a
   rejection;
4. an unassigned candidate whose object is strong (score >= ``init_min`` with at least
   ``init_min_reports`` reports, the profile's ``track.confirm_m``), old enough (the
   score's ``tau_s``, or any age with an RF fix credited to it within ``rf_tau_s``) and
   outside every track's gate
   starts a confirmed track from its object's state (at the RF start's height prior when it
   has no usable height; never from a ghost below the ground);
5. two confirmed tracks that stay close (``merge_nis`` on the combined position covariance)
   for ``merge_s`` are one UAV, unless both were updated within ``merge_s`` by different
   radar objects (two UAVs passing each other): the younger is dropped.

RF fixes go to the track of their emitter (:mod:`~uav_fusion.core.estimators.emitters`).

The output (:meth:`MultiTracker.outputs`, and so its fixed-rate epochs) holds a confirmed track
while its last accepted measurement is at most ``output_coast_s`` old and, inside the radar's
range gate, its last radar update too (3 s; the track itself
lives until the profile's ``max_coast_s``, so a UAV found again keeps its id): a track whose
radar object has gone stops being published before it drifts away as a false track, and an
emitter the radar does not see inside its cover (a UAV on its pad with its link on) is not
published.

A track's UAV probability is the logistic of the UAV score of the radar object it last took
(0.5 without one), raised for a track with an emitter: ``1 - (1 - p) * emitter_doubt``
(a control link on a drone band is strong evidence of a UAV).
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt
from scipy.optimize import linear_sum_assignment

from uav_fusion.core.estimators.adaptive import rf_status
from uav_fusion.core.estimators.base import drive
from uav_fusion.core.estimators.consider import consider_for
from uav_fusion.core.estimators.emitters import Emitters
from uav_fusion.core.estimators.grid import GridEpoch, GridState, MultiGrid, Outputs, TrackOutput
from uav_fusion.core.estimators.kalman import (
    MotionFilter,
    PackedR,
    expand_upper,
    merge_nis,
    velocity_nis,
)
from uav_fusion.core.estimators.objects import RadarObject, too_large
from uav_fusion.core.estimators.parts import (
    MofN,
    RadarFront,
    TrackParts,
    motion_filter_from_profile,
    object_start,
    scale_packed,
)
from uav_fusion.core.estimators.selection import frames_input
from uav_fusion.core.estimators.steps import Step
from uav_fusion.core.profiles.model import Profile
from uav_fusion.core.profiles.settings import MultiSettings
from uav_fusion.core.records import Flight, RadarFrame, RadarTrack, RfAttempt
from uav_fusion.core.site import Site

FloatArray = npt.NDArray[np.float64]

_FORBIDDEN = 1.0e9
# a radar report that may update a track: the report, its object, the object's UAV score, R
# and the measurement (e, n, u; or e, n for a report below the ground)
_Cand = tuple[RadarTrack, RadarObject, float, PackedR, tuple[float, ...]]


class UavTrack:
    """One UAV track."""

    __slots__ = (
        "born_t",
        "close_since",
        "confirmed",
        "emitter",
        "emitter_misses",
        "filter",
        "followed",
        "id",
        "last_radar_t",
        "last_update_t",
        "mofn",
        "n_updates",
        "rejections",
        "score",
        "t",
    )

    def __init__(self, track_id: int, t: float, f: MotionFilter, confirmed: bool) -> None:
        self.id = track_id
        self.born_t = t
        self.t = t
        self.filter = f
        self.confirmed = confirmed
        self.last_update_t = t
        self.last_radar_t: float | None = None
        self.followed: int | None = None
        self.emitter: str | None = None
        self.emitter_misses = 0
        self.mofn: MofN | None = None
        self.n_updates = 1
        self.rejections = 0
        self.score = 0.0
        self.close_since: dict[int, float] = {}


class MultiTracker:
    """Every UAV at once (see the module text)."""

    kind = "multi"
    fixed_rate = True
    reads = "frames"

    def __init__(
        self,
        profile: Profile,
        site: Site,
        settings: MultiSettings | None = None,
        grid_hz: float = 10.0,
        t0: float | None = None,
        t1: float | None = None,
    ) -> None:
        self.profile = profile
        self.site = site
        self.settings = settings or profile.multi
        self.cfg = profile.score
        self.front = RadarFront(profile, site, self.cfg)
        self.objects = self.front.objects
        self.radar_r = self.front.radar_r
        parts = TrackParts(profile)
        self.rf_r, self.rf_adaptive = parts.rf_r, parts.rf_adaptive
        self.robust = parts.robust
        self.deleter = parts.deleter
        self._g2 = parts.g2
        self._g3 = parts.g3
        self.emitters = Emitters(self)
        self.tracks: list[UavTrack] = []
        self._next_id = 1
        self.counters: dict[str, int] = {}
        self._args = (settings, grid_hz, t0, t1)
        self.grid = MultiGrid(self, grid_hz, t0, t1, profile.max_coast_s)
        #: the published covariance (the radar's elevation error as a consider term)
        self.consider = consider_for(profile, site)

    # --- the estimator interface (uav_fusion.core.estimators.base) ----------------------
    def radar_frame(self, frame: RadarFrame) -> Outputs:
        out = self._outputs(self.grid.before(frame.t))
        self.process_radar_frame(frame)
        return out

    def rf_attempt(self, attempt: RfAttempt) -> Outputs:
        out = self._outputs(self.grid.before(attempt.t))
        self.process_rf(attempt)
        return out

    def advance(self, t: float) -> Outputs:
        return self._outputs(self.grid.advance(t))

    def finish(self) -> Outputs:
        g = self.grid
        return self._outputs(g.advance(g.end)) if g.bounded else Outputs()

    def restart(self, reason: str) -> None:
        """A new timeline: no tracks, no radar objects, a new grid."""
        del reason
        self.__init__(self.profile, self.site, *self._args)  # type: ignore[misc]

    def measurement(self, step: Step) -> tuple[FloatArray, FloatArray | None] | None:
        return None  # no filter steps

    def flight_input(self, flight: Flight) -> list[RadarFrame | RfAttempt]:
        return frames_input(flight, self.profile)

    def status(self) -> dict[str, object]:
        confirmed = [t for t in self.tracks if t.confirmed]
        return {
            "multi_tracks_confirmed": len(confirmed),
            "multi_track_ids": " ".join(str(t.id) for t in confirmed) or "-",
            **self.front.status(), **rf_status(self.rf_adaptive),
        }

    def _outputs(self, epochs: list[GridEpoch]) -> Outputs:
        """The epochs, and on the single-track output each epoch's most UAV-like track."""
        hz = self.grid.frequency_hz
        grid = [
            GridState(
                round(ep.t * hz), ep.t, o.x, o.P, True, True, ep.t - o.last_update_t,
                o.track_id, "",
            )
            for ep in epochs
            if ep.tracks
            for o in ep.tracks[:1]
        ]  # fmt: skip
        return Outputs(grid=grid, tracks=epochs)

    # --- output ---------------------------------------------------------------------------
    def _count(self, key: str, n: int = 1) -> None:
        self.counters[key] = self.counters.get(key, 0) + n

    def uav_prob(self, tr: UavTrack) -> float:
        p = 0.5 if tr.followed is None else 1.0 / (1.0 + math.exp(-max(-30.0, min(30.0, tr.score))))
        if tr.emitter is not None:
            p = 1.0 - (1.0 - p) * self.settings.emitter_doubt
        return p

    def outputs(self, t: float | None = None) -> list[TrackOutput]:
        """Every confirmed track, predicted to ``t`` (default: its own time) without changing
        it, highest UAV probability first, with its published covariance (the filter's and
        the consider term, :mod:`uav_fusion.core.estimators.consider`)."""
        out: list[TrackOutput] = []
        for tr in self.tracks:
            if not tr.confirmed:
                continue
            f = tr.filter
            at = tr.t
            if t is not None and t > tr.t:
                f = f.copy()
                f.predict(t - tr.t)
                at = t
            x, p = f.mean()
            if not self._published(tr, at, x):
                continue
            xa, P = np.array(x, dtype=float), expand_upper(p)
            if self.consider is not None:
                P = self.consider.cov(xa, P)
            out.append(
                TrackOutput(
                    tr.id, at, xa, P, self.uav_prob(tr), tr.emitter, tr.followed,
                    tr.last_update_t,
                )
            )  # fmt: skip
        out.sort(key=lambda o: (-o.uav_prob, o.track_id))
        return out

    def _published(self, tr: UavTrack, t: float, x: list[float]) -> bool:
        """Whether a confirmed track at ``t`` (position ``x``) is output: its last update at
        most ``output_coast_s`` old and, inside the radar's range gate, its last radar update
        too (an emitter inside radar cover that the radar does not
        see is on the ground: a UAV on its pad with its link on, or one that has landed)."""
        st = self.settings
        coast = st.output_coast_s
        if coast is None:
            return True
        if t - tr.last_update_t > coast:
            return False
        if tr.last_radar_t is not None and t - tr.last_radar_t <= coast:
            return True
        rx, ry, rz = self.front.radar_pos
        d2 = (x[0] - rx) ** 2 + (x[1] - ry) ** 2 + (x[2] - rz) ** 2
        return d2 > self.front.gate2

    # --- track life ------------------------------------------------------------------------
    def _new_track(self, t: float, x: list[float], P: FloatArray, confirmed: bool) -> UavTrack:
        f = motion_filter_from_profile(self.profile)
        f.set_state(x, P)
        tr = UavTrack(self._next_id, t, f, confirmed)
        self._next_id += 1
        self.tracks.append(tr)
        self._count("started" if confirmed else "tentative_started")
        return tr

    def _drop(self, tr: UavTrack, reason: str) -> None:
        self.tracks.remove(tr)
        self._count(f"dropped_{reason}")

    def _advance(self, t: float) -> None:
        for tr in list(self.tracks):
            if t < tr.t:
                continue
            if self.deleter.coast_expired(t, tr.last_update_t):
                self._drop(tr, "max_coast")
                continue
            if t > tr.t:
                tr.filter.predict(t - tr.t)
                tr.t = t

    def _reject(self, tr: UavTrack) -> None:
        tr.rejections += 1
        self._count("rejected_nis")
        if tr.confirmed and self.deleter.too_many_rejections(tr.rejections):
            self._drop(tr, "max_rejections")

    def _accept(self, tr: UavTrack, t: float) -> None:
        tr.last_update_t = t
        tr.rejections = 0
        tr.n_updates += 1
        self._count("updated")

    # --- radar ------------------------------------------------------------------------------
    def process_radar_frame(self, frame: RadarFrame) -> None:
        t = frame.t
        cands, far_cands, weak = self._candidates(frame)
        self._advance(t)
        live = [tr for tr in self.tracks if tr.t <= t and tr.confirmed]
        g2 = self._g2
        g3 = self._g3
        nis_rows: list[list[float]] = []
        for tr in live:
            f = tr.filter
            row = []
            for c in cands:
                n = f.nis(c[4], c[3])
                row.append(n if len(c[4]) == 3 else n * g3 / g2)  # 2D on the 3D gate's scale
            nis_rows.append(row)
        took: dict[int, int] = {}  # live track index -> the candidate it took
        if live and cands:
            took = self._assign(t, live, cands, weak, nis_rows)
        # a confirmed track whose own object reported outside its gate: a rejection
        for a, tr in enumerate(live):
            if tr.followed is None or tr.last_update_t == t or tr not in self.tracks:
                continue
            for b, c in enumerate(cands):
                if c[0].track_id == tr.followed and nis_rows[a][b] > g3:
                    self._reject(tr)
                    break
        self._births(t, cands, far_cands, set(took.values()), took, nis_rows)
        self._merge(t)

    def _candidates(self, frame: RadarFrame) -> tuple[list[_Cand], set[int], set[int]]:
        """The frame's reports that may update a track (every report updates its radar
        object first), the indices of those beyond the range gate (horizontal only), and of
        the weak ones (for the track of their object's emitter only)."""
        t = frame.t
        cfg = self.cfg
        cands: list[_Cand] = []
        far_cands: set[int] = set()
        weak: set[int] = set()
        efm = self.settings.emitter_follow_min
        if frame.tracks:
            self._count("radar_reports", len(frame.tracks))
        bad, reports = self.front.reports(frame)
        if bad:
            self._count("rejected_invalid", len(bad))
        gate2 = self.front.gate2
        far2 = self.front.far2
        for _, trk, obj, p3, r, d2 in reports:
            if (d2 > gate2 and not d2 <= far2) or obj.coasting:
                continue
            if too_large(trk, cfg):  # not a small UAV's report
                self._count("rejected_large_rcs")
                continue
            e, n_, u = p3
            z: tuple[float, ...] = p3
            s = obj.score(cfg)
            if d2 > gate2:
                # inside the far gate: horizontal only
                z, r = (e, n_), (r[0], r[1], r[3])
            elif u < -cfg.below_ground_m:
                # the elevation of a low target is the radar's weak point (ground multipath):
                # range and azimuth still place it; its object without the below-ground term
                if obj.below_ground(cfg):
                    s += cfg.veto
                z, r = (e, n_), (r[0], r[1], r[3])
            if s < cfg.follow_min:
                # too weak to follow, unless where an emitter's fix says its UAV is: then only
                # the track carrying that emitter may take it
                if (
                    efm is None
                    or s < efm
                    or obj.rf_key is None
                    or not obj.rf_recent(t, cfg.rf_tau_s)
                ):
                    continue
                weak.add(len(cands))
            if d2 > gate2:
                far_cands.add(len(cands))
            cands.append((trk, obj, s, r, z))
        return cands, far_cands, weak

    def _assign(
        self,
        t: float,
        live: list[UavTrack],
        cands: list[_Cand],
        weak: set[int],
        nis_rows: list[list[float]],
    ) -> dict[int, int]:
        """Tracks and candidates one to one (Hungarian assignment); every assigned report
        updates its track. Returns live track index -> the candidate it took."""
        g2 = self._g2
        g3 = self._g3
        took: dict[int, int] = {}
        # NIS (and the reported velocity's); the UAV score only decides who may update a
        # track (follow_min): between two UAVs it says nothing
        st = self.settings
        wv = st.velocity_weight
        s2 = st.velocity_sigma_mps**2
        cost_rows: list[list[float]] = []
        any_inside = False
        for tr, row in zip(live, nis_rows, strict=True):
            x, pk = tr.filter.mean() if wv > 0.0 else ([], [])
            crow = []
            for bi, (c, n) in enumerate(zip(cands, row, strict=True)):
                if not n <= g3 or (bi in weak and (c[1].rf_key != tr.emitter)):
                    crow.append(_FORBIDDEN)
                    continue
                any_inside = True
                v = n
                if wv > 0.0:
                    v += wv * velocity_nis(x, pk, c[0].vel_ned, s2)
                crow.append(v)
            cost_rows.append(crow)
        if not any_inside:
            return took
        cost = np.array(cost_rows)
        rows, cols = linear_sum_assignment(cost)
        for a, b in zip(rows.tolist(), cols.tolist(), strict=True):
            if cost_rows[a][b] >= _FORBIDDEN:
                continue
            tr = live[a]
            trk, _obj, s, r, z = cands[b]
            dof = len(z)
            n = nis_rows[a][b] if dof == 3 else nis_rows[a][b] * g2 / g3
            w = self.robust.weight(n, dof)
            if dof == 2:
                self._hold_height(tr)
            elif tr.confirmed:  # measurement.adaptive: the innovation, before the update
                self.front.innovation(z, tr.filter)
            tr.filter.update(z, scale_packed(r, 1.0 / w) if w != 1.0 else r)
            self._accept(tr, t)
            if not tr.confirmed:
                tr.confirmed = True
                tr.mofn = None
                self._count("confirmed")
            tr.followed = trk.track_id
            tr.last_radar_t = t
            tr.score = s
            took[a] = b
        return took

    def _births(
        self,
        t: float,
        cands: list[_Cand],
        far_cands: set[int],
        taken: set[int],
        took: dict[int, int],
        nis_rows: list[list[float]],
    ) -> None:
        """Strong objects that no track explains start tracks."""
        cfg = self.cfg
        g3 = self._g3
        n_live = len(nis_rows)
        for b, (trk, obj, s, _r, z) in enumerate(cands):
            if b in taken or s < cfg.init_min or obj.n_reports < cfg.init_min_reports:
                continue
            far = b in far_cands
            flat_start = far or len(z) != 3  # no usable height: start at the height prior
            if flat_start and not far and obj.below_ground(cfg):  # a ghost: no birth
                continue
            if not self._old_enough(obj, t):
                continue
            if any(
                nis_rows[a][b] <= g3 and not self._apart(a, b, took, cands)
                for a in range(n_live)
            ):
                continue
            x0, P0 = object_start(obj, self.profile, flat_start)
            tr = self._new_track(t, x0, P0, confirmed=True)
            tr.followed = trk.track_id
            tr.last_radar_t = t
            tr.score = s

    def _old_enough(self, obj: RadarObject, t: float) -> bool:
        """Whether a strong object has been seen long enough to start a track: for the
        score's ``tau_s`` (its class history and age term are full, and clutter has shown
        that it stands still), or at any age with an RF fix credited to it within
        ``rf_tau_s``."""
        return obj.age_s >= self.cfg.tau_s or obj.rf_recent(t, self.cfg.rf_tau_s)

    def _apart(self, a: int, b: int, took: dict[int, int], cands: list[_Cand]) -> bool:
        """Whether candidate ``b``, inside live track ``a``'s gate, is another UAV than the
        one ``a`` follows: ``a`` took another report of this frame, more than ``birth_sep_m``
        away horizontally (two radar tracks reporting in the same frame, neither coasting,
        follow two objects; one UAV split into two radar tracks gives nearby reports)."""
        sep = self.settings.birth_sep_m
        c = took.get(a)
        if sep is None or c is None:
            return False
        za, zb = cands[c][0], cands[b][0]
        return (za.e - zb.e) ** 2 + (za.n - zb.n) ** 2 > sep * sep

    def _hold_height(self, tr: UavTrack) -> None:
        """Before an update without height: hold the climb rate near 0 and keep the track
        above the ground (soft: a pseudo-measurement at ground level when it is below)."""
        p = self.profile
        sd = p.hold_sigma_mps
        f = tr.filter
        f.update_scalar(5, 0.0, sd * sd)
        x, _ = f.mean()
        if x[2] < -self.cfg.below_ground_m:
            f.update_scalar(2, 0.0, self.cfg.below_ground_m**2)

    def _merge(self, t: float) -> None:
        conf = [tr for tr in self.tracks if tr.confirmed]
        if len(conf) < 2:
            return
        st = self.settings
        means = [tr.filter.mean() for tr in conf]
        recent = [self._radar_recent(tr, t) for tr in conf]
        for i, a in enumerate(conf):
            xa, pa = means[i]
            for j in range(i + 1, len(conf)):
                b = conf[j]
                if a not in self.tracks or b not in self.tracks:
                    continue
                xb, pb = means[j]
                # a track without a recent radar update has no altitude worth comparing
                m = merge_nis(xa, pa, xb, pb, 3 if recent[i] and recent[j] else 2)
                if m is None:
                    continue
                if m > st.merge_nis:
                    a.close_since.pop(b.id, None)
                    continue
                since = a.close_since.setdefault(b.id, t)
                if t - since < st.merge_s:
                    continue
                ra, rb = a.last_radar_t, b.last_radar_t
                if (
                    ra is not None
                    and rb is not None
                    and t - ra <= st.merge_s
                    and t - rb <= st.merge_s
                    and a.followed != b.followed
                ):
                    continue  # two objects side by side: two UAVs
                # keep the older track; it inherits the younger one's emitter. A track
                # updated within merge_s is kept over one that is not (a coasting track that
                # lost its UAV drifting onto another UAV's track), and a coasting track's
                # emitter is not inherited.
                keep, lose = (a, b) if (a.born_t, a.id) <= (b.born_t, b.id) else (b, a)
                la = t - a.last_update_t <= st.merge_s
                lb = t - b.last_update_t <= st.merge_s
                if la != lb:
                    keep, lose = (a, b) if la else (b, a)
                if t - lose.last_update_t > st.merge_s:
                    lose.emitter = None
                if keep.emitter is None:
                    keep.emitter = lose.emitter
                self._drop(lose, "merged")

    def _radar_recent(self, tr: UavTrack, t: float) -> bool:
        return tr.last_radar_t is not None and t - tr.last_radar_t <= self.settings.merge_s

    # --- RF -----------------------------------------------------------------------------------

    def process_rf(self, att: RfAttempt) -> None:
        """One RF attempt: to the track of its emitter (:mod:`.emitters`)."""
        self.emitters.fix(att)


def run_multi(
    tracker: MultiTracker,
    stream: list[RadarFrame | RfAttempt],
    grid_hz: float,
    t_start: float,
    t_end: float,
) -> list[GridEpoch]:
    """Drive ``tracker`` over ``stream`` (time order) with its output at ``grid_hz`` on
    ``[t_start, t_end]``: its confirmed tracks at every epoch."""
    tracker.grid = MultiGrid(tracker, grid_hz, t_start, t_end, tracker.profile.max_coast_s)
    return drive(tracker, stream, t_end).tracks
