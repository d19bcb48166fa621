"""Run many independent tasks in parallel on a Dask cluster, with a progress bar.

:class:`Engine` starts a local cluster (worker processes on this machine, by default one per
core, one thread each) or connects to an existing scheduler (``scheduler="tcp://host:8786"``);
both go through the same :meth:`Engine.map`, which submits ``fn(item)`` for every item,
shows progress while they finish, and returns the results in the items' order. The task
function must be a module-level function of picklable arguments that workers can import
(workers of an existing cluster need this package installed).

This module imports no rclpy; Dask is imported only when an engine starts.
"""

from __future__ import annotations

import math
import os
import sys
import time
from collections.abc import Callable, Sequence
from types import TracebackType
from typing import Any, TextIO, TypeVar

T = TypeVar("T")
R = TypeVar("R")


class Progress:
    """A progress bar on a terminal; periodic lines (every 10 %) elsewhere."""

    def __init__(self, total: int, label: str, stream: TextIO | None = None) -> None:
        self.total = total
        self.label = label
        self.stream = stream if stream is not None else sys.stderr
        self.done = 0
        self.t0 = time.perf_counter()
        self._tty = bool(getattr(self.stream, "isatty", lambda: False)())
        self._last_decile = -1
        self.update(0)

    def update(self, n: int = 1) -> None:
        self.done += n
        frac = self.done / self.total if self.total else 1.0
        el = time.perf_counter() - self.t0
        width = 30
        fill = round(width * frac)
        line = (
            f"{self.label}: [{'#' * fill}{'.' * (width - fill)}] {self.done}/{self.total} "
            f"{el:.1f} s"
        )
        if self._tty:
            end = "\n" if self.done >= self.total else ""
            self.stream.write("\r" + line + end)
            self.stream.flush()
            return
        decile = math.floor(10 * frac)
        if decile > self._last_decile:
            self.stream.write(line + "\n")
            self.stream.flush()
            self._last_decile = decile


class Engine:
    """A Dask client for the duration of a ``with`` block.

    ``workers``: local worker count (default: the number of cores); ``scheduler``: address of
    an existing cluster (then ``workers`` and ``processes`` are not used); ``processes``:
    local workers as processes (default) or as threads of this process; ``progress``: show
    progress on ``stream`` (default stderr).
    """

    def __init__(
        self,
        workers: int | None = None,
        scheduler: str | None = None,
        processes: bool = True,
        progress: bool = True,
        stream: TextIO | None = None,
    ) -> None:
        if workers is not None and workers < 1:
            raise ValueError(f"workers must be >= 1, got {workers}")
        self.workers = workers if workers is not None else (os.cpu_count() or 1)
        self.scheduler = scheduler
        self.processes = processes
        self.progress = progress
        self.stream = stream if stream is not None else sys.stderr
        self._client: Any = None
        self._cluster: Any = None
        self._config: Any = None

    @property
    def description(self) -> str:
        if self.scheduler:
            n = len(self._client.scheduler_info().get("workers", {})) if self._client else 0
            return f"Dask scheduler {self.scheduler} ({n} workers)"
        kind = "processes" if self.processes else "threads"
        return f"Dask local cluster, {self.workers} worker {kind}"

    def __enter__(self) -> Engine:
        import dask
        from distributed import Client, LocalCluster

        # Dask workers sample their own stacks every 10 ms for the dashboard's profiler; on
        # this package's pure-Python tasks that cost about 40 % of the run time in a worker
        # process (measured with scripts/bench_sweep.py). No dashboard runs here, so local
        # workers start with it off (workers of an existing cluster keep their own setting).
        self._config = dask.config.set({"distributed.worker.profile.enabled": False})
        if self.scheduler:
            self._client = Client(self.scheduler)
        else:
            # worker processes talk over TCP on the loopback interface only; thread workers
            # share this process (in-process transport)
            where = {"host": "127.0.0.1"} if self.processes else {}
            self._cluster = LocalCluster(
                n_workers=self.workers,
                threads_per_worker=1,
                processes=self.processes,
                dashboard_address=None,
                **where,
            )
            self._client = Client(self._cluster)
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        if self._client is not None:
            self._client.close()
        if self._cluster is not None:
            self._cluster.close()
        self._client = self._cluster = None
        if self._config is not None:
            self._config.__exit__(None, None, None)
            self._config = None

    def map(
        self,
        fn: Callable[[T], R],
        items: Sequence[T],
        label: str = "tasks",
        describe: Callable[[T], str] = str,
        on_result: Callable[[int, R], None] | None = None,
    ) -> list[R]:
        """``[fn(item) for item in items]``, in parallel; the first failure stops the rest
        and is raised (with a note naming the item). ``on_result(i, result)`` is called as
        each task finishes (in completion order), e.g. to save results as they come."""
        if not items:
            return []
        if self._client is None:
            raise RuntimeError("Engine.map outside its 'with' block")
        from distributed import as_completed

        futures = self._client.map(fn, list(items), pure=False)
        index = {f.key: i for i, f in enumerate(futures)}
        results: list[Any] = [None] * len(items)
        bar = Progress(len(items), label, self.stream) if self.progress else None
        try:
            for fut in as_completed(futures):
                i = index[fut.key]
                try:
                    results[i] = fut.result()
                except Exception as exc:
                    exc.add_note(f"in {label} task {describe(items[i])}")
                    raise
                if on_result is not None:
                    on_result(i, results[i])
                if bar is not None:
                    bar.update()
        finally:
            self._client.cancel(futures)
        return results
