"""Where do the paper profile's "after validation" shares of a flight go?

Breaks the radar and RF rows of Table II down step by step, to compare a twin flight with
what the paper's own numbers imply (Table II: radar 2403 of 3106 UAV reports kept = 77.3 %;
RF 125 of 216 attempts kept = 57.9 %, accepted RF errors mean 25.8 m, max 113.9 m).

Radar: UAV reports (tracks with mean catProb[0] >= 0.5) -> beyond the 800 m gate -> not in
the largest track -> rejected by the NIS gate. RF: attempts -> failed -> fixes with an error
above the paper's largest accepted error (113.9 m) -> accepted by the NIS gate, also with the
profile's RF R scaled, and by north/south half.

Usage: python scripts/twin_fidelity.py [FOLDER ...] [--profile paper]
"""

from __future__ import annotations

import argparse
import sys
from collections import Counter
from pathlib import Path

import numpy as np

from uav_fusion.core.data import load_flight, uav_class
from uav_fusion.core.estimators.offline import run_flight
from uav_fusion.core.estimators.profile import load_profile
from uav_fusion.core.estimators.selection import largest_track_id
from uav_fusion.core.records import RF
from uav_fusion.core.scoring.metrics import interpolate_truth
from uav_fusion.core.site import load_site
from uav_fusion.resources import DEFAULT_FLIGHT, data_path

PAPER_RF_MAX_ACCEPTED_M = 113.9


def pct(a: int, b: int) -> str:
    return f"{a}/{b} = {100.0 * a / max(b, 1):.1f} %"


def analyse(folder: Path, profile_name: str) -> None:
    site = load_site()
    flight = load_flight(folder, site)
    profile = load_profile(profile_name)
    gate = profile.range_gate_m or site.radar.range_gate_m
    rpos = np.asarray(site.radar.enu, dtype=float)
    tt, tenu = flight.truth_arrays()

    uav_ids, _ = uav_class.uav_track_ids(flight.radar, profile.raw_radar_min_mean_uav_prob)
    uav = [t for f in flight.radar for t in f.tracks if t.track_id in uav_ids]
    n_uav = len(uav)
    rng = np.array([np.linalg.norm(np.array((t.e, t.n, t.u)) - rpos) for t in uav])
    within = int(np.sum(rng <= gate))
    counts = Counter(t.track_id for t in uav)
    largest = largest_track_id(flight.radar)
    lt = [t for f in flight.radar for t in f.tracks if t.track_id == largest]
    lt_in = sum(1 for t in lt if np.linalg.norm(np.array((t.e, t.n, t.u)) - rpos) <= gate)
    res = run_flight(flight, profile, site)
    pc = res.paper_counts()
    print(f"## {folder}")
    print("Radar (UAV reports = tracks with mean catProb[0] >= 0.5):")
    print(f"  UAV reports {n_uav} in {len(counts)} tracks; per track {sorted(counts.values())}")
    print(f"  within the {gate:.0f} m gate: {pct(within, n_uav)} (upper bound of the kept share)")
    print(
        f"  largest track {largest}: {len(lt)} reports ({pct(len(lt), n_uav)} of UAV reports),"
        f" {lt_in} within the gate ({pct(lt_in, n_uav)})"
    )
    print(f"  UAV reports within the gate outside the largest track: {within - lt_in}")
    print(
        f"  NIS accepted {pc['radar_accepted']} of {lt_in} gated reports of the largest track;"
        f" kept {pct(pc['radar_accepted'], n_uav)}  (paper 2403/3106 = 77.3 %)"
    )

    ok = [a for a in flight.rf if a.ok]
    t_ok = np.array([a.t for a in ok])
    ref = interpolate_truth(tt, tenu, t_ok)
    err = np.hypot(np.array([a.e for a in ok]) - ref[:, 0], np.array([a.n for a in ok]) - ref[:, 1])
    fin = np.isfinite(err)
    small = int(np.sum(err[fin] <= PAPER_RF_MAX_ACCEPTED_M))
    n_att = len(flight.rf)
    print("RF:")
    print(f"  attempts {n_att}, fixes {pct(len(ok), n_att)}")
    print(
        f"  fixes with error <= {PAPER_RF_MAX_ACCEPTED_M} m (the paper's largest accepted): "
        f"{pct(small, n_att)} of attempts (upper bound if the gate accepted exactly those)"
    )
    for q in (10, 25, 50, 75, 90):
        print(f"  error p{q}: {np.percentile(err[fin], q):.1f} m")
    acc_seq = {s.seq for s in res.steps if s.validated and s.source == RF}
    rf_steps = {s.seq: s for s in res.steps if s.source == RF}
    acc_err = [
        e for e, s in zip(err, sorted(rf_steps), strict=False) if s in acc_seq and np.isfinite(e)
    ]
    print(
        f"  NIS accepted {pct(pc['rf_accepted'], n_att)} (paper 125/216 = 57.9 %);"
        f" accepted error mean {np.mean(acc_err):.1f} m, max {np.max(acc_err):.1f} m"
        " (paper 25.8 m, 113.9 m)"
    )
    reasons = Counter(s.reason for s in res.steps if s.source == RF and not s.validated)
    print(f"  RF not accepted, by reason: {dict(reasons)}")
    split = float(np.median(interpolate_truth(tt, tenu, np.array([a.t for a in flight.rf]))[:, 1]))
    north = ref[:, 1] >= split
    print(
        f"  fixes <= {PAPER_RF_MAX_ACCEPTED_M} m: north {int(np.sum(fin & north & (err <= 113.9)))}"
        f"/{int(np.sum(north))} fixes, south {int(np.sum(fin & ~north & (err <= 113.9)))}"
        f"/{int(np.sum(~north))} fixes"
    )
    for scale in (1.0, 4.0, 16.0, 64.0):
        p2 = profile.with_changes(r_rf=profile.r_rf * scale)
        r2 = run_flight(flight, p2, site)
        c2 = r2.paper_counts()
        print(
            f"  RF R x{scale:g}: RF accepted {pct(c2['rf_accepted'], n_att)},"
            f" radar accepted {c2['radar_accepted']}"
        )


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("folders", nargs="*", type=Path)
    ap.add_argument("--profile", default="paper")
    args = ap.parse_args(argv)
    folders = args.folders or [data_path(DEFAULT_FLIGHT)]
    for i, f in enumerate(folders, 1):
        print(f"[{i}/{len(folders)}]", file=sys.stderr)
        analyse(f, args.profile)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
