"""The twin's radar scene and RF outages, checked on the written files read back.

One short (240 s) low-pass flight with a busy scene (scene scale 2) is generated and written;
the loaders read it back. The twin's own label of each report (the kind of the object its
track follows) says which track to look at; every property is checked on the loaded values.
"""

from __future__ import annotations

import csv
import itertools
import json
from collections import defaultdict
from pathlib import Path

import numpy as np
import pytest

from uav_fusion.cli import main as cli_main
from uav_fusion.core.data import load_flight
from uav_fusion.core.errors import ConfigError
from uav_fusion.core.records import Flight, RadarTrack
from uav_fusion.core.site import Site, load_site
from uav_fusion.core.twin.config import load_twin_config, twin_config_from_dict
from uav_fusion.core.twin.generate import TwinFlight, generate_twin
from uav_fusion.core.twin.radar_model import BIRD, CLUTTER, GHOST, UAV, VEHICLE
from uav_fusion.core.twin.trajectory import flight_plan_from_dict, load_flight_plan
from uav_fusion.core.twin.writers import write_twin
from uav_fusion.resources import config_path

LOW_PASS = config_path("waypoints/low_pass.yaml")

# the busy scene: the twin, its flight as read back from the files, and their folder
Busy = tuple[TwinFlight, Flight, Path]


@pytest.fixture(scope="module")
def site() -> Site:
    return load_site()


@pytest.fixture(scope="module")
def busy(site: Site, tmp_path_factory: pytest.TempPathFactory) -> Busy:
    plan = load_flight_plan(LOW_PASS, site)
    twin = generate_twin(
        site, load_twin_config(), plan, seed=101, duration_s=240.0, scene_scale=2.0
    )
    out = tmp_path_factory.mktemp("busy")
    write_twin(twin, out)
    return twin, load_flight(out, site, strict=True), out


def _tracks_by_kind(twin: TwinFlight, flight: Flight) -> dict[str, dict[int, list[RadarTrack]]]:
    """Loaded reports grouped by track id, under the kind most of that track's reports follow."""
    labels: dict[int, list[str]] = defaultdict(list)
    for f in twin.radar_sim:
        for r in f.tracks:
            labels[r.track_id].append(r.kind)
    loaded: dict[int, list[RadarTrack]] = defaultdict(list)
    for fr in flight.radar:
        for trk in fr.tracks:
            loaded[trk.track_id].append(trk)
    out: dict[str, dict[int, list[RadarTrack]]] = defaultdict(dict)
    for tid, reps in loaded.items():
        kinds = labels[tid]
        assert len(kinds) == len(reps)  # the written file holds every simulated report
        main = max(set(kinds), key=kinds.count)
        out[main][tid] = reps
    return out


def _xyz(reps: list[RadarTrack]) -> np.ndarray:
    return np.array([(r.e, r.n, r.u) for r in reps])


def _vel(r: RadarTrack) -> tuple[float, float, float]:
    """A report's NED velocity: the twin's radar reports all carry one."""
    assert r.vel_ned is not None
    return r.vel_ned


def test_stationary_clutter_track_lasts_minutes_and_sometimes_looks_like_a_uav(busy: Busy) -> None:
    twin, flight, _ = busy
    clutter = _tracks_by_kind(twin, flight)[CLUTTER]
    long_ones = [r for r in clutter.values() if r[-1].t - r[0].t >= 120.0]
    assert long_ones, "no clutter track lasted 2 min"
    hits = 0
    for reps in long_ones:
        p = _xyz(reps)
        speed = np.hypot([_vel(r)[0] for r in reps], [_vel(r)[1] for r in reps])
        assert np.median(speed) < 1.5  # near-zero velocity
        # stays put on the map (its height wanders with the elevation noise far away)
        assert np.max(np.linalg.norm(p[:, :2] - np.median(p[:, :2], axis=0), axis=1)) < 150.0
        probs = np.array([r.uav_prob for r in reps])
        assert np.mean(probs) < 0.5  # mostly classified as not a UAV ...
        hits += int(np.any(probs >= 0.5))  # ... but not always
    assert hits >= 1


def test_uav_track_is_sometimes_classified_below_half(busy: Busy) -> None:
    twin, flight, _ = busy
    uav = _tracks_by_kind(twin, flight)[UAV]
    assert uav
    longest = max(uav.values(), key=len)
    probs = np.array([r.uav_prob for r in longest])
    assert np.mean(probs) >= 0.5
    assert np.any(probs < 0.5)


def test_multipath_ghost_lies_below_the_uav(busy: Busy) -> None:
    twin, flight, _ = busy
    # the loaded reports whose track currently follows the UAV's multipath image
    labels = [[r.kind for r in f.tracks] for f in twin.radar_sim]
    ghost = [t for fr, kinds in zip(flight.radar, labels, strict=True)
             for t, k in zip(fr.tracks, kinds, strict=True) if k == GHOST]  # fmt: skip
    assert len(ghost) >= 8
    tt, tenu = flight.truth_arrays()
    by_track: dict[int, list[RadarTrack]] = defaultdict(list)
    for r in ghost:
        by_track[r.track_id].append(r)
    mirrored = 0
    for reps in by_track.values():
        if len(reps) < 8:
            continue
        t = np.array([r.t for r in reps])
        truth = np.column_stack([np.interp(t, tt, tenu[:, k]) for k in range(3)])
        p = _xyz(reps)
        horiz = np.median(np.hypot(*(p[:, :2] - truth[:, :2]).T))
        # under the UAV on the map and below the ground: the mirror image
        mirrored += int(horiz < 60.0 and np.median(p[:, 2]) < twin.traj.ground_u)
    assert mirrored >= 1


def test_ground_vehicle_drives_along_a_road(busy: Busy) -> None:
    twin, flight, _ = busy
    cars = _tracks_by_kind(twin, flight)[VEHICLE]
    roads = [np.asarray(r, dtype=float) for r in twin.config.vehicles.roads]
    ground = twin.traj.ground_u

    def road_distance(xy: np.ndarray) -> float:
        best = np.inf
        for road in roads:
            for a, b in itertools.pairwise(road):
                d = b - a
                s = np.clip(np.dot(xy - a, d) / np.dot(d, d), 0.0, 1.0)
                best = min(best, float(np.linalg.norm(xy - (a + s * d))))
        return best

    good = 0
    for reps in cars.values():
        if reps[-1].t - reps[0].t < 20.0:
            continue
        p = _xyz(reps)
        on_road = np.median([road_distance(x) for x in p[:, :2]])
        agl = np.median(p[:, 2]) - ground
        moved = np.linalg.norm(p[-1, :2] - p[0, :2])
        good += int(on_road < 40.0 and -15.0 < agl < 15.0 and moved > 100.0)
    assert good >= 1
    assert 0.0 <= twin.config.vehicles.height_m <= 2.0


def test_bird_flock_small_and_erratic(busy: Busy) -> None:
    twin, flight, _ = busy
    birds = _tracks_by_kind(twin, flight)[BIRD]
    assert len(birds) >= 2
    rcs = [r.rcs_dbsm for reps in birds.values() for r in reps if r.rcs_dbsm is not None]
    assert np.median(rcs) < -10.0  # small birds, far below the UAV's ~-11 dBsm median
    # a flock: two bird tracks reported in the same frame within 100 m of each other
    together = False
    for fr in flight.radar:
        ps = [np.array((t.e, t.n, t.u)) for t in fr.tracks if t.track_id in birds]
        for i in range(len(ps)):
            for j in range(i + 1, len(ps)):
                together |= bool(np.linalg.norm(ps[i] - ps[j]) < 100.0)
    assert together
    # erratic: the heading of a long bird track turns by tens of degrees
    longest = max(birds.values(), key=len)
    hd = np.unwrap(np.arctan2([_vel(r)[1] for r in longest], [_vel(r)[0] for r in longest]))
    assert np.ptp(hd) > np.radians(20.0)


def test_rf_outage_gives_runs_of_failed_attempts(site: Site, tmp_path: Path) -> None:
    doc = {"rf_outage": {"enter_prob": 0.08, "mean_run": 4.0}}
    cfg = twin_config_from_dict(doc)
    plan = load_flight_plan(LOW_PASS, site)
    write_twin(generate_twin(site, cfg, plan, seed=11, duration_s=240.0), tmp_path)
    with (tmp_path / "AADM.csv").open(newline="", encoding="utf-8") as fh:
        rows = list(csv.DictReader(fh))
    failed = [r["Comment"].endswith("no signal captured") for r in rows]
    longest = run = 0
    for f in failed:
        run = run + 1 if f else 0
        longest = max(longest, run)
    assert longest >= 2
    flight = load_flight(tmp_path, site, strict=True)
    assert sum(not a.ok for a in flight.rf) >= sum(failed)
    # without outages no attempt fails for that reason
    calm = twin_config_from_dict({"rf_outage": {"enter_prob": 0.0}})
    quiet = generate_twin(site, calm, plan, seed=11, duration_s=240.0)
    assert not any(a.attempt.reason == "no signal captured" for a in quiet.rf)


def test_busy_scene_is_deterministic(busy: Busy, site: Site, tmp_path: Path) -> None:
    _, _, first = busy
    plan = load_flight_plan(LOW_PASS, site)
    again = generate_twin(
        site, load_twin_config(), plan, seed=101, duration_s=240.0, scene_scale=2.0
    )
    write_twin(again, tmp_path)
    a = {p.name: p.read_bytes() for p in sorted(Path(first).iterdir())}
    b = {p.name: p.read_bytes() for p in sorted(tmp_path.iterdir())}
    assert a == b


def test_scene_scale_from_the_command_line_and_the_plan(site: Site, tmp_path: Path) -> None:
    counts = {}
    for k in ("0", "2"):
        out = tmp_path / k
        args = ["generate", "--out", str(out), "--waypoints", str(LOW_PASS), "--seed", "101"]
        assert cli_main([*args, "--duration", "120", "--scene-scale", k]) == 0
        man = json.loads((out / "twin_manifest.json").read_text())
        assert man["scene_scale"] == float(k)
        counts[k] = sum(len(f.tracks) for f in load_flight(out, site, strict=True).radar)
    assert counts["0"] < counts["2"]  # the scene adds tracks
    doc = {"name": "x", "scene_scale": -1, "waypoints": [{"e": 0, "n": 0, "alt": 20}]}
    with pytest.raises(ConfigError, match="scene_scale"):
        flight_plan_from_dict(doc, site)


def test_bad_scene_configuration_names_the_key() -> None:
    with pytest.raises(ConfigError, match=r"vehicles: roads\[0\]\[1\]"):
        twin_config_from_dict({"vehicles": {"roads": [[[0, 0], [1, "x"]]]}})
    with pytest.raises(ConfigError, match=r"vehicles: roads\[0\]: expected a list of at least two"):
        twin_config_from_dict({"vehicles": {"roads": [[[0, 0]]]}})
    with pytest.raises(ConfigError, match="clutter: unknown key 'site'"):
        twin_config_from_dict({"clutter": {"site": 3}})
    with pytest.raises(ConfigError, match="rf_outage"):
        twin_config_from_dict({"rf_outage": {"mean_run": 0.5}})
    cfg = twin_config_from_dict({"vehicles": {"roads": [[[0, 0], [100, 50], [200, 0]]]}})
    assert cfg.vehicles.roads == (((0.0, 0.0), (100.0, 50.0), (200.0, 0.0)),)
