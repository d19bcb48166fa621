"""How well the multi-UAV tracker's filter could do if it knew which radar report is which UAV.

    python scripts/multi_oracle.py [--definition multi] [--split tune] [--profile tracker]

The multi-UAV benchmark's GOSPA is mostly localisation: on the test half the GOSPA of the
assigned pairs alone is 33.5 m of the 40.8 m mean. This script asks what is left when
association is perfect. Every flight of a benchmark definition's split is run twice and
scored exactly as ``uav_fusion bench`` scores it (``bench.multi.multi_score_task``):

* ``tracker``: the multi-UAV tracker, as shipped;
* ``oracle``: the same profile's motion filter, radar and RF measurement models, robust
  update, NIS gates, deleter, misalignment correction, horizontal-only updates (far gate, below
  the ground), climb-rate hold and publication rules, but association from the twin: the twin
  is generated again in memory (the same bytes as the cached flight) to learn which object
  each radar track follows at each report (``SimTrackReport.object_id``, which the files do not
  carry). A UAV's track takes only reports of radar tracks then following that UAV (of
  several in one frame, the one with the smallest NIS), is started from the first of them
  (whatever its UAV score: no wait for the classifier) and takes only the fixes of that UAV's
  own control link (no wrong emitter links); a UAV keeps one id for the whole flight (a track
  dropped by the deleter starts again under the same id). Reports of other objects (birds,
  clutter, cars, ghosts) are never used, so it has no false tracks.

What the oracle cannot do better than the tracker is what the sensors themselves allow: the
radar's own report errors (angle noise and glint, its onboard tracker's lag), the epochs
where no radar track follows the UAV, and the RF fixes' errors. Its GOSPA is a practical
floor for association on this filter, not a strict one: a tracker that leaves a UAV's worst
reports out can have a smaller localisation part, but only by missing those epochs. The
difference between the two rows is what association costs; what the oracle row still lacks
from a target is beyond association.

Printed: the benchmark's pooled multi-UAV table for both, and the oracle's flights.
"""

from __future__ import annotations

import argparse
import dataclasses
import functools
import json
import math
import sys
from pathlib import Path

import numpy as np

from uav_fusion.core.bench.definition import load_definition
from uav_fusion.core.bench.multi import (
    MultiFlightResult,
    MultiScoreTask,
    markdown_multi,
    multi_score_task,
    pool_multi,
)
from uav_fusion.core.estimators.components import scale_packed
from uav_fusion.core.estimators.kalman import PackedR
from uav_fusion.core.estimators.multi import (
    MultiSettings,
    MultiTracker,
    UavTrack,
    emitter_key,
)
from uav_fusion.core.estimators.objects import RadarObject
from uav_fusion.core.estimators.profile import Profile, load_profile
from uav_fusion.core.estimators.tracker import object_start
from uav_fusion.core.records import Flight, RadarFrame, RfAttempt
from uav_fusion.core.site import Site, load_site
from uav_fusion.core.twin import radar_model
from uav_fusion.core.twin.writers import MANIFEST
from uav_fusion.resources import DEFAULT_SITE, config_path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from multi_false_tracks import KindsByTrack, kind_at, labelled_flights


def vehicle_links(folder: Path) -> tuple[dict[int, str], dict[str, str]]:
    """From a twin flight's manifest: the twin object id of each UAV -> its vehicle name, and
    each emitting UAV's emitter key (``emitter_key`` of its centre frequency) -> its name."""
    doc = json.loads((folder / MANIFEST).read_text(encoding="utf-8"))
    objects: dict[int, str] = {}
    emitters: dict[str, str] = {}
    for i, v in enumerate(doc.get("vehicles", []) or []):
        name = str(v["name"])
        objects[radar_model.uav_object_id(i)] = name
        freq = v.get("center_frequency_hz")
        if freq is not None:
            emitters[emitter_key(float(freq))] = name
    return objects, emitters


class LabelOracle(MultiTracker):
    """The multi-UAV tracker with association from the twin's labels (module text)."""

    def __init__(
        self,
        profile: Profile,
        site: Site,
        kinds: KindsByTrack,
        objects: dict[int, str],
        emitters: dict[str, str],
        vehicles: list[str],
        settings: MultiSettings | None = None,
    ) -> None:
        super().__init__(profile, site, settings or MultiSettings(emitter_misses=None))
        self.kinds = kinds
        self.vehicle_of_object = objects
        self.vehicle_of_emitter = emitters
        self.ids = {v: i + 1 for i, v in enumerate(vehicles)}
        self.own: dict[str, UavTrack] = {}

    def _track_of(self, vehicle: str) -> UavTrack | None:
        tr = self.own.get(vehicle)
        return tr if tr is not None and tr in self.tracks else None

    def _own(self, vehicle: str, tr: UavTrack) -> UavTrack:
        """``tr`` is ``vehicle``'s track, under the vehicle's id."""
        tr.id = self.ids[vehicle]
        self.own[vehicle] = tr
        return tr

    def process_radar_frame(self, frame: RadarFrame) -> None:
        t = frame.t
        cfg = self.cfg
        dv = self._extra_var
        rx, ry, rz = self._radar_pos
        # per vehicle: its labelled reports (object, R, measurement, beyond the range gate)
        mine: dict[str, list[tuple[RadarObject, PackedR, tuple[float, ...], bool]]] = {}
        align = self._align.point if self._align is not None else None
        for trk in frame.tracks:
            e, n_, u = trk.e, trk.n, trk.u
            if not math.isfinite(trk.t + e + n_ + u):
                continue
            if align is not None:
                e, n_, u = align(e, n_, u)
            ro = self._r_obj.r_at(e, n_, u)
            p3 = (e, n_, u)
            obj = self.objects.update(trk, ro, p3)
            lab = kind_at(self.kinds, trk.track_id, t)
            if lab is None or lab[0] != radar_model.UAV:
                continue
            vehicle = self.vehicle_of_object.get(lab[1])
            if vehicle is None:
                continue
            r: PackedR = (ro[0] + dv, ro[1], ro[2], ro[3] + dv, ro[4], ro[5] + dv) if dv else ro
            d2 = (e - rx) ** 2 + (n_ - ry) ** 2 + (u - rz) ** 2
            if (d2 > self._gate2 and not d2 <= self._far2) or (
                cfg.skip_radar_coasts and obj.coasting
            ):
                continue
            z: tuple[float, ...] = p3
            far = d2 > self._gate2
            if far or (self.settings.flat_below_ground and u < -cfg.below_ground_m):
                z, r = (e, n_), (r[0], r[1], r[3])
            mine.setdefault(vehicle, []).append((obj, r, z, far))
        self._advance(t)
        for vehicle, cands in mine.items():
            tr = self._track_of(vehicle)
            if tr is None or not tr.confirmed:
                if tr is not None:
                    self._drop(tr, "superseded")
                obj, _, z, far = cands[0]
                x0, P0 = object_start(obj, self.profile, far or len(z) == 2)
                tr = self._own(vehicle, self._new_track(t, x0, P0, confirmed=True))
                tr.last_radar_t = t
                continue
            scored = []
            for _obj, r, z, _far in cands:
                n = tr.filter.nis(z, r)
                scored.append((n if len(z) == 3 else n * self._g3 / self._g2, r, z))
            n3, r, z = min(scored, key=lambda c: c[0])
            if n3 > self._g3:
                self._reject(tr)
                continue
            dof = len(z)
            w = self.robust.weight(n3 if dof == 3 else n3 * self._g2 / self._g3, dof)
            if dof == 2:
                self._hold_height(tr)
            tr.filter.update(z, r if w == 1.0 else scale_packed(r, 1.0 / w))
            self._accept(tr, t)
            tr.last_radar_t = t

    def process_rf(self, att: RfAttempt) -> None:
        if not att.ok or not math.isfinite(att.t + att.e + att.n):
            return
        max_cep = self.profile.rf_max_cep_m
        if max_cep is not None and att.cep is not None and att.cep > max_cep:
            return
        vehicle = self.vehicle_of_emitter.get(emitter_key(att.center_freq_hz))
        if vehicle is None:
            return
        t = att.t
        self._advance(t)
        r = self.rf_r.r_for(att.cep, att.valid_sensors)
        z = (att.e, att.n)
        tr = self._track_of(vehicle)
        if tr is None:  # as the tracker: an RF start is tentative, confirmed by M of N fixes
            self._own(vehicle, self._rf_start(t, z, r))
            return
        self._rf_to(tr, t, z, r)


def _oracle_for(
    profile: Profile,
    site: Site,
    kinds: KindsByTrack,
    objects: dict[int, str],
    emitters: dict[str, str],
    flight: Flight,
) -> MultiTracker:
    return LabelOracle(profile, site, kinds, objects, emitters, list(flight.vehicles))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--definition", default="multi", help="benchmark definition (multi)")
    ap.add_argument("--split", default="tune", choices=("tune", "test"))
    ap.add_argument("--profile", default="tracker")
    ap.add_argument("--cache", default="out/bench_cache", help="flight cache folder")
    args = ap.parse_args(argv)

    site_file = config_path(DEFAULT_SITE)
    site = load_site(site_file)
    definition = load_definition(args.definition)
    profile = load_profile(args.profile)
    s = definition.settings
    results: dict[str, list[MultiFlightResult]] = {"tracker": [], "oracle": []}
    for k, n_flights, cf, _flight, kinds in labelled_flights(
        definition, args.split, Path(args.cache), site, site_file
    ):
        task = MultiScoreTask(
            cf, profile, site, definition.grid_hz, s.airborne_min_m, s.observable_window_s,
            definition.excuse_grounded,
        )  # fmt: skip
        objects, emitters = vehicle_links(cf.folder)

        ours = multi_score_task(task)
        oracle = functools.partial(_oracle_for, profile, site, kinds, objects, emitters)
        best = dataclasses.replace(multi_score_task(task, oracle), profile="oracle")
        results["tracker"].append(ours)
        results["oracle"].append(best)
        print(
            f"[{k}/{n_flights}] {cf.flight.flight_id}: GOSPA tracker "
            f"{np.mean(ours.samples.distance):.1f} m, oracle {np.mean(best.samples.distance):.1f} m"
        )
        sys.stdout.flush()
    print(markdown_multi(pool_multi(results["tracker"] + results["oracle"])))
    return 0


if __name__ == "__main__":
    sys.exit(main())
