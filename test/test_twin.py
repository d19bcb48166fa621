"""Digital twin: determinism, exact round trip through the real-format files, CLI, physics."""

from __future__ import annotations

import csv
import json
import re
from pathlib import Path

import numpy as np
import pytest

from uav_fusion.cli import main as cli_main
from uav_fusion.core.data import load_flight
from uav_fusion.core.errors import ConfigError
from uav_fusion.core.site import Site, load_site
from uav_fusion.core.twin.config import (
    DEFAULT_WAYPOINTS,
    load_twin_config,
    twin_config_from_dict,
)
from uav_fusion.core.twin.generate import TwinFlight, generate_twin, twin_to_flight
from uav_fusion.core.twin.rf_model import solve_tdoa_2d
from uav_fusion.core.twin.trajectory import flight_plan_from_dict, load_flight_plan
from uav_fusion.core.twin.writers import RF_HEADER, write_twin
from uav_fusion.resources import DEFAULT_FLIGHT, config_path, data_path

NORTH_BOX = config_path("waypoints/lake_wheeler_north_box.yaml")


@pytest.fixture(scope="module")
def site() -> Site:
    return load_site()


@pytest.fixture(scope="module")
def short_twin(site: Site) -> TwinFlight:
    """The default plan cut to 240 s (take-off, the radar loop, the start of the trip north)."""
    plan = load_flight_plan(config_path(DEFAULT_WAYPOINTS), site)
    return generate_twin(site, load_twin_config(), plan, seed=7, duration_s=240.0)


def _files(folder: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(folder.iterdir())}


def test_same_seed_gives_identical_files(site: Site, tmp_path: Path) -> None:
    plan = load_flight_plan(config_path(DEFAULT_WAYPOINTS), site)
    cfg = load_twin_config()
    for name, seed in (("a", 5), ("b", 5), ("c", 6)):
        write_twin(generate_twin(site, cfg, plan, seed=seed, duration_s=120.0), tmp_path / name)
    a, b, c = (_files(tmp_path / n) for n in "abc")
    assert a == b
    assert set(a) == set(c)
    for name in a:
        if name != "twin_manifest.json":
            assert a[name] != c[name], name


def test_bundled_default_flight_is_what_the_code_generates(site: Site, tmp_path: Path) -> None:
    out = tmp_path / "regen"
    assert cli_main(["generate", "--out", str(out)]) == 0
    shipped = data_path(DEFAULT_FLIGHT)
    if _files(out) == _files(shipped):
        return  # byte for byte, with the pinned numpy/scipy/pymap3d
    # Other library versions may round the last printed digit differently: then the flights
    # must still agree record by record to well below a millimetre.
    a, b = load_flight(out, site, strict=True), load_flight(shipped, site, strict=True)
    at, aenu = a.truth_arrays()
    bt, benu = b.truth_arrays()
    assert at.shape == bt.shape and np.max(np.abs(at - bt)) < 1e-6
    assert np.max(np.abs(aenu - benu)) < 1e-4
    ra = np.array([(t.t, t.track_id, t.e, t.n, t.u) for f in a.radar for t in f.tracks])
    rb = np.array([(t.t, t.track_id, t.e, t.n, t.u) for f in b.radar for t in f.tracks])
    assert ra.shape == rb.shape and np.max(np.abs(ra - rb)) < 1e-4
    fa = np.array([(x.t, x.ok, x.e, x.n) for x in a.rf], dtype=float)
    fb = np.array([(x.t, x.ok, x.e, x.n) for x in b.rf], dtype=float)
    assert fa.shape == fb.shape
    np.testing.assert_allclose(fa, fb, rtol=0, atol=1e-4, equal_nan=True)


def test_round_trip_through_files_reproduces_the_twin(
    short_twin: TwinFlight, site: Site, tmp_path: Path
) -> None:
    write_twin(short_twin, tmp_path)
    loaded = load_flight(tmp_path, site, strict=True)
    mine = twin_to_flight(short_twin)

    assert len(loaded.truth) == len(mine.truth) == int(short_twin.truth.valid.sum())
    lt, lenu = loaded.truth_arrays()
    mt, menu = mine.truth_arrays()
    assert np.max(np.abs(lt - mt)) < 1e-5
    assert np.max(np.abs(lenu - menu)) < 1e-6
    assert [f.line for f in loaded.truth] == [f.line for f in mine.truth]
    # the loaded truth is the simulated flight plus RTK noise (cm), nothing else
    sim = short_twin.traj.position(mt - short_twin.start_unix)
    assert np.max(np.abs(lenu - sim)) < 0.2

    assert len(loaded.radar) == len(mine.radar)
    l_tr = [t for f in loaded.radar for t in f.tracks]
    m_tr = [t for f in mine.radar for t in f.tracks]
    assert len(l_tr) == len(m_tr) > 0
    assert [t.track_id for t in l_tr] == [t.track_id for t in m_tr]
    assert [t.line for t in l_tr] == [t.line for t in m_tr]
    le = np.array([(t.t, t.e, t.n, t.u) for t in l_tr])
    me = np.array([(t.t, t.e, t.n, t.u) for t in m_tr])
    assert np.max(np.abs(le[:, 0] - me[:, 0])) < 1e-5
    assert np.max(np.abs(le[:, 1:] - me[:, 1:])) < 1e-6
    assert [t.uav_prob for t in l_tr] == pytest.approx([t.uav_prob for t in m_tr])

    assert len(loaded.rf) == len(mine.rf) > 0
    assert [a.ok for a in loaded.rf] == [a.ok for a in mine.rf]
    assert [a.meas_id for a in loaded.rf] == [a.meas_id for a in mine.rf]
    for la, ma in zip(loaded.rf, mine.rf, strict=True):
        assert la.t == pytest.approx(ma.t, abs=1e-6)
        if ma.ok:
            assert la.e == pytest.approx(ma.e, abs=1e-6)
            assert la.n == pytest.approx(ma.n, abs=1e-6)
        assert la.valid_sensors == ma.valid_sensors
        assert la.line == ma.line


def test_files_follow_the_dataset_formats(short_twin: TwinFlight, tmp_path: Path) -> None:
    paths = write_twin(short_twin, tmp_path)
    with paths["rf"].open(newline="", encoding="utf-8") as fh:
        rows = list(csv.reader(fh))
    assert [h.strip() for h in rows[0]] == [h.strip() for h in RF_HEADER]
    assert rows[0] != [h.strip() for h in RF_HEADER]  # stray spaces, as in the real file
    assert len(rows[1]) == 16
    assert re.fullmatch(r"2025-10-07 19:\d\d:\d\d\.\d{3}", rows[1][14])  # UTC, ms
    failed = [r for r in rows[1:] if r[5] == "0" and r[6] == "0"]
    assert len(failed) == sum(1 for a in short_twin.rf if not a.attempt.ok)
    assert all("," in r[13] for r in rows[1:] if r[5] != "0")  # quoted sensor list

    radar_lines = paths["radar"].read_text(encoding="utf-8").splitlines()
    docs = [json.loads(ln) for ln in radar_lines]
    assert any("error" in d for d in docs)
    frames = [d for d in docs if "params" in d]
    assert any("trackData" in d["params"] for d in frames)
    assert any("trackData" in d for d in frames)
    one = next(t for d in frames for t in d.get("trackData", d["params"].get("trackData", [])))
    assert set(one) == {
        "id", "lla", "velocityNed", "catProb", "range", "radialVelocity", "numInliers", "rcsDbsm"
    }  # fmt: skip
    gt = [d["params"]["globalTime"] for d in frames]
    assert np.median(np.diff(gt)) == pytest.approx(0.25, abs=0.01)

    truth = paths["truth"].read_text(encoding="utf-8").splitlines()
    assert paths["truth"].name == "2025-10-07_15-40-00_vehicleOut.txt"
    assert truth[0].startswith("1,-999,-999,-999,")  # no fix yet
    assert '"(' in truth[10] and "2025-10-07 15:4" in truth[10]  # local time, UTC-4
    nofix = [ln for ln in truth if ",-999,-999,-999," in ln]
    assert len(nofix) == int((~short_twin.truth.valid).sum()) >= 3


def test_cli_generates_another_plan_and_seed(site: Site, tmp_path: Path) -> None:
    out = tmp_path / "north"
    rc = cli_main(
        ["generate", "--seed", "11", "--waypoints", str(NORTH_BOX), "--out", str(out),
         "--sensors", "LW2,LW4,LW5", "--radar-tower", "LW4", "--duration", "300"]
    )  # fmt: skip
    assert rc == 0
    man = json.loads((out / "twin_manifest.json").read_text())
    assert man["seed"] == 11
    assert man["flight_plan"] == "lake_wheeler_north_box"
    assert man["rf_sensors"] == ["LW2", "LW4", "LW5"]
    assert man["radar"]["tower"] == "LW4"
    assert man["duration_s"] == pytest.approx(300.0, abs=0.05)
    fl = load_flight(out, site)
    assert fl.truth and fl.radar and fl.rf
    assert {a.total_sensors for a in fl.rf} == {3}
    # the plan's second waypoint is 60 m up: the flight climbed to it
    assert max(f.h for f in fl.truth) - site.takeoff_h > 55.0


def test_cli_reports_bad_arguments(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    rc = cli_main(["generate", "--out", str(tmp_path), "--sensors", "LW2,LW9,LW5"])
    assert rc == 2
    assert "LW9" in capsys.readouterr().err
    rc = cli_main(["generate", "--out", str(tmp_path), "--waypoints", str(tmp_path / "none.yaml")])
    assert rc == 2
    assert "none.yaml: waypoint file not found" in capsys.readouterr().err


def test_flight_plan_validation(site: Site) -> None:
    ok = {"waypoints": [{"e": 0, "n": 0, "alt": 30}, {"lat": 35.73, "lon": -78.698, "alt": 40}]}
    plan = flight_plan_from_dict(ok, site)
    assert plan.waypoints[1].n == pytest.approx(277.0, abs=2.0)
    with pytest.raises(ConfigError, match="waypoint 1: give either e/n"):
        flight_plan_from_dict({"waypoints": [{"e": 0, "lat": 35.7, "alt": 30}]}, site)
    with pytest.raises(ConfigError, match="waypoint 2: alt must lie"):
        wps = [{"e": 0, "n": 0, "alt": 3}, {"e": 1, "n": 1, "alt": -5}]
        flight_plan_from_dict({"waypoints": wps}, site)
    with pytest.raises(ConfigError, match="unknown key"):
        flight_plan_from_dict({"waypoints": [{"e": 0, "n": 0, "alt": 3, "spd": 3}]}, site)


def test_twin_config_validation() -> None:
    with pytest.raises(ConfigError, match="radar: unknown key 'sigma_az'"):
        twin_config_from_dict({"radar": {"sigma_az": 1.0}})
    with pytest.raises(ConfigError, match="rf: 'interval_s' must be a number"):
        twin_config_from_dict({"rf": {"interval_s": "fast"}})
    with pytest.raises(ConfigError, match=r"rf.interval_s must be > 0"):
        twin_config_from_dict({"rf": {"interval_s": 0}})
    cfg = twin_config_from_dict({"radar": {"sigma_az_deg": 2}})
    assert cfg.radar.sigma_az_deg == 2.0


def test_flight_physics(short_twin: TwinFlight) -> None:
    tr = short_twin.traj
    air = tr.pos[:, 2] > tr.ground_u + 20.0
    speed = np.linalg.norm(tr.vel[air, :2], axis=1)
    assert 8.0 < float(np.median(speed)) < 12.0
    acc = np.linalg.norm(tr.acc[air, :2], axis=1)  # manoeuvres plus wind gusts
    assert float(np.percentile(acc, 99)) < 4.0
    dt_truth = np.diff(short_twin.truth.t_us) / 1e6
    assert float(np.max(dt_truth)) <= 0.2 + 1e-9  # >= 5 Hz
    assert tr.t_takeoff == pytest.approx(55.0, abs=0.05)  # the plan's hold before take-off


def test_tdoa_solver_recovers_exact_position(site: Site) -> None:
    S = np.array([t.enu for t in site.rf_sensor_towers()])
    for p in ([100.0, 200.0], [-300.0, 1200.0], [500.0, -100.0]):
        q = np.array([p[0], p[1], 40.0])
        toa = np.linalg.norm(S - q, axis=1) + 1234.5  # unknown emission time
        xy, ok, cov, rms = solve_tdoa_2d(S, toa, 40.0, 100, 0.01)
        assert ok
        assert np.hypot(*(xy - q[:2])) < 0.01
        assert rms < 1e-3
        assert np.all(np.isfinite(cov))


def test_hold_at_a_waypoint_hovers_there(site: Site) -> None:
    from uav_fusion.core.twin.config import FlightDynamics
    from uav_fusion.core.twin.trajectory import fly

    doc = {
        "hold_before_s": 5,
        "waypoints": [
            {"e": 0, "n": 0, "alt": 30},
            {"e": 200, "n": 0, "alt": 30, "hold_s": 40},
            {"e": 0, "n": 0, "alt": 0},
        ],
    }
    plan = flight_plan_from_dict(doc, site)
    assert plan.waypoints[1].hold == 40.0
    tr = fly(plan, site, FlightDynamics(), np.random.default_rng(3))
    near = np.hypot(tr.pos[:, 0] - 200.0, tr.pos[:, 1]) < 6.0
    t_near = tr.t[near]
    # it stays over the spot for the hold (plus the approach and departure inside 6 m)
    assert 40.0 <= float(t_near[-1] - t_near[0]) < 50.0
    mid = (tr.t > t_near[0] + 5.0) & (tr.t < t_near[0] + 35.0)
    speed = np.linalg.norm(tr.vel[mid], axis=1)
    assert float(np.median(speed)) < 0.15  # inside the radar's Doppler notch most of the time
    with pytest.raises(ConfigError, match=r"waypoint 1: hold_s must lie"):
        flight_plan_from_dict({"waypoints": [{"e": 0, "n": 0, "alt": 3, "hold_s": -1}]}, site)


@pytest.mark.parametrize(
    "name",
    ["zigzag_dash", "west_leg", "out_and_back", "hover_notch", "low_pass", "high_altitude"],
)
def test_stress_plans_load_and_fly(site: Site, name: str) -> None:
    from uav_fusion.core.twin.config import FlightDynamics
    from uav_fusion.core.twin.trajectory import fly

    plan = load_flight_plan(config_path(f"waypoints/{name}.yaml"), site)
    tr = fly(plan, site, FlightDynamics(), np.random.default_rng(1), tail_s=5.0)
    assert 200.0 < tr.t_landed - tr.t_takeoff < 900.0
    agl = tr.pos[:, 2] - tr.ground_u
    speed = np.linalg.norm(tr.vel[:, :2], axis=1)
    if name == "zigzag_dash":
        assert float(np.max(speed)) >= 15.0
    if name == "low_pass":
        air = tr.t_takeoff + 60.0 < tr.t
        assert float(np.min(agl[air & (agl > 1.0)])) < 10.0
    if name == "high_altitude":
        assert float(np.max(agl)) > 100.0
