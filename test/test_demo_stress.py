"""``uav_fusion demo``'s stress part: the benchmark's own figures for one flight, side by side."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path
from typing import Any

import pytest
import yaml

from uav_fusion.commands.stress_flight import (
    STRESS_DEFINITION,
    STRESS_PLAN,
    STRESS_SEED,
    compare_on_stress_flight,
    explain,
    format_stress,
)
from uav_fusion.core.bench.definition import load_definition
from uav_fusion.core.bench.single import ScoreTask, score_task
from uav_fusion.core.estimators import load_profile
from uav_fusion.core.scoring.fixed_rate import GridScore, pool
from uav_fusion.core.site import load_site


def test_the_stress_flight_is_in_the_benchmarks_test_half() -> None:
    d = load_definition(STRESS_DEFINITION)
    assert STRESS_PLAN in [p.name for p in d.plans] and STRESS_SEED in d.splits["test"]


def test_both_profiles_are_scored_as_the_benchmark_scores_them(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    doc = {
        "name": "tiny",
        "plans": [STRESS_PLAN],
        "splits": {"tune": [3], "test": [4]},
        "duration_s": 40.0,
    }
    definition = tmp_path / "tiny.yaml"
    definition.write_text(yaml.safe_dump(doc), encoding="utf-8")
    cache = tmp_path / "cache"
    cf, scores = compare_on_stress_flight(cache, definition=definition, seed=4)
    out = capsys.readouterr().out
    assert "generating zigzag_dash-s4 with the digital twin" in out and cf.exists()
    assert list(scores) == ["paper", "tracker"]
    d = load_definition(definition)
    ref = score_task(ScoreTask(cf, load_profile("tracker"), load_site(), d.grid_hz, d.settings))
    assert scores["tracker"] == pool([ref.samples], d.settings)
    compare_on_stress_flight(cache, definition=definition, seed=4, profiles=["paper"])
    assert "from the flight cache" in capsys.readouterr().out  # generated once


def _score(**changes: float) -> GridScore:
    # every field zero (counts and measures alike), then the changes
    fields: dict[str, Any] = {f.name: 0 for f in dataclasses.fields(GridScore)}
    fields.update({"anees": math.nan, **changes})
    return GridScore(**fields)


def test_the_table_and_its_explanation_say_only_what_the_figures_show() -> None:
    locked = _score(gross_pct=84.0, gross_age_p50_s=0.1, err_mean_m=305.9)
    good = _score(gross_pct=1.9, err_mean_m=35.2)
    table = format_stress({"paper": locked, "tracker": good})
    assert "305.9" in table and "35.2" in table and "ANEES" in table
    assert "clutter" in explain({"paper": locked, "tracker": good})
    assert "clutter site" not in explain({"paper": good, "tracker": good})
