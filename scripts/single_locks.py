"""What the single-UAV tracker follows, from what only the twin knows.

    python scripts/single_locks.py [--definition accuracy] [--split tune] [--profiles tracker ...]

For every flight of a benchmark definition's split (generated into the flight cache first
when missing), each profile's tracker runs over the flight as ``uav_fusion run`` runs it.
After every radar frame with a confirmed track, the radar object the track follows (the one
whose report updated it last) is looked up in the twin, generated again in memory (same
plan, seed and parameters: the same bytes as the cached flight), which knows the kind of
object every radar track was following then (UAV, ghost, bird, clutter, vehicle;
``SimTrackReport.kind``, which the files do not carry). The time to the next frame is
counted against that kind, and separately when the track is then more than 100 m from the
UAV (a lock: following a ghost mirrored below the UAV mostly costs height only).

Printed: per flight, the seconds on objects other than the UAV (only flights with any), then
per profile the pooled seconds by kind and the locked seconds.
"""

from __future__ import annotations

import argparse
import sys
from collections import Counter
from pathlib import Path

import numpy as np

from uav_fusion.core.bench.definition import load_definition
from uav_fusion.core.estimators.base import feed
from uav_fusion.core.estimators.profile import load_profile
from uav_fusion.core.estimators.selection import frames_input
from uav_fusion.core.estimators.tracker import Tracker
from uav_fusion.core.records import RadarFrame
from uav_fusion.core.site import load_site
from uav_fusion.resources import DEFAULT_SITE, config_path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from multi_false_tracks import kind_at, labelled_flights

LOCK_M = 100.0


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--definition", default="accuracy", help="benchmark definition (accuracy)")
    ap.add_argument("--split", default="tune", choices=("tune", "test"))
    ap.add_argument("--profiles", nargs="+", default=["tracker"])
    ap.add_argument("--cache", default="out/bench_cache", help="flight cache folder")
    args = ap.parse_args(argv)

    site_file = config_path(DEFAULT_SITE)
    site = load_site(site_file)
    definition = load_definition(args.definition)
    profiles = [load_profile(p) for p in args.profiles]
    names = [p.name for p in profiles]
    pooled = {n: Counter[str]() for n in names}
    locked = dict.fromkeys(names, 0.0)
    n_flights = 0
    for k, n_flights, cf, flight, kinds in labelled_flights(
        definition, args.split, Path(args.cache), site, site_file
    ):
        tt, enu = flight.truth_arrays()
        parts = []
        for name, profile in zip(names, profiles, strict=True):
            tracker = Tracker(profile, site)
            secs: Counter[str] = Counter()
            lock = 0.0
            prev: tuple[float, str, bool] | None = None  # (t, kind, more than 100 m off)
            for item in frames_input(flight, profile):
                feed(tracker, item)
                if not isinstance(item, RadarFrame):
                    continue
                t = item.t
                if prev is not None:
                    secs[prev[1]] += t - prev[0]
                    if prev[2]:
                        lock += t - prev[0]
                prev = None
                if tracker.confirmed and tracker.filter is not None:
                    ka = kind_at(kinds, tracker.followed, t)
                    kind = ka[0] if ka is not None else "RF fixes only"
                    off = False
                    if kind != "uav":
                        x, _ = tracker.predict_to(t)
                        p = np.array([np.interp(t, tt, enu[:, i]) for i in range(3)])
                        off = float(np.linalg.norm(x[:3] - p)) > LOCK_M
                    prev = (t, kind, off)
            pooled[name].update(secs)
            locked[name] += lock
            other = {c: s for c, s in secs.items() if c != "uav"}
            if other:
                what = ", ".join(f"{c} {s:.1f}" for c, s in sorted(other.items()))
                parts.append(f"{name}: {what} s; more than {LOCK_M:.0f} m off {lock:.1f} s")
        line = "; ".join(parts) or "the UAV only"
        print(f"[{k}/{n_flights}] {cf.flight.flight_id}: {line}")
        sys.stdout.flush()
    print(f"\npooled over {n_flights} flights (seconds of confirmed track by what it follows):")
    for name in names:
        c = pooled[name]
        total = sum(c.values())
        row = ", ".join(f"{kind} {s:.1f}" for kind, s in c.most_common())
        print(f"  {name}: {row} (of {total:.1f} s); more than {LOCK_M:.0f} m off the UAV "
              f"while on another object: {locked[name]:.1f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
