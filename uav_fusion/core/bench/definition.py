"""The accuracy benchmark's definition: which generated flights, split into tune and test.

A definition (``bench/accuracy.yaml``) lists flight plans and seeds; every plan is flown with
every seed of a split. The **tune** half is for choosing a profile's numbers, the **test** half
for reporting them (docs/benchmark.md). The default flight (plan ``lake_wheeler_default``,
seed 1) reproduces the paper and belongs to neither half.

Keys (unknown keys are errors naming the file and the key):

``name``, ``description``
    free text;
``plans``
    flight plan names (``config/waypoints/<name>.yaml``) or YAML paths (relative to the
    definition's folder);
``splits``
    ``tune`` and ``test``: lists of integer seeds >= 0, disjoint; or, for flights generated in
    drawn worlds (docs/twin.md, "Worlds"), mappings ``{seeds: [...], families: [...]}``: every
    plan is flown in every listed world family with every seed, and the two halves share no
    family (leave families out: the test half's worlds come from families tuning never sees);
``worlds``
    the world families file (default ``config/worlds.yaml``; relative to the definition; only
    with families in the splits);
``twin_config``
    twin parameter file (default ``config/twin_default.yaml``; relative to the definition);
``duration_s``
    optional recording length of every flight (cuts the flights; for quick checks);
``targets``
    ``single`` (default: one UAV, scored on its fixed-rate output) or ``multi`` (flights with
    several UAVs, scored as a set of targets: GOSPA, per-UAV coverage, ID switches, false
    tracks; see :mod:`uav_fusion.core.scoring.gospa`);
``scoring``
    ``grid_hz`` (10; 1 for ``multi``), ``airborne_min_m`` (5), ``fresh_age_s`` (1),
    ``gross_error_m`` (100), ``observable_window_s`` (2), ``nees_probability`` (0.95),
    ``episode_error_m`` (300: a gross episode is a run of epochs with a larger error),
    ``excuse_grounded`` (true; ``multi`` only: a track on a UAV that is not airborne is
    excused rather than false, see :mod:`uav_fusion.core.scoring.gospa`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from uav_fusion.core.errors import ConfigError
from uav_fusion.core.scoring.fixed_rate import ScoreSettings
from uav_fusion.core.twin.worlds import DEFAULT_WORLDS, WorldFamilies, load_worlds
from uav_fusion.core.yamlio import read_yaml_file
from uav_fusion.resources import bench_path, config_path

SPLITS = ("tune", "test")
DEFAULT_DEFINITION = "accuracy.yaml"
DEFAULT_FLIGHT_PLAN = "lake_wheeler_default"
DEFAULT_FLIGHT_SEED = 1

_TOP_KEYS = (
    "name",
    "description",
    "targets",
    "plans",
    "splits",
    "twin_config",
    "worlds",
    "duration_s",
    "scoring",
)
TARGETS = ("single", "multi")
_SCORING_KEYS = (
    "grid_hz",
    "airborne_min_m",
    "fresh_age_s",
    "gross_error_m",
    "observable_window_s",
    "nees_probability",
    "episode_error_m",
    "excuse_grounded",
)


@dataclass(frozen=True)
class PlanRef:
    name: str  # the plan's key in flight ids (its file stem)
    path: Path


@dataclass(frozen=True)
class BenchFlight:
    """One flight of the benchmark: a plan flown with a seed."""

    plan: PlanRef
    seed: int
    split: str
    family: str | None = None  # the world family it is generated in (None: the twin's own)

    @property
    def flight_id(self) -> str:
        if self.family is None:
            return f"{self.plan.name}-s{self.seed}"
        return f"{self.plan.name}-{self.family}-s{self.seed}"


@dataclass(frozen=True)
class BenchDefinition:
    name: str
    description: str
    plans: tuple[PlanRef, ...]
    splits: dict[str, tuple[int, ...]]
    twin_config: Path
    duration_s: float | None
    grid_hz: float
    settings: ScoreSettings
    source: Path
    targets: str = "single"
    excuse_grounded: bool = True  # multi: tracks on UAVs not airborne are not false
    families: dict[str, tuple[str, ...]] | None = None  # world families per split
    worlds: WorldFamilies | None = None  # the families file, loaded (with ``families``)

    @property
    def multi(self) -> bool:
        """Flights with several UAVs, scored as a set of targets."""
        return self.targets == "multi"

    def flights(self, split: str) -> list[BenchFlight]:
        """The split's flights: plan by plan, seed by seed; with world families, family by
        family first."""
        if split not in self.splits:
            raise ConfigError(f"{self.source}: unknown split {split!r} (have {', '.join(SPLITS)})")
        seeds = self.splits[split]
        if self.families is None:
            return [BenchFlight(p, s, split) for p in self.plans for s in seeds]
        return [
            BenchFlight(p, s, split, fam)
            for fam in self.families[split]
            for p in self.plans
            for s in seeds
        ]


def definition_path(path_or_name: str | Path | None) -> Path:
    """A definition name (``accuracy``) maps to ``bench/<name>.yaml``; paths stay paths."""
    if path_or_name is None:
        return bench_path(DEFAULT_DEFINITION)
    s = str(path_or_name)
    p = Path(s)
    if p.suffix in (".yaml", ".yml") or p.is_file() or "/" in s:
        return p
    return bench_path(f"{s}.yaml")


def _plan(v: Any, i: int, base: Path, where: str) -> PlanRef:
    key = f"plans[{i}]"
    if not isinstance(v, str) or not v.strip():
        raise ConfigError(f"{where}: {key} must be a plan name or a YAML path, got {v!r}")
    s = v.strip()
    if s.endswith((".yaml", ".yml")) or "/" in s:
        p = Path(s) if Path(s).is_absolute() else base / s
        if not p.is_file():
            raise ConfigError(f"{where}: {key}: flight plan file {p} not found")
        return PlanRef(p.stem, p)
    p = config_path(f"waypoints/{s}.yaml")
    if not p.is_file():
        known = sorted(q.stem for q in p.parent.glob("*.yaml"))
        raise ConfigError(
            f"{where}: {key}: unknown plan {s!r} (known: {', '.join(known)}; or give a YAML path)"
        )
    return PlanRef(s, p)


def _seeds(v: Any, key: str, where: str) -> tuple[int, ...]:
    if not isinstance(v, list) or not v:
        raise ConfigError(f"{where}: {key} must be a non-empty list of seeds, got {v!r}")
    out: list[int] = []
    for j, s in enumerate(v):
        if not isinstance(s, int) or isinstance(s, bool) or s < 0:
            raise ConfigError(f"{where}: {key}[{j}] must be an integer >= 0, got {s!r}")
        if s in out:
            raise ConfigError(f"{where}: {key}: seed {s} is listed twice")
        out.append(s)
    return tuple(out)


def _world_split(raw: dict[str, Any], key: str, where: str) -> tuple[tuple[int, ...],
                                                                       tuple[str, ...]]:
    """A split flown in world families: ``{seeds: [...], families: [...]}``."""
    extra = sorted(set(raw) - {"seeds", "families"})
    if extra:
        raise ConfigError(
            f"{where}: unknown key(s) {', '.join(f'{key}.{x}' for x in extra)} "
            "(allowed: seeds, families)"
        )
    seeds = _seeds(raw.get("seeds"), f"{key}.seeds", where)
    fams = raw.get("families")
    if not isinstance(fams, list) or not fams or not all(isinstance(f, str) for f in fams):
        raise ConfigError(f"{where}: {key}.families must be a non-empty list of family names")
    for f in fams:
        if fams.count(f) > 1:
            raise ConfigError(f"{where}: {key}.families: {f!r} is listed twice")
    return seeds, tuple(fams)


def _families(
    doc: dict[str, Any], fams: dict[str, tuple[str, ...]], base: Path, where: str
) -> tuple[dict[str, tuple[str, ...]] | None, WorldFamilies | None]:
    """The splits' world families (both halves or neither, disjoint) and their file."""
    wf = doc.get("worlds")
    if not fams:
        if wf is not None:
            raise ConfigError(
                f"{where}: worlds: a families file needs world families in the splits "
                "(splits.<half>: {seeds: [...], families: [...]})"
            )
        return None, None
    if set(fams) != set(SPLITS):
        missing = [k for k in SPLITS if k not in fams]
        raise ConfigError(
            f"{where}: splits.{missing[0]} must name its world families too "
            "({seeds: [...], families: [...]}): both halves or neither"
        )
    common = sorted(set(fams["tune"]) & set(fams["test"]))
    if common:
        raise ConfigError(
            f"{where}: splits.test.families: {', '.join(common)} also in splits.tune.families "
            "(the test half's worlds come from families tuning never sees)"
        )
    if wf is None:
        path = config_path(DEFAULT_WORLDS)
    elif isinstance(wf, str) and wf.strip():
        path = Path(wf) if Path(wf).is_absolute() else base / wf
        if not path.is_file():
            raise ConfigError(f"{where}: worlds: file {path} not found")
    else:
        raise ConfigError(f"{where}: worlds must be a file path or null, got {wf!r}")
    worlds = load_worlds(path)
    for k in SPLITS:
        for f in fams[k]:
            if f not in worlds.families:
                raise ConfigError(
                    f"{where}: splits.{k}.families: unknown world family {f!r} in {path} "
                    f"(known: {', '.join(worlds.families)})"
                )
    return {k: fams[k] for k in SPLITS}, worlds


def _number(d: dict[str, Any], key: str, where: str, default: float, positive: bool) -> float:
    v = d.get(key, default)
    if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
        raise ConfigError(f"{where}: {key} must be a number, got {v!r}")
    if positive and not v > 0:
        raise ConfigError(f"{where}: {key} must be > 0, got {v!r}")
    return float(v)


def definition_from_dict(doc: Any, source: Path) -> BenchDefinition:
    """Validate a parsed definition document (``source``: its file, for errors and paths)."""
    where = str(source)
    if not isinstance(doc, dict):
        raise ConfigError(f"{where}: expected a mapping at top level")
    for k in doc:
        if k not in _TOP_KEYS:
            raise ConfigError(f"{where}: unknown key {k!r} (allowed: {', '.join(_TOP_KEYS)})")
    base = source.parent
    targets = doc.get("targets", "single")
    if targets not in TARGETS:
        raise ConfigError(f"{where}: targets must be one of {', '.join(TARGETS)}, got {targets!r}")
    raw_plans = doc.get("plans")
    if not isinstance(raw_plans, list) or not raw_plans:
        raise ConfigError(f"{where}: plans must be a non-empty list of flight plans")
    plans = tuple(_plan(v, i, base, where) for i, v in enumerate(raw_plans))
    names = [p.name for p in plans]
    for n in names:
        if names.count(n) > 1:
            raise ConfigError(f"{where}: plans: {n!r} is listed twice")
    raw_splits = doc.get("splits")
    if not isinstance(raw_splits, dict):
        raise ConfigError(f"{where}: splits must be a mapping with 'tune' and 'test' seed lists")
    for k in raw_splits:
        if k not in SPLITS:
            raise ConfigError(f"{where}: unknown key 'splits.{k}' (allowed: {', '.join(SPLITS)})")
    splits = {}
    fams: dict[str, tuple[str, ...]] = {}
    for k in SPLITS:
        if k not in raw_splits:
            raise ConfigError(f"{where}: splits.{k} is missing")
        raw = raw_splits[k]
        if isinstance(raw, dict):
            splits[k], fams[k] = _world_split(raw, f"splits.{k}", where)
        else:
            splits[k] = _seeds(raw, f"splits.{k}", where)
    families, worlds = _families(doc, fams, base, where)
    common = sorted(set(splits["tune"]) & set(splits["test"]))
    if common:
        raise ConfigError(
            f"{where}: splits.test: seed(s) {', '.join(map(str, common))} also in splits.tune "
            "(a flight tuned on cannot be a test flight)"
        )
    if DEFAULT_FLIGHT_PLAN in names:
        for k in SPLITS:
            if DEFAULT_FLIGHT_SEED in splits[k]:
                raise ConfigError(
                    f"{where}: splits.{k}: seed {DEFAULT_FLIGHT_SEED} with plan "
                    f"{DEFAULT_FLIGHT_PLAN!r} is the default flight (the paper reproduction); "
                    "it belongs to neither half"
                )
    tc = doc.get("twin_config")
    if tc is None:
        twin_config = config_path("twin_default.yaml")
    elif isinstance(tc, str) and tc.strip():
        twin_config = Path(tc) if Path(tc).is_absolute() else base / tc
        if not twin_config.is_file():
            raise ConfigError(f"{where}: twin_config: file {twin_config} not found")
    else:
        raise ConfigError(f"{where}: twin_config must be a file path or null, got {tc!r}")
    dur = doc.get("duration_s")
    duration = None if dur is None else _number(doc, "duration_s", where, 0.0, True)
    sc = doc.get("scoring", {}) or {}
    if not isinstance(sc, dict):
        raise ConfigError(f"{where}: scoring must be a mapping")
    for k in sc:
        if k not in _SCORING_KEYS:
            raise ConfigError(
                f"{where}: unknown key 'scoring.{k}' (allowed: {', '.join(_SCORING_KEYS)})"
            )
    sw = f"{where}: scoring"
    d = ScoreSettings()
    prob = _number(sc, "nees_probability", sw, d.nees_probability, True)
    if not prob < 1:
        raise ConfigError(f"{sw}: nees_probability must lie in (0, 1), got {prob}")
    settings = ScoreSettings(
        airborne_min_m=_number(sc, "airborne_min_m", sw, d.airborne_min_m, False),
        fresh_age_s=_number(sc, "fresh_age_s", sw, d.fresh_age_s, True),
        gross_error_m=_number(sc, "gross_error_m", sw, d.gross_error_m, True),
        observable_window_s=_number(sc, "observable_window_s", sw, d.observable_window_s, True),
        max_truth_gap_s=d.max_truth_gap_s,
        nees_probability=prob,
        episode_error_m=_number(sc, "episode_error_m", sw, d.episode_error_m, True),
    )
    excuse = sc.get("excuse_grounded", True)
    if not isinstance(excuse, bool):
        raise ConfigError(f"{sw}: excuse_grounded must be true or false, got {excuse!r}")
    desc = doc.get("description", "") or ""
    return BenchDefinition(
        name=str(doc.get("name", source.stem)),
        description=str(desc).strip(),
        plans=plans,
        splits=splits,
        twin_config=twin_config,
        duration_s=duration,
        grid_hz=_number(sc, "grid_hz", sw, 1.0 if targets == "multi" else 10.0, True),
        settings=settings,
        source=source,
        targets=str(targets),
        excuse_grounded=excuse,
        families=families,
        worlds=worlds,
    )


def load_definition(path_or_name: str | Path | None = None) -> BenchDefinition:
    """Load and validate a benchmark definition (default ``bench/accuracy.yaml``)."""
    p = definition_path(path_or_name)
    return definition_from_dict(read_yaml_file(p, "benchmark definition"), p)
