"""scripts/multi_oracle.py: the multi-UAV filter with association from the twin's labels."""

from __future__ import annotations

import json
from pathlib import Path
from types import ModuleType

import numpy as np
import pytest
from script_util import load_script
from test_multi_tracker import FREQ_A, Crossing

from uav_fusion.core.estimators import load_profile
from uav_fusion.core.estimators.multi import MultiSettings, emitter_key, run_multi
from uav_fusion.core.site import Site, load_site
from uav_fusion.core.twin import radar_model
from uav_fusion.core.twin.writers import MANIFEST

A = radar_model.uav_object_id(0)
B = radar_model.uav_object_id(1)


@pytest.fixture(scope="module")
def mo() -> ModuleType:
    return load_script("multi_oracle")


@pytest.fixture(scope="module")
def site() -> Site:
    return load_site()


def _kinds(swap_at: float | None, clutter_label: tuple[str, int]) -> dict:  # type: ignore[type-arg]
    """Labels of the Crossing scene's radar tracks 10 (on A), 20 (on B) and 99 (clutter);
    from ``swap_at`` track 10 follows B and 20 follows A."""
    ts = np.array([1000.0] if swap_at is None else [1000.0, swap_at])
    uav = radar_model.UAV
    lab10 = [(uav, A)] if swap_at is None else [(uav, A), (uav, B)]
    lab20 = [(uav, B)] if swap_at is None else [(uav, B), (uav, A)]
    return {10: (ts, lab10), 20: (ts, lab20), 99: (np.array([1000.0]), [clutter_label])}


def _ids_at(epochs: list, truth, within: float = 40.0) -> list[int | None]:  # type: ignore[no-untyped-def]
    out: list[int | None] = []
    for ep in epochs:
        p = truth(ep.t - 1000.0)
        near = [(float(np.linalg.norm(o.x[:3] - p)), o.track_id) for o in ep.tracks]
        near = [x for x in near if x[0] < within]
        out.append(min(near)[1] if near else None)
    return out


def test_each_uav_keeps_one_track_from_its_first_report_through_a_radar_swap(
    mo: ModuleType, site: Site
) -> None:
    sc = Crossing(site, seed=2, swap_ids=True)
    oracle = mo.LabelOracle(
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


def test_the_labels_alone_decide(mo: ModuleType, site: Site) -> None:
    """The same scene with the reflector labelled as uav2 and track 20 as clutter: uav2's
    track sits on the reflector and nothing follows the real uav2."""
    sc = Crossing(site, seed=2)
    kinds = _kinds(None, (radar_model.UAV, B))
    kinds[20] = (np.array([1000.0]), [("clutter", 5)])
    oracle = mo.LabelOracle(
        load_profile("tracker"), site, kinds, {A: "uav1", B: "uav2"}, {}, ["uav1", "uav2"]
    )
    epochs = run_multi(oracle, sc.stream(), 1.0, 1000.0, 1099.0)
    clutter = sc.r0 + np.array([100.0, 250.0, 30.0])
    for ep in epochs:
        assert sorted(o.track_id for o in ep.tracks) == [1, 2]
        for o in ep.tracks:
            on = clutter if o.track_id == 2 else sc.a(ep.t - 1000.0)
            assert np.linalg.norm(o.x[:3] - on) < 40.0


def test_fixes_go_to_their_own_uav_only(mo: ModuleType, site: Site) -> None:
    """RF alone: uav1's control link gives uav1 a track (M of N, as the tracker starts one;
    inside the radar's cover it is not published without radar, as the tracker's is not);
    fixes of a link no UAV of the flight has are not used."""
    sc = Crossing(site, seed=4)
    fixes = [x for x in sc.stream() if not isinstance(x, mo.RadarFrame)]
    stray = [mo.dataclasses.replace(f, center_freq_hz=5745e6) for f in fixes]
    stream = sorted(fixes + stray, key=lambda f: (f.t, f.center_freq_hz))
    oracle = mo.LabelOracle(
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


def test_with_the_single_uav_output_rule_an_rf_only_track_is_published(
    mo: ModuleType, site: Site
) -> None:
    """scripts/single_oracle.py scores the oracle as the single-UAV grid is scored: a track is
    published until the deleter drops it, also inside the radar's cover without radar."""
    sc = Crossing(site, seed=4)
    fixes = [x for x in sc.stream() if not isinstance(x, mo.RadarFrame)]
    rule = MultiSettings(emitter_misses=None, output_coast_s=None, radar_output_s=None)
    published = {}
    for settings in (None, rule):
        oracle = mo.LabelOracle(
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


def test_vehicle_links_come_from_the_manifest(mo: ModuleType, tmp_path: Path) -> None:
    doc = {
        "vehicles": [
            {"name": "uav1", "center_frequency_hz": 2437e6},
            {"name": "uav2", "center_frequency_hz": None},
            {"name": "uav3", "center_frequency_hz": 5745e6},
        ]
    }
    (tmp_path / MANIFEST).write_text(json.dumps(doc), encoding="utf-8")
    objects, emitters = mo.vehicle_links(tmp_path)
    assert objects == {
        radar_model.uav_object_id(0): "uav1",
        radar_model.uav_object_id(1): "uav2",
        radar_model.uav_object_id(2): "uav3",
    }
    assert emitters == {emitter_key(2437e6): "uav1", emitter_key(5745e6): "uav3"}
