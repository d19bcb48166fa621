"""Evaluation report: Table II as Markdown, metrics as CSV and JSON, figures as PNG.

Figures are drawn with matplotlib's object API on the Agg canvas (no display, no pyplot
global state), so the report can be written from any thread of a running node.
"""

from __future__ import annotations

import csv
import json
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.colors import LogNorm
from matplotlib.figure import Figure

from uav_fusion.core.errors import UavFusionError
from uav_fusion.core.scoring.evaluation import ROWS, Evaluation, FloatArray, TableRow
from uav_fusion.core.site import Site

CSV_FIELDS = (
    "key",
    "label",
    "dims",
    "group",
    "count",
    "min",
    "max",
    "mean",
    "std",
    "coverage_pct",
    "denominator",
    "denominator_of",
    "samples",
    "unscored",
    "time_coverage_pct",
)

GROUP_TITLES = {
    "raw": "Before fusion (raw measurements)",
    "validated": "After sensor validation (NIS testing, range gating, largest track)",
    "fused": "After fusion (Kalman filter output)",
}

FIGURE_DPI = 120


@dataclass
class ReportFiles:
    """What :func:`write_report` wrote."""

    folder: Path
    markdown: Path
    csv: Path
    json: Path
    figures: dict[str, Path] = field(default_factory=dict)
    skipped_figures: dict[str, str] = field(default_factory=dict)  # name -> why


def _fmt(v: float, digits: int = 1) -> str:
    return "–" if not math.isfinite(v) else f"{v:.{digits}f}"


def markdown_table(ev: Evaluation) -> str:
    """Table II as a Markdown table, grouped like the paper, plus the time-coverage column."""
    tol = f"{ev.tolerance_s:g}"
    lines = [
        "| stage | count | min m | max m | mean m | std m | coverage % (count) "
        f"| of | time coverage % (≤ {tol} s) |",
        "|---|---:|---:|---:|---:|---:|---:|---|---:|",
    ]
    group = ""
    for r in ev.rows:
        if r.spec.group != group:
            group = r.spec.group
            lines.append(f"| **{GROUP_TITLES[group]}** | | | | | | | | |")
        s = r.stats
        of = f"{s.count}/{r.denominator} {_denominator_name(r)}"
        lines.append(
            f"| {r.spec.label} | {s.count} | {_fmt(s.min)} | {_fmt(s.max)} | {_fmt(s.mean)} "
            f"| {_fmt(s.std)} | {_fmt(s.coverage_pct)} | {of} | {_fmt(r.time_coverage_pct)} |"
        )
    return "\n".join(lines)


def _denominator_name(r: TableRow) -> str:
    return {"rf_attempts": "RF attempts", "radar_reports": "radar reports", "steps": "steps"}[
        r.spec.denominator
    ]


def write_metrics_csv(ev: Evaluation, path: Path) -> None:
    with path.open("w", newline="", encoding="utf-8") as fh:
        w = csv.DictWriter(fh, fieldnames=list(CSV_FIELDS))
        w.writeheader()
        for r in ev.rows:
            d = r.as_dict()
            w.writerow({k: ("" if d[k] is None else d[k]) for k in CSV_FIELDS})


def write_metrics_json(ev: Evaluation, path: Path, info: Mapping[str, Any]) -> None:
    doc = {"info": dict(info), **ev.as_dict()}
    path.write_text(json.dumps(doc, indent=2, allow_nan=False) + "\n", encoding="utf-8")


def _utc(t: float) -> str:
    if not math.isfinite(t):
        return "–"
    from datetime import UTC, datetime

    return datetime.fromtimestamp(t, tz=UTC).strftime("%Y-%m-%d %H:%M:%S.%f")[:-3] + " UTC"


def markdown_report(
    ev: Evaluation, info: Mapping[str, Any], figures: Mapping[str, Path], skipped: Mapping[str, str]
) -> str:
    out = ["# Tracking evaluation", ""]
    if info:
        out += ["## Run", ""]
        out += [f"- **{k}**: {v}" for k, v in info.items()]
        out.append("")
    out += [
        "## Position error statistics (Table II)",
        "",
        markdown_table(ev),
        "",
        "RF errors are horizontal (2D), all others 3D, against RTK truth linearly interpolated "
        f"to each sample's time (truth gaps over {ev.max_truth_gap_s:g} s are not bridged; "
        "samples outside truth are not scored and are listed as unscored in metrics.csv).",
        "Count coverage follows the paper: successful or accepted RF fixes over all "
        f"{ev.rf_attempts} RF attempts, radar reports over all {ev.radar_reports} raw radar "
        f"reports, filter estimates over all {ev.steps} filter steps.",
        f"Time coverage: share of the {ev.truth_epochs_in_window} truth epochs between "
        f"{_utc(ev.window[0])} and {_utc(ev.window[1])} that have a sample of the row at most "
        f"{ev.tolerance_s:g} s old.",
        "",
        "## Inputs",
        "",
        f"- truth samples: {ev.truth_t.size}",
        f"- raw radar reports: {ev.radar_reports} "
        f"(mean interval {_fmt(ev.mean_interval_s('radar_raw'), 2)} s)",
        f"- RF attempts: {ev.rf_attempts} ({ev.rf_failed_t.size} failed; mean interval of "
        f"fixes {_fmt(ev.mean_interval_s('rf_raw'), 2)} s)",
        "- filter steps by status: "
        + (", ".join(f"{k} {v}" for k, v in sorted(ev.step_status.items())) or "none"),
        "- dropped inputs: "
        + (", ".join(f"{k}: {v}" for k, v in sorted(ev.dropped.items())) or "none"),
        "",
    ]
    if figures or skipped:
        out += ["## Figures", ""]
        for name, p in figures.items():
            out += [f"![{FIGURE_TITLES.get(name, name)}]({p.name})", ""]
        for name, why in skipped.items():
            out += [f"- {FIGURE_TITLES.get(name, name)}: not drawn ({why})"]
        out.append("")
    return "\n".join(out)


# --- figures -------------------------------------------------------------------------------
FIGURE_TITLES = {
    "error_cdf": "Empirical CDFs of position error",
    "radar_error_vs_range": "Radar error versus 3D range from the radar",
    "rf_error_vs_time": "RF error versus time since flight start",
    "fused_error_trajectory": "Fused track coloured by error over the truth trajectory",
    "radar_error_trajectory": "Radar reports coloured by error over the truth trajectory",
    "radar_rcs_histogram": "Histogram of radar RCS",
    "trajectory_altitude": "Truth trajectory coloured by altitude, with the towers",
}


def _new_figure(size: tuple[float, float] = (8.0, 5.5)) -> tuple[Figure, Axes]:
    fig = Figure(figsize=size, dpi=FIGURE_DPI)
    FigureCanvasAgg(fig)
    ax = fig.add_subplot(1, 1, 1)
    return fig, ax


def _save(fig: Figure, path: Path) -> Path:
    fig.tight_layout()
    fig.savefig(path, format="png", dpi=FIGURE_DPI)
    return path


def _finite_err(ev: Evaluation, key: str) -> FloatArray:
    e = ev.samples[key].err
    return e[np.isfinite(e)]


def _row_legend(ev: Evaluation, key: str) -> str:
    r = ev.row(key)
    return (
        f"{r.spec.label}: n={r.stats.count}, cov {_fmt(r.stats.coverage_pct)} % "
        f"(time, ≤ {ev.tolerance_s:g} s: {_fmt(r.time_coverage_pct)} %)"
    )


def figure_error_cdf(ev: Evaluation, path: Path) -> Path | None:
    styles = {
        "rf_raw": ("tab:orange", ":"),
        "rf_validated": ("tab:orange", "-"),
        "radar_raw": ("tab:blue", ":"),
        "radar_validated": ("tab:blue", "-"),
        "kf_all": ("black", "-"),
    }
    fig, ax = _new_figure((9.0, 7.0))
    drawn = 0
    for key, (color, ls) in styles.items():
        e = np.sort(_finite_err(ev, key))
        e = e[e > 0]
        if e.size == 0:
            continue
        y = np.arange(1, e.size + 1) / e.size
        ax.step(e, y, where="post", color=color, linestyle=ls, lw=1.8, label=_row_legend(ev, key))
        drawn += 1
    if not drawn:
        return None
    ax.set_xscale("log")
    ax.set_xlabel("position error (m, log scale)")
    ax.set_ylabel("empirical CDF")
    ax.set_ylim(0, 1.02)
    ax.grid(True, which="both", alpha=0.3)
    ax.set_title("Position error CDFs: RF, radar and KF fusion")
    # below the axes: long labels would hide curves anywhere inside
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.12), fontsize=8, frameon=False)
    return _save(fig, path)


def figure_radar_error_vs_range(ev: Evaluation, path: Path, gate_m: float | None) -> Path | None:
    s = ev.samples["radar_raw"]
    ok = np.isfinite(s.err)
    if not ok.any():
        return None
    fig, ax = _new_figure()
    ax.scatter(ev.radar_range[ok], s.err[ok], s=6, alpha=0.5, color="tab:blue",
               label=f"raw radar reports (n={int(ok.sum())})")
    v = ev.samples["radar_validated"]
    vok = np.isfinite(v.err)
    if vok.any():
        ax.scatter(ev.radar_validated_range[vok], v.err[vok], s=4, alpha=0.6, color="tab:green",
                   label=f"accepted by the filter (n={int(vok.sum())})")
    if gate_m is not None and math.isfinite(gate_m):
        ax.axvline(gate_m, color="tab:red", ls="--", lw=1.5, label=f"range gate {gate_m:g} m")
    ax.set_xlabel("3D distance of the report from the radar (m)")
    ax.set_ylabel("3D position error (m)")
    ax.set_title("Radar localisation error versus range")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="upper left", fontsize=8)
    return _save(fig, path)


def figure_rf_error_vs_time(ev: Evaluation, path: Path) -> Path | None:
    s = ev.samples["rf_raw"]
    ok = np.isfinite(s.err)
    if not ok.any():
        return None
    t0 = ev.window[0] if math.isfinite(ev.window[0]) else float(s.t[0])
    fig, ax = _new_figure()
    ax.scatter(s.t[ok] - t0, s.err[ok], s=14, color="tab:orange", alpha=0.7,
               label=f"raw RF fixes (n={int(ok.sum())})")
    v = ev.samples["rf_validated"]
    vok = np.isfinite(v.err)
    if vok.any():
        ax.scatter(v.t[vok] - t0, v.err[vok], s=30, facecolors="none", edgecolors="tab:green",
                   label=f"accepted by the filter (n={int(vok.sum())})")
    if ev.rf_failed_t.size:
        ymin = max(float(np.nanmin(s.err[ok])) * 0.5, 0.1)
        ax.plot(ev.rf_failed_t - t0, np.full(ev.rf_failed_t.size, ymin), "x", color="tab:red",
                label=f"failed attempts (n={ev.rf_failed_t.size})")
    ax.set_yscale("log")
    ax.set_xlabel("time since flight start (s)")
    ax.set_ylabel("2D position error (m, log scale)")
    ax.set_title("RF sensor localisation error versus time")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(loc="upper right", fontsize=8)
    return _save(fig, path)


def _draw_site(ax: Axes, site: Site | None) -> None:
    if site is None:
        return
    rf = set(site.rf_sensors)
    for name, tw in site.towers.items():
        marker, color = ("^", "tab:purple") if name in rf else ("s", "dimgray")
        ax.plot(tw.enu[0], tw.enu[1], marker, color=color, ms=9, mec="black", zorder=5)
        origin = abs(tw.enu[0]) < 1 and abs(tw.enu[1]) < 1
        label = f"{name} (origin)" if origin else name
        ax.annotate(label, (tw.enu[0], tw.enu[1]), xytext=(6, -14) if origin else (6, 6),
                    textcoords="offset points", fontsize=9, weight="bold", zorder=6)
    r = site.radar
    ax.plot(r.enu[0], r.enu[1], "*", color="tab:red", ms=15, mec="black", zorder=6)
    ax.annotate("radar", (r.enu[0], r.enu[1]), xytext=(6, -12), textcoords="offset points",
                fontsize=9, color="tab:red", weight="bold", zorder=6)


def _site_legend_handles(ax: Axes, site: Site | None) -> None:
    if site is None:
        return
    ax.plot([], [], "^", color="tab:purple", mec="black", label="RF sensor tower")
    ax.plot([], [], "s", color="dimgray", mec="black", label="other tower")
    ax.plot([], [], "*", color="tab:red", mec="black", ms=12, label="radar")


def _view_limits(ev: Evaluation, site: Site | None) -> tuple[float, float, float, float] | None:
    """East/north limits framing the truth path and the site, with a margin."""
    pts = [ev.truth_enu[:, :2]] if ev.truth_t.size else []
    if site is not None:
        pts.append(np.array([t.enu[:2] for t in site.towers.values()]))
        pts.append(np.array([site.radar.enu[:2]]))
    if not pts:
        return None
    xy = np.concatenate(pts)
    lo, hi = xy.min(axis=0), xy.max(axis=0)
    pad = 0.08 * float(max(hi[0] - lo[0], hi[1] - lo[1], 100.0))
    return float(lo[0] - pad), float(hi[0] + pad), float(lo[1] - pad), float(hi[1] + pad)


def figure_error_trajectory(
    ev: Evaluation, path: Path, key: str, site: Site | None, title: str
) -> Path | None:
    s = ev.samples[key]
    ok = np.isfinite(s.err)
    if not ok.any():
        return None
    fig, ax = _new_figure((8.0, 8.0))
    if ev.truth_t.size:
        ax.plot(ev.truth_enu[:, 0], ev.truth_enu[:, 1], color="0.6", lw=1.0, label="truth",
                zorder=2)
    err = s.err[ok]
    # errors span decades (metres to kilometres): a log colour scale keeps both readable
    vmin = max(float(np.min(err)), 1.0)
    vmax = max(float(np.max(err)), 10.0 * vmin)
    sc = ax.scatter(s.pos[ok, 0], s.pos[ok, 1], c=np.clip(err, vmin, None), s=6, cmap="viridis",
                    norm=LogNorm(vmin=vmin, vmax=vmax), zorder=3)
    fig.colorbar(sc, ax=ax, label="position error (m, log colour scale)", shrink=0.8)
    _draw_site(ax, site)
    _site_legend_handles(ax, site)
    lim = _view_limits(ev, site)
    if lim is not None:
        x0, x1, y0, y1 = lim
        outside = int(np.count_nonzero(
            (s.pos[ok, 0] < x0) | (s.pos[ok, 0] > x1) | (s.pos[ok, 1] < y0) | (s.pos[ok, 1] > y1)
        ))
        ax.set_xlim(x0, x1)
        ax.set_ylim(y0, y1)
        if outside:
            title += f"\n({outside} of {int(ok.sum())} points lie outside this view)"
    ax.set_aspect("equal", adjustable="box")
    ax.set_xlabel("east of LW1 (m)")
    ax.set_ylabel("north of LW1 (m)")
    ax.set_title(title)
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best", fontsize=8)
    return _save(fig, path)


def figure_rcs_histogram(ev: Evaluation, path: Path) -> Path | None:
    rcs_db = ev.radar_rcs_dbsm[np.isfinite(ev.radar_rcs_dbsm)]
    if rcs_db.size == 0:
        return None
    rcs = 10.0 ** (rcs_db / 10.0)
    fig, ax = _new_figure()
    ax.hist(rcs, bins=40, color="tab:blue", edgecolor="black", alpha=0.8)
    ax.axvline(float(rcs.mean()), color="tab:red", ls="--",
               label=f"mean {rcs.mean():.3g} m² (min {rcs.min():.3g}, max {rcs.max():.3g})")
    ax.set_xlabel("radar cross-section (m²)")
    ax.set_ylabel("number of radar reports")
    ax.set_title(f"Radar RCS of the raw reports (n={rcs.size})")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8)
    return _save(fig, path)


def figure_trajectory_altitude(ev: Evaluation, path: Path, site: Site | None) -> Path | None:
    if ev.truth_t.size == 0:
        return None
    fig, ax = _new_figure((8.0, 8.0))
    e, n, u = ev.truth_enu[:, 0], ev.truth_enu[:, 1], ev.truth_enu[:, 2]
    ax.plot(e, n, color="0.8", lw=0.8, zorder=1)
    sc = ax.scatter(e, n, c=u, s=4, cmap="plasma", zorder=2)
    fig.colorbar(sc, ax=ax, label="height above LW1 ground (m)", shrink=0.8)
    ax.plot(e[0], n[0], "o", color="tab:green", ms=8, mec="black", label="start", zorder=7)
    ax.plot(e[-1], n[-1], "X", color="black", ms=9, label="end", zorder=7)
    _draw_site(ax, site)
    _site_legend_handles(ax, site)
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("east of LW1 (m)")
    ax.set_ylabel("north of LW1 (m)")
    ax.set_title("Truth trajectory coloured by altitude")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best", fontsize=8)
    return _save(fig, path)


# --- the whole report ----------------------------------------------------------------------
def write_report(
    ev: Evaluation,
    out_dir: str | Path,
    site: Site | None = None,
    info: Mapping[str, Any] | None = None,
    figures: bool = True,
) -> ReportFiles:
    """Write report.md, metrics.csv, metrics.json and (unless ``figures`` is False) PNGs.

    ``site`` marks the towers and the radar on the maps and draws the radar's range gate.
    ``info`` is free run information (flight, profile, ...) written at the top of report.md
    and into metrics.json.
    """
    folder = Path(out_dir)
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise UavFusionError(f"{folder}: cannot create the report folder: {exc}") from None
    info = dict(info or {})
    files = ReportFiles(
        folder=folder,
        markdown=folder / "report.md",
        csv=folder / "metrics.csv",
        json=folder / "metrics.json",
    )
    if figures:
        gate = site.radar.range_gate_m if site is not None else None
        plan = {
            "error_cdf": lambda p: figure_error_cdf(ev, p),
            "radar_error_vs_range": lambda p: figure_radar_error_vs_range(ev, p, gate),
            "rf_error_vs_time": lambda p: figure_rf_error_vs_time(ev, p),
            "fused_error_trajectory": lambda p: figure_error_trajectory(
                ev, p, "kf_all", site, "KF fused estimates coloured by error, over truth"
            ),
            "radar_error_trajectory": lambda p: figure_error_trajectory(
                ev, p, "radar_raw", site, "Raw radar reports coloured by error, over truth"
            ),
            "radar_rcs_histogram": lambda p: figure_rcs_histogram(ev, p),
            "trajectory_altitude": lambda p: figure_trajectory_altitude(ev, p, site),
        }
        for name, draw in plan.items():
            p = draw(folder / f"{name}.png")
            if p is None:
                files.skipped_figures[name] = "no data for it"
            else:
                files.figures[name] = p
    try:
        write_metrics_csv(ev, files.csv)
        write_metrics_json(ev, files.json, info)
        files.markdown.write_text(
            markdown_report(ev, info, files.figures, files.skipped_figures), encoding="utf-8"
        )
    except OSError as exc:
        raise UavFusionError(f"{folder}: cannot write the report: {exc}") from None
    return files


__all__ = [
    "CSV_FIELDS",
    "FIGURE_TITLES",
    "ROWS",
    "ReportFiles",
    "markdown_table",
    "write_report",
]
