"""One benchmark task: a profile run over one cached flight, scored on the fixed-rate grid.

The functions here are what the parallel workers execute (:mod:`uav_fusion.batch`): plain
module-level functions of picklable arguments, no global state.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

from uav_fusion.core.bench.cache import CachedFlight, generate_flight, read_labels
from uav_fusion.core.bench.definition import BenchDefinition
from uav_fusion.core.data import load_flight
from uav_fusion.core.errors import DataError
from uav_fusion.core.estimators.offline import run_flight
from uav_fusion.core.profiles.model import Profile
from uav_fusion.core.scoring.fixed_rate import (
    FlightTruth,
    GridSamples,
    ScoreSettings,
    grid_from_steps,
    score_grid,
)
from uav_fusion.core.site import Site


@dataclass(frozen=True)
class GenerateTask:
    flight: CachedFlight
    definition: BenchDefinition
    site: Site


@dataclass(frozen=True)
class ScoreTask:
    flight: CachedFlight
    profile: Profile
    site: Site
    grid_hz: float
    settings: ScoreSettings


@dataclass(frozen=True)
class FlightResult:
    """The outcome of one (flight, profile) task."""

    flight_id: str
    plan: str
    seed: int
    split: str
    profile: str
    samples: GridSamples
    steps: int
    seconds: float
    family: str | None = None  # the world family of the flight (None: the twin's own world)
    #: the radar registration at the end of the run (azimuth, its sigma; degrees), if any
    registration: tuple[float, float] | None = None


def generate_task(task: GenerateTask) -> bool:
    """Generate the task's flight into the cache unless it is there; True if generated."""
    return generate_flight(task.flight, task.definition, task.site)[1]


def score_task(task: ScoreTask) -> FlightResult:
    """Run the profile over the cached flight and score its fixed-rate output."""
    t0 = time.perf_counter()
    cf = task.flight
    flight = load_flight(cf.folder, task.site)
    truth = FlightTruth.from_flight(flight, task.site)
    result = run_flight(flight, task.profile, task.site)
    t_start, t_end = truth.span
    if not t_end > t_start:
        raise DataError(cf.folder, None, "the flight has fewer than two truth samples")
    grid = grid_from_steps(result.steps, task.profile, task.grid_hz, t_start, t_end)
    samples = score_grid(grid, truth, read_labels(cf.folder), task.settings)
    return FlightResult(
        flight_id=cf.flight_id,
        plan=cf.flight.plan.name,
        seed=cf.flight.seed,
        split=cf.flight.split,
        profile=task.profile.name,
        samples=samples,
        steps=len(result.steps),
        seconds=time.perf_counter() - t0,
        family=cf.flight.family,
        registration=registration(result.status),
    )


def registration(status: dict[str, object]) -> tuple[float, float] | None:
    """The azimuth registration (estimate, sigma; degrees) of an estimator's status."""
    az, sd = status.get("registration_az_deg"), status.get("registration_az_sigma_deg")
    if az is None or sd is None:
        return None
    return float(str(az)), float(str(sd))
