"""The multi-UAV tracker's rules between tracks, at their boundaries: two confirmed tracks
that stay close (``multi.merge_nis``) are one UAV only once they have been close for
``merge_s``, and not while each has been updated by a different radar object within
``merge_s``; which track a merge keeps and what it inherits; when a report inside a track's
gate is another UAV (``birth_sep_m``); the ground hold before an update without height; and
when an emitter leaves its track (``emitter_misses``)."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from uav_fusion.core.estimators import load_profile
from uav_fusion.core.estimators.kalman import CvFilter
from uav_fusion.core.estimators.multi import MultiTracker, UavTrack
from uav_fusion.core.profiles.settings import MultiSettings
from uav_fusion.core.records import RadarTrack
from uav_fusion.core.site import load_site

T0 = 100.0


def _place(tr: UavTrack, e: float, up: float = 60.0) -> None:
    """Put ``tr`` at ``e`` east, 500 m north, ``up`` high, flying east at 5 m/s (position
    variances 25, 25 and 100 m^2)."""
    tr.filter.set_state([e, 500.0, up, 5.0, 0.0, 0.0], np.diag([25.0, 25.0, 100.0, 4.0, 4.0, 1.0]))


def _track(track_id: int, born: float, e: float) -> UavTrack:
    tr = UavTrack(track_id, born, CvFilter((1.0, 1.0, 1.0)), confirmed=True)
    _place(tr, e)
    tr.last_update_t = T0
    return tr


def _pair(merge_s: float) -> tuple[MultiTracker, UavTrack, UavTrack]:
    mt = MultiTracker(load_profile("tracker"), load_site(), MultiSettings(merge_s=merge_s))
    older, younger = _track(1, T0 - 20.0, 0.0), _track(2, T0 - 5.0, 3.0)  # 3 m apart
    mt.tracks = [older, younger]
    return mt, older, younger


@pytest.mark.parametrize("merge_s", [3.0, 0.5])
def test_close_tracks_merge_once_close_for_merge_s_and_not_before(merge_s: float) -> None:
    mt, older, younger = _pair(merge_s)
    mt._merge(T0)  # close from now on
    assert mt.tracks == [older, younger]
    mt._merge(T0 + merge_s - 1e-6)
    assert mt.tracks == [older, younger]
    mt._merge(T0 + merge_s)
    assert mt.tracks == [older]  # the older track is kept
    assert mt.counters["dropped_merged"] == 1


def test_tracks_that_part_start_their_merge_clock_again() -> None:
    mt, older, younger = _pair(3.0)
    mt._merge(T0)
    _place(younger, 300.0)
    mt._merge(T0 + 2.0)  # apart: the clock stops
    _place(younger, 3.0)
    mt._merge(T0 + 2.5)  # close again: the clock restarts here
    mt._merge(T0 + 5.0)
    assert len(mt.tracks) == 2
    mt._merge(T0 + 5.5)
    assert mt.tracks == [older]


@pytest.mark.parametrize(("age", "merged"), [(3.0, False), (3.0 + 1e-6, True)])
def test_two_radar_objects_side_by_side_stay_two_uavs_while_both_are_seen(
    age: float, merged: bool
) -> None:
    """Both tracks updated by different radar objects: two UAVs while the younger track's
    last radar update is at most ``merge_s`` old at the time the merge is due."""
    mt, older, younger = _pair(3.0)
    t = T0 + 3.0
    older.followed, younger.followed = 11, 12
    older.last_radar_t = t
    younger.last_radar_t = t - age
    mt._merge(T0)
    mt._merge(t)
    assert (mt.tracks == [older]) is merged
    # the same object behind both: one UAV whatever the ages
    mt2, o2, y2 = _pair(3.0)
    o2.followed = y2.followed = 11
    o2.last_radar_t = y2.last_radar_t = t
    mt2._merge(T0)
    mt2._merge(t)
    assert mt2.tracks == [o2]


@pytest.mark.parametrize(("scale", "merged"), [(0.99, True), (1.01, False)])
def test_tracks_merge_only_inside_merge_nis(scale: float, merged: bool) -> None:
    """``merge_nis`` at its edge: neither track has a recent radar update, so their
    horizontal positions are compared (2 dof) on the sum of their covariances (25 + 25 m^2
    per axis): apart by just under ``sqrt(50 merge_nis)`` they merge after ``merge_s``, by
    just over it they never do."""
    mt, older, younger = _pair(3.0)
    d = scale * float(np.sqrt(50.0 * mt.settings.merge_nis))
    _place(younger, d)
    for k in range(5):
        mt._merge(T0 + k)
    assert (mt.tracks == [older]) is merged


def test_a_horizontal_update_keeps_the_track_above_the_ground_beyond_below_ground_m() -> None:
    """Before an update without height, a track more than ``below_ground_m`` under the
    ground is pulled up by a pseudo-measurement of height 0 with that sigma (with a vertical
    variance of 100 m^2 and a 5 m sigma, four fifths of the way); one less deep is left where
    it is."""
    mt = MultiTracker(load_profile("tracker"), load_site())
    lim = mt.cfg.below_ground_m
    assert lim == 5.0
    for depth, want in ((1.01 * lim, -0.2 * 1.01 * lim), (0.99 * lim, -0.99 * lim)):
        tr = _track(1, T0, 0.0)
        _place(tr, 0.0, -depth)
        mt._hold_height(tr)
        x, _ = tr.filter.mean()
        assert x[2] == pytest.approx(want)


@pytest.mark.parametrize(("age", "merged"), [(3.0, False), (3.0 + 1e-6, True)])
def test_side_by_side_holds_whichever_track_has_the_older_radar_update(
    age: float, merged: bool
) -> None:
    """The side-by-side rule above with the roles swapped: the older track's last radar
    update is the one at the edge of ``merge_s``."""
    mt, older, younger = _pair(3.0)
    t = T0 + 3.0
    older.followed, younger.followed = 11, 12
    older.last_radar_t = t - age
    younger.last_radar_t = t
    mt._merge(T0)
    mt._merge(t)
    assert (len(mt.tracks) == 1) is merged


@pytest.mark.parametrize(("age", "inherited"), [(2.99, True), (3.01, False)])
def test_the_kept_track_inherits_the_emitter_of_a_track_updated_within_merge_s(
    age: float, inherited: bool
) -> None:
    """A merge keeps the older track, which takes the emitter of the one it drops only when
    that one was updated within ``merge_s``: a coasting track that drifted onto another UAV
    does not pass its emitter on."""
    mt, older, younger = _pair(3.0)
    t = T0 + 3.0
    younger.emitter = "2437.0 MHz"
    mt._merge(T0)
    older.last_update_t = t
    younger.last_update_t = t - age
    mt._merge(t)
    assert mt.tracks == [older]
    assert (older.emitter == "2437.0 MHz") is inherited


@pytest.mark.parametrize(("age", "kept"), [(2.99, "younger"), (3.01, "older")])
def test_a_track_updated_within_merge_s_is_kept_over_one_that_is_not(
    age: float, kept: str
) -> None:
    """The older track has coasted for 10 s; the younger one was updated ``age`` ago. Within
    ``merge_s`` the live younger track is kept; beyond it neither is live and the older one
    is kept, as in any merge."""
    mt, older, younger = _pair(3.0)
    t = T0 + 3.0
    mt._merge(T0)
    older.last_update_t = t - 10.0
    younger.last_update_t = t - age
    mt._merge(t)
    assert mt.tracks == [younger if kept == "younger" else older]


@pytest.mark.parametrize(("age", "merged"), [(3.0, False), (3.0 + 1e-6, True)])
def test_heights_are_compared_only_while_both_tracks_have_a_recent_radar_update(
    age: float, merged: bool
) -> None:
    """Two tracks on one radar object, at one horizontal place but 100 m apart in height:
    while both have a radar update at most ``merge_s`` old their heights count (3 dof) and
    they are apart; once one is older than that it has no height worth comparing (2 dof) and
    they merge."""
    mt, older, younger = _pair(3.0)
    _place(younger, 0.0, 160.0)
    older.followed = younger.followed = 11
    mt._merge(T0)  # no radar update yet: compared horizontally, close from now on
    t = T0 + 3.0
    older.last_radar_t = t
    younger.last_radar_t = t - age
    mt._merge(t)
    assert (len(mt.tracks) == 1) is merged


def test_a_report_inside_a_tracks_gate_is_another_uav_only_beyond_birth_sep_m() -> None:
    """Track 0 took report 0 of the frame; report 1, inside its gate, is another UAV (it may
    start its own track) only when it lies more than ``birth_sep_m`` away horizontally; one
    UAV split into two radar tracks gives reports closer than that. Without a report taken,
    nothing is apart."""
    mt = MultiTracker(load_profile("tracker"), load_site())
    sep = mt.settings.birth_sep_m
    assert sep == 60.0

    def cand(e: float) -> Any:
        trk = RadarTrack(T0, 1, 0.0, 0.0, 0.0, e, 500.0, 60.0, None, 0.8, None, -10.0)
        return (trk, None, 1.0, None, (e, 500.0, 60.0))

    for d, apart in ((0.99 * sep, False), (1.01 * sep, True)):
        cands = [cand(0.0), cand(d)]
        assert mt._apart(0, 1, {0: 0}, cands) is apart
        assert mt._apart(0, 1, {}, cands) is False


def test_an_emitter_leaves_its_track_at_the_nth_fix_in_a_row_outside_the_gate() -> None:
    """``emitter_misses`` at its edge: a confirmed track carrying an emitter keeps it through
    ``emitter_misses - 1`` fixes of that emitter in a row outside its gate and loses it at the
    next; a fix inside the gate starts the count again."""
    mt = MultiTracker(load_profile("tracker"), load_site())
    n = mt.settings.emitter_misses
    assert n == 3
    tr = _track(1, T0 - 20.0, 0.0)
    tr.emitter = "2437.0 MHz"
    mt.tracks = [tr]
    r = (100.0, 0.0, 100.0)
    far, near = (900.0, 500.0), (0.0, 500.0)
    for _ in range(n - 1):
        mt.emitters.update(tr, T0, far, r)
    assert tr.emitter == "2437.0 MHz"
    mt.emitters.update(tr, T0, near, r)  # inside: the run ends
    for _ in range(n - 1):
        mt.emitters.update(tr, T0, far, r)
    assert tr.emitter == "2437.0 MHz"
    mt.emitters.update(tr, T0, far, r)
    assert tr.emitter is None and mt.counters["emitter_unlinked"] == 1
