"""The benchmark's outputs: the pooled table, the per-flight CSV, the figure, provenance."""

from __future__ import annotations

import csv
import json
import math
import platform
import subprocess
from collections.abc import Mapping, Sequence
from datetime import UTC, datetime
from importlib import metadata
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from uav_fusion.core.bench.radar_baseline import RadarComparison
from uav_fusion.core.bench.single import FlightResult, RegistrationOutcome
from uav_fusion.core.scoring.fixed_rate import (
    TABLE_COLUMNS,
    GridScore,
    ScoreSettings,
    format_value,
    pool,
)
from uav_fusion.resources import share_dir

FIGURE_DPI = 110
CSV_FILE = "per_flight.csv"
FIGURE_FILE = "bench_accuracy.png"
RADAR_FIGURE_FILE = "bench_vs_radar.png"
TABLE_FILE = "table.md"
JSON_FILE = "summary.json"
VERSION_PACKAGES = ("uav_fusion", "numpy", "scipy", "dask", "distributed")


def pooled(results: Sequence[FlightResult], settings: ScoreSettings) -> dict[str, GridScore]:
    """Pooled figures per profile, in the order the profiles first appear."""
    by: dict[str, list[FlightResult]] = {}
    for r in results:
        by.setdefault(r.profile, []).append(r)
    return {p: pool([r.samples for r in rs], settings) for p, rs in by.items()}


def git_commit(root: Path | None = None) -> str:
    """``<hash>`` of the source tree (``+dirty`` with uncommitted changes), or "unknown"."""
    root = root or share_dir()
    try:
        head = subprocess.run(
            ["git", "-C", str(root), "rev-parse", "HEAD"],
            capture_output=True, text=True, timeout=10, check=True,
        ).stdout.strip()
        dirty = subprocess.run(
            ["git", "-C", str(root), "status", "--porcelain", "--untracked-files=no"],
            capture_output=True, text=True, timeout=10, check=True,
        ).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return "unknown (not a git checkout)"
    return head + ("+dirty" if dirty else "")


def versions() -> dict[str, str]:
    out = {"python": platform.python_version()}
    for name in VERSION_PACKAGES:
        try:
            out[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            out[name] = "not installed"
    return out


def provenance(
    split: str, flights: int, definition: Path, extra: Mapping[str, str] | None = None
) -> dict[str, Any]:
    doc: dict[str, Any] = {
        "date": datetime.now(tz=UTC).strftime("%Y-%m-%d %H:%M UTC"),
        "commit": git_commit(),
        "split": split,
        "flights": flights,
        "definition": str(definition),
        "versions": versions(),
    }
    doc.update(extra or {})
    return doc


def provenance_lines(prov: Mapping[str, Any]) -> list[str]:
    lines = []
    for k, v in prov.items():
        if isinstance(v, Mapping):
            v = ", ".join(f"{a} {b}" for a, b in v.items())
        lines.append(f"{k}: {v}")
    return lines


def text_table(scores: Mapping[str, GridScore]) -> str:
    """The pooled figures, one row per profile (fixed-width, for terminals)."""
    heads = ["profile"] + [h for _, h, _ in TABLE_COLUMNS]
    rows = [
        [name] + [format_value(getattr(s, f), fmt) for f, _, fmt in TABLE_COLUMNS]
        for name, s in scores.items()
    ]
    widths = [max(len(r[i]) for r in [heads, *rows]) for i in range(len(heads))]

    def line(cells: list[str]) -> str:
        pairs = zip(cells, widths, strict=True)
        return "  ".join(c.ljust(w) if i == 0 else c.rjust(w) for i, (c, w) in enumerate(pairs))

    out = [line(heads), "  ".join("-" * w for w in widths)]
    out += [line(r) for r in rows]
    return "\n".join(out)


def markdown_flights(results: Sequence[FlightResult], settings: ScoreSettings) -> str:
    """One row per (profile, flight), in the results' order."""
    heads = ["profile", "flight"] + [h for _, h, _ in FLIGHT_COLUMNS]
    out = ["| " + " | ".join(heads) + " |", "|---|---|" + "---:|" * len(FLIGHT_COLUMNS)]
    for r, s in per_flight_scores(results, settings):
        cells = [r.profile, r.flight_id]
        cells += [format_value(getattr(s, f), fmt) for f, _, fmt in FLIGHT_COLUMNS]
        out.append("| " + " | ".join(cells) + " |")
    return "\n".join(out)


def markdown_table(scores: Mapping[str, GridScore]) -> str:
    heads = ["profile"] + [h for _, h, _ in TABLE_COLUMNS]
    out = ["| " + " | ".join(heads) + " |", "|---|" + "---:|" * len(TABLE_COLUMNS)]
    for name, s in scores.items():
        cells = [name] + [format_value(getattr(s, f), fmt) for f, _, fmt in TABLE_COLUMNS]
        out.append("| " + " | ".join(cells) + " |")
    return "\n".join(out)


CSV_FIELDS = (
    "profile", "flight", "plan", "seed", "family", "split", "epochs", "coverage_pct",
    "fresh_coverage_pct", "err_mean_m", "err_p50_m", "err_p95_m", "err_max_m", "gross_pct",
    "observable_epochs", "observable_coverage_pct", "observable_gross_pct",
    "observable_after_start_pct", "anees",
    "nees_in95_pct", "ttf_s", "restarts", "gross_vertical_pct", "gross_age_p50_s",
    "gross_rf_pct", "longest_gross_s", "registration_az_deg", "registration_az_sigma_deg",
    "registration_az_bound_deg", "registration_az_true_deg",
    "steps", "seconds",
)

# the per-flight Markdown table, (GridScore field, header, format): most of the printed
# table's columns, and where the gross errors come from
_PRINTED = {c[0]: c for c in TABLE_COLUMNS}
_SHARED = (
    "coverage_pct", "fresh_coverage_pct", "err_mean_m", "err_p95_m", "err_max_m", "gross_pct",
    "observable_coverage_pct", "observable_gross_pct",
)  # fmt: skip
FLIGHT_COLUMNS: tuple[tuple[str, str, str], ...] = (
    *(_PRINTED[f] for f in _SHARED),
    ("observable_after_start_pct", "obs cov after 1st track %", ".1f"),
    _PRINTED["anees"],
    ("gross_vertical_pct", "gross: vertical %", ".0f"),
    ("gross_age_p50_s", "gross: age p50 s", ".1f"),
    ("gross_rf_pct", "gross: last RF %", ".0f"),
    ("longest_gross_s", "longest gross episode s", ".1f"),
    _PRINTED["restarts"],
)

# the per-family table of a definition flown in world families: (GridScore field, header,
# format); the header of longest_gross_s names the episode threshold
ALL_FAMILIES = "all"
FAMILY_COLUMNS: tuple[tuple[str, str, str], ...] = (
    ("flights", "flights", "d"),
    ("coverage_pct", "cov %", ".1f"),
    ("err_mean_m", "mean m", ".1f"),
    ("err_p95_m", "p95 m", ".1f"),
    ("flight_mean_max_m", "worst flight mean m", ".1f"),
    ("longest_gross_s", "longest > {episode:g} m s", ".1f"),
    ("anees", "ANEES", ".1f"),
    ("nees_in95_pct", "NEES in 95 % %", ".1f"),
)


def pooled_by_family(
    results: Sequence[FlightResult], settings: ScoreSettings
) -> dict[str, dict[str, GridScore]]:
    """Family -> profile -> the figures pooled over the family's flights, families in the
    order they first appear, then ``ALL_FAMILIES``: every flight of the results."""
    groups: dict[str, dict[str, list[FlightResult]]] = {}
    for r in results:
        groups.setdefault(r.family or "-", {}).setdefault(r.profile, []).append(r)
    out = {
        fam: {p: pool([r.samples for r in rs], settings) for p, rs in by.items()}
        for fam, by in groups.items()
    }
    out[ALL_FAMILIES] = pooled(results, settings)
    return out


def _family_rows(
    by_family: Mapping[str, Mapping[str, GridScore]], episode_m: float
) -> tuple[list[str], list[list[str]]]:
    heads = ["family", "profile"] + [h.format(episode=episode_m) for _, h, _ in FAMILY_COLUMNS]
    rows = []
    n_fam = sum(1 for f in by_family if f != ALL_FAMILIES)
    for fam, by in by_family.items():
        label = f"all {n_fam} families" if fam == ALL_FAMILIES else fam
        for prof, sc in by.items():
            rows.append(
                [label, prof]
                + [format_value(getattr(sc, f), fmt) for f, _, fmt in FAMILY_COLUMNS]
            )
    return heads, rows


def markdown_families(
    by_family: Mapping[str, Mapping[str, GridScore]], episode_m: float
) -> str:
    """The per-family table in Markdown (a row per family and profile, the pool last)."""
    heads, rows = _family_rows(by_family, episode_m)
    out = ["| " + " | ".join(heads) + " |", "|---|---|" + "---:|" * len(FAMILY_COLUMNS)]
    out += ["| " + " | ".join(r) + " |" for r in rows]
    return "\n".join(out)


def text_families(
    by_family: Mapping[str, Mapping[str, GridScore]], episode_m: float
) -> str:
    """The per-family table, fixed-width (for terminals)."""
    heads, rows = _family_rows(by_family, episode_m)
    widths = [max(len(r[i]) for r in [heads, *rows]) for i in range(len(heads))]

    def line(cells: list[str]) -> str:
        pairs = zip(cells, widths, strict=True)
        return "  ".join(c.ljust(w) if i < 2 else c.rjust(w) for i, (c, w) in enumerate(pairs))

    return "\n".join([line(heads), "  ".join("-" * w for w in widths), *map(line, rows)])


#: The registration criterion: within this of the true mount, or within the flight's bound.
REGISTRATION_TOL_DEG = 0.1
#: The bound is a standard deviation: an unbiased estimate with an honest bound lies within
#: one bound on about 68 % of flights, and within this many on 90 % (two-sided, Gaussian).
REGISTRATION_90_BOUNDS = 1.645


def registration_lines(results: Sequence[FlightResult]) -> list[str]:
    """Per profile, over the flights with a true mount (generated in a world): on how many
    the end-of-flight azimuth lies within REGISTRATION_TOL_DEG of it or within the bound of
    the flight's data where that is larger (and within REGISTRATION_90_BOUNDS bounds: the
    share an honest bound predicts is 68 % and 90 %), and the bounds' spread."""
    out = []
    by: dict[str, list[RegistrationOutcome]] = {}
    for r in results:
        if r.registration is not None and r.registration.true_deg is not None:
            by.setdefault(r.profile, []).append(r.registration)
    for prof, regs in by.items():
        ok = sum(bool(g.within(REGISTRATION_TOL_DEG)) for g in regs)
        ok90 = sum(bool(g.within(REGISTRATION_TOL_DEG, REGISTRATION_90_BOUNDS)) for g in regs)
        tight = sum((g.error_deg or 0.0) <= REGISTRATION_TOL_DEG for g in regs)
        bounds = sorted(g.bound_deg for g in regs)
        out.append(
            f"{prof}: azimuth within {REGISTRATION_TOL_DEG:g} deg of the true mount, or within "
            f"the flight's bound, on {ok} of {len(regs)} flights ({tight} within "
            f"{REGISTRATION_TOL_DEG:g} deg; within {REGISTRATION_90_BOUNDS:g} bounds on {ok90}); "
            f"bound median {bounds[len(bounds) // 2]:.2f} deg, {bounds[0]:.2f}-{bounds[-1]:.2f}"
        )
    return out


def per_flight_scores(
    results: Sequence[FlightResult], settings: ScoreSettings
) -> list[tuple[FlightResult, GridScore]]:
    return [(r, pool([r.samples], settings)) for r in results]


def write_csv(
    results: Sequence[FlightResult], settings: ScoreSettings, path: Path
) -> Path:
    with path.open("w", newline="", encoding="utf-8") as fh:
        w = csv.DictWriter(fh, fieldnames=list(CSV_FIELDS))
        w.writeheader()
        for r, s in per_flight_scores(results, settings):
            d: dict[str, Any] = {
                "profile": r.profile, "flight": r.flight_id, "plan": r.plan, "seed": r.seed,
                "family": r.family or "", "split": r.split, "steps": r.steps,
                "seconds": f"{r.seconds:.3f}",
            }
            reg = r.registration
            if reg is not None:
                d["registration_az_deg"] = f"{reg.az_deg:.3f}"
                d["registration_az_sigma_deg"] = f"{reg.sigma_deg:.3f}"
                d["registration_az_bound_deg"] = f"{reg.bound_deg:.3f}"
                if reg.true_deg is not None:
                    d["registration_az_true_deg"] = f"{reg.true_deg:.3f}"
            for k, v in s.as_dict().items():
                if k in CSV_FIELDS and k not in d:
                    d[k] = "" if isinstance(v, float) and not math.isfinite(v) else (
                        f"{v:.4f}" if isinstance(v, float) else v
                    )
            w.writerow(d)
    return path


def write_summary_json(
    scores: Mapping[str, GridScore],
    prov: Mapping[str, Any],
    path: Path,
    families: Mapping[str, Mapping[str, GridScore]] | None = None,
    against_radar: Sequence[RadarComparison] = (),
) -> Path:
    def clean(d: dict[str, Any]) -> dict[str, Any]:
        return {
            k: (None if isinstance(v, float) and not math.isfinite(v) else v)
            for k, v in d.items()
        }

    doc: dict[str, Any] = {
        "provenance": dict(prov),
        "pooled": {p: clean(s.as_dict()) for p, s in scores.items()},
    }
    if families is not None:
        doc["families"] = {
            fam: {p: clean(s.as_dict()) for p, s in by.items()} for fam, by in families.items()
        }
    if against_radar:
        doc["against_radar"] = {c.profile: c.as_dict() for c in against_radar}
    path.write_text(json.dumps(doc, indent=2, allow_nan=False) + "\n", encoding="utf-8")
    return path


def write_figure(
    results: Sequence[FlightResult], settings: ScoreSettings, path: Path
) -> Path:
    """Error CDF per profile (pooled); coverage and gross-error share per flight and profile."""
    profiles = list(dict.fromkeys(r.profile for r in results))
    flights = list(dict.fromkeys(r.flight_id for r in results))
    fig = Figure(figsize=(11.0, 10.0), dpi=FIGURE_DPI)
    FigureCanvasAgg(fig)
    ax_cdf = fig.add_subplot(3, 1, 1)
    ax_cov = fig.add_subplot(3, 1, 2)
    ax_gross = fig.add_subplot(3, 1, 3)
    for p in profiles:
        err = np.sort(np.concatenate([r.samples.errors for r in results if r.profile == p]))
        if err.size:
            y = np.arange(1, err.size + 1) / err.size
            ax_cdf.plot(np.maximum(err, 1e-2), y, label=f"{p} (n={err.size} epochs)")
    ax_cdf.set_xscale("log")
    ax_cdf.axvline(settings.gross_error_m, color="grey", ls="--", lw=0.8)
    ax_cdf.set_xlabel("3D error of the published track at covered airborne epochs (m)")
    ax_cdf.set_ylabel("CDF")
    ax_cdf.grid(True, which="both", alpha=0.3)
    if profiles:
        ax_cdf.legend(loc="lower right", fontsize=8)
    width = 0.8 / max(1, len(profiles))
    x = np.arange(len(flights))
    scores = {(r.profile, r.flight_id): pool([r.samples], settings) for r in results}
    for j, p in enumerate(profiles):
        cov = [scores[(p, f)].coverage_pct if (p, f) in scores else np.nan for f in flights]
        gross = [scores[(p, f)].gross_pct if (p, f) in scores else np.nan for f in flights]
        off = (j - (len(profiles) - 1) / 2) * width
        ax_cov.bar(x + off, cov, width, label=p)
        ax_gross.bar(x + off, gross, width, label=p)
    for ax, lab in (
        (ax_cov, "coverage (% of airborne epochs)"),
        (ax_gross, f"gross errors (> {settings.gross_error_m:g} m, % of covered)"),
    ):
        ax.set_xticks(x)
        ax.set_xticklabels(flights, rotation=45, ha="right", fontsize=7)
        ax.set_ylabel(lab, fontsize=8)
        ax.grid(True, axis="y", alpha=0.3)
        if profiles:  # outside the axes: the bars reach the top
            ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.0, 1.0))
    ax_cov.set_ylim(0, 100)
    fig.tight_layout()
    fig.savefig(path, format="png", dpi=FIGURE_DPI)
    return path


def write_radar_figure(comparisons: Sequence[RadarComparison], path: Path) -> Path:
    """Each flight's mean error of each profile against the radar's own track's, on the epochs
    both cover (log axes): below the diagonal the profile does better; the flights above it
    are labelled."""
    fig = Figure(figsize=(7.5, 7.0), dpi=FIGURE_DPI)
    FigureCanvasAgg(fig)
    ax = fig.add_subplot(1, 1, 1)
    lo, hi = math.inf, 0.0
    for c in comparisons:
        pts = [f for f in c.per_flight if f.epochs > 0]
        if not pts:
            continue
        x = np.array([f.radar_mean_m for f in pts])
        y = np.array([f.mean_m for f in pts])
        lo, hi = min(lo, float(x.min()), float(y.min())), max(hi, float(x.max()), float(y.max()))
        label = f"{c.profile}: at most the radar on {c.at_most} of {c.flights}"
        ax.scatter(x, y, s=22, label=label)
        for f in c.above:
            ax.annotate(f.flight_id, (f.radar_mean_m, f.mean_m), fontsize=6,
                        xytext=(3, 3), textcoords="offset points")  # fmt: skip
    if hi > 0:
        lo = max(lo / 1.5, 1e-1)
        hi = hi * 1.5
        ax.plot([lo, hi], [lo, hi], color="grey", lw=0.8, ls="--")
        ax.set_xlim(lo, hi)
        ax.set_ylim(lo, hi)
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.legend(loc="upper left", fontsize=8)
    ax.set_title("one point per flight: below the diagonal, better than the radar's own track",
                 fontsize=9)  # fmt: skip
    ax.set_xlabel("the radar's own track: mean 3D error per flight (m, epochs both cover)")
    ax.set_ylabel("profile: mean 3D error per flight (m, the same epochs)")
    ax.grid(True, which="both", alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, format="png", dpi=FIGURE_DPI)
    return path
