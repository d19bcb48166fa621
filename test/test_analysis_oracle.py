"""``uav_fusion analyse oracle``: the multi-UAV filter with association from the twin's labels,
and (single-UAV) the epochs where the radar itself had the UAV far off."""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from test_multi_tracker import FREQ_A, Crossing

from uav_fusion.core.analysis.labels import KindsByTrack, vehicle_links
from uav_fusion.core.analysis.oracle import (
    SINGLE_RULE,
    LabelOracle,
    sensor_off,
    uav_report_errors,
)
from uav_fusion.core.errors import DataError
from uav_fusion.core.estimators import load_profile
from uav_fusion.core.estimators.emitters import emitter_key
from uav_fusion.core.estimators.grid import GridEpoch
from uav_fusion.core.estimators.multi import run_multi
from uav_fusion.core.records import RadarFrame, RadarTrack, RfAttempt
from uav_fusion.core.site import Site, load_site
from uav_fusion.core.twin import radar_model
from uav_fusion.core.twin.writers import MANIFEST

A = radar_model.uav_object_id(0)
B = radar_model.uav_object_id(1)


@pytest.fixture(scope="module")
def site() -> Site:
    return load_site()


def _kinds(swap_at: float | None, clutter_label: tuple[str, int]) -> KindsByTrack:
    """Labels of the Crossing scene's radar tracks 10 (on A), 20 (on B) and 99 (clutter);
    from ``swap_at`` track 10 follows B and 20 follows A."""
    ts = np.array([1000.0] if swap_at is None else [1000.0, swap_at])
    uav = radar_model.UAV
    lab10 = [(uav, A)] if swap_at is None else [(uav, A), (uav, B)]
    lab20 = [(uav, B)] if swap_at is None else [(uav, B), (uav, A)]
    return {10: (ts, lab10), 20: (ts, lab20), 99: (np.array([1000.0]), [clutter_label])}


def _ids_at(
    epochs: list[GridEpoch], truth: Callable[[float], np.ndarray], within: float = 40.0
) -> list[int | None]:
    out: list[int | None] = []
    for ep in epochs:
        p = truth(ep.t - 1000.0)
        near = [(float(np.linalg.norm(o.x[:3] - p)), o.track_id) for o in ep.tracks]
        near = [x for x in near if x[0] < within]
        out.append(min(near)[1] if near else None)
    return out


def test_each_uav_keeps_one_track_from_its_first_report_through_a_radar_swap(site: Site) -> None:
    sc = Crossing(site, seed=2, swap_ids=True)
    oracle = LabelOracle(
        load_profile("tracker"),
        site,
        _kinds(1050.0, ("clutter", 77)),
        {A: "uav1", B: "uav2"},
        {emitter_key(FREQ_A): "uav1"},
        ["uav1", "uav2"],
    )
    epochs = run_multi(oracle, sc.stream(), 1.0, 1000.0, 1099.0)
    # from the first epoch on (no wait for a class history), uav1 is track 1 and uav2 track 2
    assert _ids_at(epochs, sc.a) == [1] * 100
    assert _ids_at(epochs, sc.b) == [2] * 100
    # the reflector's reports (classed UAV half of the time) are never used: every track
    # published is on its own UAV
    truth = {1: sc.a, 2: sc.b}
    for ep in epochs:
        assert sorted(o.track_id for o in ep.tracks) == [1, 2]
        for o in ep.tracks:
            assert np.linalg.norm(o.x[:3] - truth[o.track_id](ep.t - 1000.0)) < 40.0


def test_the_labels_alone_decide(site: Site) -> None:
    """The same scene with the reflector labelled as uav2 and track 20 as clutter: uav2's
    track sits on the reflector and nothing follows the real uav2."""
    sc = Crossing(site, seed=2)
    kinds = _kinds(None, (radar_model.UAV, B))
    kinds[20] = (np.array([1000.0]), [("clutter", 5)])
    oracle = LabelOracle(
        load_profile("tracker"), site, kinds, {A: "uav1", B: "uav2"}, {}, ["uav1", "uav2"]
    )
    epochs = run_multi(oracle, sc.stream(), 1.0, 1000.0, 1099.0)
    clutter = sc.r0 + np.array([100.0, 250.0, 30.0])
    for ep in epochs:
        assert sorted(o.track_id for o in ep.tracks) == [1, 2]
        for o in ep.tracks:
            on = clutter if o.track_id == 2 else sc.a(ep.t - 1000.0)
            assert np.linalg.norm(o.x[:3] - on) < 40.0


def test_fixes_go_to_their_own_uav_only(site: Site) -> None:
    """RF alone: uav1's control link gives uav1 a track (M of N, as the tracker starts one;
    inside the radar's cover it is not published without radar, as the tracker's is not);
    fixes of a link no UAV of the flight has are not used."""
    sc = Crossing(site, seed=4)
    fixes = [x for x in sc.stream() if not isinstance(x, RadarFrame)]
    stray = [dataclasses.replace(f, center_freq_hz=5745e6) for f in fixes]
    stream = sorted(fixes + stray, key=lambda f: (f.t, f.center_freq_hz))
    oracle = LabelOracle(
        load_profile("tracker"), site, {}, {A: "uav1", B: "uav2"},
        {emitter_key(FREQ_A): "uav1"}, ["uav1", "uav2"],
    )  # fmt: skip
    for k, item in enumerate(stream):
        oracle.process_rf(item)
        if k > len(stream) // 3:
            (tr,) = oracle.tracks
            assert tr.id == 1 and tr.confirmed
            x, _ = tr.filter.mean()
            assert np.linalg.norm(np.array(x[:2]) - sc.a(item.t - 1000.0)[:2]) < 40.0


def test_with_the_single_uav_output_rule_an_rf_only_track_is_published(site: Site) -> None:
    """The single-UAV oracle is scored as the single-UAV grid is: a track is published until
    the deleter drops it, also inside the radar's cover without radar."""
    sc = Crossing(site, seed=4)
    fixes: list[RadarFrame | RfAttempt] = [x for x in sc.stream() if not isinstance(x, RadarFrame)]
    published = {}
    for settings in (None, SINGLE_RULE):
        oracle = LabelOracle(
            load_profile("tracker"), site, {}, {A: "uav1"}, {emitter_key(FREQ_A): "uav1"},
            ["uav1"], settings,
        )  # fmt: skip
        epochs = run_multi(oracle, fixes, 1.0, 1000.0, 1099.0)
        published[settings is None] = [ep for ep in epochs if ep.tracks]
    assert published[True] == []  # the multi-UAV rule: an emitter the radar does not see
    assert len(published[False]) > 60
    for ep in published[False][10:]:
        (o,) = ep.tracks
        assert o.track_id == 1
        assert np.linalg.norm(o.x[:2] - sc.a(ep.t - 1000.0)[:2]) < 40.0


def test_vehicle_links_come_from_the_manifest(tmp_path: Path) -> None:
    doc = {
        "vehicles": [
            {"name": "uav1", "center_frequency_hz": 2437e6},
            {"name": "uav2", "center_frequency_hz": None},
            {"name": "uav3", "center_frequency_hz": 5745e6},
        ]
    }
    (tmp_path / MANIFEST).write_text(json.dumps(doc), encoding="utf-8")
    objects, emitters = vehicle_links(tmp_path)
    assert objects == {
        radar_model.uav_object_id(0): "uav1",
        radar_model.uav_object_id(1): "uav2",
        radar_model.uav_object_id(2): "uav3",
    }
    assert emitters == {emitter_key(2437e6): "uav1", emitter_key(5745e6): "uav3"}


def test_a_manifest_that_is_missing_is_named(tmp_path: Path) -> None:
    with pytest.raises(DataError, match="twin manifest not found"):
        vehicle_links(tmp_path)


def test_an_epoch_is_sensor_bound_when_its_recent_reports_are_far_off() -> None:
    rep_t = np.array([0.0, 1.0, 2.0, 3.0, 4.0, 10.0])
    rep_err = np.array([20.0, 150.0, 160.0, 170.0, 30.0, 500.0])
    epochs = np.array([-1.0, 0.5, 3.0, 4.0, 8.0, 9.5, 10.0, 16.0])
    off = sensor_off(epochs, rep_t, rep_err, 5.0, 100.0)
    # windows [t - 5, t]: -1 none; 0.5 [20]; 3 [20 150 160 170] -> 155; 4 [.. 30] -> 150;
    # 8 [170 30] -> 100, not above; 9.5 none; 10 [500]; 16 none
    assert off.tolist() == [False, False, True, True, False, False, True, False]


def test_only_reports_of_tracks_following_the_uav_are_read() -> None:
    uav = radar_model.uav_object_id(0)
    kinds = {
        1: (np.array([0.0, 2.0]), [(radar_model.UAV, uav), (radar_model.BIRD, 9)]),
        2: (np.array([0.0]), [(radar_model.UAV, radar_model.uav_object_id(1))]),
    }

    def rep(t: float, tid: int, e: float) -> RadarTrack:
        return RadarTrack(t, tid, 0.0, 0.0, 0.0, e, 0.0, 50.0, None, 0.8, None, -10.0)

    stream = [RadarFrame(t, (rep(t, 1, 30.0 * t), rep(t, 2, 999.0))) for t in (0.0, 1.0, 2.0)]
    truth_t = np.array([0.0, 10.0])
    truth_enu = np.array([[0.0, 0.0, 50.0], [100.0, 0.0, 50.0]])  # east at 10 m/s
    ts, errs = uav_report_errors(stream, kinds, uav, truth_t, truth_enu, None)
    # track 1 follows the UAV until t = 2 (then a bird); track 2 is another UAV
    assert ts.tolist() == [0.0, 1.0]
    assert errs.tolist() == pytest.approx([0.0, 20.0])
    shifted = uav_report_errors(
        stream, kinds, uav, truth_t, truth_enu, lambda e, n, u: (e - 20.0, n, u)
    )
    assert shifted[1].tolist() == pytest.approx([20.0, 0.0])
