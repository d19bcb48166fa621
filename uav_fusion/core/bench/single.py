"""One benchmark task: a profile run over one cached flight, scored on the fixed-rate grid.

The functions here are what the parallel workers execute (:mod:`uav_fusion.batch`): plain
module-level functions of picklable arguments, no global state.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

from uav_fusion.core.bench.cache import CachedFlight, generate_flight, read_labels
from uav_fusion.core.bench.definition import BenchDefinition
from uav_fusion.core.bench.radar_baseline import NAME as RADAR_BASELINE
from uav_fusion.core.bench.radar_baseline import radar_grid
from uav_fusion.core.data import load_flight
from uav_fusion.core.errors import DataError
from uav_fusion.core.estimators.consider import published_cov
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
from uav_fusion.core.twin.worlds import read_world
from uav_fusion.core.twin.writers import MANIFEST, read_manifest


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
    #: score the radar's own track passed through instead of the profile (radar_baseline.py)
    baseline: bool = False


@dataclass(frozen=True)
class RegistrationOutcome:
    """The azimuth registration at the end of a run, degrees: the estimate, its sigma, the
    bound of the flight's data (``registration.Registration.bound_deg``) and, for a flight
    generated in a world, the radar's true mount misalignment."""

    az_deg: float
    sigma_deg: float
    bound_deg: float
    true_deg: float | None = None

    @property
    def error_deg(self) -> float | None:
        return None if self.true_deg is None else abs(self.az_deg - self.true_deg)

    def within(self, tol_deg: float, bounds: float = 1.0) -> bool | None:
        """Within ``tol_deg`` of the true mount, or within ``bounds`` times the bound where
        that is larger (None without a true mount)."""
        err = self.error_deg
        return None if err is None else err <= max(tol_deg, bounds * self.bound_deg)


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
    #: the radar registration at the end of the run, if any
    registration: RegistrationOutcome | None = None


def generate_task(task: GenerateTask) -> bool:
    """Generate the task's flight into the cache unless it is there; True if generated."""
    return generate_flight(task.flight, task.definition, task.site)[1]


def score_task(task: ScoreTask) -> FlightResult:
    """Run the profile over the cached flight and score its fixed-rate output (with
    ``task.baseline``: the radar's own track instead, on the same grid)."""
    t0 = time.perf_counter()
    cf = task.flight
    flight = load_flight(cf.folder, task.site)
    truth = FlightTruth.from_flight(flight, task.site)
    t_start, t_end = truth.span
    if not t_end > t_start:
        raise DataError(cf.folder, None, "the flight has fewer than two truth samples")
    reg: RegistrationOutcome | None = None
    if task.baseline:
        name, steps = RADAR_BASELINE, 0
        grid = radar_grid(flight, task.site, task.grid_hz, t_start, t_end)
    else:
        result = run_flight(flight, task.profile, task.site)
        name, steps = task.profile.name, len(result.steps)
        cons = published_cov(task.profile, task.site)
        grid = grid_from_steps(
            result.steps, task.profile, task.grid_hz, t_start, t_end, consider=cons
        )
        reg = registration(result.status, true_mount_az(cf.folder))
    return FlightResult(
        flight_id=cf.flight_id,
        plan=cf.flight.plan.name,
        seed=cf.flight.seed,
        split=cf.flight.split,
        profile=name,
        samples=score_grid(grid, truth, read_labels(cf.folder), task.settings),
        steps=steps,
        seconds=time.perf_counter() - t0,
        family=cf.flight.family,
        registration=reg,
    )


def registration(
    status: dict[str, object], true_deg: float | None = None
) -> RegistrationOutcome | None:
    """The azimuth registration of an estimator's status (None without one)."""
    az, sd = status.get("registration_az_deg"), status.get("registration_az_sigma_deg")
    if az is None or sd is None:
        return None
    bound = status.get("registration_az_bound_deg", sd)
    return RegistrationOutcome(float(str(az)), float(str(sd)), float(str(bound)), true_deg)


def true_mount_az(folder: Path) -> float | None:
    """The radar's true azimuth misalignment of a twin flight: from its ``world.yaml`` when it
    was generated in a world, else from its manifest's ``radar_mount``; None for a flight
    that records neither (a recorded flight, or a twin flight written before the manifest
    held the mount)."""
    doc = read_world(folder)
    if doc is not None:
        return float(doc["radar_mount"]["az_bias_deg"])
    man = read_manifest(folder)
    mount = None if man is None else man.get("radar_mount")
    if mount is None:
        return None
    try:
        return float(mount["az_bias_deg"])
    except (KeyError, TypeError, ValueError):
        raise DataError(
            folder / MANIFEST, None, f"radar_mount.az_bias_deg: a number expected, got {mount!r}"
        ) from None
