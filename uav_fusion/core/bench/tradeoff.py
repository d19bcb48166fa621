"""Multi-UAV sweeps: what a setting buys in coverage and costs in false-track time (the
trade-off table and figure of ``uav_fusion sweep``)."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

from uav_fusion.core.bench.sweep import MULTI_PREFIX, SweepSpec, combo_label
from uav_fusion.core.bench.sweep_figure import save_figure


def _mean_over_flights(rows: list[dict[str, Any]], metric: str) -> float:
    vals = [float(r[metric]) for r in rows if r.get(metric) is not None
            and math.isfinite(float(r[metric]))]
    return sum(vals) / len(vals) if vals else math.nan


def tradeoff_rows(
    rows: list[dict[str, Any]], spec: SweepSpec
) -> list[tuple[str, str, float, float, float]]:
    """Multi-UAV sweeps: per profile and combination, the means over the flights of coverage,
    false-track time and GOSPA: (profile, combination, coverage %, false-track %, GOSPA m)."""
    groups: dict[tuple[str, str], list[dict[str, Any]]] = {}
    for r in rows:
        label = combo_label(r["params"])
        groups.setdefault((r["profile"], label), []).append(r)
    return [
        (
            prof,
            label,
            _mean_over_flights(rs, "coverage_pct"),
            _mean_over_flights(rs, "false_track_pct"),
            _mean_over_flights(rs, "gospa_mean_m"),
        )
        for (prof, label), rs in sorted(groups.items())
    ]


def write_tradeoff_figure(rows: list[dict[str, Any]], spec: SweepSpec, path: Path) -> Path | None:
    """Multi-UAV sweeps: coverage against false-track time, a point per profile and
    combination (means over the flights), labelled with the combination and its GOSPA: what
    a setting buys on one axis and costs on the other."""
    if not spec.definition.multi or not rows:
        return None
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    pts = tradeoff_rows(rows, spec)
    fig, ax = plt.subplots(figsize=(7.5, 5.5))
    for k, prof in enumerate(sorted({p[0] for p in pts})):
        mine = [p for p in pts if p[0] == prof]
        ax.scatter([p[3] for p in mine], [p[2] for p in mine], label=prof,
                   marker="os^Dv"[k % 5], zorder=3)
        for _prof, label, cov, fal, gospa in mine:
            short = label.replace(MULTI_PREFIX, "").replace(", ", "\n")
            ax.annotate(f"{short}\nGOSPA {gospa:.1f} m", (fal, cov), fontsize=6,
                        xytext=(4, 3), textcoords="offset points")
    ax.margins(x=0.3, y=0.15)
    ax.set_xlabel("false-track time (% of flight time, mean over flights)")
    if any(k.startswith(MULTI_PREFIX) for k in spec.parameters):
        ax.text(0.01, 0.01, "labels: multi.<key> settings of the profile", fontsize=7,
                transform=ax.transAxes)
    ax.set_ylabel("coverage (% of airborne UAV-epochs, mean over flights)")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8)
    n_fl = len({r["flight"] for r in rows})
    ax.set_title(f"sweep {spec.name}: coverage against false-track time, {n_fl} {spec.split} "
                 "flights", fontsize=10)
    return save_figure(fig, path)
