"""The benchmark's flight cache: generated on demand, keyed by what makes a flight.

A flight is generated with the digital twin into ``<cache>/<plan>-s<seed>-<key>/`` (the three
Dataset-28 files, the twin's manifest, and ``bench_labels.json``). ``key`` is a hash of
everything that decides the flight's bytes: the plan file, the twin parameter file and the
site file (their contents), the twin's source code, the seed, the duration override and, for a
flight generated in a world family, the family's name and the families file; so a
changed twin or plan gives a new folder and an old folder is never used for it. Generation is
deterministic (same inputs, same bytes) and atomic (written to a temporary folder, then
renamed), so parallel workers and interrupted runs cannot leave a half-written flight behind.

``bench_labels.json`` holds what only the twin knows: the times (on the flight's radar
timeline, unix seconds) of every radar report of a track that was following the UAV
(``SimTrackReport.kind == UAV``), from which the scorer finds the radar-observable epochs.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import numpy.typing as npt

from uav_fusion.core.bench.definition import BenchDefinition, BenchFlight
from uav_fusion.core.errors import ConfigError, DataError
from uav_fusion.core.site import Site
from uav_fusion.core.twin import radar_model
from uav_fusion.core.twin.config import load_twin_config
from uav_fusion.core.twin.generate import TwinFlight, generate_twin
from uav_fusion.core.twin.trajectory import load_flight_plan
from uav_fusion.core.twin.worlds import WorldFamilies
from uav_fusion.core.twin.writers import write_twin

FloatArray = npt.NDArray[np.float64]

LABELS_FILE = "bench_labels.json"
CACHE_FORMAT = 1  # bump when the cached folder's layout changes
_TWIN_SOURCE = Path(radar_model.__file__).resolve().parent
_CORE_SOURCE = _TWIN_SOURCE.parent


@dataclass(frozen=True)
class CachedFlight:
    """Where a benchmark flight lives (or will live) in the cache."""

    flight: BenchFlight
    key: str
    folder: Path

    @property
    def flight_id(self) -> str:
        return self.flight.flight_id

    def exists(self) -> bool:
        return (self.folder / LABELS_FILE).is_file()


def _digest(h: hashlib._Hash, label: str, data: bytes) -> None:
    h.update(f"{label}:{len(data)}:".encode())
    h.update(data)


def twin_source_digest() -> str:
    """Hash of the twin's source files (a change in the simulation changes every key)."""
    h = hashlib.sha256()
    for p in sorted(_TWIN_SOURCE.glob("*.py")):
        _digest(h, p.name, p.read_bytes())
    return h.hexdigest()


def core_source_digest(root: Path | None = None) -> str:
    """Hash of the source files of the package's core (every ``.py`` under ``root``, by
    default ``uav_fusion/core``: the estimators, the scoring, the twin): a change in the code
    that computes a benchmark result changes the key that stores it
    (:func:`uav_fusion.core.bench.sweep.task_key`)."""
    base = _CORE_SOURCE if root is None else root
    h = hashlib.sha256()
    for p in sorted(base.rglob("*.py")):
        _digest(h, p.relative_to(base).as_posix(), p.read_bytes())
    return h.hexdigest()


def flight_key(
    flight: BenchFlight, definition: BenchDefinition, site_file: Path, twin_digest: str
) -> str:
    """The cache key of ``flight`` (16 hex digits)."""
    h = hashlib.sha256()
    _digest(h, "format", str(CACHE_FORMAT).encode())
    _digest(h, "plan", flight.plan.path.read_bytes())
    _digest(h, "twin_config", definition.twin_config.read_bytes())
    _digest(h, "site", site_file.read_bytes())
    _digest(h, "twin_source", twin_digest.encode())
    _digest(h, "seed", str(flight.seed).encode())
    _digest(h, "duration", repr(definition.duration_s).encode())
    if flight.family is not None:  # only then: the twin's own flights keep their keys
        worlds = _worlds(definition)
        _digest(h, "world_family", flight.family.encode())
        _digest(h, "worlds", worlds.source.read_bytes())
    return h.hexdigest()[:16]


def _worlds(definition: BenchDefinition) -> WorldFamilies:
    if definition.worlds is None:
        raise ConfigError(f"{definition.source}: flights in world families need a worlds file")
    return definition.worlds


def generate_twin_flight(
    flight: BenchFlight, definition: BenchDefinition, site: Site
) -> TwinFlight:
    """The twin's flight of a benchmark flight, in memory (the bytes the cache holds)."""
    cfg = load_twin_config(definition.twin_config)
    plan = load_flight_plan(flight.plan.path, site)
    world = None if flight.family is None else _worlds(definition).family(flight.family)
    return generate_twin(
        site, cfg, plan, seed=flight.seed, duration_s=definition.duration_s, world=world
    )


def cached_flights(
    definition: BenchDefinition, split: str, cache_dir: Path, site_file: Path
) -> list[CachedFlight]:
    """The split's flights with their cache folders (generated or not)."""
    digest = twin_source_digest()
    out = []
    for f in definition.flights(split):
        key = flight_key(f, definition, site_file, digest)
        out.append(CachedFlight(f, key, cache_dir / f"{f.flight_id}-{key}"))
    return out


def uav_report_times(twin: TwinFlight, index: int = 0) -> list[float]:
    """Times (the flight's radar timeline) of the radar reports of tracks on one UAV.

    ``index`` is the UAV's place among the flight's vehicles (0: the first UAV).
    """
    offset = twin.site.clock_offset_s("radar")
    oid = radar_model.uav_object_id(index)
    return [
        f.t_unix - offset
        for f in twin.radar
        if any(tr.report.kind == radar_model.UAV and tr.report.object_id == oid for tr in f.tracks)
    ]


def write_labels(twin: TwinFlight, folder: Path, flight: BenchFlight, key: str) -> Path:
    doc: dict[str, object] = {
        "flight": flight.flight_id,
        "plan": flight.plan.name,
        "seed": flight.seed,
        "key": key,
        "uav_radar_report_times": uav_report_times(twin),
    }
    if flight.family is not None:
        doc["family"] = flight.family
    if twin.others:
        doc["vehicle_radar_report_times"] = {
            name: uav_report_times(twin, i) for i, (name, _) in enumerate(twin.vehicles)
        }
    path = folder / LABELS_FILE
    path.write_text(json.dumps(doc, indent=1) + "\n", encoding="utf-8")
    return path


def read_labels(folder: Path) -> FloatArray:
    """The UAV radar report times of a cached flight."""
    path = folder / LABELS_FILE
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
        times = doc["uav_radar_report_times"]
        return np.asarray(times, dtype=float).reshape(-1)
    except FileNotFoundError:
        raise DataError(path, None, "benchmark labels not found") from None
    except (ValueError, KeyError, TypeError) as exc:
        raise DataError(path, None, f"unreadable benchmark labels: {exc}") from None


def read_vehicle_labels(folder: Path) -> dict[str, FloatArray]:
    """Every UAV's radar report times of a cached flight, by vehicle (the first UAV first)."""
    path = folder / LABELS_FILE
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
        per = doc.get("vehicle_radar_report_times")
        if per is None:
            per = {"uav1": doc["uav_radar_report_times"]}
        if not isinstance(per, dict):
            raise TypeError("vehicle_radar_report_times is not a mapping")
        return {str(k): np.asarray(v, dtype=float).reshape(-1) for k, v in per.items()}
    except FileNotFoundError:
        raise DataError(path, None, "benchmark labels not found") from None
    except (ValueError, KeyError, TypeError) as exc:
        raise DataError(path, None, f"unreadable benchmark labels: {exc}") from None


def generate_flight(cf: CachedFlight, definition: BenchDefinition, site: Site) -> tuple[Path, bool]:
    """Make sure ``cf`` is in the cache; returns (folder, generated now)."""
    if cf.exists():
        return cf.folder, False
    cf.folder.parent.mkdir(parents=True, exist_ok=True)
    tmp = cf.folder.parent / f".tmp-{cf.folder.name}-{os.getpid()}"
    if tmp.exists():
        shutil.rmtree(tmp)
    twin = generate_twin_flight(cf.flight, definition, site)
    write_twin(twin, tmp)
    write_labels(twin, tmp, cf.flight, cf.key)
    try:
        tmp.rename(cf.folder)
    except OSError:
        if not cf.exists():  # not a concurrent writer that finished first
            raise
        shutil.rmtree(tmp, ignore_errors=True)
        return cf.folder, False
    return cf.folder, True
