"""Parameter sweeps: flights x profiles x a grid of profile parameters, scored like the benchmark.

A sweep spec (YAML, e.g. ``bench/sweep_q.yaml``) names:

``name``, ``description``
    free text;
``definition``
    the benchmark definition whose flights and scoring settings are used (a name under
    ``bench/`` or a path relative to the spec; default ``accuracy``);
``split``
    ``tune`` (default) or ``test``: which half's seeds (tuning belongs on ``tune``);
``plans``, ``seeds``, ``families``
    optional subsets of the definition's plans, of the split's seeds and (a definition flown
    in world families) of the split's families;
``profiles``
    estimator profiles (names under ``config/profiles/`` or paths relative to the spec);
``parameters``
    a mapping from a profile key, by its YAML path (``motion.q``, ``gating.nis_probability``,
    ``association.object.tau_s``; any key of the schema, :mod:`~uav_fusion.core.estimators.
    schema`, whose value is a number, an integer, true/false, a choice or ``motion.q``), to
    the list of values to try; ``multi.<key>`` (the multi-UAV tracker's section) needs a
    multi-UAV definition; every combination is run with every profile on every flight;
``metric``
    the figure plotted against each parameter (a
    :class:`~uav_fusion.core.scoring.fixed_rate.GridScore`
    field, default ``err_mean_m``; with a multi-UAV definition a
    :class:`~uav_fusion.core.bench.multi.MultiBenchScore` field, default ``gospa_mean_m``).

Each task (one flight, one profile, one combination) loads the flight from the benchmark's
cache (generating it if missing), runs the estimator and scores its fixed-rate output with the
benchmark's metrics (:func:`uav_fusion.core.bench.single.score_task`; a multi-UAV definition's
flights run the multi-UAV tracker and are scored as a set of targets,
:func:`uav_fusion.core.bench.multi.multi_score_task`, each flight's figures on their own).
Its result is keyed by a hash of its inputs (the flight's cache key, the bytes of the profile
file and of the files it extends, the parameter values, the scoring settings and the source of
the package's core, which computes it), so a re-run computes only what is missing and a
changed estimator computes everything again. A task that raises is reported as a failure row
with its inputs and does not stop the others.
"""

from __future__ import annotations

import hashlib
import itertools
import json
import math
import time
import traceback
from dataclasses import asdict, dataclass, fields
from pathlib import Path
from typing import Any

from uav_fusion.core.bench.cache import (
    CachedFlight,
    cached_flights,
    core_source_digest,
    generate_flight,
)
from uav_fusion.core.bench.definition import (
    SPLITS,
    BenchDefinition,
    definition_path,
    load_definition,
)
from uav_fusion.core.bench.multi import (
    MultiBenchScore,
    MultiScoreTask,
    multi_score_task,
    pool_multi,
)
from uav_fusion.core.bench.single import ScoreTask, score_task
from uav_fusion.core.errors import ConfigError, UavFusionError
from uav_fusion.core.profiles.checks import BOOL, CHOICE, INTEGER, NUMBER, Q3, check, convert
from uav_fusion.core.profiles.model import (
    Profile,
    load_profile,
    profile_files,
    profile_path,
)
from uav_fusion.core.profiles.schema import belongs, find
from uav_fusion.core.scoring.fixed_rate import GridScore, ScoreSettings, pool
from uav_fusion.core.site import Site
from uav_fusion.core.yamlio import read_yaml_file

_TOP_KEYS = (
    "name",
    "description",
    "definition",
    "split",
    "plans",
    "seeds",
    "families",
    "profiles",
    "parameters",
    "mode",
    "metric",
)

#: How a sweep combines its parameters: ``grid``, every combination of their values;
#: ``one_at_a_time``, the profiles as they are and then each value of each parameter alone
#: (what each rule or setting buys, against the profile's own value).
MODES = ("grid", "one_at_a_time")

#: The kinds of profile key a sweep may vary (numbers, integers, true/false, choices, q).
SWEEPABLE = (NUMBER, INTEGER, BOOL, CHOICE, Q3)

METRICS = tuple(f.name for f in fields(GridScore) if f.name not in ("flights",))
#: The figures of a multi-UAV definition's tasks (one flight each).
MULTI_METRICS = tuple(
    f.name for f in fields(MultiBenchScore) if f.name not in ("profile", "flights", "run_s")
)
#: ``multi.<key>``: a key of the profile's multi section (multi-UAV definitions only).
MULTI_PREFIX = "multi."


@dataclass(frozen=True)
class SweepSpec:
    name: str
    description: str
    definition: BenchDefinition
    split: str
    plans: tuple[str, ...]  # plan names in the sweep
    seeds: tuple[int, ...]
    profiles: tuple[Path, ...]
    parameters: dict[str, tuple[Any, ...]]
    metric: str
    source: Path
    families: tuple[str, ...] | None = None  # world families in the sweep (None: no worlds)
    mode: str = "grid"

    @property
    def metrics(self) -> tuple[str, ...]:
        """The figures each task gives: the benchmark's, single- or multi-UAV."""
        return MULTI_METRICS if self.definition.multi else METRICS

    def combinations(self) -> list[dict[str, Any]]:
        """Every combination of the parameter values (one empty one without parameters); in
        ``one_at_a_time`` mode the empty one (the profiles as they are) and each value of each
        parameter alone."""
        names = list(self.parameters)
        if self.mode == "one_at_a_time":
            return [{}] + [{n: v} for n in names for v in self.parameters[n]]
        return [
            dict(zip(names, values, strict=True))
            for values in itertools.product(*(self.parameters[n] for n in names))
        ]


def _parameter(name: str, values: Any, definition: BenchDefinition, src: str) -> tuple[Any, ...]:
    """A parameter's values, converted and checked by the profile schema (the profile's own
    rules between keys follow when a combination is applied)."""
    where = f"{src}: parameters.{name}"
    key = find(name)
    if key is None or not key.attr or key.kind not in SWEEPABLE:
        there = [p for p in belongs(name.rpartition(".")[2]) if p != name]
        hint = f"; {name!r} is at {' or '.join(there)}" if key is None and there else ""
        raise ConfigError(
            f"{where}: unknown parameter (a profile key with a number, an integer, true/false "
            f"or a choice, by its YAML path such as motion.q or gating.nis_probability{hint})"
        )
    if name.startswith(MULTI_PREFIX) and not definition.multi:
        raise ConfigError(
            f"{where}: a multi-UAV tracker setting needs a multi-UAV definition "
            f"({definition.source} has targets: {definition.targets})"
        )
    if not isinstance(values, list) or not values:
        raise ConfigError(f"{where}: a non-empty list of values expected")
    out = []
    for v in values:
        x = convert(key, v, f"{src}: parameters")
        check(key, x, f"{src}: parameters")
        out.append(x)
    return tuple(out)


def spec_from_dict(doc: Any, source: Path) -> SweepSpec:
    """Validate a parsed sweep spec; every error names the file and the key."""
    src = str(source)
    if not isinstance(doc, dict):
        raise ConfigError(f"{src}: expected a mapping at top level")
    unknown = sorted(set(doc) - set(_TOP_KEYS))
    if unknown:
        raise ConfigError(
            f"{src}: unknown key(s) {', '.join(unknown)} (allowed: {', '.join(_TOP_KEYS)})"
        )
    base = source.parent
    ddef = doc.get("definition", "accuracy")
    if not isinstance(ddef, str):
        raise ConfigError(f"{src}: definition: a definition name or path expected")
    dpath = definition_path(ddef)
    if not dpath.is_absolute() and "/" in ddef:
        dpath = base / ddef
    definition = load_definition(dpath)
    split = doc.get("split", "tune")
    if split not in SPLITS:
        raise ConfigError(f"{src}: split: one of {', '.join(SPLITS)} expected, got {split!r}")
    have_plans = [p.name for p in definition.plans]
    plans = doc.get("plans", have_plans)
    if not isinstance(plans, list) or not plans or not all(isinstance(p, str) for p in plans):
        raise ConfigError(f"{src}: plans: a non-empty list of plan names expected")
    for p in plans:
        if p not in have_plans:
            raise ConfigError(
                f"{src}: plans: unknown plan {p!r} (the definition {definition.source} has "
                f"{', '.join(have_plans)})"
            )
    have_seeds = list(definition.splits[split])
    seeds = doc.get("seeds", have_seeds)
    if not isinstance(seeds, list) or not seeds:
        raise ConfigError(f"{src}: seeds: a non-empty list of seeds expected")
    for s in seeds:
        if s not in have_seeds:
            raise ConfigError(
                f"{src}: seeds: seed {s!r} is not in the {split} half of {definition.source} "
                f"({', '.join(str(x) for x in have_seeds)})"
            )
    have_fams = list(definition.families[split]) if definition.families else []
    fams = doc.get("families", have_fams)
    if "families" in doc and not have_fams:
        raise ConfigError(
            f"{src}: families: the definition {definition.source} flies no world families"
        )
    if not isinstance(fams, list) or (have_fams and not fams):
        raise ConfigError(f"{src}: families: a non-empty list of world family names expected")
    for f in fams:
        if f not in have_fams:
            raise ConfigError(
                f"{src}: families: {f!r} is not a family of the {split} half of "
                f"{definition.source} ({', '.join(have_fams)})"
            )
    profs = doc.get("profiles")
    if not isinstance(profs, list) or not profs or not all(isinstance(p, str) for p in profs):
        raise ConfigError(f"{src}: profiles: a non-empty list of profile names expected")
    paths = []
    for p in profs:
        path = profile_path(p)
        if not path.is_absolute() and not path.is_file() and (base / p).is_file():
            path = base / p
        if not path.is_file():
            raise ConfigError(f"{src}: profiles: unknown profile {p!r} (no file {path})")
        paths.append(path)
    params_raw = doc.get("parameters", {})
    if params_raw is None:
        params_raw = {}
    if not isinstance(params_raw, dict):
        raise ConfigError(f"{src}: parameters: a mapping of parameter -> list of values expected")
    params: dict[str, tuple[Any, ...]] = {}
    for name, values in params_raw.items():
        params[str(name)] = _parameter(str(name), values, definition, src)
    mode = doc.get("mode", "grid")
    if mode not in MODES:
        raise ConfigError(f"{src}: mode: one of {', '.join(MODES)} expected, got {mode!r}")
    metrics = MULTI_METRICS if definition.multi else METRICS
    metric = doc.get("metric", "gospa_mean_m" if definition.multi else "err_mean_m")
    if metric not in metrics:
        raise ConfigError(f"{src}: metric: one of {', '.join(metrics)} expected, got {metric!r}")
    spec = SweepSpec(
        name=str(doc.get("name", source.stem)),
        description=str(doc.get("description", "")),
        definition=definition,
        split=split,
        plans=tuple(plans),
        seeds=tuple(int(s) for s in seeds),
        profiles=tuple(paths),
        parameters=params,
        metric=metric,
        source=source,
        families=tuple(fams) if have_fams else None,
        mode=mode,
    )
    # apply every combination to every profile once, so a value the profile refuses (e.g. a
    # q of the wrong sign) stops here, naming the spec and the parameter, not in a worker
    for path in spec.profiles:
        prof = load_profile(path)
        for combo in spec.combinations():
            try:
                apply_parameters(prof, combo)
            except ConfigError as exc:
                raise ConfigError(f"{src}: parameters {combo}: {exc}") from None
    return spec


def load_spec(path: str | Path) -> SweepSpec:
    p = Path(path)
    return spec_from_dict(read_yaml_file(p, "sweep spec"), p)


def apply_parameters(profile: Profile, combo: dict[str, Any]) -> Profile:
    """``profile`` with the combination's values (validated by the profile's own rules)."""
    return profile.with_keys(combo) if combo else profile


@dataclass(frozen=True)
class SweepTask:
    """One task: a flight, a profile (file) and a parameter combination."""

    key: str
    flight: CachedFlight
    definition: BenchDefinition
    profile_path: Path
    params: dict[str, Any]
    site: Site
    grid_hz: float
    settings: ScoreSettings

    def describe(self) -> str:
        return f"{self.profile_path.stem} {self.params} on {self.flight.flight_id}"


def task_key(
    flight: CachedFlight,
    profile_file: Path,
    params: dict[str, Any],
    definition: BenchDefinition,
    code: str,
) -> str:
    """Hash of a task's inputs: what decides its result (``code``: the digest of the core's
    source, :func:`~uav_fusion.core.bench.cache.core_source_digest`)."""
    h = hashlib.sha256()
    h.update(b"\0code\0" + code.encode())
    h.update(flight.folder.name.encode())  # plan, seed and the flight's cache key
    for f in profile_files(profile_file):  # the file and those it extends
        h.update(b"\0profile\0" + f.read_bytes())
    h.update(b"\0params\0" + json.dumps(params, sort_keys=True).encode())
    scoring: tuple[object, ...] = (definition.grid_hz, definition.settings)
    if definition.multi:
        scoring += ("multi", definition.excuse_grounded)
    h.update(b"\0scoring\0" + repr(scoring).encode())
    return h.hexdigest()[:20]


def sweep_tasks(spec: SweepSpec, cache_dir: Path, site_file: Path, site: Site) -> list[SweepTask]:
    """Every task of the sweep, flight by flight, profile by profile, combination by
    combination."""
    flights = [
        f
        for f in cached_flights(spec.definition, spec.split, cache_dir, site_file)
        if f.flight.plan.name in spec.plans
        and f.flight.seed in spec.seeds
        and (spec.families is None or f.flight.family in spec.families)
    ]
    code = core_source_digest()
    out = []
    for f in flights:
        for path in spec.profiles:
            for combo in spec.combinations():
                out.append(
                    SweepTask(
                        key=task_key(f, path, combo, spec.definition, code),
                        flight=f,
                        definition=spec.definition,
                        profile_path=path,
                        params=combo,
                        site=site,
                        grid_hz=spec.definition.grid_hz,
                        settings=spec.definition.settings,
                    )
                )
    return out


def run_sweep_task(task: SweepTask) -> dict[str, Any]:
    """Run one task; never raises: a failure comes back as a row with ``error`` set."""
    t0 = time.perf_counter()
    row: dict[str, Any] = {
        "key": task.key,
        "flight": task.flight.flight_id,
        "plan": task.flight.flight.plan.name,
        "seed": task.flight.flight.seed,
        "family": task.flight.flight.family or "",
        "profile": task.profile_path.stem,
        "params": task.params,
        "error": "",
    }
    try:
        generate_flight(task.flight, task.definition, task.site)
        profile = apply_parameters(load_profile(task.profile_path), task.params)
        if task.definition.multi:
            st = task.settings
            mres = multi_score_task(
                MultiScoreTask(
                    task.flight, profile, task.site, task.grid_hz, st.airborne_min_m,
                    st.observable_window_s, task.definition.excuse_grounded,
                )
            )  # fmt: skip
            mscore = pool_multi([mres])[profile.name]
            row.update({k: v for k, v in asdict(mscore).items() if k in MULTI_METRICS})
        else:
            result = score_task(
                ScoreTask(task.flight, profile, task.site, task.grid_hz, task.settings)
            )
            score = pool([result.samples], task.settings)
            row.update({k: v for k, v in asdict(score).items() if k != "flights"})
        row["profile"] = profile.name
    except Exception as exc:
        kind = "" if isinstance(exc, UavFusionError) else f"{type(exc).__name__}: "
        row["error"] = f"{kind}{exc}"
        row["traceback"] = traceback.format_exc(limit=6)
    row["seconds"] = round(time.perf_counter() - t0, 3)
    return row


class ResultStore:
    """The sweep's results, one JSON line per finished task (``results.jsonl``), appended as
    tasks finish so an interrupted run keeps what was done. Failures are not stored: a re-run
    tries them again."""

    def __init__(self, folder: Path) -> None:
        folder.mkdir(parents=True, exist_ok=True)
        self.path = folder / "results.jsonl"
        self.rows: dict[str, dict[str, Any]] = {}
        if self.path.is_file():
            text = self.path.read_text(encoding="utf-8")
            cut = 0
            for n, line in enumerate(text.splitlines(), 1):
                if not line.strip():
                    continue
                try:
                    row = json.loads(line)
                except json.JSONDecodeError:  # a line cut by an interruption
                    cut += 1
                    continue
                if isinstance(row, dict) and isinstance(row.get("key"), str):
                    self.rows[row["key"]] = row
                else:
                    raise ConfigError(f"{self.path}:{n}: not a sweep result row")
            if cut or (text and not text.endswith("\n")):
                # rewrite without the cut line, so appended rows start on a line of their own
                self.path.write_text(
                    "".join(json.dumps(r, default=_json_default) + "\n"
                            for r in self.rows.values()),
                    encoding="utf-8",
                )

    def __contains__(self, key: str) -> bool:
        return key in self.rows

    def add(self, row: dict[str, Any]) -> None:
        if row.get("error"):
            return
        self.rows[row["key"]] = row
        with self.path.open("a", encoding="utf-8") as fh:
            fh.write(json.dumps(row, default=_json_default) + "\n")


def _json_default(v: Any) -> Any:
    if isinstance(v, float) and not math.isfinite(v):
        return None
    if hasattr(v, "item"):
        return v.item()
    raise TypeError(f"not JSON serialisable: {v!r}")


RESULT_COLUMNS = ("flight", "plan", "seed", "family", "profile")


def write_table(rows: list[dict[str, Any]], spec: SweepSpec, path: Path) -> Path:
    """One CSV row per task: inputs (flight, profile, one column per parameter) then the
    benchmark's figures."""
    import csv

    pnames = list(spec.parameters)
    with path.open("w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh)
        w.writerow([*RESULT_COLUMNS, *pnames, *spec.metrics, "seconds", "key"])
        for r in rows:
            w.writerow(
                [r.get(c, "") for c in RESULT_COLUMNS]
                + [_cell(r["params"].get(p)) for p in pnames]
                + [_cell(r.get(m)) for m in spec.metrics]
                + [r.get("seconds", ""), r["key"]]
            )
    return path


def _cell(v: Any) -> str:
    if v is None:
        return ""
    if isinstance(v, (list, tuple)):
        return " ".join(_cell(x) for x in v)
    if isinstance(v, float):
        return f"{v:.6g}"
    return str(v)


def value_label(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (list, tuple)):
        return str(v[0]) if len(set(v)) == 1 else "/".join(str(x) for x in v)
    if v is None:
        return "null"
    return v if isinstance(v, str) else f"{v:g}"


def combo_label(params: dict[str, Any]) -> str:
    """A parameter combination as ``name=value, ...`` (``-`` without parameters)."""
    return ", ".join(f"{k}={value_label(v)}" for k, v in params.items()) or "-"


def summary_rows(rows: list[dict[str, Any]], spec: SweepSpec) -> list[tuple[str, str, float,
                                                                               float, float, int]]:
    """Per profile and combination: the metric's mean, min and max over the flights."""
    groups: dict[tuple[str, str], list[float]] = {}
    for r in rows:
        label = combo_label(r["params"])
        val = r.get(spec.metric)
        if val is None or not math.isfinite(float(val)):
            continue
        groups.setdefault((r["profile"], label), []).append(float(val))
    out = []
    for (prof, label), vals in groups.items():
        out.append((prof, label, sum(vals) / len(vals), min(vals), max(vals), len(vals)))
    return out
