"""What the twin's worlds put into a benchmark's flights, per flight and per world family.

For every flight of a definition's split (generated into the flight cache when missing):

* the radar mount: the misalignment the flight was generated with (its ``world.yaml``; the
  twin configuration's for a flight of the twin's own world) against the median angle
  residual (report minus truth, seen from the radar) of its UAV radar reports, by the rule of
  ``uav_fusion calibrate``;
* the RF fixes: the share more than 100 m off, and the share of those whose CEP is below
  20 m (an NLOS fix the CEP does not mark);
* the clutter the radar's classifier calls a UAV (the twin generated again in memory tells
  which radar tracks followed a clutter reflector): the longest time one track on clutter held
  ``catProb[0] >= 0.5``, and the longest-lived clutter track's duration and peak class.

Usage: python scripts/world_stats.py [--definition worlds] [--split test] [--cache DIR]
"""

from __future__ import annotations

import argparse
import sys
from collections import defaultdict
from pathlib import Path

import numpy as np

from uav_fusion.core.analysis.labels import FlightSet, kind_at, labelled_flights
from uav_fusion.core.bench.definition import load_definition
from uav_fusion.core.scoring.calibration import angle_residuals
from uav_fusion.core.scoring.metrics import interpolate_truth
from uav_fusion.core.site import load_site
from uav_fusion.core.twin.config import load_twin_config
from uav_fusion.core.twin.radar_model import CLUTTER
from uav_fusion.core.twin.worlds import read_world
from uav_fusion.resources import DEFAULT_SITE, config_path


def clutter_stats(lf) -> tuple[float, float, float]:  # type: ignore[no-untyped-def]
    """(longest run of one clutter track at class >= 0.5 in s, the longest-lived clutter
    track's duration in s and its peak class)."""
    per: dict[int, list[tuple[float, float, bool]]] = defaultdict(list)
    for fr in lf.flight.radar:
        for tr in fr.tracks:
            k = kind_at(lf.kinds, tr.track_id, tr.t)
            per[tr.track_id].append((tr.t, tr.uav_prob, k is not None and k[0] == CLUTTER))
    longest_uav, life, peak = 0.0, 0.0, float("nan")
    for rows in per.values():
        rows.sort()
        on = [r for r in rows if r[2]]
        if len(on) < 2:
            continue
        if on[-1][0] - on[0][0] > life:
            life, peak = on[-1][0] - on[0][0], max(r[1] for r in on)
        start = None
        for t, p, clut in rows:
            if clut and p >= 0.5:
                start = t if start is None else start
                longest_uav = max(longest_uav, t - start)
            else:
                start = None
    return longest_uav, life, peak


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    ap.add_argument("--definition", default="worlds")
    ap.add_argument("--split", default="test")
    ap.add_argument("--cache", default="out/bench_cache")
    args = ap.parse_args(argv)
    site_file = config_path(DEFAULT_SITE)
    site = load_site(site_file)
    definition = load_definition(args.definition)
    default = load_twin_config(definition.twin_config).radar
    fs = FlightSet(definition, args.split, Path(args.cache), site, site_file)
    heads = ("flight", "az bias", "az resid", "el bias", "el resid", "RF >100 m %",
             "of them CEP<20 m %", "clutter UAV s", "clutter life s", "peak class")  # fmt: skip
    print(" | ".join(heads))
    fam_rows: dict[str, list[tuple[float, ...]]] = defaultdict(list)
    for lf in labelled_flights(fs):
        world = read_world(lf.cached.folder)
        if world is None:
            az_b, el_b = default.az_bias_deg, default.el_bias_deg
        else:
            az_b = world["radar_mount"]["az_bias_deg"]
            el_b = world["radar_mount"]["el_bias_deg"]
        res = angle_residuals(lf.flight, site.radar.enu)
        az_r = float(np.median(res.az_deg)) if res.az_deg.size else float("nan")
        el_r = float(np.median(res.el_deg)) if res.el_deg.size else float("nan")
        ok = [a for a in lf.flight.rf if a.ok]
        tt, tenu = lf.flight.truth_arrays()
        ref = interpolate_truth(tt, tenu, np.array([a.t for a in ok]), 2.0)
        fix = np.array([(a.e, a.n) for a in ok]).reshape(-1, 2)
        err = np.hypot(fix[:, 0] - ref[:, 0], fix[:, 1] - ref[:, 1])
        cep = np.array([a.cep for a in ok])
        big = np.isfinite(err) & (err > 100.0)
        big_pct = 100.0 * big.sum() / max(np.isfinite(err).sum(), 1)
        small_cep = 100.0 * (big & (cep < 20.0)).sum() / max(big.sum(), 1)
        c_uav, c_life, c_peak = clutter_stats(lf)
        row = (az_b, az_r, el_b, el_r, big_pct, small_cep, c_uav, c_life, c_peak)
        fam_rows[lf.cached.flight.family or "-"].append(row)
        print(lf.cached.flight_id + " | " + " | ".join(f"{x:.2f}" for x in row), flush=True)
    print()
    print("family | flights | median |az resid - az bias| deg | median |el resid - el bias| deg"
          " | RF >100 m % | of them CEP<20 m % | longest clutter UAV s | clutter peak class range")
    for fam, rows in fam_rows.items():
        a = np.array(rows)
        print(
            f"{fam} | {len(rows)} | {np.nanmedian(np.abs(a[:, 1] - a[:, 0])):.2f} | "
            f"{np.nanmedian(np.abs(a[:, 3] - a[:, 2])):.2f} | {np.mean(a[:, 4]):.1f} | "
            f"{np.mean(a[:, 5]):.1f} | {np.max(a[:, 6]):.1f} | "
            f"{np.nanmin(a[:, 8]):.2f}-{np.nanmax(a[:, 8]):.2f}"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
