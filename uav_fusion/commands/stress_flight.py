"""``uav_fusion demo``'s last part: what the tracker is for, on one stress flight.

The bundled flight is a quiet radar scene, where the paper profile and the tracker are close.
On the accuracy benchmark's stress flights they are not: the paper profile keeps the radar
track with the most reports over the whole flight (the paper's offline choice), and on
``zigzag_dash`` seed 201 (the test half of ``bench/accuracy.yaml``) that track is a clutter
site. This part generates that flight with the digital twin into the benchmark's flight
cache when it is not there yet, runs both profiles over it offline with the benchmark's own
task (estimator, 10 Hz output, scoring; no DDS), and prints their figures side by side: the
same figures as the flight's rows of ``uav_fusion bench``.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from pathlib import Path

from uav_fusion.core.bench.cache import CachedFlight, cached_flights, generate_flight
from uav_fusion.core.bench.definition import BenchDefinition, load_definition
from uav_fusion.core.bench.single import ScoreTask, score_task
from uav_fusion.core.errors import ConfigError
from uav_fusion.core.profiles.model import load_profile
from uav_fusion.core.scoring.fixed_rate import GridScore, format_value, pool
from uav_fusion.core.site import load_site
from uav_fusion.resources import DEFAULT_SITE, config_path

STRESS_DEFINITION = "accuracy"
STRESS_PLAN = "zigzag_dash"
STRESS_SEED = 201
STRESS_PROFILES = ("paper", "tracker")

# (GridScore field, label, format)
ROWS: tuple[tuple[str, str, str], ...] = (
    ("coverage_pct", "airborne epochs with a published track %", ".1f"),
    ("err_mean_m", "mean error m", ".1f"),
    ("err_p95_m", "p95 error m", ".1f"),
    ("err_max_m", "largest error m", ".0f"),
    ("gross_pct", "published epochs more than 100 m off %", ".1f"),
    ("gross_age_p50_s", "... median age of their last measurement s", ".1f"),
    ("anees", "ANEES (3 when the covariance is honest)", ".1f"),
)


def stress_flight(
    definition: BenchDefinition, plan: str, seed: int, cache: Path, site_file: Path
) -> CachedFlight:
    """The cache entry of ``plan`` / ``seed`` among the definition's flights."""
    for split in definition.splits:
        for cf in cached_flights(definition, split, cache, site_file):
            if cf.flight.plan.name == plan and cf.flight.seed == seed:
                return cf
    raise ConfigError(f"{definition.source}: no flight of plan {plan!r} with seed {seed}")


def compare_on_stress_flight(
    cache: Path,
    site_file: Path | None = None,
    profiles: Sequence[str] = STRESS_PROFILES,
    definition: str | Path = STRESS_DEFINITION,
    plan: str = STRESS_PLAN,
    seed: int = STRESS_SEED,
) -> tuple[CachedFlight, dict[str, GridScore]]:
    """Generate the flight if needed, run and score every profile on it; prints progress."""
    site_file = site_file or config_path(DEFAULT_SITE)
    site = load_site(site_file)
    d = load_definition(str(definition))
    cf = stress_flight(d, plan, seed, cache, site_file)
    if cf.exists():
        print(f"demo: {cf.flight_id} from the flight cache {cf.folder}", flush=True)
    else:
        print(
            f"demo: generating {cf.flight_id} with the digital twin into {cf.folder} (once) ...",
            flush=True,
        )
        t0 = time.perf_counter()
        generate_flight(cf, d, site)
        print(f"demo: generated in {time.perf_counter() - t0:.1f} s", flush=True)
    scores: dict[str, GridScore] = {}
    for name in profiles:
        t0 = time.perf_counter()
        res = score_task(ScoreTask(cf, load_profile(name), site, d.grid_hz, d.settings))
        scores[name] = pool([res.samples], d.settings)
        print(
            f"demo: profile {name}: {res.steps} filter steps, run and scored in "
            f"{time.perf_counter() - t0:.1f} s",
            flush=True,
        )
    return cf, scores


def format_stress(scores: dict[str, GridScore]) -> str:
    """The figures of every profile side by side, a row per figure."""
    w = max(len(label) for _, label, _ in ROWS)
    names = list(scores)
    head = f"{'10 Hz output, airborne epochs':<{w}}" + "".join(f" | {n[:10]:>10}" for n in names)
    lines = [head, "-" * len(head)]
    for field, label, fmt in ROWS:
        cells = "".join(f" | {format_value(getattr(scores[n], field), fmt):>10}" for n in names)
        lines.append(f"{label:<{w}}{cells}")
    return "\n".join(lines)


def explain(scores: dict[str, GridScore]) -> str:
    """One line on what the figures show (only what they do show)."""
    paper, tracker = scores.get("paper"), scores.get("tracker")
    if paper is None or tracker is None:
        return "(explained for the paper and tracker profiles)"
    if paper.gross_pct > 50.0 and paper.gross_age_p50_s < 1.0 and tracker.gross_pct < 10.0:
        return (
            f"paper keeps the radar track with the most reports over the flight, here a clutter "
            f"site: {paper.gross_pct:.0f} % of what it publishes is over 100 m off, right after "
            f"a radar update; the tracker scores every radar track of every frame as a UAV "
            f"candidate and stays on the UAV ({tracker.gross_pct:.1f} %)."
        )
    return (
        "these figures do not show paper following clutter on this flight; the benchmark's "
        "test half does (README.md, docs/benchmark.md)"
    )


def run_stress(cache: Path, site: str | None) -> int:
    """The demo's stress part: progress, the side-by-side table and the explanation."""
    print()
    print(
        f"demo: what the tracker is for: {STRESS_PLAN} seed {STRESS_SEED}, a stress flight of "
        f"the accuracy benchmark's test half (bench/{STRESS_DEFINITION}.yaml), offline through "
        f"the core",
        flush=True,
    )
    cf, scores = compare_on_stress_flight(cache, Path(site) if site else None)
    print()
    print(f"{cf.flight_id}:")
    print(format_stress(scores))
    print(explain(scores))
    return 0
