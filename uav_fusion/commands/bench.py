"""``uav_fusion bench``: the accuracy benchmark (docs/benchmark.md).

Generates the definition's flights into the cache (once), runs every listed profile over every
flight of the split in parallel on a Dask cluster, scores each run's fixed-rate output beside
the radar's own track passed through (the row ``radar``, :mod:`uav_fusion.core.bench.
radar_baseline`), prints one table (a row per profile, the pooled figures) with provenance
and each profile against the radar on the epochs both cover, and writes the per-flight
CSV, the figure, the table in Markdown and a JSON summary. A multi-UAV definition
(``targets: multi``, e.g. ``--definition multi``) runs the multi-UAV tracker instead and
scores every flight's tracks as a set (:mod:`uav_fusion.core.bench.multi`). With
``--readme`` it also writes the pooled figures to ``bench/results/<definition>-<split>.json``
and the table rendered from them into the README (:mod:`uav_fusion.core.bench.results`).
"""

from __future__ import annotations

import argparse
import json
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any, TypeVar

from uav_fusion.core.bench.cache import CachedFlight, cached_flights
from uav_fusion.core.bench.definition import SPLITS, BenchDefinition, load_definition
from uav_fusion.core.bench.radar_baseline import NAME as RADAR_BASELINE
from uav_fusion.core.bench.radar_baseline import against_radar_single, markdown_against_radar
from uav_fusion.core.bench.report import (
    CSV_FILE,
    FIGURE_FILE,
    JSON_FILE,
    RADAR_FIGURE_FILE,
    TABLE_FILE,
    markdown_families,
    markdown_flights,
    markdown_table,
    pooled,
    pooled_by_family,
    provenance,
    provenance_lines,
    registration_lines,
    text_families,
    text_table,
    write_csv,
    write_figure,
    write_radar_figure,
    write_summary_json,
)
from uav_fusion.core.bench.results import (
    markers,
    render_block,
    replace_block,
    results_doc,
    results_name,
    results_path,
    write_results,
)
from uav_fusion.core.bench.single import GenerateTask, ScoreTask, generate_task, score_task
from uav_fusion.core.errors import ConfigError
from uav_fusion.core.profiles.model import Profile, load_profile, profile_path
from uav_fusion.core.site import Site, load_site
from uav_fusion.resources import DEFAULT_SITE, config_path

T = TypeVar("T")
R = TypeVar("R")

HELP = "accuracy benchmark: profiles x generated flights (tune/test split), fixed-rate scores"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--definition",
        help="benchmark definition: a name under bench/ or a YAML path (default: "
        "bench/accuracy.yaml)",
    )
    parser.add_argument(
        "--profiles",
        nargs="+",
        default=["paper"],
        metavar="PROFILE",
        help="estimator profiles: names (config/profiles/<name>.yaml) or YAML paths "
        "(default: paper)",
    )
    parser.add_argument(
        "--split", choices=SPLITS, default="test", help="which half to run (default: test)"
    )
    parser.add_argument("--out", help="output folder (default: out/bench/<definition>-<split>)")
    add_engine_arguments(parser)
    parser.add_argument("--no-figure", action="store_true", help="do not draw the figure")
    parser.add_argument(
        "--readme",
        nargs="?",
        const="README.md",
        metavar="FILE",
        help="also write the pooled figures to bench/results/<definition>-<split>.json beside "
        "FILE and replace FILE's table between the bench:<definition>-<split> markers "
        "(FILE default: README.md)",
    )


def add_engine_arguments(parser: argparse.ArgumentParser) -> None:
    """The options of the commands that run on the Dask engine (bench, sweep)."""
    parser.add_argument(
        "--cache", default="out/bench_cache", help="flight cache folder (default: out/bench_cache)"
    )
    parser.add_argument(
        "--workers", type=int, help="local worker processes (default: one per core)"
    )
    parser.add_argument(
        "--scheduler", metavar="ADDRESS", help="use an existing Dask cluster (e.g. tcp://host:8786)"
    )
    parser.add_argument(
        "--threads",
        action="store_true",
        help="local workers as threads of this process instead of processes (for debugging)",
    )
    parser.add_argument("--site", help="site YAML (default: the shipped Lake Wheeler site)")


def run(args: argparse.Namespace) -> int:
    wall0 = time.perf_counter()
    definition = load_definition(args.definition)
    profiles = [load_profile(p) for p in args.profiles]
    names = [p.name for p in profiles]
    for p, arg in zip(profiles, args.profiles, strict=True):
        if names.count(p.name) > 1:
            raise ConfigError(
                f"{profile_path(arg)}: profile name {p.name!r} is used by two of the listed "
                "profiles (the table's rows are named by it)"
            )
    for p in profiles:
        if p.name == RADAR_BASELINE:
            raise ConfigError(
                f"{p.source}: the profile name {RADAR_BASELINE!r} is the benchmark's baseline "
                "(the radar's own tracks); rename the profile"
            )
    if args.workers is not None and args.workers < 1:
        raise ConfigError(f"--workers must be >= 1, got {args.workers}")
    site_file = Path(args.site) if args.site else config_path(DEFAULT_SITE)
    site = load_site(site_file)
    if args.readme:  # refuse before the run, not after it
        _check_readme(Path(args.readme), results_name(definition.name, args.split))
    cache = Path(args.cache)
    flights = cached_flights(definition, args.split, cache, site_file)
    out = Path(args.out) if args.out else Path("out/bench") / f"{definition.name}-{args.split}"
    out.mkdir(parents=True, exist_ok=True)
    missing = [f for f in flights if not f.exists()]
    fams = definition.families[args.split] if definition.families else ()
    in_worlds = f" x {len(fams)} world families ({', '.join(fams)})" if fams else ""
    print(
        f"bench {definition.name} ({definition.source}): split {args.split}, "
        f"{len(flights)} flights ({len(definition.plans)} plans{in_worlds} x "
        f"{len(definition.splits[args.split])} seeds), profiles {', '.join(names)}"
    )
    print(
        f"  cache {cache}: {len(flights) - len(missing)} flights cached, {len(missing)} to generate"
    )
    if definition.multi:
        return _run_multi(args, definition, profiles, site, flights, missing, out, wall0)
    # the profiles, then the radar's own track passed through (radar_baseline.py)
    tasks = [
        ScoreTask(f, p, site, definition.grid_hz, definition.settings, baseline=base)
        for p, base in [*((p, False) for p in profiles), (profiles[0], True)]
        for f in flights
    ]
    results, runs = _generate_and_run(
        args, definition, site, missing, score_task, tasks,
        lambda t: f"{RADAR_BASELINE if t.baseline else t.profile.name} on {t.flight.flight_id}",
    )  # fmt: skip
    settings = definition.settings
    scores = pooled(results, settings)
    prov = _provenance(args, definition, flights, profiles)
    print()
    print(
        f"pooled over {len(flights)} {args.split} flights, {definition.grid_hz:g} Hz grid, "
        f"airborne epochs (truth > {settings.airborne_min_m:g} m above take-off):"
    )
    print(text_table(scores))
    by_family = pooled_by_family(results, settings) if definition.families else None
    if by_family is not None:
        print()
        print(
            f"per world family (worst flight mean: the largest mean error of one flight; "
            f"longest: the longest run of epochs more than {settings.episode_error_m:g} m off):"
        )
        print(text_families(by_family, settings.episode_error_m))
    vs_radar = against_radar_single(results)
    print()
    print("against the radar's own track (its most UAV-like report, class >= 0.5, passed "
          "through):")
    for c in vs_radar:
        print(f"  {c.line()}")
    reg_lines = registration_lines(results)
    if reg_lines:
        print()
        print("radar registration at the end of each flight (the bound: the estimate's "
              "sigma widened for noisier, correlated residuals):")
        for line in reg_lines:
            print(f"  {line}")
    print()
    for line in provenance_lines(prov):
        print(f"  {line}")
    csv_path = write_csv(results, settings, out / CSV_FILE)
    table_path = out / TABLE_FILE
    family_md = (
        "" if by_family is None
        else markdown_families(by_family, settings.episode_error_m) + "\n\n"
    )  # fmt: skip
    table_path.write_text(
        markdown_table(scores) + "\n\n" + family_md + markdown_flights(results, settings)
        + "\n\n" + markdown_against_radar(vs_radar) + "\n",
        encoding="utf-8",
    )  # fmt: skip
    print(f"per-flight figures: {csv_path}")
    if not args.no_figure:
        print(f"figure: {write_figure(results, settings, out / FIGURE_FILE)}")
        print(f"figure: {write_radar_figure(vs_radar, out / RADAR_FIGURE_FILE)}")
    timing = f"{time.perf_counter() - wall0:.1f} s ({runs})"
    prov["wall_time"] = timing
    json_path = write_summary_json(scores, prov, out / JSON_FILE, by_family, vs_radar)
    print(f"table (Markdown): {table_path}; summary: {json_path}")
    if args.readme:
        figures = {p: sc.as_dict() for p, sc in scores.items()}
        extra: dict[str, Any] = {}
        if by_family is not None:
            extra = {
                "episode_error_m": settings.episode_error_m,
                "families": {
                    fam: {p: sc.as_dict() for p, sc in by.items()}
                    for fam, by in by_family.items()
                },
            }
        _publish(args, definition, "worlds" if extra else "accuracy", prov, figures, extra)
    print(f"wall time {timing}")
    return 0


def _check_readme(readme: Path, name: str) -> None:
    begin, end = markers(name)
    try:
        text = readme.read_text(encoding="utf-8")
    except OSError as exc:
        raise ConfigError(f"--readme {readme}: {exc.strerror or exc}") from None
    if begin not in text or end not in text:
        raise ConfigError(f"--readme {readme}: the markers {begin} / {end} are missing")


def _command(args: argparse.Namespace, definition: BenchDefinition) -> str:
    """The command line that reproduces the run's figures (engine and output options left out)."""
    parts = ["uav_fusion bench"]
    if definition.name != "accuracy":
        parts.append(f"--definition {definition.name}")
    parts.append("--profiles " + " ".join(args.profiles))
    if args.split != "test":
        parts.append(f"--split {args.split}")
    return " ".join(parts)


def _publish(
    args: argparse.Namespace,
    definition: BenchDefinition,
    kind: str,
    prov: dict[str, Any],
    figures: dict[str, dict[str, Any]],
    extra: dict[str, Any] | None = None,
) -> None:
    """``--readme``: the results file, and the README's table rendered from it."""
    readme = Path(args.readme)
    name = results_name(definition.name, args.split)
    doc = results_doc(kind, name, _command(args, definition), prov, figures, extra)
    path = write_results(results_path(readme, name), doc)
    text = readme.read_text(encoding="utf-8")
    readme.write_text(replace_block(text, name, render_block(doc)), encoding="utf-8")
    print(f"results: {path}; {readme}: the bench:{name} table replaced")


def _generate_and_run(
    args: argparse.Namespace,
    definition: BenchDefinition,
    site: Site,
    missing: list[CachedFlight],
    fn: Callable[[T], R],
    tasks: list[T],
    describe: Callable[[T], str],
) -> tuple[list[R], str]:
    """Generate the flights the cache lacks, then run ``fn`` over ``tasks`` on the engine
    the arguments ask for; the results and what the two took, for the wall-time line."""
    from uav_fusion.batch import Engine  # dask: imported when a benchmark runs

    engine = Engine(workers=args.workers, scheduler=args.scheduler, processes=not args.threads)
    with engine:
        print(f"  engine: {engine.description}")
        t0 = time.perf_counter()
        engine.map(
            generate_task,
            [GenerateTask(f, definition, site) for f in missing],
            label="generate",
            describe=lambda t: t.flight.flight_id,
        )
        t_gen = time.perf_counter() - t0
        t0 = time.perf_counter()
        results = engine.map(fn, tasks, label="run+score", describe=describe)
        t_run = time.perf_counter() - t0
    return results, (
        f"generation {t_gen:.1f} s for {len(missing)} flights, runs {t_run:.1f} s for "
        f"{len(tasks)} profile x flight tasks; {engine.description}"
    )


def _provenance(
    args: argparse.Namespace,
    definition: BenchDefinition,
    flights: list[CachedFlight],
    profiles: list[Profile],
) -> dict[str, Any]:
    return provenance(
        args.split,
        len(flights),
        definition.source,
        {"profiles": ", ".join(f"{p.name} ({p.source})" for p in profiles)},
    )


def _run_multi(
    args: argparse.Namespace,
    definition: BenchDefinition,
    profiles: list[Profile],
    site: Site,
    flights: list[CachedFlight],
    missing: list[CachedFlight],
    out: Path,
    wall0: float,
) -> int:
    """The multi-UAV part: the multi-UAV tracker per profile and flight, scored as a set."""
    from uav_fusion.core.bench.multi import (
        CSV_FILE as MULTI_CSV,
    )
    from uav_fusion.core.bench.multi import (
        FIGURE_FILE as MULTI_FIGURE,
    )
    from uav_fusion.core.bench.multi import (
        MultiScoreTask,
        markdown_multi,
        markdown_multi_flights,
        multi_score_task,
        pool_multi,
        text_multi,
        write_multi_csv,
        write_multi_figure,
    )
    from uav_fusion.core.bench.radar_baseline import against_radar

    for p in profiles:
        if not p.uses_tracker:
            raise ConfigError(
                f"{p.source}: the multi-UAV benchmark needs a tracker profile (estimator: "
                f"tracker or multi); {p.name!r} is not one"
            )
    settings = definition.settings
    # the profiles, then the radar's own tracks passed through (radar_baseline.py)
    tasks = [
        MultiScoreTask(
            f, p, site, definition.grid_hz, settings.airborne_min_m,
            settings.observable_window_s, definition.excuse_grounded, baseline=base,
        )
        for p, base in [*((p, False) for p in profiles), (profiles[0], True)]
        for f in flights
    ]  # fmt: skip
    results, runs = _generate_and_run(
        args, definition, site, missing, multi_score_task, tasks,
        lambda t: f"{RADAR_BASELINE if t.baseline else t.profile.name} on {t.flight.flight_id}",
    )  # fmt: skip
    scores = pool_multi(results)
    prov = _provenance(args, definition, flights, profiles)
    print()
    print(
        f"pooled over {len(flights)} {args.split} flights, {definition.grid_hz:g} Hz grid, "
        f"GOSPA p 2, c 100 m, alpha 2; a UAV counts when more than "
        f"{settings.airborne_min_m:g} m above its first truth sample"
        + (
            "; a track on a UAV that is not (yet, or any longer) airborne is excused, not false:"
            if definition.excuse_grounded
            else "; a track on a UAV that is not airborne is false:"
        )
    )
    print(text_multi(scores))
    print()
    print("against the radar's own tracks (class >= 0.5, passed through):")
    print(against_radar(results))
    print()
    for line in provenance_lines(prov):
        print(f"  {line}")
    csv_path = write_multi_csv(results, out / MULTI_CSV)
    table_path = out / TABLE_FILE
    table_path.write_text(
        markdown_multi(scores) + "\n\n" + markdown_multi_flights(results) + "\n",
        encoding="utf-8",
    )
    print(f"per-flight, per-UAV figures: {csv_path}")
    if not args.no_figure:
        print(f"figure: {write_multi_figure(results, out / MULTI_FIGURE)}")
    timing = f"{time.perf_counter() - wall0:.1f} s ({runs})"
    prov["wall_time"] = timing
    doc = {"provenance": prov, "profiles": {k: v.as_dict() for k, v in scores.items()}}
    json_path = out / JSON_FILE
    json_path.write_text(json.dumps(doc, indent=2, allow_nan=True) + "\n", encoding="utf-8")
    print(f"table (Markdown): {table_path}; summary: {json_path}")
    if args.readme:
        _publish(args, definition, "multi", prov, {k: v.as_dict() for k, v in scores.items()})
    print(f"wall time {timing}")
    return 0
