"""Where the multi-UAV tracker misses a UAV: each airborne UAV-epoch without a track, by cause.

    python scripts/multi_misses.py [--definition multi] [--split tune] [--profile tracker]

Every flight of a benchmark definition's split (generated into the flight cache first when
missing) is run and scored as ``uav_fusion bench`` scores it: the definition's grid over the
truth's span, GOSPA's optimal assignment per epoch, a UAV counted while it is more than
``airborne_min_m`` above its pad, and "the radar sees it" from the benchmark's labels (a radar
report on that UAV within ``observable_window_s``). Each airborne epoch of a UAV with no track
assigned gets one cause, the first that applies:

* ``start-up, seen`` / ``start-up, unseen``: before the UAV's first assigned epoch, with the
  radar seeing it or not;
* ``low``: the UAV within ``--low-m`` (20 m) of its pad's height (landing, a low pass);
* ``beside another UAV``: another airborne UAV within ``--near-m`` (100 m, GOSPA's cut-off)
  horizontally (a crossing, two UAVs side by side);
* ``other, seen`` / ``other, unseen``.

Printed: per flight the counts that are not zero, then the pooled counts with their shares,
for all UAVs and for the silent ones (no control link).
"""

from __future__ import annotations

import argparse
import sys
from collections import Counter
from pathlib import Path

import numpy as np
import numpy.typing as npt

from uav_fusion.core.bench.cache import cached_flights, generate_flight, read_vehicle_labels
from uav_fusion.core.bench.definition import load_definition
from uav_fusion.core.bench.multi import MultiScoreTask, multi_score_task, near_labels
from uav_fusion.core.data import load_flight
from uav_fusion.core.estimators.profile import load_profile
from uav_fusion.core.scoring.gospa import UavTruth
from uav_fusion.core.site import load_site
from uav_fusion.resources import DEFAULT_SITE, config_path

BoolArray = npt.NDArray[np.bool_]


def miss_causes(
    covered: BoolArray, seen: BoolArray, low: BoolArray, beside: BoolArray
) -> list[str]:
    """The cause of each uncovered epoch of one UAV's airborne epochs, in order (module text).
    All four arrays are per airborne epoch, in time order."""
    first = np.flatnonzero(covered)
    start = int(first[0]) if first.size else covered.size
    out: list[str] = []
    for i in np.flatnonzero(~covered):
        if i < start:
            out.append("start-up, seen" if seen[i] else "start-up, unseen")
        elif low[i]:
            out.append("low")
        elif beside[i]:
            out.append("beside another UAV")
        else:
            out.append("other, seen" if seen[i] else "other, unseen")
    return out


def _at(tr: UavTruth, t: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    return np.column_stack([np.interp(t, tr.t, tr.enu[:, c]) for c in range(3)])


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--definition", default="multi", help="benchmark definition (multi)")
    ap.add_argument("--split", default="tune", choices=("tune", "test"))
    ap.add_argument("--profile", default="tracker")
    ap.add_argument("--cache", default="out/bench_cache", help="flight cache folder")
    ap.add_argument("--low-m", type=float, default=20.0)
    ap.add_argument("--near-m", type=float, default=100.0)
    args = ap.parse_args(argv)

    site_file = config_path(DEFAULT_SITE)
    site = load_site(site_file)
    definition = load_definition(args.definition)
    profile = load_profile(args.profile)
    st = definition.settings
    pooled: Counter[str] = Counter()
    pooled_silent: Counter[str] = Counter()
    n_epochs = n_silent = 0
    flights = cached_flights(definition, args.split, Path(args.cache), site_file)
    for k, cf in enumerate(flights, 1):
        generate_flight(cf, definition, site)
        # run and scored by the benchmark's own task; the flight is read again for its truth
        result = multi_score_task(
            MultiScoreTask(
                cf, profile, site, definition.grid_hz, st.airborne_min_m, st.observable_window_s
            )
        )
        flight = load_flight(cf.folder, site)
        truths = {v: UavTruth(*flight.truth_arrays(v)) for v in flight.vehicles}
        labels = read_vehicle_labels(cf.folder)
        silent = {u.name for u in result.uavs if u.silent}
        counts: Counter[str] = Counter()
        for u in result.samples.uavs:
            tr = truths[u.name]
            pos = _at(tr, u.times)
            low = pos[:, 2] - tr.enu[0, 2] <= args.low_m
            beside = np.zeros(u.times.size, dtype=bool)
            for name, other in truths.items():
                if name == u.name:
                    continue
                op = _at(other, u.times)
                up = op[:, 2] - other.enu[0, 2] > st.airborne_min_m
                d = np.hypot(op[:, 0] - pos[:, 0], op[:, 1] - pos[:, 1])
                beside |= up & (d <= args.near_m)
            seen = near_labels(
                u.times, np.sort(labels.get(u.name, np.zeros(0))), st.observable_window_s
            )
            c = Counter(miss_causes(u.covered(), seen, low, beside))
            counts.update(c)
            n_epochs += u.epochs
            if u.name in silent:
                pooled_silent.update(c)
                n_silent += u.epochs
        pooled.update(counts)
        summary = ", ".join(f"{c} {n}" for c, n in counts.most_common()) or "none"
        print(f"[{k}/{len(flights)}] {cf.flight_id}: missed UAV-epochs: {summary}")
        sys.stdout.flush()

    def share(c: Counter[str], title: str, of: int) -> None:
        total = sum(c.values())
        pct = 100.0 * total / max(of, 1)
        print(f"\n{title}: {total} of {of} airborne UAV-epochs missed ({pct:.2f} %)")
        for cause, n in c.most_common():
            print(f"  {n:5d}  {100.0 * n / max(total, 1):5.1f} %  {cause}")

    share(pooled, f"all UAVs, {len(flights)} flights", n_epochs)
    share(pooled_silent, "silent UAVs", n_silent)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
