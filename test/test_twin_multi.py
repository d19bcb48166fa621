"""Multi-UAV twin: plans with several vehicles, their files, their sensors and their labels."""

from __future__ import annotations

import math
import re
from collections import Counter
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from uav_fusion.core.bench.cache import uav_report_times
from uav_fusion.core.data import load_flight
from uav_fusion.core.errors import ConfigError
from uav_fusion.core.site import Site, load_site
from uav_fusion.core.twin import radar_model
from uav_fusion.core.twin.config import load_twin_config
from uav_fusion.core.twin.generate import TwinFlight, generate_twin, twin_to_flight
from uav_fusion.core.twin.trajectory import FlightPlan, flight_plan_from_dict, load_flight_plan
from uav_fusion.core.twin.writers import write_twin
from uav_fusion.resources import config_path

MULTI_PLANS = ("multi_crossing_pair", "multi_three", "multi_four")


@pytest.fixture(scope="module")
def site() -> Site:
    return load_site()


def _plan(name: str, site: Site) -> FlightPlan:
    return load_flight_plan(config_path(f"waypoints/{name}.yaml"), site)


@pytest.fixture(scope="module")
def three(site: Site) -> TwinFlight:
    """multi_three cut to 420 s: all three UAVs up, uav2 crossing uav1."""
    return generate_twin(site, load_twin_config(), _plan("multi_three", site), 5, 420.0)


def _vehicle(name: str, **extra: Any) -> dict[str, Any]:
    doc: dict[str, Any] = {"name": name, "waypoints": [{"e": 0, "n": 100, "alt": 30}]}
    doc.update(extra)
    return doc


@pytest.mark.parametrize(
    ("vehicles", "message"),
    [
        ([_vehicle("uav2")], "the first vehicle, and only it, is named 'uav1'"),
        ([_vehicle("uav1"), _vehicle("uav1")], "the first vehicle, and only it"),
        ([_vehicle("uav1"), _vehicle("b"), _vehicle("B")], "listed twice"),
        ([_vehicle("uav1"), _vehicle("uav 2")], "letters, digits and '-'"),
        ([_vehicle("uav1", rf={"silent": True, "interval_s": 3})], "a silent UAV has no link"),
        ([_vehicle("uav1", rf={"band": 2})], "unknown key(s) band"),
        ([_vehicle("uav1", rf={"center_frequency_mhz": 2.4})], "center_frequency_mhz"),
        ([_vehicle("uav1", pad={"e": 1})], "vehicle uav1: pad: missing key 'n'"),
        ([_vehicle("uav1", pad={"e": 1, "n": 2, "x": 3})], "pad: unknown key(s) x"),
        ([_vehicle("uav1", colour="red")], "unknown key(s) colour"),
        ([], "non-empty list"),
    ],
)
def test_bad_multi_plans_are_refused_naming_the_vehicle_and_key(
    site: Site, vehicles: list[dict[str, Any]], message: str
) -> None:
    with pytest.raises(ConfigError, match=re.escape(message)):
        flight_plan_from_dict({"name": "m", "vehicles": vehicles}, site, Path("m.yaml"))


def test_waypoints_beside_vehicles_are_refused(site: Site) -> None:
    doc = {"vehicles": [_vehicle("uav1")], "waypoints": [{"e": 0, "n": 0, "alt": 10}]}
    with pytest.raises(ConfigError, match=r"m\.yaml: unknown top-level key"):
        flight_plan_from_dict(doc, site, Path("m.yaml"))


@pytest.mark.parametrize("name", MULTI_PLANS)
def test_shipped_multi_plans_have_a_silent_uav_and_distinct_links(site: Site, name: str) -> None:
    plan = _plan(name, site)
    vehicles = plan.all_vehicles
    assert 2 <= len(vehicles) <= 4
    assert vehicles[0].vehicle == "uav1"
    assert any(v.emitter is None for v in vehicles)
    freqs = [v.emitter.center_frequency_hz for v in vehicles if v.emitter is not None]
    assert freqs and len(set(freqs)) == len(freqs)


def test_each_uav_has_its_own_truth_file_with_one_stamp(
    three: TwinFlight, site: Site, tmp_path: Path
) -> None:
    paths = write_twin(three, tmp_path)
    truth_files = sorted(p.name for p in tmp_path.glob("*_vehicleOut.txt"))
    stamp = paths["truth"].name.removesuffix("_vehicleOut.txt")
    assert truth_files == sorted(
        [f"{stamp}_vehicleOut.txt", f"{stamp}_uav2_vehicleOut.txt", f"{stamp}_uav3_vehicleOut.txt"]
    )
    loaded = load_flight(tmp_path, site, strict=True)
    mine = twin_to_flight(three)
    assert list(loaded.vehicles) == list(mine.vehicles) == ["uav1", "uav2", "uav3"]
    for name in loaded.vehicles:
        lt, lenu = loaded.truth_arrays(name)
        mt, menu = mine.truth_arrays(name)
        assert np.max(np.abs(lt - mt)) < 1e-5
        assert np.max(np.abs(lenu - menu)) < 1e-6
        # every log covers the whole recording
        assert lt[0] - three.start_unix < 2.0
        assert three.start_unix + three.traj.duration - lt[-1] < 2.0


def test_a_uav_not_yet_flying_sits_on_its_pad(three: TwinFlight) -> None:
    other = {o.vehicle: o for o in three.others}["uav2"]
    assert other.plan.pad is not None
    before = np.arange(0.0, other.traj.t_takeoff - 1.0, 1.0)
    assert before.size > 100  # uav2 takes off after about three minutes
    pos = other.traj.position(before)
    assert np.allclose(pos[:, 0], other.plan.pad[0]) and np.allclose(pos[:, 1], other.plan.pad[1])
    assert np.allclose(pos[:, 2], other.traj.ground_u)


def test_rf_fixes_carry_their_emitters_frequency_and_silent_uavs_have_none(
    three: TwinFlight, site: Site, tmp_path: Path
) -> None:
    write_twin(three, tmp_path)
    loaded = load_flight(tmp_path, site, strict=True)
    by_vehicle = Counter(a.attempt.vehicle for a in three.rf)
    assert set(by_vehicle) == {"uav1", "uav2"}  # uav3 is silent
    freq = {a.meas_id: a.center_freq_hz for a in loaded.rf}
    for a in three.rf:
        want = 2437e6 if a.attempt.vehicle == "uav1" else 5745e6
        assert freq[a.attempt.meas_id] == want
    ids = [a.meas_id for a in loaded.rf]
    assert ids == list(range(ids[0], ids[0] + len(ids)))  # one log, numbered in order
    # each emitter keeps its own schedule: its attempts are interval_s apart on average
    for vehicle, interval in (("uav1", 3.88), ("uav2", 4.2)):
        t = np.array([a.attempt.t for a in three.rf if a.attempt.vehicle == vehicle])
        assert np.mean(np.diff(t)) == pytest.approx(interval, rel=0.05)
    # a good fix lies near the UAV that emitted it (TDOA errors are tens of metres)
    trajs = {"uav1": three.traj, **{o.vehicle: o.traj for o in three.others}}
    err = [
        math.hypot(
            *(trajs[a.attempt.vehicle].position(a.attempt.t)[0, :2] - (a.attempt.e, a.attempt.n))
        )
        for a in three.rf
        if a.attempt.ok and trajs[a.attempt.vehicle].position(a.attempt.t)[0, 2] > 20.0
    ]
    assert len(err) > 20 and float(np.median(err)) < 60.0


def test_every_uav_is_seen_by_the_radar_and_labelled(three: TwinFlight) -> None:
    names = [name for name, _ in three.vehicles]
    for i, name in enumerate(names):
        times = uav_report_times(three, i)
        assert len(times) > 200, name  # > 50 s of reports on each UAV
    kinds = {
        (r.kind, r.object_id)
        for f in three.radar_sim
        for r in f.tracks
        if r.kind in (radar_model.UAV, radar_model.GHOST)
    }
    assert {(radar_model.UAV, radar_model.uav_object_id(i)) for i in range(3)} <= kinds


def test_the_first_uav_flies_as_it_does_alone(site: Site) -> None:
    """The other UAVs draw from their own streams: uav1's flight and truth do not change."""
    plan = _plan("multi_crossing_pair", site)
    alone = FlightPlan(
        plan.name,
        plan.waypoints,
        plan.hold_before_s,
        plan.source,
        plan.scene_scale,
        pad=plan.pad,
        emitter=plan.emitter,
    )
    cfg = load_twin_config()
    a = generate_twin(site, cfg, alone, 3, 200.0)
    b = generate_twin(site, cfg, plan, 3, 200.0)
    assert np.array_equal(a.traj.pos, b.traj.pos)
    assert np.array_equal(a.truth.lat, b.truth.lat) and np.array_equal(a.truth.alt, b.truth.alt)
    assert [x.attempt.t for x in a.rf] == [x.attempt.t for x in b.rf]
    assert len(b.others) == 1 and b.others[0].truth.t_us.size == b.truth.t_us.size


def test_multi_uav_generation_is_deterministic(site: Site) -> None:
    plan = _plan("multi_four", site)
    cfg = load_twin_config()
    a = generate_twin(site, cfg, plan, 11, 120.0)
    b = generate_twin(site, cfg, plan, 11, 120.0)
    assert [len(f.tracks) for f in a.radar] == [len(f.tracks) for f in b.radar]
    for oa, ob in zip(a.others, b.others, strict=True):
        assert np.array_equal(oa.truth.lat, ob.truth.lat)
