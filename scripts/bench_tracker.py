"""Tracker benchmark: offline run time of `tracker` vs `paper`, and 10 Hz grid accuracy.

    python scripts/bench_tracker.py                          # speed on the bundled flight
    python scripts/bench_tracker.py --speed FOLDER --repeats 5
    python scripts/bench_tracker.py --accuracy F1 F2 ... [--profiles paper tracker]

Speed: `run_flight` of each profile on the same loaded flight, the profiles alternating,
best of the repeats; prints both times and the ratio tracker / paper, then the same for the
whole offline run (reading the flight folder, then `run_flight`, as `uav_fusion run` does
before it writes its CSV).

Accuracy (a stand-in for the benchmark's grid scoring, used to compare profiles on tune
flights): at every 10 Hz epoch over airborne truth (more than 5 m above the take-off point),
the published estimate is the latest step that is an estimate of a confirmed track
(``Step.counted``) at or before the epoch, predicted to the epoch with its velocity, as long
as the last measurement used by the track is at most the profile's ``max_coast_s`` old.
Prints per flight and pooled: coverage, mean / p50 / p95 / max 3D error, share of errors
over 100 m, and the average position NEES (3 for an honest covariance; the covariance is
predicted to the epoch with the profile's CV ``q``).
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np
import numpy.typing as npt

from uav_fusion.core.data import load_flight
from uav_fusion.core.estimators import Profile, RunResult, load_profile, run_flight
from uav_fusion.core.estimators.models import cv_process_noise, cv_transition
from uav_fusion.core.records import Flight
from uav_fusion.core.scoring.metrics import interpolate_truth
from uav_fusion.core.site import Site, load_site
from uav_fusion.resources import data_path

FloatArray = npt.NDArray[np.float64]
DEFAULT_FLIGHT = "default_flight"


def grid_errors(
    result: RunResult,
    flight: Flight,
    max_coast_s: float | None,
    q: tuple[float, float, float],
    rate_hz: float = 10.0,
) -> tuple[int, FloatArray, FloatArray]:
    """(airborne epochs, errors and position NEES of the covered epochs) of a run on a
    ``rate_hz`` grid; the covariance is predicted to the epoch with the CV model's ``q``."""
    t_truth, enu = flight.truth_arrays()
    if t_truth.size < 2:
        return 0, np.zeros(0)
    epochs = np.arange(math.ceil(t_truth[0] * rate_hz), math.floor(t_truth[-1] * rate_hz) + 1)
    epochs = epochs / rate_hz
    truth = interpolate_truth(t_truth, enu, epochs, max_gap_s=2.0)
    up0 = float(enu[0, 2])
    air = np.isfinite(truth[:, 0]) & (truth[:, 2] > up0 + 5.0)
    epochs, truth = epochs[air], truth[air]
    steps = [s for s in result.steps]
    t_steps = np.array([s.t for s in steps])
    counted = np.array([s.counted for s in steps], dtype=bool)
    used = np.array([s.updated for s in steps], dtype=bool)
    # index of the latest counted step at or before each step, and latest used time
    last_counted = np.full(len(steps), -1)
    last_used_t = np.full(len(steps), -np.inf)
    lc, lu = -1, -np.inf
    for k, s in enumerate(steps):
        if counted[k]:
            lc = k
            if used[k]:
                lu = s.t
        elif s.status == "discarded" and not np.all(np.isfinite(s.x[:3])):
            lc, lu = -1, -np.inf  # no track at this step: a dropped track stops publishing
        last_counted[k] = lc
        last_used_t[k] = lu
    idx = np.searchsorted(t_steps, epochs, side="right") - 1
    errs = []
    nees = []
    limit = math.inf if max_coast_s is None else max_coast_s
    for e, k, tr in zip(epochs, idx, truth, strict=True):
        if k < 0 or last_counted[k] < 0 or e - last_used_t[k] > limit:
            continue
        s = steps[last_counted[k]]
        x = s.x
        dt = e - s.t
        p = x[:3] + x[3:6] * dt
        d = p - tr
        errs.append(float(np.linalg.norm(d)))
        F = cv_transition(dt)
        P = (F @ s.P @ F.T + cv_process_noise(dt, q))[:3, :3]
        nees.append(float(d @ np.linalg.solve(P, d)))
    return int(epochs.size), np.asarray(errs), np.asarray(nees)


def _summary(n_epochs: int, errs: FloatArray, nees: FloatArray) -> str:
    if errs.size == 0:
        return f"coverage 0.0 % of {n_epochs} epochs"
    return (
        f"ANEES {nees.mean():6.2f}  "
        f"coverage {100.0 * errs.size / max(n_epochs, 1):5.1f} %  mean {errs.mean():7.1f}  "
        f"p50 {np.percentile(errs, 50):6.1f}  p95 {np.percentile(errs, 95):7.1f}  "
        f"max {errs.max():7.1f} m  >100 m {100.0 * np.mean(errs > 100.0):5.1f} %"
    )


def speed(folder: Path, site: Site, repeats: int) -> None:
    flight = load_flight(folder, site)
    profiles = {name: load_profile(name) for name in ("paper", "tracker")}
    best = {name: math.inf for name in profiles}
    best_full = {name: math.inf for name in profiles}
    steps = {}
    for r in range(repeats):
        for name, prof in profiles.items():
            t0 = time.perf_counter()
            res = run_flight(flight, prof, site)
            best[name] = min(best[name], time.perf_counter() - t0)
            steps[name] = len(res.steps)
            # the whole offline run as `uav_fusion run` does it: read the folder, then run
            t0 = time.perf_counter()
            run_flight(load_flight(folder, site), prof, site)
            best_full[name] = min(best_full[name], time.perf_counter() - t0)
        print(f"  repeat {r + 1}/{repeats} done", file=sys.stderr)
    print(f"flight {flight.name} ({folder}); best of {repeats}")
    for name in profiles:
        print(
            f"  {name:8s} {best[name]:8.3f} s  ({steps[name]} steps); "
            f"with reading the folder {best_full[name]:8.3f} s"
        )
    print(f"  ratio tracker / paper: {best['tracker'] / best['paper']:.2f}")
    print(
        "  ratio tracker / paper, reading the folder included: "
        f"{best_full['tracker'] / best_full['paper']:.2f}"
    )


def accuracy(folders: list[Path], names: list[str], site: Site) -> None:
    profiles: dict[str, Profile] = {n: load_profile(n) for n in names}
    pooled: dict[str, list[FloatArray]] = {n: [] for n in names}
    pooled_nees: dict[str, list[FloatArray]] = {n: [] for n in names}
    epochs_total = dict.fromkeys(names, 0)
    for i, folder in enumerate(folders):
        flight = load_flight(folder, site)
        print(f"[{i + 1}/{len(folders)}] {folder.name}", file=sys.stderr)
        for n, prof in profiles.items():
            res = run_flight(flight, prof, site)
            q = prof.q if prof.motion_model == "cv" else prof.imm_q[-1]
            ne, errs, nees = grid_errors(res, flight, prof.max_coast_s, q)
            pooled[n].append(errs)
            pooled_nees[n].append(nees)
            epochs_total[n] += ne
            print(f"  {folder.name:32s} {n:17s} {_summary(ne, errs, nees)}")
    print("pooled:")
    for n in names:
        e, v = np.concatenate(pooled[n]), np.concatenate(pooled_nees[n])
        print(f"  {n:17s} {_summary(epochs_total[n], e, v)}")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--speed", type=Path, default=None, help="flight folder for the speed test")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--accuracy", type=Path, nargs="*", default=None, help="flight folders")
    ap.add_argument("--profiles", nargs="+", default=["paper", "tracker", "tracker_smoothed"])
    args = ap.parse_args(argv)
    site = load_site()
    if args.accuracy:
        accuracy(list(args.accuracy), list(args.profiles), site)
    if args.speed is not None or not args.accuracy:
        speed(args.speed or data_path(DEFAULT_FLIGHT), site, args.repeats)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
