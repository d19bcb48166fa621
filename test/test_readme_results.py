"""The README's benchmark tables are the ones rendered from the committed results files.

``uav_fusion bench --readme`` writes ``bench/results/<definition>-<split>.json`` and the
README block rendered from it; editing one without the other fails here.
"""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from uav_fusion.core.bench.results import (
    RESULTS_DIR,
    block_names,
    load_results,
    read_block,
    render_block,
    replace_block,
    results_doc,
)

ROOT = Path(__file__).resolve().parent.parent
README = ROOT / "README.md"


def test_every_readme_table_is_rendered_from_its_results_file() -> None:
    text = README.read_text(encoding="utf-8")
    names = block_names(text)
    assert {"accuracy-test", "multi-test"} <= set(names)
    for name in names:
        path = ROOT / RESULTS_DIR / f"{name}.json"
        assert path.is_file(), f"README block bench:{name} has no results file {path}"
        assert read_block(text, name) == render_block(load_results(path)), (
            f"README block bench:{name} differs from {path}: run the command it names "
            "with --readme"
        )


def test_every_results_file_has_its_readme_table() -> None:
    names = set(block_names(README.read_text(encoding="utf-8")))
    for path in sorted((ROOT / RESULTS_DIR).glob("*.json")):
        assert path.stem in names, f"{path} is shown nowhere in the README"
        doc = load_results(path)
        assert doc["name"] == path.stem and doc["split"] == "test"


def test_a_block_is_replaced_between_its_markers_only() -> None:
    prov = {"date": "2026-01-02 03:04 UTC", "split": "test", "flights": 2, "versions": {"x": "1"}}
    doc = results_doc(
        "multi",
        "m-test",
        "uav_fusion bench --definition m --profiles tracker",
        prov,
        {"tracker": {"profile": "tracker", "flights": 2, "gospa_mean_m": 12.34, "run_s": 9.9,
                     "coverage_pct": math.nan}},
    )  # fmt: skip
    assert doc["date"] == "2026-01-02" and "run_s" not in doc["profiles"]["tracker"]
    assert doc["profiles"]["tracker"]["coverage_pct"] is None
    block = "<!-- bench:m-test:begin -->\nnew\n<!-- bench:m-test:end -->"
    text = "a\n<!-- bench:m-test:begin -->\nold\n<!-- bench:m-test:end -->\nb\n"
    assert replace_block(text, "m-test", block) == f"a\n{block}\nb\n"
    assert read_block(f"a\n{block}\nb\n", "m-test") == block
    assert block_names(text) == ["m-test"]
    with pytest.raises(ValueError, match="markers"):
        replace_block("no markers", "m-test", block)
    with pytest.raises(ValueError, match="unknown benchmark kind"):
        results_doc("other", "m-test", "x", prov, {})
