"""The accuracy benchmark: definition checks, the flight cache, the command end to end."""

from __future__ import annotations

import csv
import json
import pickle
import types
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml

from uav_fusion.cli import main
from uav_fusion.core.bench.cache import LABELS_FILE, cached_flights, generate_flight, read_labels
from uav_fusion.core.bench.definition import load_definition
from uav_fusion.core.bench.single import GenerateTask, ScoreTask, generate_task, score_task
from uav_fusion.core.errors import ConfigError
from uav_fusion.core.estimators import load_profile
from uav_fusion.core.site import load_site
from uav_fusion.core.twin.trajectory import load_flight_plan
from uav_fusion.resources import DEFAULT_SITE, config_path

SITE_FILE = config_path(DEFAULT_SITE)
ROOT = Path(__file__).resolve().parent.parent


def write_def(tmp_path: Path, doc: dict[str, object], name: str = "def.yaml") -> Path:
    p = tmp_path / name
    p.write_text(yaml.safe_dump(doc), encoding="utf-8")
    return p


def tiny(**changes: object) -> dict[str, object]:
    doc: dict[str, object] = {
        "name": "tiny",
        "plans": ["zigzag_dash"],
        "splits": {"tune": [3], "test": [4, 5]},
        "duration_s": 60.0,
    }
    doc.update(changes)
    return doc


def test_the_shipped_definition_has_16_flights_per_half_without_the_default_flight() -> None:
    d = load_definition()
    assert len(d.plans) == 8
    tune, test = d.flights("tune"), d.flights("test")
    assert len(tune) == len(test) == 16
    ids = {f.flight_id for f in tune} | {f.flight_id for f in test}
    assert len(ids) == 32
    assert "lake_wheeler_default-s1" not in ids
    assert not {f.seed for f in tune} & {f.seed for f in test}
    site = load_site()
    single = {
        p.stem
        for p in config_path("waypoints").glob("*.yaml")
        if not load_flight_plan(p, site).others
    }
    assert {p.name for p in d.plans} == single
    assert d.grid_hz == 10.0 and d.settings.gross_error_m == 100.0


@pytest.mark.parametrize(
    ("changes", "message"),
    [
        ({"plans": ["zigzag_dash", "no_such_plan"]}, r"plans\[1\]: unknown plan 'no_such_plan'"),
        ({"splits": {"tune": [3, 4], "test": [4, 5]}}, r"splits.test: seed\(s\) 4 also in"),
        (
            {"plans": ["lake_wheeler_default"], "splits": {"tune": [1], "test": [2]}},
            r"splits.tune: seed 1 with plan 'lake_wheeler_default' is the default flight",
        ),
        ({"seeds": [1]}, r"unknown key 'seeds'"),
        ({"scoring": {"grid_hz": 10, "gross_m": 50}}, r"unknown key 'scoring.gross_m'"),
        ({"splits": {"tune": [3], "test": [4], "val": [6]}}, r"unknown key 'splits.val'"),
        ({"splits": {"tune": [3]}}, r"splits.test is missing"),
        ({"splits": {"tune": [3], "test": ["x"]}}, r"splits.test\[0\] must be an integer"),
        ({"scoring": {"grid_hz": 0}}, r"grid_hz must be > 0"),
        ({"scoring": {"excuse_grounded": "yes"}}, r"excuse_grounded must be true or false"),
        ({"plans": "zigzag_dash"}, r"plans must be a non-empty list"),
        ({"twin_config": "missing.yaml"}, r"twin_config: file .*missing.yaml not found"),
    ],
)
def test_bad_definitions_stop_naming_the_file_and_key(
    tmp_path: Path, changes: dict[str, object], message: str
) -> None:
    p = write_def(tmp_path, tiny(**changes))
    with pytest.raises(ConfigError, match=message) as info:
        load_definition(p)
    assert str(p) in str(info.value)


def test_cached_flights_are_deterministic_and_keyed_by_their_inputs(tmp_path: Path) -> None:
    site = load_site()
    d = load_definition(write_def(tmp_path, tiny(duration_s=40.0)))
    a = cached_flights(d, "tune", tmp_path / "a", SITE_FILE)[0]
    b = cached_flights(d, "tune", tmp_path / "b", SITE_FILE)[0]
    assert a.key == b.key and a.folder.name == b.folder.name
    assert generate_flight(a, d, site) == (a.folder, True)
    assert generate_flight(a, d, site) == (a.folder, False)  # cached
    generate_flight(b, d, site)
    files = sorted(p.name for p in a.folder.iterdir())
    assert LABELS_FILE in files and len(files) == 5
    for name in files:
        assert (a.folder / name).read_bytes() == (b.folder / name).read_bytes(), name
    assert not list((tmp_path / "a").glob(".tmp-*"))
    labels = read_labels(a.folder)
    assert labels.size > 0 and np.all(np.diff(labels) >= 0)
    # another seed, duration, plan file or twin configuration: another key
    keys = {a.key, cached_flights(d, "test", tmp_path / "a", SITE_FILE)[0].key}
    d2 = load_definition(write_def(tmp_path, tiny(duration_s=41.0), "d2.yaml"))
    keys.add(cached_flights(d2, "tune", tmp_path, SITE_FILE)[0].key)
    twin = tmp_path / "twin.yaml"
    twin.write_text(config_path("twin_default.yaml").read_text() + "\n# changed\n")
    d3 = load_definition(write_def(tmp_path, tiny(duration_s=40.0, twin_config=str(twin)), "d3"))
    keys.add(cached_flights(d3, "tune", tmp_path, SITE_FILE)[0].key)
    plan = tmp_path / "zigzag_dash.yaml"
    plan.write_text(config_path("waypoints/zigzag_dash.yaml").read_text() + "\n# changed\n")
    d4 = load_definition(write_def(tmp_path, tiny(duration_s=40.0, plans=[str(plan)]), "d4"))
    keys.add(cached_flights(d4, "tune", tmp_path, SITE_FILE)[0].key)
    assert len(keys) == 5


def test_bench_command_end_to_end(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Two short flights, the paper profile and a second profile file, one thread worker."""
    definition = write_def(tmp_path, tiny())
    other = tmp_path / "fast_q.yaml"
    doc = load_profile("paper").as_dict()
    doc["name"] = "paper_q8"
    doc["motion"]["q"] = [8.0, 8.0, 8.0]
    other.write_text(yaml.safe_dump(doc), encoding="utf-8")
    out, cache = tmp_path / "out", tmp_path / "cache"
    argv = [
        "bench", "--definition", str(definition), "--profiles", "paper", str(other),
        "--out", str(out), "--cache", str(cache), "--workers", "1", "--threads",
    ]
    assert main(argv) == 0
    text = capsys.readouterr().out
    assert "2 flights cached, 0 to generate" not in text
    assert "0 flights cached, 2 to generate" in text
    table = text[text.index("pooled over 2 test flights") :]
    assert "\npaper " in table and "\npaper_q8 " in table and "\nradar " in table
    # each profile against the radar's own track, on the epochs both cover
    assert "  paper: mean error at most the radar's own track's on " in text
    assert "  paper_q8: mean error at most the radar's own track's on " in text
    assert "commit:" in text and "dask 2026.8.0" in text and "wall time" in text
    with (out / "per_flight.csv").open() as fh:
        rows = list(csv.DictReader(fh))
    assert sorted((r["profile"], r["flight"]) for r in rows) == [
        ("paper", "zigzag_dash-s4"), ("paper", "zigzag_dash-s5"),
        ("paper_q8", "zigzag_dash-s4"), ("paper_q8", "zigzag_dash-s5"),
        ("radar", "zigzag_dash-s4"), ("radar", "zigzag_dash-s5"),
    ]
    radar_row = next(r for r in rows if r["profile"] == "radar")
    assert radar_row["anees"] == "" and radar_row["registration_az_deg"] == ""
    assert (out / "bench_accuracy.png").stat().st_size > 10_000
    assert (out / "bench_vs_radar.png").stat().st_size > 10_000
    summary = json.loads((out / "summary.json").read_text())
    assert summary["provenance"]["split"] == "test"
    assert set(summary["pooled"]) == {"paper", "paper_q8", "radar"}
    assert summary["pooled"]["radar"]["anees"] is None  # the radar's track has no covariance
    vs = summary["against_radar"]
    assert set(vs) == {"paper", "paper_q8"}
    per = vs["paper"]["per_flight"]
    assert set(per) == {"zigzag_dash-s4", "zigzag_dash-s5"}
    assert vs["paper"]["flights"] == sum(f["epochs"] > 0 for f in per.values()) >= 1
    md = (out / "table.md").read_text().splitlines()
    assert md[2].startswith("| paper |") and md[3].startswith("| paper_q8 |")
    assert md[4].startswith("| radar |") and md[5] == ""
    assert [x.split(" | ")[1] for x in md[8:14]] == ["zigzag_dash-s4", "zigzag_dash-s5"] * 3
    assert md[14] == "" and md[15].startswith("| profile | flight | epochs both cover |")
    assert [x.split(" | ")[:2] for x in md[17:]] == [
        ["| paper", "zigzag_dash-s4"], ["| paper", "zigzag_dash-s5"],
        ["| paper_q8", "zigzag_dash-s4"], ["| paper_q8", "zigzag_dash-s5"],
    ]
    # the command's figures are the task's, computed here directly
    d = load_definition(definition)
    cf = cached_flights(d, "test", cache, SITE_FILE)[0]
    r = score_task(ScoreTask(cf, load_profile("paper"), load_site(), d.grid_hz, d.settings))
    row = next(x for x in rows if x["profile"] == "paper" and x["flight"] == cf.flight_id)
    assert int(row["epochs"]) == r.samples.epochs > 0
    cov = 100 * r.samples.covered / r.samples.epochs
    assert float(row["coverage_pct"]) == pytest.approx(cov, abs=1e-4)
    assert r.registration is None  # the paper profile does not register the radar
    # warm cache: nothing generated again
    assert main(argv) == 0
    assert "2 flights cached, 0 to generate" in capsys.readouterr().out
    # the tracker registers the radar; a plain twin flight's manifest holds the true mount
    # (the twin's default, 0.5 deg), so the bench scores it as it does a world's
    rt = score_task(ScoreTask(cf, load_profile("tracker"), load_site(), d.grid_hz, d.settings))
    assert rt.registration is not None and rt.registration.true_deg == 0.5
    assert main([*argv[:4], "tracker", *argv[6:]]) == 0
    text = capsys.readouterr().out
    line = next(x for x in text.splitlines() if "tracker: azimuth within 0.1 deg" in x)
    assert "of the true mount, or within the flight's bound, on " in line
    assert " of 2 flights (" in line
    # --readme: the results file beside the README, and the README's table rendered from it
    readme = tmp_path / "README.md"
    begin, end = "<!-- bench:tiny-test:begin -->", "<!-- bench:tiny-test:end -->"
    readme.write_text(f"# x\n{begin}\nold\n{end}\nafter\n")
    assert main([*argv, "--readme", str(readme)]) == 0
    new = readme.read_text()
    assert "old" not in new and new.endswith(f"{end}\nafter\n")
    assert "`uav_fusion bench --definition tiny --profiles paper " in new and md[2] in new
    results = json.loads((tmp_path / "bench" / "results" / "tiny-test.json").read_text())
    assert results["kind"] == "accuracy"
    assert set(results["profiles"]) == {"paper", "paper_q8", "radar"}
    assert "commit" not in json.dumps(results) and "seconds" not in results["profiles"]["paper"]
    # a README without the run's markers is refused before anything runs
    readme.write_text("# x\n")
    assert main([*argv, "--readme", str(readme)]) == 2


def test_bench_command_rejects_duplicate_profile_names(tmp_path: Path) -> None:
    definition = write_def(tmp_path, tiny())
    argv = ["bench", "--definition", str(definition), "--profiles", "paper", "paper",
            "--out", str(tmp_path / "o"), "--cache", str(tmp_path / "c")]
    assert main(argv) == 2


def test_bench_command_refuses_a_profile_named_like_the_baseline(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The radar's own track is the row ``radar``: a profile of that name would share it."""
    definition = write_def(tmp_path, tiny())
    prof = tmp_path / "radar.yaml"
    prof.write_text("extends: paper\nname: radar\n", encoding="utf-8")
    argv = ["bench", "--definition", str(definition), "--profiles", str(prof),
            "--out", str(tmp_path / "o"), "--cache", str(tmp_path / "c")]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert f"{prof}: the profile name 'radar' is the benchmark's baseline" in err
    assert not (tmp_path / "c").exists()  # refused before any flight was generated


def test_tasks_and_results_pickle_for_worker_processes(tmp_path: Path) -> None:
    """Worker processes receive tasks and return results by pickle (module-level types)."""
    d = load_definition(write_def(tmp_path, tiny(duration_s=30.0)))
    site = load_site()
    cf = cached_flights(d, "tune", tmp_path / "cache", SITE_FILE)[0]
    gen = GenerateTask(cf, d, site)
    assert pickle.loads(pickle.dumps(gen)).flight == cf
    assert generate_task(pickle.loads(pickle.dumps(gen))) is True
    task = ScoreTask(cf, load_profile("paper"), site, d.grid_hz, d.settings)
    res = score_task(pickle.loads(pickle.dumps(task)))
    back = pickle.loads(pickle.dumps(res))
    assert back.flight_id == res.flight_id == "zigzag_dash-s3"
    np.testing.assert_array_equal(back.samples.errors, res.samples.errors)


def test_bench_runs_on_an_existing_scheduler(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from distributed import LocalCluster

    definition = write_def(tmp_path, tiny(duration_s=30.0, splits={"tune": [3], "test": [4]}))
    with LocalCluster(n_workers=1, processes=False, dashboard_address=None) as cluster:
        argv = [
            "bench", "--definition", str(definition), "--out", str(tmp_path / "o"),
            "--cache", str(tmp_path / "c"), "--scheduler", cluster.scheduler_address,
            "--no-figure",
        ]
        assert main(argv) == 0
    text = capsys.readouterr().out
    assert f"Dask scheduler {cluster.scheduler_address} (1 workers)" in text
    with (tmp_path / "o" / "per_flight.csv").open() as fh:
        rows = [(r["profile"], r["flight"]) for r in csv.DictReader(fh)]
    assert rows == [("paper", "zigzag_dash-s4"), ("radar", "zigzag_dash-s4")]


def test_registration_is_judged_against_the_true_mount_within_the_tolerance_or_the_bound() -> None:
    from uav_fusion.core.bench.report import registration_lines
    from uav_fusion.core.bench.single import RegistrationOutcome

    assert RegistrationOutcome(0.5, 0.02, 0.05, None).within(0.1) is None  # no true mount
    assert RegistrationOutcome(0.59, 0.02, 0.05, 0.5).within(0.1)  # within 0.1 deg
    assert not RegistrationOutcome(0.61, 0.02, 0.05, 0.5).within(0.1)
    assert RegistrationOutcome(0.79, 0.1, 0.3, 0.5).within(0.1)  # within its wider bound
    assert not RegistrationOutcome(0.81, 0.1, 0.3, 0.5).within(0.1)
    assert RegistrationOutcome(0.99, 0.1, 0.3, 0.5).within(0.1, 1.645)  # 0.49 <= 0.4935
    assert not RegistrationOutcome(1.0, 0.1, 0.3, 0.5).within(0.1, 1.645)

    def result(reg: RegistrationOutcome | None) -> Any:
        return types.SimpleNamespace(profile="tracker", registration=reg)

    lines = registration_lines([
        result(RegistrationOutcome(0.55, 0.02, 0.05, 0.5)),
        result(RegistrationOutcome(0.79, 0.1, 0.3, 0.5)),
        result(RegistrationOutcome(0.81, 0.1, 0.3, 0.5)),
        result(RegistrationOutcome(0.8, 0.1, 0.3, None)),  # not a world flight: not counted
        result(None),
    ])
    assert lines == [
        "tracker: azimuth within 0.1 deg of the true mount, or within the flight's bound, on 2 of "
        "3 flights (1 within 0.1 deg; within 1.645 bounds on 3); bound median 0.30 deg, "
        "0.05-0.30"
    ]
