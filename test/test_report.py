"""Report writer: Markdown table, CSV/JSON metrics, PNG figures that decode and show data."""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from uav_fusion.core.scoring.evaluation import ROWS, Evaluation, Evaluator
from uav_fusion.core.scoring.report import CSV_FIELDS, FIGURE_TITLES, markdown_table, write_report
from uav_fusion.core.site import Site, load_site

T0 = 1_760_000_000.0


def synthetic(site: Site, with_rcs: bool = True) -> Evaluation:
    """A loop around the site: radar noise grows with range, RF errors are heavy-tailed."""
    rng = np.random.default_rng(5)
    ev = Evaluator(radar_enu=site.radar.enu, tolerance_s=1.0)
    tt = T0 + np.arange(0.0, 400.0, 0.2)
    a = (tt - T0) / 400.0 * 2 * math.pi
    e, n, u = -100 + 450 * np.sin(a), 500 - 600 * np.cos(a), 45 + 15 * np.sin(2 * a)
    for row in zip(tt, e, n, u, strict=True):
        ev.add_truth(*row)

    def truth(t: float) -> np.ndarray:
        return np.array([np.interp(t, tt, e), np.interp(t, tt, n), np.interp(t, tt, u)])

    radar = np.asarray(site.radar.enu)
    for t in np.arange(T0 + 2.0, T0 + 398.0, 0.25):
        p = truth(t)
        rng_m = float(np.linalg.norm(p - radar))
        z = p + rng.normal(0.0, 3.0 + rng_m / 50.0, 3)
        rcs = float(rng.normal(-10, 3)) if with_rcs else None
        ev.add_radar_report(t, float(z[0]), float(z[1]), float(z[2]), rcs_dbsm=rcs)
        if rng_m < site.radar.range_gate_m:
            ev.add_validated(t, "radar", z)
            ev.add_step(t, "updated", np.r_[0.5 * (z + p), 0.0, 0.0, 0.0])
        else:
            ev.add_step(t, "coasted", np.r_[p + rng.normal(0.0, 15.0, 3), 0.0, 0.0, 0.0])
    for k, t in enumerate(np.arange(T0 + 1.0, T0 + 398.0, 3.88)):
        if k % 17 == 3:
            ev.add_rf_attempt(t, False)
            continue
        en = truth(t)[:2] + rng.standard_t(2.0, 2) * 25.0
        ev.add_rf_attempt(t, True, *en)
        if np.linalg.norm(en - truth(t)[:2]) < 80.0:
            ev.add_validated(t, "rf", en)
    return ev.evaluate()


@pytest.fixture(scope="module")
def site() -> Site:
    return load_site()


@pytest.fixture(scope="module")
def written(site: Site, tmp_path_factory: pytest.TempPathFactory) -> tuple[Evaluation, Path]:
    ev = synthetic(site)
    out = tmp_path_factory.mktemp("report")
    write_report(ev, out, site, {"flight": "synthetic loop", "profile": "paper"})
    return ev, out


def test_every_figure_is_a_real_png_with_content(written: tuple[Evaluation, Path]) -> None:
    _, out = written
    for name in FIGURE_TITLES:
        path = out / f"{name}.png"
        assert path.is_file(), name
        with Image.open(path) as im:
            im.load()
            assert im.format == "PNG"
            w, h = im.size
            assert w >= 600 and h >= 400, (name, im.size)
            px = np.asarray(im.convert("L"), dtype=float)
        # not a blank canvas: a plot has many distinct grey levels
        assert px.std() > 5.0, name
        assert len(np.unique(px)) > 50, name


def test_markdown_report_has_every_row_and_figure(written: tuple[Evaluation, Path]) -> None:
    ev, out = written
    md = (out / "report.md").read_text(encoding="utf-8")
    assert "flight**: synthetic loop" in md
    for r in ev.rows:
        line = next(ln for ln in md.splitlines() if ln.startswith(f"| {r.spec.label} |"))
        cells = [c.strip() for c in line.strip("|").split("|")]
        assert int(cells[1]) == r.stats.count
        assert float(cells[4]) == pytest.approx(r.stats.mean, abs=0.05)
        assert float(cells[6]) == pytest.approx(r.stats.coverage_pct, abs=0.05)
        assert cells[7].startswith(f"{r.stats.count}/{r.denominator} ")
    for name in FIGURE_TITLES:
        assert f"({name}.png)" in md


def test_csv_and_json_carry_the_numbers(written: tuple[Evaluation, Path]) -> None:
    ev, out = written
    with (out / "metrics.csv").open(newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert list(rows[0].keys()) == list(CSV_FIELDS)
    assert [r["key"] for r in rows] == [s.key for s in ROWS]
    for got, r in zip(rows, ev.rows, strict=True):
        assert int(got["count"]) == r.stats.count
        assert float(got["std"]) == pytest.approx(r.stats.std, rel=1e-12)
        assert float(got["time_coverage_pct"]) == pytest.approx(r.time_coverage_pct)
    doc = json.loads((out / "metrics.json").read_text())
    assert doc["info"]["profile"] == "paper"
    assert doc["rows"] == [r.as_dict() for r in ev.rows]
    assert doc["rf_attempts"] == ev.rf_attempts
    assert doc["time_coverage_tolerance_s"] == 1.0


def test_markdown_table_groups_rows_like_the_paper(written: tuple[Evaluation, Path]) -> None:
    ev, _ = written
    lines = markdown_table(ev).splitlines()
    assert lines[0].startswith("| stage | count | min m | max m | mean m | std m |")
    assert "time coverage % (≤ 1 s)" in lines[0]
    groups = [i for i, ln in enumerate(lines) if ln.startswith("| **")]
    assert len(groups) == 3
    assert len(lines) == 2 + 3 + len(ROWS)


def test_empty_evaluation_writes_tables_and_explains_missing_figures(tmp_path: Path) -> None:
    files = write_report(Evaluator().evaluate(), tmp_path / "empty", None, {})
    assert files.figures == {}
    assert set(files.skipped_figures) == set(FIGURE_TITLES)
    md = files.markdown.read_text()
    assert "not drawn (no data for it)" in md
    doc = json.loads(files.json.read_text())
    assert all(r["count"] == 0 and r["mean"] is None for r in doc["rows"])


def test_rcs_histogram_is_skipped_without_rcs(site: Site, tmp_path: Path) -> None:
    files = write_report(synthetic(site, with_rcs=False), tmp_path, site, figures=True)
    assert "radar_rcs_histogram" in files.skipped_figures
    assert "error_cdf" in files.figures


def test_figures_can_be_turned_off(site: Site, tmp_path: Path) -> None:
    files = write_report(synthetic(site), tmp_path, site, figures=False)
    assert not list(tmp_path.glob("*.png"))
    assert files.csv.is_file() and files.json.is_file() and files.markdown.is_file()
