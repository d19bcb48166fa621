"""Worlds: the twin's physics drawn per flight from the families of config/worlds.yaml, the
worlds benchmark that tunes on some families and tests on others, and the flights of the twin's
own world left as they were."""

from __future__ import annotations

import csv
import hashlib
import itertools
import json
from pathlib import Path

import numpy as np
import pytest
import yaml

from uav_fusion.cli import main
from uav_fusion.core.bench.cache import cached_flights, generate_flight
from uav_fusion.core.bench.definition import load_definition
from uav_fusion.core.bench.single import true_mount_az
from uav_fusion.core.bench.sweep import spec_from_dict, sweep_tasks
from uav_fusion.core.errors import ConfigError, DataError
from uav_fusion.core.scoring.calibration import angle_residuals
from uav_fusion.core.scoring.fixed_rate import longest_run
from uav_fusion.core.site import Site, load_site
from uav_fusion.core.twin.config import load_twin_config
from uav_fusion.core.twin.generate import generate_twin, twin_to_flight
from uav_fusion.core.twin.trajectory import load_flight_plan
from uav_fusion.core.twin.worlds import (
    WORLD_FILE,
    draw_world,
    load_worlds,
    read_world,
    worlds_from_dict,
)
from uav_fusion.core.twin.writers import MANIFEST, write_twin
from uav_fusion.resources import DEFAULT_SITE, config_path

SITE_FILE = config_path(DEFAULT_SITE)
ZIGZAG = config_path("waypoints/zigzag_dash.yaml")


@pytest.fixture(scope="module")
def site() -> Site:
    return load_site()


def test_world_draws_are_seeded_and_within_their_ranges() -> None:
    worlds = load_worlds()
    assert len(worlds.families) >= 8
    for fam in worlds.families.values():
        for seed, plan in itertools.product(range(6), ("zigzag_dash", "low_pass")):
            w = draw_world(fam, seed, plan)
            assert w == draw_world(fam, seed, plan)  # reproducible
            assert list(w.values) == list(fam.draws)
            for key, d in fam.draws.items():
                v = w.values[key]
                lo, hi = d.bounds
                assert lo - 1e-4 <= v <= hi + 1e-4, (fam.name, key, v)
                if d.kind == "symmetric":
                    assert abs(v) >= d.values[0] - 1e-4, (fam.name, key, v)
                if d.kind == "fixed":
                    assert v == d.values[0]


def test_the_flights_of_a_family_differ_in_the_drawn_physics() -> None:
    definition = load_definition("worlds")
    assert definition.worlds is not None
    for split in ("tune", "test"):
        flights = definition.flights(split)
        for name in {f.family for f in flights}:
            assert name is not None
            fam = definition.worlds.family(name)
            drawn = [draw_world(fam, f.seed, f.plan.name) for f in flights if f.family == name]
            assert len(drawn) == len(definition.plans) * len(definition.splits[split])
            for key, d in fam.draws.items():
                if d.kind in ("fixed", "choice"):
                    continue
                values = [w.values[key] for w in drawn]
                assert len(set(values)) == len(values), (name, key, values)


def test_a_parameter_draws_from_its_own_stream(tmp_path: Path) -> None:
    """Adding a parameter to a family leaves the draws of the others as they were."""
    one = {"families": {"f": {"draw": {"radar.az_bias_deg": [-1.0, 1.0]}}}}
    two = {"families": {"f": {"draw": {"radar.az_bias_deg": [-1.0, 1.0],
                                       "rf.sigma_timing_ns": [30.0, 70.0]}}}}  # fmt: skip
    a = draw_world(worlds_from_dict(one, tmp_path / "a.yaml").family("f"), 11, "p")
    b = draw_world(worlds_from_dict(two, tmp_path / "b.yaml").family("f"), 11, "p")
    assert a.values["radar.az_bias_deg"] == b.values["radar.az_bias_deg"]
    other_family = worlds_from_dict({"families": {"g": one["families"]["f"]}}, tmp_path / "c")
    assert draw_world(other_family.family("g"), 11, "p").values != a.values


# sha256 of the files of zigzag_dash, seed 201, cut to 90 s, from the code before worlds
# existed (the twin's own world must not change)
PINNED = {
    "2025-10-07_15-40-00_vehicleOut.txt": (
        "882a6debfe538537f7dac288f77e365db5504409c61931980989c6d3315b0c4d"
    ),
    "AADM.csv": "ef9b8760bb8ef68082a026ca68b4b91cc97c01bc27cf87576aba8e798b3de6e6",
    "radar_data_2025-10-07_19-40-00.json": (
        "64d8da803345a78901eb2e4e6f55d7f74360f477808ac2dabbd53019c2083bd6"
    ),
    "twin_manifest.json": "6ef1adb9de4e5b3800dc49902f14954ad5bf6fdadb6488e3876ffa3a74fd8e9d",
}


def test_a_flight_of_an_existing_plan_is_unchanged(site: Site, tmp_path: Path) -> None:
    plan = load_flight_plan(ZIGZAG, site)
    twin = generate_twin(site, load_twin_config(), plan, seed=201, duration_s=90.0)
    assert twin.world is None
    write_twin(twin, tmp_path)
    got = {p.name: hashlib.sha256(p.read_bytes()).hexdigest() for p in tmp_path.iterdir()}
    if got == PINNED:
        return  # byte for byte, with the pinned numpy/scipy/pymap3d
    # other library versions may print a last digit differently: the records must agree
    assert set(got) == set(PINNED)
    flight = twin_to_flight(twin)
    r = np.array([(t.e, t.n, t.u) for f in flight.radar for t in f.tracks])
    ok = [a for a in flight.rf if a.ok]
    assert len(r) == 1818 and len(ok) == 23
    np.testing.assert_allclose(r.sum(axis=0), [-301642.917, 544190.893, 52860.167], atol=0.01)
    assert sum(a.e + a.n for a in ok) == pytest.approx(14.348, abs=0.01)


def test_a_world_is_applied_and_recorded_with_the_flight(site: Site, tmp_path: Path) -> None:
    """A 3 deg mount misalignment shows in the reports' azimuth; the trajectory and the truth
    log are those of the same seed without a world."""
    doc = {"families": {"turned": {"description": "turned mount", "draw": {
        "radar.az_bias_deg": 3.0, "radar.el_bias_deg": [-0.2, 0.2],
        "site_radar.fov_az_deg": [100.0, 110.0]}}}}  # fmt: skip
    fam = worlds_from_dict(doc, tmp_path / "worlds.yaml").family("turned")
    plan = load_flight_plan(ZIGZAG, site)
    cfg = load_twin_config()
    twin = generate_twin(site, cfg, plan, seed=5, duration_s=150.0, world=fam)
    plain = generate_twin(site, cfg, plan, seed=5, duration_s=150.0)
    assert twin.world is not None and twin.world.values["radar.az_bias_deg"] == 3.0
    assert twin.config.radar.az_bias_deg == 3.0 and plain.config.radar.az_bias_deg == 0.5
    assert 100.0 <= twin.site.radar.fov_az_deg <= 110.0
    write_twin(twin, tmp_path / "w")
    write_twin(plain, tmp_path / "p")
    truth = "2025-10-07_15-40-00_vehicleOut.txt"
    assert (tmp_path / "w" / truth).read_bytes() == (tmp_path / "p" / truth).read_bytes()
    world = read_world(tmp_path / "w")
    assert world is not None and read_world(tmp_path / "p") is None
    assert world["family"] == "turned" and world["seed"] == 5 and world["plan"] == plan.name
    assert world["radar_mount"]["az_bias_deg"] == 3.0
    el = world["drawn"]["radar.el_bias_deg"]
    assert world["radar_mount"]["el_bias_deg"] == el and -0.2 <= el <= 0.2
    assert world["radar_mount"]["fov_az_deg"] == twin.site.radar.fov_az_deg
    manifest = json.loads((tmp_path / "w" / MANIFEST).read_text())
    assert manifest["world"] == {"family": "turned", "file": WORLD_FILE}
    plain_manifest = json.loads((tmp_path / "p" / MANIFEST).read_text())
    assert "world" not in plain_manifest
    # both manifests record the mount the reports were given; the bench reads it as the truth
    assert manifest["radar_mount"] == {"az_bias_deg": 3.0, "el_bias_deg": el}
    assert plain_manifest["radar_mount"] == {"az_bias_deg": 0.5, "el_bias_deg": 0.3}
    assert true_mount_az(tmp_path / "w") == 3.0 and true_mount_az(tmp_path / "p") == 0.5
    # the reports are turned by the drawn misalignment
    res = angle_residuals(twin_to_flight(twin), site.radar.enu)
    base = angle_residuals(twin_to_flight(plain), site.radar.enu)
    assert res.az_deg.size > 100 and base.az_deg.size > 100
    assert float(np.median(res.az_deg) - np.median(base.az_deg)) == pytest.approx(2.5, abs=0.5)


def test_cep_nlos_weight_makes_the_cep_reflect_the_excess_paths(site: Site) -> None:
    import dataclasses

    plan = load_flight_plan(ZIGZAG, site)
    cfg = load_twin_config()
    honest = dataclasses.replace(cfg, rf=dataclasses.replace(cfg.rf, cep_nlos_weight=1.0))
    a = generate_twin(site, cfg, plan, seed=8, duration_s=200.0)
    b = generate_twin(site, honest, plan, seed=8, duration_s=200.0)
    fixes = [(x.attempt, y.attempt) for x, y in zip(a.rf, b.rf, strict=True) if x.attempt.ok]
    assert len(fixes) > 20
    for x, y in fixes:  # the same fixes, only their CEP grows
        assert (x.e, x.n) == (y.e, y.n) and y.cep_m >= x.cep_m
    nlos = [y.cep_m / x.cep_m for x, y in fixes if x.nlos_links > 0]
    assert nlos and float(np.median(nlos)) > 3.0


def test_bad_world_families_stop_naming_the_file_and_key(tmp_path: Path) -> None:
    def load(doc: object) -> None:
        worlds_from_dict(doc, tmp_path / "w.yaml")

    cases = [
        ({"families": {"f": {"draw": {"radar.nope": 1.0}}}}, r"unknown world parameter"),
        ({"families": {"f": {"draw": {"recording.tail_s": 1.0}}}}, r"unknown world parameter"),
        ({"families": {"f": {"draw": {"radar.sigma_az_deg": [2.0, 1.0]}}}}, r"lo <= hi"),
        ({"families": {"f": {"draw": {"radar.sigma_az_deg": [-1.0, 1.0]}}}}, r"must be >= 0"),
        ({"families": {"f": {"draw": {"site_radar.fov_az_deg": [100, 400]}}}}, r"\[1, 360\]"),
        ({"families": {"f": {"draw": {"rf.cep_nlos_weight": [0.5, 1.5]}}}}, r"cep_nlos_weight"),
        ({"families": {"f": {"draw": {"radar.pd_max": {"gauss": [0, 1]}}}}}, r"unknown draw"),
        ({"families": {"f": {"draw": {}, "extra": 1}}}, r"unknown key\(s\) extra"),
        ({"famlies": {}}, r"unknown key\(s\) famlies"),
    ]
    for doc, message in cases:
        with pytest.raises(ConfigError, match=message) as info:
            load(doc)
        assert "w.yaml" in str(info.value)


def test_the_worlds_definition_leaves_families_out() -> None:
    d = load_definition("worlds")
    assert d.families is not None and d.worlds is not None
    tune, test = set(d.families["tune"]), set(d.families["test"])
    assert tune and test and not tune & test
    assert not {p.name for p in d.plans} & {"lake_wheeler_default"}
    for split, fams in (("tune", tune), ("test", test)):
        flights = d.flights(split)
        assert {f.family for f in flights} == fams
        assert len(flights) == len(d.plans) * len(fams) * len(d.splits[split])
        assert len({f.flight_id for f in flights}) == len(flights)
    assert d.settings.episode_error_m == 300.0
    # the accuracy definition flies the twin's own world
    acc = load_definition("accuracy")
    assert acc.families is None and all(f.family is None for f in acc.flights("test"))
    assert acc.flights("test")[0].flight_id == "lake_wheeler_default-s201"


def _tiny(tmp_path: Path, **changes: object) -> Path:
    doc: dict[str, object] = {
        "name": "tinyworlds",
        "plans": ["zigzag_dash"],
        "splits": {
            "tune": {"seeds": [3], "families": ["calibrated"]},
            "test": {"seeds": [4], "families": ["narrow_fov", "false_uav_clutter"]},
        },
        "worlds": str(config_path("worlds.yaml")),
        "duration_s": 45.0,
    }
    doc.update(changes)
    p = tmp_path / "tinyworlds.yaml"
    p.write_text(yaml.safe_dump(doc), encoding="utf-8")
    return p


@pytest.mark.parametrize(
    ("splits", "message"),
    [
        (
            {"tune": {"seeds": [3], "families": ["calibrated"]},
             "test": {"seeds": [4], "families": ["calibrated", "narrow_fov"]}},
            r"splits.test.families: calibrated also in splits.tune.families",
        ),
        (
            {"tune": [3], "test": {"seeds": [4], "families": ["narrow_fov"]}},
            r"splits.tune must name its world families too",
        ),
        (
            {"tune": {"seeds": [3], "families": ["calibrated"]},
             "test": {"seeds": [4], "families": ["no_such"]}},
            r"unknown world family 'no_such'",
        ),
        (
            {"tune": {"seeds": [3], "families": ["calibrated"], "plans": []},
             "test": {"seeds": [4], "families": ["narrow_fov"]}},
            r"unknown key\(s\) splits.tune.plans",
        ),
    ],
)  # fmt: skip
def test_bad_world_splits_stop_naming_the_file_and_key(
    tmp_path: Path, splits: dict[str, object], message: str
) -> None:
    p = _tiny(tmp_path, splits=splits)
    with pytest.raises(ConfigError, match=message) as info:
        load_definition(p)
    assert str(p) in str(info.value)
    q = _tiny(tmp_path, splits={"tune": [3], "test": [4]})
    with pytest.raises(ConfigError, match=r"worlds: a families file needs world families"):
        load_definition(q)


def test_cache_keys_and_folders_of_world_flights(site: Site, tmp_path: Path) -> None:
    d = load_definition(_tiny(tmp_path))
    a, b = cached_flights(d, "test", tmp_path / "c", SITE_FILE)
    assert a.flight.family == "narrow_fov" and b.flight.family == "false_uav_clutter"
    assert a.folder.name.startswith("zigzag_dash-narrow_fov-s4-") and a.key != b.key
    assert generate_flight(a, d, site) == (a.folder, True)
    world = read_world(a.folder)
    assert world is not None and world["family"] == "narrow_fov" and world["seed"] == 4
    labels = json.loads((a.folder / "bench_labels.json").read_text())
    assert labels["family"] == "narrow_fov"


def test_worlds_bench_and_sweep_end_to_end(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Two tiny flights in two test families, paper and tracker, one thread worker."""
    definition = _tiny(tmp_path)
    out, cache = tmp_path / "out", tmp_path / "cache"
    readme = tmp_path / "README.md"
    begin, end = "<!-- bench:tinyworlds-test:begin -->", "<!-- bench:tinyworlds-test:end -->"
    readme.write_text(f"# x\n{begin}\nold\n{end}\n")
    argv = [
        "bench", "--definition", str(definition), "--profiles", "paper", "tracker",
        "--out", str(out), "--cache", str(cache), "--workers", "1", "--threads", "--no-figure",
        "--readme", str(readme),
    ]  # fmt: skip
    assert main(argv) == 0
    text = capsys.readouterr().out
    assert "1 plans x 2 world families (narrow_fov, false_uav_clutter) x 1 seeds" in text
    table = text[text.index("per world family") :]
    for row in ("narrow_fov", "false_uav_clutter", "all 2 families"):
        assert f"\n{row} " in table
    assert "longest > 300 m s" in table and "worst flight mean m" in table
    with (out / "per_flight.csv").open() as fh:
        rows = list(csv.DictReader(fh))
    assert sorted((r["profile"], r["family"]) for r in rows) == [
        ("paper", "false_uav_clutter"), ("paper", "narrow_fov"),
        ("radar", "false_uav_clutter"), ("radar", "narrow_fov"),
        ("tracker", "false_uav_clutter"), ("tracker", "narrow_fov"),
    ]  # fmt: skip
    assert all(float(r["longest_gross_s"]) >= 0 for r in rows)
    # the tracker's registration against each world's true mount, and the flight's bound
    trk = [r for r in rows if r["profile"] == "tracker"]
    worlds = {r["family"]: read_world(next(cache.glob(f"*{r['family']}*"))) for r in trk}
    for r in trk:
        world = worlds[r["family"]]
        assert world is not None
        true = world["radar_mount"]["az_bias_deg"]
        assert float(r["registration_az_true_deg"]) == pytest.approx(true, abs=1e-3)
        assert float(r["registration_az_bound_deg"]) >= float(r["registration_az_sigma_deg"])
    assert all(r["registration_az_true_deg"] == "" for r in rows if r["profile"] != "tracker")
    assert "tracker: azimuth within 0.1 deg of the true mount, or within the flight's bound" in text
    summary = json.loads((out / "summary.json").read_text())
    assert set(summary["families"]) == {"narrow_fov", "false_uav_clutter", "all"}
    results = json.loads((tmp_path / "bench" / "results" / "tinyworlds-test.json").read_text())
    assert results["kind"] == "worlds" and results["episode_error_m"] == 300.0
    assert set(results["families"]["all"]) == {"paper", "tracker", "radar"}
    new = readme.read_text()
    assert "old" not in new and "| all 2 families | tracker |" in new
    assert "| false_uav_clutter | radar |" in new  # the radar's own track, per family
    assert "`uav_fusion bench --definition tinyworlds --profiles paper tracker`" in new
    # a sweep on the tune half, one family
    spec = spec_from_dict(
        {"definition": str(definition), "profiles": ["tracker"], "families": ["calibrated"],
         "parameters": {"motion.q": [1.0, 2.0]}},
        tmp_path / "sweep.yaml",
    )  # fmt: skip
    tasks = sweep_tasks(spec, cache, SITE_FILE, load_site())
    assert len(tasks) == 2 and {t.flight.flight.family for t in tasks} == {"calibrated"}
    with pytest.raises(ConfigError, match=r"'narrow_fov' is not a family of the tune half"):
        spec_from_dict({"definition": str(definition), "profiles": ["tracker"],
                        "families": ["narrow_fov"]}, tmp_path / "sweep.yaml")  # fmt: skip


def test_longest_run_counts_consecutive_epochs() -> None:
    assert longest_run(np.zeros(0, dtype=bool)) == 0
    assert longest_run(np.array([False, False])) == 0
    flags = np.array([True, False, True, True, True, False, True, True])
    assert longest_run(flags) == 3
    assert longest_run(np.ones(5, dtype=bool)) == 5


def test_the_true_mount_of_a_folder_without_one_is_unknown_and_a_bad_one_is_named(
    tmp_path: Path,
) -> None:
    """A recorded flight (no manifest) and an older twin manifest (no mount) have no true
    mount, so registration is not scored; a manifest that is not JSON, or whose mount is not
    a number, stops with the file named."""
    assert true_mount_az(tmp_path) is None
    man = tmp_path / MANIFEST
    man.write_text(json.dumps({"generator": "uav_fusion digital twin", "seed": 1}))
    assert true_mount_az(tmp_path) is None
    man.write_text(json.dumps({"radar_mount": {"az_bias_deg": 0.25, "el_bias_deg": 0.1}}))
    assert true_mount_az(tmp_path) == 0.25
    man.write_text(json.dumps({"radar_mount": {"az_bias_deg": "left"}}))
    with pytest.raises(DataError, match=r"twin_manifest\.json: radar_mount\.az_bias_deg"):
        true_mount_az(tmp_path)
    man.write_text("{not json")
    with pytest.raises(DataError, match=r"twin_manifest\.json: unreadable twin manifest"):
        true_mount_az(tmp_path)
