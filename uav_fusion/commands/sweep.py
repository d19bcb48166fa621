"""``uav_fusion sweep SPEC.yaml``: flights x profiles x a parameter grid on a Dask cluster.

Runs every task of the spec that has no stored result yet (``results.jsonl`` in the output
folder, keyed by the task's inputs), saving each result as it finishes; failed tasks are
listed with their inputs and do not stop the others. Writes ``results.csv`` (one row per task
of the spec), ``failures.json`` and ``sweep.png`` (the spec's metric against each parameter;
with a multi-UAV definition also ``tradeoff.png``, coverage against false-track time).
See docs/benchmark.md, "Sweeps".
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path
from typing import Any

from uav_fusion.commands.bench import add_engine_arguments
from uav_fusion.core.bench.sweep import (
    ResultStore,
    SweepTask,
    load_spec,
    run_sweep_task,
    summary_rows,
    sweep_tasks,
    write_table,
)
from uav_fusion.core.bench.sweep_figure import write_figure
from uav_fusion.core.bench.tradeoff import tradeoff_rows, write_tradeoff_figure
from uav_fusion.core.errors import ConfigError
from uav_fusion.core.site import load_site
from uav_fusion.resources import DEFAULT_SITE, config_path

HELP = "parameter sweep: flights x profiles x parameter values, scored like the benchmark"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("spec", help="sweep spec YAML (e.g. bench/sweep_q.yaml)")
    parser.add_argument("--out", help="output folder (default: out/sweep/<spec name>)")
    add_engine_arguments(parser)
    parser.add_argument("--no-figure", action="store_true", help="do not draw the figure")


def run(args: argparse.Namespace) -> int:
    from uav_fusion.batch import Engine

    wall0 = time.perf_counter()
    spec = load_spec(args.spec)
    if args.workers is not None and args.workers < 1:
        raise ConfigError(f"--workers must be >= 1, got {args.workers}")
    site_file = Path(args.site) if args.site else config_path(DEFAULT_SITE)
    site = load_site(site_file)
    out = Path(args.out) if args.out else Path("out/sweep") / spec.name
    store = ResultStore(out)
    tasks = sweep_tasks(spec, Path(args.cache), site_file, site)
    todo = [t for t in tasks if t.key not in store]
    n_fl = len({t.flight.flight_id for t in tasks})
    print(
        f"sweep {spec.name} ({spec.source}): {n_fl} {spec.split} flights x "
        f"{len(spec.profiles)} profiles x {len(spec.combinations())} parameter combinations "
        f"= {len(tasks)} tasks; {len(tasks) - len(todo)} stored in {store.path}, "
        f"{len(todo)} to run"
    )
    failures: list[dict[str, Any]] = []
    if todo:
        engine = Engine(workers=args.workers, scheduler=args.scheduler, processes=not args.threads)

        def done(_i: int, row: dict[str, Any]) -> None:
            if row.get("error"):
                failures.append(row)
            else:
                store.add(row)

        with engine:
            print(f"  engine: {engine.description}")
            # each flight is generated once, before the tasks that share it
            firsts: dict[str, SweepTask] = {}
            for t in todo:
                if not t.flight.exists():
                    firsts.setdefault(t.flight.flight_id, t)
            rest = [t for t in todo if t not in firsts.values()]
            engine.map(
                run_sweep_task, list(firsts.values()), label="generate+run",
                describe=SweepTask.describe, on_result=done,
            )
            engine.map(
                run_sweep_task, rest, label="run+score", describe=SweepTask.describe,
                on_result=done,
            )
    rows = [store.rows[t.key] for t in tasks if t.key in store]
    table = write_table(rows, spec, out / "results.csv")
    (out / "failures.json").write_text(
        json.dumps(failures, indent=1, default=str) + "\n", encoding="utf-8"
    )
    print()
    print(f"{spec.metric} per profile and parameters (mean, min, max over flights):")
    for prof, label, mean, lo, hi, n in sorted(summary_rows(rows, spec)):
        print(f"  {prof:18s} {label:40s} {mean:9.2f} {lo:9.2f} {hi:9.2f}  ({n} flights)")
    if spec.definition.multi:
        print("coverage % / false-track time % / GOSPA m per profile and parameters (means over "
              "flights):")
        for prof, label, cov, fal, gospa in tradeoff_rows(rows, spec):
            print(f"  {prof:18s} {label:40s} {cov:7.2f} {fal:7.2f} {gospa:7.2f}")
    for f in failures:
        print(
            f"FAILED: {f['profile']} {f['params']} on {f['flight']}: {f['error']}"
        )
    print(f"results: {table} ({len(rows)} of {len(tasks)} tasks); failures: {len(failures)}")
    if not args.no_figure:
        fig = write_figure(rows, spec, out / "sweep.png")
        if fig is not None:
            print(f"figure: {fig}")
        fig = write_tradeoff_figure(rows, spec, out / "tradeoff.png")
        if fig is not None:
            print(f"figure: {fig}")
    print(f"wall time {time.perf_counter() - wall0:.1f} s")
    return 1 if failures else 0
