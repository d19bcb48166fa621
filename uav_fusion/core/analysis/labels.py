"""What only the twin knows about a benchmark flight: the object behind every radar report.

The flight files do not say which object a radar track was following (the UAV, its ghost, a
bird, clutter, a vehicle). The twin does (``SimTrackReport.kind`` and ``object_id``), and the
twin is deterministic: generated again in memory with the flight's plan, seed and parameters
it gives the same bytes as the cached flight. :func:`labelled_flights` does that for every
flight of a benchmark split, and :func:`kind_at` answers "what did radar track ``i`` follow at
time ``t``".
"""

from __future__ import annotations

from collections import defaultdict
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import numpy.typing as npt

from uav_fusion.core.bench.cache import (
    CachedFlight,
    cached_flights,
    generate_flight,
    generate_twin_flight,
)
from uav_fusion.core.bench.definition import BenchDefinition
from uav_fusion.core.data import load_flight
from uav_fusion.core.errors import DataError
from uav_fusion.core.estimators.emitters import emitter_key
from uav_fusion.core.records import Flight
from uav_fusion.core.site import Site
from uav_fusion.core.twin import radar_model
from uav_fusion.core.twin.generate import TwinFlight
from uav_fusion.core.twin.writers import MANIFEST, read_manifest

FloatArray = npt.NDArray[np.float64]
# per radar track id: its report times (the flight's radar timeline) and, at each, the kind
# and twin object id of what it followed
KindsByTrack = dict[int, tuple[FloatArray, list[tuple[str, int]]]]
Progress = Callable[[str], None]


@dataclass(frozen=True)
class FlightSet:
    """The flights an analysis reads: a benchmark definition's split, in a flight cache."""

    definition: BenchDefinition
    split: str
    cache: Path
    site: Site
    site_file: Path

    def flights(self) -> list[CachedFlight]:
        return cached_flights(self.definition, self.split, self.cache, self.site_file)


@dataclass(frozen=True)
class LabelledFlight:
    """One flight of a split with the twin's labels of its radar tracks."""

    number: int  # 1-based place in the split
    count: int  # flights in the split
    cached: CachedFlight
    flight: Flight
    kinds: KindsByTrack

    @property
    def tag(self) -> str:
        """``[k/n] <flight id>``: how the analyses' per-flight lines start."""
        return f"[{self.number}/{self.count}] {self.cached.flight_id}"


def radar_kinds(twin: TwinFlight) -> KindsByTrack:
    """Per radar track id: its report times (the flight's radar timeline) and, at each, the
    kind and twin object id of what it followed."""
    off = twin.site.clock_offset_s("radar")
    rows: dict[int, list[tuple[float, str, int]]] = defaultdict(list)
    for f in twin.radar:
        for tr in f.tracks:
            r = tr.report
            rows[r.track_id].append((f.t_unix - off, r.kind, r.object_id))
    out: KindsByTrack = {}
    for tid, lst in rows.items():
        lst.sort()
        out[tid] = (np.array([x[0] for x in lst]), [(x[1], x[2]) for x in lst])
    return out


def prepared_flights(fs: FlightSet, progress: Progress | None = None) -> list[CachedFlight]:
    """The split's flights, each generated into the cache first when missing (``progress``
    hears of every flight generated)."""
    flights = fs.flights()
    for k, cf in enumerate(flights, 1):
        if progress is not None and not cf.exists():
            progress(f"[{k}/{len(flights)}] {cf.flight_id}: generating into {fs.cache}")
        generate_flight(cf, fs.definition, fs.site)
    return flights


def labelled_flights(fs: FlightSet, progress: Progress | None = None) -> Iterator[LabelledFlight]:
    """Every flight of the split (generated into the cache first when missing), loaded, with
    the kinds of its radar tracks from the twin generated again in memory. ``progress`` hears
    of each flight as its work starts."""
    definition = fs.definition
    flights = prepared_flights(fs, progress)
    for k, cf in enumerate(flights, 1):
        if progress is not None:
            progress(f"[{k}/{len(flights)}] {cf.flight_id}")
        flight = load_flight(cf.folder, fs.site)
        twin = generate_twin_flight(cf.flight, definition, fs.site)
        yield LabelledFlight(k, len(flights), cf, flight, radar_kinds(twin))


def kind_at(kinds: KindsByTrack, track_id: int | None, t: float) -> tuple[str, int] | None:
    """What radar track ``track_id`` followed at ``t`` (its last report at or before ``t``,
    else its first): (kind, twin object id); None for a track the twin does not know."""
    if track_id is None or track_id not in kinds:
        return None
    ts, ks = kinds[track_id]
    i = max(0, int(np.searchsorted(ts, t, side="right")) - 1)
    return ks[i]


def vehicle_links(folder: Path) -> tuple[dict[int, str], dict[str, str]]:
    """From a twin flight's manifest: the twin object id of each UAV -> its vehicle name, and
    each emitting UAV's emitter key (``emitter_key`` of its centre frequency) -> its name."""
    doc = read_manifest(folder)
    if doc is None:
        raise DataError(folder / MANIFEST, None, "twin manifest not found")
    objects: dict[int, str] = {}
    emitters: dict[str, str] = {}
    for i, v in enumerate(doc.get("vehicles", []) or []):
        name = str(v["name"])
        objects[radar_model.uav_object_id(i)] = name
        freq = v.get("center_frequency_hz")
        if freq is not None:
            emitters[emitter_key(float(freq))] = name
    return objects, emitters
