"""The benchmark's committed results, and the README tables rendered from them.

``uav_fusion bench --readme`` writes a run's pooled figures to
``bench/results/<definition>-<split>.json`` (beside the README) and replaces the README's
block between ``<!-- bench:<definition>-<split>:begin -->`` and
``<!-- bench:<definition>-<split>:end -->`` with the table rendered from that file.
``test/test_readme_results.py`` renders every results file again and checks that the
README's block equals it, so the README cannot show figures the benchmark did not write.

A results file holds the figures, not the run's timing: the same code on the same flights
writes the same figures (only the date and the package versions may change), and the
README's table changes only when the figures do.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from uav_fusion.core.bench.multi import MultiBenchScore, markdown_multi
from uav_fusion.core.bench.report import markdown_families, markdown_table
from uav_fusion.core.scoring.fixed_rate import GridScore

RESULTS_DIR = Path("bench") / "results"
# accuracy: one UAV; worlds: one UAV in world families (the pooled figures and, per family,
# ``families`` with the gross-episode threshold ``episode_error_m``); multi: several UAVs
KINDS = ("accuracy", "worlds", "multi")
# timing figures vary from run to run: they stay in the run's own summary.json
TIMING_FIELDS = frozenset({"run_s"})


def results_name(definition: str, split: str) -> str:
    """The block's and the file's name: ``<definition>-<split>``."""
    return f"{definition}-{split}"


def results_path(readme: Path, name: str) -> Path:
    """Where the results of ``name`` live for the README at ``readme``."""
    return readme.parent / RESULTS_DIR / f"{name}.json"


def markers(name: str) -> tuple[str, str]:
    return f"<!-- bench:{name}:begin -->", f"<!-- bench:{name}:end -->"


def _clean(fields: Mapping[str, Any]) -> dict[str, Any]:
    return {
        k: (None if isinstance(v, float) and not math.isfinite(v) else v)
        for k, v in fields.items()
        if k not in TIMING_FIELDS
    }


def results_doc(
    kind: str,
    name: str,
    command: str,
    prov: Mapping[str, Any],
    figures: Mapping[str, Mapping[str, Any]],
    extra: Mapping[str, Any] | None = None,
) -> dict[str, Any]:
    """The results file's contents: what was run, on what, and the pooled figures per profile
    (``extra``: for ``worlds``, ``episode_error_m`` and the per-family figures ``families``)."""
    if kind not in KINDS:
        raise ValueError(f"unknown benchmark kind {kind!r} (expected one of {KINDS})")
    doc: dict[str, Any] = {
        "name": name,
        "kind": kind,
        "command": command,
        "date": str(prov["date"])[:10],
        "split": prov["split"],
        "flights": prov["flights"],
        "versions": dict(prov["versions"]),
        "profiles": {p: _clean(f) for p, f in figures.items()},
    }
    if kind == "worlds":
        if not extra or "families" not in extra:
            raise ValueError("a worlds results file needs the per-family figures")
        doc["episode_error_m"] = float(extra["episode_error_m"])
        doc["families"] = {
            fam: {p: _clean(f) for p, f in by.items()} for fam, by in extra["families"].items()
        }
    return doc


def write_results(path: Path, doc: Mapping[str, Any]) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(doc, indent=1, allow_nan=False) + "\n", encoding="utf-8")
    return path


def load_results(path: Path) -> dict[str, Any]:
    doc: dict[str, Any] = json.loads(path.read_text(encoding="utf-8"))
    return doc


def _nan(fields: Mapping[str, Any]) -> dict[str, Any]:
    return {k: (math.nan if v is None else v) for k, v in fields.items()}


def render_table(doc: Mapping[str, Any]) -> str:
    """The pooled table of a results file, as the benchmark's own ``table.md`` renders it."""
    profiles: Mapping[str, Mapping[str, Any]] = doc["profiles"]
    if doc["kind"] == "accuracy":
        grid = {p: GridScore(**_nan(f)) for p, f in profiles.items()}
        return markdown_table(grid)
    if doc["kind"] == "worlds":
        fams = {
            fam: {p: GridScore(**_nan(f)) for p, f in by.items()}
            for fam, by in doc["families"].items()
        }
        return markdown_families(fams, float(doc["episode_error_m"]))
    multi = {p: MultiBenchScore(**{"run_s": math.nan, **_nan(f)}) for p, f in profiles.items()}
    return markdown_multi(multi, timing=False)


def render_block(doc: Mapping[str, Any]) -> str:
    """The README block of a results file, markers included."""
    begin, end = markers(str(doc["name"]))
    versions = ", ".join(f"{k} {v}" for k, v in doc["versions"].items())
    source = (RESULTS_DIR / f"{doc['name']}.json").as_posix()
    lines = [
        begin,
        f"`{doc['command']}` ({doc['split']} half, {doc['flights']} flights; {doc['date']}; "
        f"{versions}; written by the command into `{source}`):",
        "",
        render_table(doc),
        end,
    ]
    return "\n".join(lines)


def replace_block(text: str, name: str, block: str) -> str:
    """``text`` with the block of ``name`` (markers included) replaced by ``block``."""
    begin, end = markers(name)
    head, sep, rest = text.partition(begin)
    if not sep or end not in rest:
        raise ValueError(f"the markers {begin} / {end} are missing")
    _, _, tail = rest.partition(end)
    return head + block + tail


def read_block(text: str, name: str) -> str | None:
    """The block of ``name`` in ``text`` (markers included), or None."""
    begin, end = markers(name)
    start = text.find(begin)
    stop = text.find(end, start + len(begin)) if start >= 0 else -1
    if start < 0 or stop < 0:
        return None
    return text[start : stop + len(end)]


def block_names(text: str) -> list[str]:
    """Every benchmark block named in ``text``, in order."""
    out = []
    for part in text.split("<!-- bench:")[1:]:
        label, sep, _ = part.partition(":begin -->")
        if sep and " " not in label:
            out.append(label)
    return out
