"""``uav_fusion sweep``: spec checks, failure isolation, re-runs that compute only what is
missing, and results keyed by the tasks' inputs."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import pytest
import yaml

from uav_fusion.cli import main
from uav_fusion.core.bench.cache import core_source_digest
from uav_fusion.core.bench.sweep import (
    combo_label,
    load_spec,
    run_sweep_task,
    sweep_tasks,
    task_key,
)
from uav_fusion.core.bench.sweep_figure import write_figure
from uav_fusion.core.errors import ConfigError
from uav_fusion.core.site import load_site
from uav_fusion.resources import DEFAULT_SITE, config_path

SITE_FILE = config_path(DEFAULT_SITE)


def _write(path: Path, doc: object) -> Path:
    path.write_text(yaml.safe_dump(doc), encoding="utf-8")
    return path


def _setup(tmp_path: Path, **changes: object) -> Path:
    """A 40 s two-flight definition and a sweep of q over it with the paper profile."""
    definition = _write(
        tmp_path / "tiny.yaml",
        {
            "name": "tiny",
            "plans": ["zigzag_dash", "hover_notch"],
            "splits": {"tune": [3, 4], "test": [5]},
            "duration_s": 40.0,
        },
    )
    spec: dict[str, object] = {
        "name": "tiny_q",
        "definition": str(definition),
        "split": "tune",
        "plans": ["zigzag_dash"],
        "profiles": ["paper"],
        "parameters": {"motion.q": [1.0, 4.0]},
    }
    spec.update(changes)
    return _write(tmp_path / "spec.yaml", spec)


@pytest.mark.parametrize(
    ("changes", "message"),
    [
        ({"parameters": {"qq": [1.0]}}, r"spec.yaml: parameters.qq: unknown parameter"),
        ({"parameters": {"q": [1.0]}}, r"spec.yaml: parameters.q: unknown parameter .*'q' is at "
         r"motion.q"),
        ({"parameters": {"measurement.radar.R": [1.0]}}, r"parameters.measurement.radar.R: "
         r"unknown parameter"),
        ({"profiles": ["no_such_profile"]}, r"spec.yaml: profiles: unknown profile 'no_such"),
        ({"plans": ["no_such_plan"]}, r"spec.yaml: plans: unknown plan 'no_such_plan'"),
        ({"seeds": [5]}, r"spec.yaml: seeds: seed 5 is not in the tune half"),
        ({"colour": "red"}, r"spec.yaml: unknown key\(s\) colour"),
        ({"split": "train"}, r"spec.yaml: split: one of tune, test expected"),
        ({"parameters": {"motion.q": "fast"}}, r"spec.yaml: parameters.motion.q: a non-empty "),
        ({"parameters": {"gating.nis_probability": [0.9, "high"]}},
         r"spec.yaml: parameters: gating.nis_probability must be a number in \(0, 1\), got 'high'"),
        ({"parameters": {"motion.q": [-1.0]}}, r"spec.yaml: parameters: motion.q must be a "),
        ({"parameters": {"track.confirm_m": [9]}},
         r"spec.yaml: parameters \{'track.confirm_m': 9\}: .*paper.yaml: track.confirm_m and "),
        ({"metric": "happiness"}, r"spec.yaml: metric: one of"),
        ({"mode": "random"}, r"spec.yaml: mode: one of grid, one_at_a_time expected, got 'random'"),
    ],
)
def test_bad_specs_stop_with_the_file_and_key(
    tmp_path: Path, changes: dict[str, object], message: str
) -> None:
    with pytest.raises(ConfigError, match=message):
        load_spec(_setup(tmp_path, **changes))


def test_the_shipped_example_spec_is_valid_and_uses_tune_flights_only() -> None:
    spec = load_spec(Path(__file__).resolve().parent.parent / "bench" / "sweep_q.yaml")
    assert spec.split == "tune"
    assert set(spec.seeds) == set(spec.definition.splits["tune"])
    assert len(spec.combinations()) == 6


def test_one_at_a_time_varies_each_parameter_alone_against_the_profile_as_it_is(
    tmp_path: Path,
) -> None:
    params = {"motion.q": [1.0, 4.0], "gating.nis_probability": [0.9]}
    grid = load_spec(_setup(tmp_path, parameters=params))
    assert len(grid.combinations()) == 2
    spec = load_spec(_setup(tmp_path, parameters=params, mode="one_at_a_time"))
    combos = spec.combinations()
    assert combos[0] == {}  # the profile as it is, then each value alone
    assert sorted(map(repr, combos[1:])) == sorted(map(repr, [
        {"motion.q": (1.0, 1.0, 1.0)}, {"motion.q": (4.0, 4.0, 4.0)},
        {"gating.nis_probability": 0.9},
    ]))
    tasks = sweep_tasks(spec, tmp_path / "cache", SITE_FILE, load_site(SITE_FILE))
    assert len(tasks) == 2 * 4 and len({t.key for t in tasks}) == 8
    labels = [combo_label(c) for c in combos]
    assert labels[0] == "-" and "gating.nis_probability=0.9" in labels
    assert combo_label({"update.robust": "none", "smoother.lag_s": None}) == (
        "update.robust=none, smoother.lag_s=null")
    # the figure: a bar per changed setting, its change against the profile as it is
    rows = [{"profile": "paper", "flight": f, "params": c, "err_mean_m": 10.0 + i}
            for i, c in enumerate(combos) for f in ("a", "b")]
    out = write_figure(rows, spec, tmp_path / "sweep.png")
    assert out is not None and out.stat().st_size > 1000


def test_the_shipped_rule_ablations_are_valid_and_use_tune_flights_only() -> None:
    bench = Path(__file__).resolve().parent.parent / "bench"
    for name in ("ablate_accuracy.yaml", "ablate_worlds.yaml"):
        spec = load_spec(bench / name)
        assert spec.split == "tune" and spec.mode == "one_at_a_time"
        assert len(spec.combinations()) == 1 + sum(len(v) for v in spec.parameters.values())


def test_task_keys_follow_the_inputs(tmp_path: Path) -> None:
    spec = load_spec(_setup(tmp_path))
    site = load_site(SITE_FILE)
    a = sweep_tasks(spec, tmp_path / "cache", SITE_FILE, site)
    assert len(a) == 2 * 2  # 2 seeds x 2 values of q
    assert len({t.key for t in a}) == 4
    b = sweep_tasks(spec, tmp_path / "cache", SITE_FILE, site)
    assert [t.key for t in a] == [t.key for t in b]  # same inputs, same keys
    spec2 = load_spec(_setup(tmp_path, parameters={"motion.q": [1.0, 5.0]}))
    c = sweep_tasks(spec2, tmp_path / "cache", SITE_FILE, site)
    assert a[0].key == c[0].key and a[1].key != c[1].key  # only the changed value differs


def test_task_keys_change_with_the_core_source(tmp_path: Path) -> None:
    # a result computed by other code is not reused: the key holds the core's source digest
    root = tmp_path / "core"
    (root / "estimators").mkdir(parents=True)
    (root / "estimators" / "tracker.py").write_text("GATE = 1\n")
    (root / "notes.txt").write_text("not source")
    d1 = core_source_digest(root)
    (root / "notes.txt").write_text("changed, still not source")
    assert core_source_digest(root) == d1
    (root / "estimators" / "tracker.py").write_text("GATE = 2\n")
    d2 = core_source_digest(root)
    assert d2 != d1
    (root / "estimators" / "tracker.py").write_text("GATE = 1\n")
    assert core_source_digest(root) == d1
    spec = load_spec(_setup(tmp_path))
    site = load_site(SITE_FILE)
    task = sweep_tasks(spec, tmp_path / "cache", SITE_FILE, site)[0]
    keys = {task_key(task.flight, task.profile_path, task.params, spec.definition, d)
            for d in (d1, d2, core_source_digest())}  # fmt: skip
    assert len(keys) == 3 and task.key in keys


def test_a_failing_task_is_reported_and_a_rerun_computes_only_what_is_missing(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    spec_file = _setup(tmp_path)
    out, cache = tmp_path / "out", tmp_path / "cache"
    argv = ["sweep", str(spec_file), "--out", str(out), "--cache", str(cache),
            "--workers", "1", "--threads", "--no-figure"]
    assert main(argv) == 0
    text = capsys.readouterr().out
    assert "4 tasks; 0 stored" in text and "4 to run" in text
    store = out / "results.jsonl"
    rows = [json.loads(x) for x in store.read_text().splitlines()]
    assert len(rows) == 4 and all(r["epochs"] > 0 for r in rows)

    # an interrupted run: the seed-4 results are lost (one line cut in half), and the seed-4
    # flight in the cache is damaged, so its tasks fail
    keep = [r for r in rows if r["seed"] == 3]
    lost = [r for r in rows if r["seed"] == 4]
    store.write_text(
        "".join(json.dumps(r) + "\n" for r in keep) + json.dumps(lost[0])[:40], encoding="utf-8"
    )
    folder4 = next(p for p in cache.iterdir() if p.name.startswith("zigzag_dash-s4-"))
    for radar in folder4.glob("radar_data_*.json"):
        radar.unlink()
    assert main(argv) == 1
    text = capsys.readouterr().out
    assert "4 tasks; 2 stored" in text and "2 to run" in text
    assert text.count("FAILED: paper {'motion.q': ") == 2 and "zigzag_dash-s4" in text
    failures = json.loads((out / "failures.json").read_text())
    assert {(f["flight"], tuple(f["params"]["motion.q"])) for f in failures} == {
        ("zigzag_dash-s4", (1.0, 1.0, 1.0)), ("zigzag_dash-s4", (4.0, 4.0, 4.0))}
    assert all("radar" in f["error"] for f in failures)
    with (out / "results.csv").open() as fh:
        assert len(list(csv.DictReader(fh))) == 2  # the seed-3 results survived

    # repaired (the damaged flight regenerated): only the two missing tasks run, and the
    # stored ones are not recomputed
    for p in folder4.iterdir():
        p.unlink()
    folder4.rmdir()
    assert main(argv) == 0
    text = capsys.readouterr().out
    assert "4 tasks; 2 stored" in text and "2 to run" in text and "failures: 0" in text
    final = {json.loads(x)["key"]: json.loads(x) for x in store.read_text().splitlines()[2:]}
    assert len(final) == 2
    again = {r["key"]: r for r in lost}
    for key, row in final.items():  # the regenerated flight scores exactly as before
        for k in ("epochs", "coverage_pct", "err_mean_m", "err_max_m", "anees"):
            assert json.dumps(row[k]) == json.dumps(again[key][k])  # (NaN == NaN here)
    with (out / "results.csv").open() as fh:
        table = list(csv.DictReader(fh))
    assert sorted((r["seed"], r["motion.q"]) for r in table) == [
        ("3", "1 1 1"), ("3", "4 4 4"), ("4", "1 1 1"), ("4", "4 4 4")]


def test_run_sweep_task_never_raises(tmp_path: Path) -> None:
    spec = load_spec(_setup(tmp_path))
    task = sweep_tasks(spec, tmp_path / "cache", SITE_FILE, load_site(SITE_FILE))[0]
    broken = type(task)(**{**task.__dict__, "profile_path": tmp_path / "gone.yaml"})
    row = run_sweep_task(broken)
    assert row["error"] and "gone.yaml" in row["error"]
    assert row["flight"] == task.flight.flight_id and row["params"] == task.params


def _multi_setup(tmp_path: Path, **changes: object) -> Path:
    """A 200 s one-flight multi-UAV definition and a sweep of the publication window."""
    definition = _write(
        tmp_path / "multi_tiny.yaml",
        {
            "name": "multi_tiny",
            "targets": "multi",
            "plans": ["multi_crossing_pair"],
            "splits": {"tune": [3], "test": [4]},
            "duration_s": 200.0,
        },
    )
    spec: dict[str, object] = {
        "name": "multi_tiny_window",
        "definition": str(definition),
        "profiles": ["tracker"],
        "parameters": {"multi.output_coast_s": [0.0, 3.0]},
    }
    spec.update(changes)
    return _write(tmp_path / "multi_spec.yaml", spec)


@pytest.mark.parametrize(
    ("changes", "message"),
    [
        ({"parameters": {"multi.merge_gap": [1.0]}},
         r"multi_spec.yaml: parameters.multi.merge_gap: unknown parameter"),
        ({"parameters": {"multi.merge_s": [1.0, -2.0]}},
         r"multi_spec.yaml: parameters: multi.merge_s must be a number >= 0, got -2.0"),
        ({"parameters": {"sources.radar": [1]}}, r"sources.radar must be true or false"),
        ({"parameters": {"multi.merge_s": []}}, r"parameters.multi.merge_s: a non-empty list"),
        ({"metric": "err_max_m"}, r"multi_spec.yaml: metric: one of gospa_mean_m, "),
    ],
)
def test_bad_multi_sweeps_stop_with_the_file_and_key(
    tmp_path: Path, changes: dict[str, object], message: str
) -> None:
    with pytest.raises(ConfigError, match=message):
        load_spec(_multi_setup(tmp_path, **changes))


def test_a_multi_setting_needs_a_multi_uav_definition(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match=r"spec.yaml: parameters.multi.merge_s: a multi-UAV "
                       r"tracker setting needs a multi-UAV definition"):
        load_spec(_setup(tmp_path, parameters={"multi.merge_s": [1.0]}))


def test_the_shipped_multi_example_spec_is_valid_and_uses_tune_flights_only() -> None:
    spec = load_spec(Path(__file__).resolve().parent.parent / "bench" / "sweep_multi.yaml")
    assert spec.definition.multi and spec.split == "tune" and spec.metric == "gospa_mean_m"
    assert set(spec.seeds) == set(spec.definition.splits["tune"])
    assert len(spec.combinations()) == 9


def test_a_multi_uav_sweep_scores_each_setting_as_the_multi_benchmark_does(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The profile's multi section is what the sweep varies: a track published only at the
    instant of its update (window 0 s) covers almost nothing on the 1 Hz grid, one published
    for 3 s covers the UAVs; the rows carry the multi-UAV benchmark's figures, and the
    coverage / false-track figure is drawn."""
    spec_file = _multi_setup(tmp_path)
    out, cache = tmp_path / "out", tmp_path / "cache"
    argv = ["sweep", str(spec_file), "--out", str(out), "--cache", str(cache),
            "--workers", "1", "--threads"]
    assert main(argv) == 0
    text = capsys.readouterr().out
    assert "2 tasks; 0 stored" in text and "coverage % / false-track time % / GOSPA m" in text
    rows = {r["params"]["multi.output_coast_s"]: r
            for r in map(json.loads, (out / "results.jsonl").read_text().splitlines())}
    assert set(rows) == {0.0, 3.0}
    assert rows[0.0]["coverage_pct"] < 20.0 < 80.0 < rows[3.0]["coverage_pct"]
    assert rows[0.0]["gospa_mean_m"] > rows[3.0]["gospa_mean_m"]
    assert rows[3.0]["crossings"] >= 1 and "err_max_m" not in rows[3.0]
    with (out / "results.csv").open() as fh:
        table = list(csv.DictReader(fh))
    assert {r["multi.output_coast_s"] for r in table} == {"0", "3"}
    assert "false_track_pct" in table[0]
    assert (out / "tradeoff.png").stat().st_size > 10_000 and (out / "sweep.png").is_file()
