"""Why the single-UAV tracker misses the UAV where the radar sees it, from what only the twin knows.

    python scripts/single_misses.py [--definition accuracy] [--split tune] [--profile tracker]

Every flight of a benchmark definition's split (generated into the flight cache first when
missing) is run and scored as ``uav_fusion bench`` scores it: the 10 Hz grid, its airborne
epochs, and among them the radar-observable ones (a radar report of the UAV within 2 s). Two
kinds of radar-observable epoch fall short of the tracker issue's acceptance (coverage of
99 % and at most 1 % of gross errors on every flight); each is put down to one cause.

An observable epoch with nothing published:

* ``start-up``: before the flight's first tracked airborne epoch (the figure the benchmark
  subtracts for ``observable_after_start_pct``);
* ``re-entry``: within ``--reentry-s`` (15 s) of the start of a run of observable epochs, the
  UAV coming back into the radar's view (out of range, in the Doppler notch);
* ``other``.

An observable epoch published more than 100 m off the UAV, by the last update before it:

* ``coast``: the last update is more than ``--stale-s`` (5 s) old;
* ``rf``: the last update is an RF fix and the last radar update is more than ``--stale-s`` old;
* ``other object: <kind>``: the last radar update came from a radar track that was following
  another object then (ghost, bird, clutter, vehicle), as the twin, generated again in memory,
  knows (``SimTrackReport.kind``, which the files do not carry);
* ``UAV report off, far`` / ``near``: it came from the UAV's own radar track, and that report
  was itself more than 100 m off the UAV (horizontally, for a horizontal-only update beyond
  the range gate), with the UAV beyond / within ``--far-m`` (1500 m) of the radar: the radar's
  own error (its onboard tracker's lag after a manoeuvre, angle errors at long range);
* ``UAV report close``: from the UAV's own track, with the report within 100 m: the fused
  track's own error.

Printed: per flight, the counts that are not zero; then the pooled counts with their shares
(the gross epochs as a share of the observable epochs with a position published, as the
benchmark's ``obs gross %``).
"""

from __future__ import annotations

import argparse
import sys
from collections import Counter
from pathlib import Path

import numpy as np

from uav_fusion.core.bench.cache import read_labels
from uav_fusion.core.bench.definition import load_definition
from uav_fusion.core.estimators.grid import grid_from_steps
from uav_fusion.core.estimators.offline import run_flight
from uav_fusion.core.estimators.profile import load_profile
from uav_fusion.core.estimators.steps import UPDATED
from uav_fusion.core.estimators.tracker import TrackerStep
from uav_fusion.core.records import RADAR
from uav_fusion.core.scoring.fixed_rate import (
    FlightTruth,
    ScoreSettings,
    epoch_errors,
    observable_epochs,
)
from uav_fusion.core.site import load_site
from uav_fusion.resources import DEFAULT_SITE, config_path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from multi_false_tracks import kind_at, labelled_flights

GRID_HZ = 10.0


def uncovered_causes(
    t: np.ndarray, obs: np.ndarray, covered: np.ndarray, first: int, reentry_s: float
) -> list[str]:
    """The cause of each observable epoch with nothing published, in order: ``start-up``
    (index before ``first``, the first tracked airborne epoch), ``re-entry`` (less than
    ``reentry_s`` after the start of its run of observable epochs) or ``other``."""
    out: list[str] = []
    run_start = -np.inf
    for i in range(t.size):
        if not obs[i]:
            continue
        if i == 0 or not obs[i - 1]:
            run_start = float(t[i])
        if covered[i]:
            continue
        if i < first:
            out.append("start-up")
        elif t[i] - run_start < reentry_s:
            out.append("re-entry")
        else:
            out.append("other")
    return out


def gross_cause(
    t: float,
    last_update_t: float | None,
    last_radar_t: float | None,
    kind: str | None,
    report_off_m: float,
    far: bool,
    stale_s: float,
    gross_m: float,
) -> str:
    """The cause of a gross epoch at ``t`` (see the module text): from the last update's time,
    the last radar update's time, the kind of object its radar track followed then, how far
    that report was from the UAV, and whether the UAV is far from the radar."""
    if last_update_t is None or t - last_update_t > stale_s:
        return "coast"
    if last_radar_t is None or t - last_radar_t > stale_s:
        return "rf"
    if kind != "uav":
        return f"other object: {kind}"
    if report_off_m > gross_m:
        return "UAV report off, far" if far else "UAV report off, near"
    return "UAV report close"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--definition", default="accuracy", help="benchmark definition (accuracy)")
    ap.add_argument("--split", default="tune", choices=("tune", "test"))
    ap.add_argument("--profile", default="tracker")
    ap.add_argument("--cache", default="out/bench_cache", help="flight cache folder")
    ap.add_argument("--reentry-s", type=float, default=15.0)
    ap.add_argument("--stale-s", type=float, default=5.0)
    ap.add_argument("--far-m", type=float, default=1500.0)
    args = ap.parse_args(argv)

    site_file = config_path(DEFAULT_SITE)
    site = load_site(site_file)
    definition = load_definition(args.definition)
    profile = load_profile(args.profile)
    if not profile.uses_tracker:
        ap.error(f"profile {profile.name!r} does not run the tracker (estimator)")
    settings = ScoreSettings()
    gross_m = settings.gross_error_m
    radar_pos = np.asarray(site.radar.enu, dtype=float)
    uncovered: Counter[str] = Counter()
    gross: Counter[str] = Counter()
    n_obs = 0
    for k, n_flights, cf, flight, kinds in labelled_flights(
        definition, args.split, Path(args.cache), site, site_file
    ):
        truth = FlightTruth.from_flight(flight, site)
        result = run_flight(flight, profile, site)
        grid = grid_from_steps(result.steps, profile, GRID_HZ, *truth.span)
        ee = epoch_errors(grid, truth, settings)
        obs = observable_epochs(
            grid.t, ee.airborne, read_labels(cf.folder), settings.observable_window_s
        )
        n_obs += int(obs.sum())
        tracked = np.flatnonzero(ee.airborne & grid.has_track)
        first = int(tracked[0]) if tracked.size else grid.t.size

        unc = Counter(uncovered_causes(grid.t, obs, ee.covered, first, args.reentry_s))

        ups = [s for s in result.steps if isinstance(s, TrackerStep) and s.status == UPDATED]
        ut = np.array([s.t for s in ups])
        radar_idx = [j for j, s in enumerate(ups) if s.source == RADAR]
        rt_up = ut[radar_idx] if radar_idx else np.zeros(0)
        tt, enu = flight.truth_arrays()
        grs: Counter[str] = Counter()
        for i in np.flatnonzero(obs & ee.covered & (ee.error_m > gross_m)):
            t = float(grid.t[i])
            j = int(np.searchsorted(ut, t, side="right")) - 1
            jr = int(np.searchsorted(rt_up, t, side="right")) - 1
            last = float(ut[j]) if j >= 0 else None
            s = ups[radar_idx[jr]] if jr >= 0 else None
            kind, off = None, 0.0
            if s is not None:
                ka = kind_at(kinds, s.track_id, s.t)
                kind = ka[0] if ka is not None else "unknown"
                p = np.array([np.interp(s.t, tt, enu[:, c]) for c in range(3)])
                z = np.asarray(s.z, dtype=float)
                off = float(np.linalg.norm(z - p[: z.size]))
            far = float(np.linalg.norm(ee.truth_enu[i] - radar_pos)) > args.far_m
            grs[
                gross_cause(
                    t,
                    last,
                    s.t if s is not None else None,
                    kind,
                    off,
                    far,
                    args.stale_s,
                    gross_m,
                )
            ] += 1
        uncovered.update(unc)
        gross.update(grs)
        parts = [f"{int(obs.sum())} observable"]
        if unc:
            parts.append("uncovered " + ", ".join(f"{c} {v}" for c, v in sorted(unc.items())))
        if grs:
            parts.append("gross " + ", ".join(f"{c} {v}" for c, v in sorted(grs.items())))
        print(f"[{k}/{n_flights}] {cf.flight.flight_id}: " + "; ".join(parts))
        sys.stdout.flush()

    def share(c: Counter[str], title: str, of: int, what: str) -> None:
        total = sum(c.values())
        print(f"  {title}: {total} ({100.0 * total / max(of, 1):.2f} % of {what})")
        for cause, v in c.most_common():
            print(f"    {cause}: {v} ({100.0 * v / max(total, 1):.1f} %)")

    n_cov = n_obs - sum(uncovered.values())
    print(f"\n{profile.name}, {args.definition} {args.split}: {n_obs} radar-observable epochs")
    share(uncovered, "nothing published", n_obs, "observable")
    share(gross, f"more than {gross_m:.0f} m off", n_cov, "observable and published")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
