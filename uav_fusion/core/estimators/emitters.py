"""Which multi-UAV track an RF fix goes to: the track of its emitter.

A fix (``ok`` attempts) first credits the radar objects it agrees with. It belongs to its
emitter, keyed by centre frequency (:func:`emitter_key`): a track that has an emitter takes
only that emitter's fixes (inside its gate: update; outside: a rejection, and after
``multi.emitter_misses`` such fixes in a row the track loses the emitter: the link was wrong,
e.g. made from a fix of a UAV still on its pad, and the emitter's next fix links anew); a fix
of an emitter no track has yet goes to the nearest confirmed track without an emitter whose
gate it falls in, which then carries that emitter; otherwise it starts a tentative track of
that emitter, confirmed by M of N fixes as in the single-UAV tracker. A fix without a
frequency is one emitter of its own (``unknown``). Fixes with a CEP above
``measurement.rf.max_cep_m`` are discarded. Before an update, a track without a 3D radar
update for ``update.hold_after_s`` has its climb rate held near zero.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from uav_fusion.core.estimators.adaptive import observe_rf_fix
from uav_fusion.core.estimators.kalman import PackedR
from uav_fusion.core.estimators.parts import MofN, rf_start, scale_packed
from uav_fusion.core.records import RfAttempt

if TYPE_CHECKING:
    from uav_fusion.core.estimators.multi import MultiTracker, UavTrack

#: Emitter key of RF fixes without a centre frequency.
UNKNOWN_EMITTER = "unknown"


def emitter_key(freq_hz: float | None) -> str:
    """The emitter a fix belongs to: its centre frequency in whole kHz, or ``unknown``."""
    if freq_hz is None or not math.isfinite(freq_hz):
        return UNKNOWN_EMITTER
    return f"{round(freq_hz / 1e3):d}kHz"


class Emitters:
    """Routes RF fixes to multi-UAV tracks by emitter (see the module text)."""

    def __init__(self, tracker: MultiTracker) -> None:
        self.mt = tracker

    def fix(self, att: RfAttempt) -> None:
        """One RF attempt (see the module text)."""
        mt = self.mt
        if not att.ok or not math.isfinite(att.t + att.e + att.n):
            return
        t = att.t
        mt._count("rf_fixes")
        max_cep = mt.profile.rf_max_cep_m
        if max_cep is not None and att.cep is not None and att.cep > max_cep:
            mt._count("rejected_cep")
            return
        r = mt.rf_r.r_for(att.cep)
        z = (att.e, att.n)
        em = emitter_key(att.center_freq_hz)
        var = 0.5 * (r[0] + r[2])
        mt.objects.rf_fix(t, att.e, att.n, var, em)
        mt._advance(t)
        own = [tr for tr in mt.tracks if tr.emitter == em and tr.t <= t]
        obj = mt.objects.credited
        if obj is not None and any(tr.confirmed and tr.followed == obj.id for tr in own):
            # the fix and the radar object its emitter's track follows agree: registration
            mt.front.register(t, att.e, att.n, var, obj)
        tentative_only = all(not tr.confirmed for tr in own)
        if own and not tentative_only:
            tr = min(own, key=lambda x: (not x.confirmed, x.id))
            self.update(tr, t, z, r, att.cep)
            return
        free = [
            (tr.filter.nis(z, r), tr.id, tr)
            for tr in mt.tracks
            if tr.emitter is None and tr.confirmed and tr.t <= t
        ]
        free = [e for e in free if e[0] <= mt._g2]
        if free:
            _, _, tr = min(free, key=lambda e: (e[0], e[1]))
            tr.emitter = em
            tr.emitter_misses = 0
            mt._count("emitter_linked")
            for o in own:  # the emitter's tentative track: the confirmed track took over
                mt._drop(o, "emitter_linked")
            self.update(tr, t, z, r, att.cep)
            return
        if own:
            self.update(min(own, key=lambda x: x.id), t, z, r, att.cep)
            return
        tr = self.start(t, z, r)
        tr.emitter = em

    def start(self, t: float, z: tuple[float, float], r: PackedR) -> UavTrack:
        """A new track from an RF fix: at the fix, with the RF start's height prior, at rest
        (the profile's velocity sigma); tentative (M of N) when the profile asks for it."""
        mt = self.mt
        p = mt.profile
        x, P = rf_start(z, r, p)
        tentative = p.confirm_m > 1
        tr = mt._new_track(t, x, P, not tentative)
        if tentative:
            tr.mofn = MofN(p.confirm_m, p.confirm_n)
        return tr

    def update(
        self, tr: UavTrack, t: float, z: tuple[float, float], r: PackedR, cep: float | None = None
    ) -> None:
        """The fix updates (or is a rejection of) ``tr``; M of N for a tentative track, and
        after ``emitter_misses`` misses in a row the track loses its emitter."""
        mt = self.mt
        f = tr.filter
        hold = mt.profile.hold_after_s
        if hold is not None and (tr.last_radar_t is None or t - tr.last_radar_t > hold):
            # no 3D measurement for a while: hold the climb rate near 0 (as the single-UAV
            # tracker does) instead of letting a stale one run away
            sd = mt.profile.hold_sigma_mps
            f.update_scalar(5, 0.0, sd * sd)
        n = f.nis(z, r)
        hit = n <= mt._g2
        if hit:
            w = mt.robust.weight(n, 2)
            if tr.confirmed:  # measurement.adaptive, before the update
                observe_rf_fix(
                    mt.front.adaptive, mt.rf_adaptive, tr.last_radar_t, t, f, z, n, cep
                )
            f.update(z, scale_packed(r, 1.0 / w) if w != 1.0 else r)
            mt._accept(tr, t)
        if tr.mofn is not None:
            state = tr.mofn.record(hit)
            if state == "confirmed":
                tr.confirmed = True
                tr.mofn = None
                mt._count("confirmed")
            elif state == "failed":
                mt._drop(tr, "unconfirmed")
            return
        if hit:
            tr.emitter_misses = 0
            return
        tr.emitter_misses += 1
        n_miss = mt.settings.emitter_misses
        if n_miss is not None and tr.emitter_misses >= n_miss:
            # its emitter is elsewhere: the track took another UAV (or the emitter is a UAV
            # on the ground); the emitter's next fix links anew
            tr.emitter = None
            tr.emitter_misses = 0
            mt._count("emitter_unlinked")
        mt._reject(tr)
