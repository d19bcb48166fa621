"""The multi-UAV tracker's merge rule at its boundaries (``multi.merge_s``): two confirmed
tracks that stay close are one UAV only once they have been close for ``merge_s``, and not
while each has been updated by a different radar object within ``merge_s``."""

from __future__ import annotations

import numpy as np
import pytest

from uav_fusion.core.estimators import load_profile
from uav_fusion.core.estimators.kalman import CvFilter
from uav_fusion.core.estimators.multi import MultiTracker, UavTrack
from uav_fusion.core.profiles.settings import MultiSettings
from uav_fusion.core.site import load_site

T0 = 100.0


def _track(track_id: int, born: float, e: float) -> UavTrack:
    f = CvFilter((1.0, 1.0, 1.0))
    f.set_state([e, 500.0, 60.0, 5.0, 0.0, 0.0], np.diag([25.0, 25.0, 100.0, 4.0, 4.0, 1.0]))
    tr = UavTrack(track_id, born, f, confirmed=True)
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
    younger.filter.set_state(
        [300.0, 500.0, 60.0, 5.0, 0.0, 0.0], np.diag([25.0, 25.0, 100.0, 4.0, 4.0, 1.0])
    )
    mt._merge(T0 + 2.0)  # apart: the clock stops
    younger.filter.set_state(
        [3.0, 500.0, 60.0, 5.0, 0.0, 0.0], np.diag([25.0, 25.0, 100.0, 4.0, 4.0, 1.0])
    )
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
    younger.filter.set_state(
        [d, 500.0, 60.0, 5.0, 0.0, 0.0], np.diag([25.0, 25.0, 100.0, 4.0, 4.0, 1.0])
    )
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
        tr.filter.set_state(
            [0.0, 500.0, -depth, 5.0, 0.0, 0.0], np.diag([25.0, 25.0, 100.0, 4.0, 4.0, 1.0])
        )
        mt._hold_height(tr)
        x, _ = tr.filter.mean()
        assert x[2] == pytest.approx(want)
