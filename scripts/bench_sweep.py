#!/usr/bin/env python3
"""Sweep engine scaling: 2 Dask workers vs 1, and Dask's per-task overhead vs a plain loop.

The workload is a 16-task sweep: one task per flight of the accuracy benchmark's tune half,
each generating its flight from scratch (an empty cache per mode) and then running and scoring
the example sweep's grid on it (``bench/sweep_q.yaml``: the ``paper`` and ``tracker`` profiles
x three values of q x two NIS gate probabilities, twelve runs; the sweep's own task function,
``uav_fusion.core.bench.sweep.run_sweep_task``). The same 16 tasks run

1. in a plain loop in this process,
2. on a Dask local cluster with 1 worker process,
3. on a Dask local cluster with 2 worker processes,

one after the other, and the script prints each mode's wall time, the per-task times, the
throughput ratio (2) / (3) and the overhead (2) vs (1). Usage::

    python scripts/bench_sweep.py [--tasks 16]
"""

from __future__ import annotations

import argparse
import os
import shutil
import statistics
import sys
import tempfile
import time
from pathlib import Path

from uav_fusion.batch import Engine
from uav_fusion.core.bench.sweep import SweepTask, load_spec, run_sweep_task, sweep_tasks
from uav_fusion.core.site import load_site
from uav_fusion.resources import DEFAULT_SITE, bench_path, config_path


def flight_task(tasks: list[SweepTask]) -> float:
    """One benchmark task: the sweep's grid on one flight (the first run generates it)."""
    t0 = time.perf_counter()
    for t in tasks:
        row = run_sweep_task(t)
        if row["error"]:
            raise RuntimeError(f"{t.describe()}: {row['error']}")
    return time.perf_counter() - t0


def build(cache: Path, n: int) -> list[list[SweepTask]]:
    spec = load_spec(bench_path("sweep_q.yaml"))
    site_file = config_path(DEFAULT_SITE)
    tasks = sweep_tasks(spec, cache, site_file, load_site(site_file))
    by_flight: dict[str, list[SweepTask]] = {}
    for t in tasks:
        by_flight.setdefault(t.flight.flight_id, []).append(t)
    groups = list(by_flight.values())[:n]
    if len(groups) < n:
        raise SystemExit(f"only {len(groups)} flights in the tune half")
    return groups


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--tasks", type=int, default=16)
    args = ap.parse_args()
    root = Path(tempfile.mkdtemp(prefix="bench_sweep_"))
    results: dict[str, tuple[float, list[float]]] = {}
    try:
        for mode in ("loop", "dask-1", "dask-2"):
            groups = build(root / mode, args.tasks)
            t0 = time.perf_counter()
            if mode == "loop":
                per = [flight_task(g) for g in groups]
            else:
                with Engine(workers=int(mode[-1]), progress=False) as eng:
                    t0 = time.perf_counter()  # cluster start-up not counted
                    per = eng.map(flight_task, groups, label=mode)
            wall = time.perf_counter() - t0
            results[mode] = (wall, per)
            print(
                f"{mode:7s}: {wall:7.1f} s wall for {len(per)} tasks; per task "
                f"min {min(per):.1f} / median {statistics.median(per):.1f} / max {max(per):.1f} s",
                flush=True,
            )
    finally:
        shutil.rmtree(root, ignore_errors=True)
    loop, d1, d2 = results["loop"][0], results["dask-1"][0], results["dask-2"][0]
    busy1 = sum(results["dask-1"][1])  # the tasks' own time inside the worker
    print()
    print(f"cores: {os.cpu_count()}; load average at the end: {os.getloadavg()[0]:.2f}")
    print(f"throughput, 2 workers vs 1: {d1 / d2:.2f}x  (target >= 1.6x)")
    print(f"Dask overhead, 1 worker vs a plain loop (wall): {100 * (d1 - loop) / loop:+.1f} %  "
          "(target <= 10 %)")
    print(f"  of which scheduling (wall minus the tasks' own time in the worker): "
          f"{100 * (d1 - busy1) / loop:+.1f} %; the tasks themselves ran "
          f"{100 * (busy1 - sum(results['loop'][1])) / loop:+.1f} % longer in the worker "
          "process than in this one")
    return 0


if __name__ == "__main__":
    sys.exit(main())
