"""The default flight's raw rows meet the twin's calibration targets with other seeds than the
bundled one (docs/twin.md, "Across seeds"), and the paper's largest radar track is the UAV's.

The targets: radar UAV reports 2900-3300, mean 3D error 18-35 m, max 120-350 m, beyond-gate
mean above 1.5 x the within-gate mean; RF fixes 90-98 % of the attempts, min < 15 m, mean
250-800 m, max > 2 km, north mean < south mean (``test_calibration.py`` checks the bundled
flight, seed 1, in more detail).

By default one further seed runs (a few seconds). ``UAV_TWIN_SEEDS=FIRST-LAST`` runs that
range instead, one test per seed; with ``-s`` each prints its row (the figures docs/twin.md
quotes)::

    UAV_TWIN_SEEDS=1-30 .venv/bin/python -m pytest -q -s test/test_twin_seeds.py

Seed 9 misses the radar mean by 0.1 m (35.1 m: its UAV track breaks in the far north and the
new track's first far reports are poor); it is expected to fail.
"""

from __future__ import annotations

import os
from collections import Counter

import pytest

from uav_fusion.core.estimators.selection import largest_track_id
from uav_fusion.core.scoring.calibration import CalibrationResult, calibrate
from uav_fusion.core.site import load_site
from uav_fusion.core.twin import generate_twin, load_flight_plan, load_twin_config, twin_to_flight
from uav_fusion.core.twin.config import DEFAULT_WAYPOINTS
from uav_fusion.resources import config_path

# seeds known to miss a target, with what they miss (docs/twin.md)
KNOWN_MISSES = {9: "radar mean 35.1 m, 0.1 m above the target"}


def _seeds() -> list[int]:
    spec = os.environ.get("UAV_TWIN_SEEDS", "")
    if not spec:
        return [2]
    first, _, last = spec.partition("-")
    return list(range(int(first), int(last or first) + 1))


def _param(seed: int) -> object:
    why = KNOWN_MISSES.get(seed)
    marks = [pytest.mark.xfail(reason=why, strict=True)] if why else []
    return pytest.param(seed, marks=marks, id=f"seed{seed}")


def misses(res: CalibrationResult) -> list[str]:
    """The targets a flight's raw rows miss (module text)."""
    r = res.radar
    rf_cov = 100.0 * res.rf_fixes / max(res.rf_attempts, 1)
    checks = {
        "radar UAV reports 2900-3300": 2900 <= r.count <= 3300,
        "radar mean 18-35 m": 18 <= r.mean <= 35,
        "radar max 120-350 m": 120 <= r.max <= 350,
        "beyond-gate mean > 1.5 x within": res.radar_beyond_gate.mean
        > 1.5 * res.radar_in_gate.mean,
        "RF fixes 90-98 %": 90 <= rf_cov <= 98,
        "RF min < 15 m": res.rf.min < 15,
        "RF mean 250-800 m": 250 <= res.rf.mean <= 800,
        "RF max > 2 km": res.rf.max > 2000,
        "RF north mean < south mean": res.rf_north.mean < res.rf_south.mean,
    }
    return [k for k, ok in checks.items() if not ok]


@pytest.mark.parametrize("seed", [_param(s) for s in _seeds()])
def test_the_default_plan_meets_the_targets(seed: int) -> None:
    site = load_site()
    plan = load_flight_plan(config_path(DEFAULT_WAYPOINTS), site)
    tw = generate_twin(site, load_twin_config(), plan, seed=seed)
    flight = twin_to_flight(tw)
    res = calibrate(flight, tw.site.radar.enu)
    lt = largest_track_id(flight.radar)
    kinds = Counter(r.kind for f in tw.radar_sim for r in f.tracks if r.track_id == lt)
    r = res.radar
    print(
        f"\nseed {seed:3d} radar n={r.count} mean={r.mean:.1f} max={r.max:.0f} "
        f"in={res.radar_in_gate.mean:.1f} beyond={res.radar_beyond_gate.mean:.1f} | RF "
        f"{100.0 * res.rf_fixes / max(res.rf_attempts, 1):.1f} % min={res.rf.min:.1f} "
        f"mean={res.rf.mean:.0f} max={res.rf.max:.0f} N={res.rf_north.mean:.0f} "
        f"S={res.rf_south.mean:.0f} | largest track {lt}: {dict(kinds)}"
    )
    assert kinds.most_common(1)[0][0] == "uav"
    assert misses(res) == []
