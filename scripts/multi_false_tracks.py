"""What the multi-UAV tracker's false tracks follow, from what only the twin knows.

    python scripts/multi_false_tracks.py [--definition multi] [--split tune] [--profile tracker]

For every flight of a benchmark definition's split (generated into the flight cache first
when missing), the multi-UAV tracker runs as ``uav_fusion bench`` runs it (the definition's
grid over the truth's span) and GOSPA's optimal assignment marks, per epoch, the confirmed
tracks assigned to no UAV (the false tracks of the false-track time). The twin is generated
again in memory (same plan, seed and parameters: the same bytes as the cached flight) to
learn, for every radar report, the kind of object its radar track was following then (UAV,
ghost, bird, clutter, vehicle; ``SimTrackReport.kind``, which the files do not carry). Each
false track-epoch gets the kind of the radar object its track took last, and for a UAV
object where that UAV was:

* ``uav: not airborne``: the UAV was within ``airborne_min_m`` of its take-off point (taking
  off or landing) and another track is excused on it (the scorer excuses one track per such
  UAV), or every track on it with ``--strict-grounded`` (such tracks counted as false);
* ``uav: a second track within 100 m``: that UAV is assigned another track;
* ``uav: height off``: horizontally within 100 m of the UAV, beyond 100 m in 3D;
* ``uav: more than 100 m off``: the radar object was on the UAV but the track is far from it.

Printed: the counts per flight and pooled, and the kinds of the radar objects the tracks were
born on (a birth on a UAV that later follows a bird is a radar track that moved off the UAV).
"""

from __future__ import annotations

import argparse
import sys
from collections import Counter, defaultdict
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from uav_fusion.core.bench.cache import CachedFlight, cached_flights, generate_flight
from uav_fusion.core.bench.definition import BenchDefinition, load_definition
from uav_fusion.core.data import load_flight
from uav_fusion.core.estimators.multi import GridEpoch, MultiTracker, run_multi
from uav_fusion.core.estimators.profile import load_profile
from uav_fusion.core.estimators.selection import frames_input
from uav_fusion.core.records import Flight, RadarFrame
from uav_fusion.core.scoring.gospa import MultiScoreSettings, UavTruth, score_flight
from uav_fusion.core.site import Site, load_site
from uav_fusion.core.twin import radar_model
from uav_fusion.core.twin.config import load_twin_config
from uav_fusion.core.twin.generate import TwinFlight, generate_twin
from uav_fusion.core.twin.trajectory import load_flight_plan
from uav_fusion.resources import DEFAULT_SITE, config_path

KindsByTrack = dict[int, tuple[np.ndarray, list[tuple[str, int]]]]


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


def labelled_flights(
    definition: BenchDefinition, split: str, cache: Path, site: Site, site_file: Path
) -> Iterator[tuple[int, int, CachedFlight, Flight, KindsByTrack]]:
    """Every flight of the split (generated into the cache first when missing), loaded, with
    the kinds of its radar tracks from the twin generated again in memory: (number, count,
    cached flight, flight, kinds)."""
    twin_cfg = load_twin_config(definition.twin_config)
    flights = cached_flights(definition, split, cache, site_file)
    for k, cf in enumerate(flights, 1):
        generate_flight(cf, definition, site)
        flight = load_flight(cf.folder, site)
        plan = load_flight_plan(cf.flight.plan.path, site)
        twin = generate_twin(
            site, twin_cfg, plan, seed=cf.flight.seed, duration_s=definition.duration_s
        )
        yield k, len(flights), cf, flight, radar_kinds(twin)


def kind_at(kinds: KindsByTrack, track_id: int | None, t: float) -> tuple[str, int] | None:
    if track_id is None or track_id not in kinds:
        return None
    ts, ks = kinds[track_id]
    i = max(0, int(np.searchsorted(ts, t, side="right")) - 1)
    return ks[i]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--definition", default="multi", help="benchmark definition (multi)")
    ap.add_argument("--split", default="tune", choices=("tune", "test"))
    ap.add_argument("--profile", default="tracker")
    ap.add_argument("--cache", default="out/bench_cache", help="flight cache folder")
    ap.add_argument(
        "--strict-grounded",
        action="store_true",
        help="a track on a UAV that is not airborne counts as false (default: one is excused)",
    )
    args = ap.parse_args(argv)

    site_file = config_path(DEFAULT_SITE)
    site = load_site(site_file)
    definition = load_definition(args.definition)
    profile = load_profile(args.profile)
    air_min = definition.settings.airborne_min_m
    cut = MultiScoreSettings().gospa.c_m
    hz = definition.grid_hz
    pooled: Counter[str] = Counter()
    births: Counter[str] = Counter()
    excused = 0
    n_flights = 0
    for k, n_flights, cf, flight, kinds in labelled_flights(
        definition, args.split, Path(args.cache), site, site_file
    ):
        truths = {v: UavTruth(*flight.truth_arrays(v)) for v in flight.vehicles}
        vehicle_of = {radar_model.uav_object_id(i): v for i, v in enumerate(truths)}
        t0 = min(float(x.t[0]) for x in truths.values())
        t1 = max(float(x.t[-1]) for x in truths.values())
        stream = list(frames_input(flight, profile))
        tracker = MultiTracker(profile, site)
        epochs: list[GridEpoch] = run_multi(tracker, stream, hz, t0, t1)
        # what each confirmed track was born on (a second pass, frame by frame)
        born: set[int] = set()
        probe = MultiTracker(profile, site)
        for item in stream:
            if not isinstance(item, RadarFrame):
                probe.process_rf(item)
                continue
            probe.process_radar_frame(item)
            for tr in probe.tracks:
                if tr.confirmed and tr.id not in born:
                    born.add(tr.id)
                    ka = kind_at(kinds, tr.followed, item.t)
                    births[ka[0] if ka else "RF fixes only"] += 1
        settings = MultiScoreSettings(
            step_s=1.0 / hz, airborne_min_m=air_min, excuse_grounded=not args.strict_grounded
        )
        scores = score_flight(truths, epochs, settings)
        excused += scores.excused_estimates
        cats: Counter[str] = Counter()
        for ep, asg in zip(epochs, scores.assignments, strict=True):
            by_id = {o.track_id: o for o in ep.tracks}
            pairs = dict(asg.pairs)
            for tid in asg.false_ids:
                o = by_id[tid]
                ka = kind_at(kinds, o.radar_object, ep.t)
                if ka is None:
                    cats["no radar object"] += 1
                    continue
                kind, oid = ka
                if kind != "uav":
                    cats[kind] += 1
                    continue
                name = vehicle_of.get(oid)
                if name is None:
                    cats["uav: not a scored vehicle"] += 1
                    continue
                ut = truths[name]
                p = np.array([np.interp(ep.t, ut.t, ut.enu[:, i]) for i in range(3)])
                d3 = float(np.linalg.norm(o.x[:3] - p))
                dh = float(np.linalg.norm(o.x[:2] - p[:2]))
                if p[2] - ut.enu[0, 2] <= air_min:
                    cats["uav: not airborne"] += 1
                elif name in pairs and d3 <= cut:
                    cats["uav: a second track within 100 m"] += 1
                elif dh <= cut:
                    cats["uav: height off"] += 1
                else:
                    cats["uav: more than 100 m off"] += 1
        pooled.update(cats)
        summary = ", ".join(f"{c} {n}" for c, n in cats.most_common()) or "none"
        print(f"[{k}/{n_flights}] {cf.flight.flight_id}: false track-epochs: {summary}")
        sys.stdout.flush()
    total = sum(pooled.values())
    print(f"\npooled over {n_flights} flights: {total} false track-epochs")
    if not args.strict_grounded:
        print(f"  (and {excused} track-epochs on UAVs not airborne, excused)")
    for c, n in pooled.most_common():
        print(f"  {n:5d}  {100.0 * n / max(total, 1):5.1f} %  {c}")
    print("confirmed tracks born on: " + ", ".join(f"{c} {n}" for c, n in births.most_common()))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
