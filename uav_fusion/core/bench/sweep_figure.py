"""The figure of a parameter sweep (``sweep.png``): the metric against each parameter, or, in
``one_at_a_time`` mode, each changed setting's change of the metric (:mod:`.sweep`)."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

from uav_fusion.core.bench.sweep import SweepSpec, combo_label, value_label


def write_figure(rows: list[dict[str, Any]], spec: SweepSpec, path: Path) -> Path | None:
    """The metric against each parameter, a line per profile (median over the flights and
    the other parameters' values) with the spread over flights as a band (min to max)."""
    if not spec.parameters or not rows:
        return None
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    if spec.mode == "one_at_a_time":
        return _write_ablation_figure(rows, spec, path, plt)
    names = list(spec.parameters)
    fig, axes = plt.subplots(1, len(names), figsize=(5.5 * len(names), 4.2), squeeze=False)
    profiles = sorted({r["profile"] for r in rows})
    for ax, name in zip(axes[0], names, strict=True):
        values = list(spec.parameters[name])
        xs = list(range(len(values)))
        for prof in profiles:
            med, lo, hi = [], [], []
            for v in values:
                vals = [
                    float(r[spec.metric])
                    for r in rows
                    if r["profile"] == prof
                    and _same(r["params"].get(name), v)
                    and r.get(spec.metric) is not None
                    and math.isfinite(float(r[spec.metric]))
                ]
                vals.sort()
                if vals:
                    med.append(vals[len(vals) // 2])
                    lo.append(vals[0])
                    hi.append(vals[-1])
                else:
                    med.append(math.nan)
                    lo.append(math.nan)
                    hi.append(math.nan)
            line = ax.plot(xs, med, marker="o", label=prof)[0]
            ax.fill_between(xs, lo, hi, color=line.get_color(), alpha=0.15)
        finite = [float(r[spec.metric]) for r in rows if r.get(spec.metric) is not None
                  and math.isfinite(float(r[spec.metric])) and float(r[spec.metric]) > 0]
        if finite and max(finite) > 20 * min(finite):
            ax.set_yscale("log")  # one bad flight must not flatten the others
        ax.set_xticks(xs, [value_label(v) for v in values])
        ax.set_xlabel(name)
        ax.set_ylabel(f"{spec.metric} (per flight)")
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=8)
    n_fl = len({r["flight"] for r in rows})
    fig.suptitle(
        f"sweep {spec.name}: {spec.metric}, median over {n_fl} {spec.split} flights "
        "(band: min to max)",
        fontsize=10,
    )
    return save_figure(fig, path)


def _write_ablation_figure(rows: list[dict[str, Any]], spec: SweepSpec, path: Path,
                           plt: Any) -> Path:
    """One-at-a-time mode: per profile, how much each changed setting moves the metric's mean
    over flights from the profile as it is (a bar per setting; red: worse)."""
    profiles = sorted({r["profile"] for r in rows})
    labels = [combo_label(c) for c in spec.combinations()[1:]]
    fig, axes = plt.subplots(
        1, len(profiles), figsize=(7.5 * len(profiles), 1.2 + 0.32 * len(labels)), squeeze=False
    )
    for ax, prof in zip(axes[0], profiles, strict=True):
        means: dict[str, float] = {}
        for label in ["-", *labels]:
            vals = [
                float(r[spec.metric]) for r in rows
                if r["profile"] == prof and combo_label(r["params"]) == label
                and r.get(spec.metric) is not None and math.isfinite(float(r[spec.metric]))
            ]
            means[label] = sum(vals) / len(vals) if vals else math.nan
        base = means["-"]
        ys = list(range(len(labels)))
        deltas = [means[lab] - base for lab in labels]
        colours = ["tab:red" if d > 0 else "tab:green" if d < 0 else "tab:gray" for d in deltas]
        ax.barh(ys, deltas, color=colours, alpha=0.7)
        ax.axvline(0.0, color="k", lw=1)
        for y, d in zip(ys, deltas, strict=True):
            if math.isfinite(d):
                ax.annotate(f"{d:+.1f}", (d, y), fontsize=7, va="center",
                            ha="left" if d >= 0 else "right")
        ax.set_yticks(ys, labels, fontsize=7)
        ax.invert_yaxis()
        ax.set_title(f"{prof}: as it is {base:.1f}", fontsize=9)
        ax.set_xlabel(f"change in {spec.metric} (mean over flights)")
        ax.grid(True, axis="x", alpha=0.3)
    n_fl = len({r["flight"] for r in rows})
    fig.suptitle(f"sweep {spec.name}: one setting at a time, {n_fl} {spec.split} flights "
                 "(red: worse than as it is)", fontsize=10)
    return save_figure(fig, path)


def save_figure(fig: Any, path: Path) -> Path:
    """Lay out, write (110 dpi) and close a sweep's figure."""
    import matplotlib.pyplot as plt

    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _same(a: Any, b: Any) -> bool:
    if isinstance(a, list):
        a = tuple(a)
    if isinstance(b, list):
        b = tuple(b)
    return bool(a == b)
