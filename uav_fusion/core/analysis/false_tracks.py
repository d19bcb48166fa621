"""What the multi-UAV tracker's false tracks follow (``uav_fusion analyse false-tracks``).

For every flight of a multi-UAV definition's split, the multi-UAV tracker runs as
``uav_fusion bench`` runs it (the definition's grid over the truth's span) and GOSPA's
optimal assignment marks, per epoch, the confirmed tracks assigned to no UAV (the false tracks
of the false-track time). The twin (:mod:`~uav_fusion.core.analysis.labels`) knows, for every
radar report, the kind of object its radar track was following then (UAV, ghost, bird,
clutter, vehicle). Each false track-epoch gets the kind of the radar object its track took
last, and for a UAV object where that UAV was:

* ``uav: not airborne``: the UAV was within ``airborne_min_m`` of its take-off point (taking
  off or landing) and another track is excused on it (the scorer excuses one track per such
  UAV), or every track on it with ``strict_grounded`` (such tracks counted as false);
* ``uav: a second track within 100 m``: that UAV is assigned another track;
* ``uav: height off``: horizontally within 100 m of the UAV, beyond 100 m in 3D;
* ``uav: more than 100 m off``: the radar object was on the UAV but the track is far from it.

Printed: the counts per flight and pooled, and the kinds of the radar objects the tracks were
born on (a birth on a UAV that later follows a bird is a radar track that moved off the UAV).
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Iterator, Sequence
from dataclasses import dataclass

import numpy as np

from uav_fusion.core.analysis.labels import (
    FlightSet,
    KindsByTrack,
    LabelledFlight,
    Progress,
    kind_at,
    labelled_flights,
)
from uav_fusion.core.estimators.grid import GridEpoch
from uav_fusion.core.estimators.multi import MultiTracker, run_multi
from uav_fusion.core.estimators.selection import frames_input
from uav_fusion.core.profiles.model import Profile
from uav_fusion.core.records import RadarFrame, RfAttempt
from uav_fusion.core.scoring.gospa import MultiScoreSettings, UavTruth, score_flight
from uav_fusion.core.site import Site
from uav_fusion.core.twin import radar_model


@dataclass(frozen=True)
class FlightFalseTracks:
    tag: str
    kinds: Counter[str]  # false track-epochs by what they followed
    births: Counter[str]  # confirmed tracks by the kind of object they were born on
    excused: int  # track-epochs on UAVs not airborne, excused by the scorer

    def line(self) -> str:
        summary = ", ".join(f"{c} {n}" for c, n in self.kinds.most_common()) or "none"
        return f"{self.tag}: false track-epochs: {summary}"


def _run_tracker(
    profile: Profile, site: Site, stream: list[RadarFrame | RfAttempt], hz: float,
    t0: float, t1: float, kinds: KindsByTrack,
) -> tuple[list[GridEpoch], Counter[str]]:  # fmt: skip
    """The estimator's part: the multi-UAV tracker's confirmed tracks on the grid, and what
    each confirmed track was born on (a second run, frame by frame)."""
    epochs = run_multi(MultiTracker(profile, site), stream, hz, t0, t1)
    births: Counter[str] = Counter()
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
    return epochs, births


def _flight(
    lf: LabelledFlight, profile: Profile, fs: FlightSet, strict_grounded: bool
) -> FlightFalseTracks:
    air_min = fs.definition.settings.airborne_min_m
    cut = MultiScoreSettings().gospa.c_m
    hz = fs.definition.grid_hz
    flight, kinds = lf.flight, lf.kinds
    truths = {v: UavTruth(*flight.truth_arrays(v)) for v in flight.vehicles}
    vehicle_of = {radar_model.uav_object_id(i): v for i, v in enumerate(truths)}
    t0 = min(float(x.t[0]) for x in truths.values())
    t1 = max(float(x.t[-1]) for x in truths.values())
    stream = list(frames_input(flight, profile))
    epochs, births = _run_tracker(profile, fs.site, stream, hz, t0, t1, kinds)
    settings = MultiScoreSettings(
        step_s=1.0 / hz, airborne_min_m=air_min, excuse_grounded=not strict_grounded
    )
    scores = score_flight(truths, epochs, settings)
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
    return FlightFalseTracks(lf.tag, cats, births, scores.excused_estimates)


def false_tracks(
    fs: FlightSet,
    profile: Profile,
    strict_grounded: bool = False,
    progress: Progress | None = None,
) -> Iterator[FlightFalseTracks]:
    """The multi-UAV tracker's false track-epochs by what they followed, flight by flight."""
    for lf in labelled_flights(fs, progress):
        yield _flight(lf, profile, fs, strict_grounded)


def summary(flights: Sequence[FlightFalseTracks], strict_grounded: bool = False) -> list[str]:
    """The pooled counts with their shares, and the kinds the tracks were born on."""
    pooled: Counter[str] = Counter()
    births: Counter[str] = Counter()
    for f in flights:
        pooled.update(f.kinds)
        births.update(f.births)
    total = sum(pooled.values())
    out = ["", f"pooled over {len(flights)} flights: {total} false track-epochs"]
    if not strict_grounded:
        out.append(f"  (and {sum(f.excused for f in flights)} track-epochs on UAVs not airborne, "
                   "excused)")  # fmt: skip
    for c, n in pooled.most_common():
        out.append(f"  {n:5d}  {100.0 * n / max(total, 1):5.1f} %  {c}")
    out.append(
        "confirmed tracks born on: " + ", ".join(f"{c} {n}" for c, n in births.most_common())
    )
    return out
