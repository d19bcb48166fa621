"""Check the default flight's raw-row targets (docs/twin.md, "Across seeds") over many seeds.

Generates the default plan with seeds FIRST..LAST in memory, calibrates each and prints one
line per seed, the ranges and whether every seed met the targets:
radar UAV reports 2900-3300, mean 18-35 m, max 120-350 m, beyond-gate mean > 1.5 x within;
RF fixes 90-98 %, min < 15 m, mean 250-800 m, max > 2 km, north mean < south mean.
It also prints which object the largest radar track follows (the paper's selection).

Usage: python scripts/twin_seed_check.py [FIRST] [LAST]
"""

from __future__ import annotations

import sys
from collections import Counter

import numpy as np

from uav_fusion.core.estimators.selection import largest_track_id
from uav_fusion.core.scoring.calibration import calibrate
from uav_fusion.core.site import load_site
from uav_fusion.core.twin import generate_twin, load_flight_plan, load_twin_config, twin_to_flight
from uav_fusion.core.twin.config import DEFAULT_WAYPOINTS
from uav_fusion.resources import config_path


def main(argv: list[str]) -> int:
    first = int(argv[0]) if argv else 1
    last = int(argv[1]) if len(argv) > 1 else 30
    site = load_site()
    cfg = load_twin_config()
    plan = load_flight_plan(config_path(DEFAULT_WAYPOINTS), site)
    rows = []
    failed = 0
    for seed in range(first, last + 1):
        tw = generate_twin(site, cfg, plan, seed=seed)
        flight = twin_to_flight(tw)
        res = calibrate(flight, np.asarray(tw.site.radar.enu, dtype=float))
        lt = largest_track_id(flight.radar)
        kinds = Counter(r.kind for f in tw.radar_sim for r in f.tracks if r.track_id == lt)
        rf_cov = 100.0 * res.rf_fixes / max(res.rf_attempts, 1)
        r = res.radar
        row = (
            r.count, r.mean, r.max, res.radar_in_gate.mean, res.radar_beyond_gate.mean,
            rf_cov, res.rf.min, res.rf.mean, res.rf.max, res.rf_north.mean, res.rf_south.mean,
        )  # fmt: skip
        ok = (
            2900 <= r.count <= 3300
            and 18 <= r.mean <= 35
            and 120 <= r.max <= 350
            and row[4] > 1.5 * row[3]
            and 90 <= rf_cov <= 98
            and res.rf.min < 15
            and 250 <= res.rf.mean <= 800
            and res.rf.max > 2000
            and row[9] < row[10]
        )
        failed += not ok
        rows.append(row)
        print(
            f"seed {seed:3d} {'ok  ' if ok else 'FAIL'} radar n={r.count} mean={r.mean:.1f} "
            f"max={r.max:.0f} in={row[3]:.1f} beyond={row[4]:.1f} | RF {rf_cov:.1f} % "
            f"min={res.rf.min:.1f} mean={res.rf.mean:.0f} max={res.rf.max:.0f} "
            f"N={row[9]:.0f} S={row[10]:.0f} | largest track {lt}: {dict(kinds)}",
            flush=True,
        )
    a = np.array(rows)
    names = ("radar n", "mean", "max", "in-gate mean", "beyond mean", "RF %", "RF min",
             "RF mean", "RF max", "RF north", "RF south")  # fmt: skip
    for i, n in enumerate(names):
        print(f"{n}: {a[:, i].min():.1f} - {a[:, i].max():.1f}")
    print(f"{len(rows) - failed} of {len(rows)} seeds met every target")
    return 1 if failed else 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
