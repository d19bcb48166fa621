"""Arrival schedules: the order in which a live pipeline receives a flight's inputs.

A live node receives each sensor's data some time after its stamp (an RF geolocation server
answers seconds late). An arrival schedule says when each input arrived, so that an offline
run (:func:`uav_fusion.core.live.rewind.simulate`, ``uav_fusion run --arrivals``) fuses them
in that order and reproduces what the live graph published at each moment.

A schedule file is CSV with the header ``source,stamp,arrival``: ``radar`` or ``rf``, the
input's sensor stamp and its arrival time (UTC seconds, or any clock: only the order counts).
A ``clock`` row says that the node's clock moved the fixed-rate output on to the sensor time
in ``stamp`` without an input (the fusion node's ``output_delay_s``): an offline run
publishes the epochs up to there at that point (:class:`ClockTick`). :func:`delayed` makes a
schedule from per-source delays and jitter instead.
"""

from __future__ import annotations

import csv
import math
import random
from collections import defaultdict, deque
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path

from uav_fusion.core.errors import ConfigError, DataError
from uav_fusion.core.records import RADAR, RF, RadarFrame, RfAttempt

CLOCK = "clock"


@dataclass(frozen=True, slots=True)
class ClockTick:
    """The fixed-rate output moved on to sensor time ``t`` by the clock, without an input."""

    t: float


Item = RadarFrame | RfAttempt
Arrival = tuple[str, Item | ClockTick]
SOURCES = (RADAR, RF)
HEADER = ("source", "stamp", "arrival")


def source_of(item: Item) -> str:
    return RADAR if isinstance(item, RadarFrame) else RF


def parse_delay(text: str) -> tuple[str, float, float]:
    """``rf=3+-1`` -> (``rf``, 3.0, 1.0): a source's mean delay and jitter, in seconds."""
    src, _, spec = text.partition("=")
    mean, _, jit = spec.replace("±", "+-").partition("+-")
    try:
        d, j = float(mean), float(jit or 0.0)
    except ValueError:
        raise ConfigError(f"--delay {text!r}: expected SOURCE=SECONDS[+-JITTER]") from None
    if src not in SOURCES or not (math.isfinite(d) and math.isfinite(j)) or d < 0 or j < 0:
        raise ConfigError(
            f"--delay {text!r}: SOURCE is one of {', '.join(SOURCES)} and the seconds are "
            "finite and >= 0"
        )
    return src, d, j


def delayed(
    items: Iterable[Item], delays: Mapping[str, tuple[float, float]], seed: int = 0
) -> list[Arrival]:
    """The arrival order when each source's inputs come ``delay`` +- ``jitter`` seconds after
    their stamp (uniform, seeded), each source still in its own order (a sensor's link is
    FIFO); ties in arrival time keep radar first, then the stamp order."""
    rng = random.Random(seed)
    last: dict[str, float] = {}
    keyed = []
    for n, it in enumerate(items):
        src = source_of(it)
        mean, jit = delays.get(src, (0.0, 0.0))
        at = it.t + mean + (rng.uniform(-jit, jit) if jit else 0.0)
        at = max(at, last.get(src, -math.inf))
        last[src] = at
        keyed.append((at, 0 if src == RADAR else 1, n, src, it))
    keyed.sort(key=lambda e: (e[0], e[1], e[2]))
    return [(src, it) for _, _, _, src, it in keyed]


def read_schedule(path: str | Path, items: Iterable[Item]) -> list[Arrival]:
    """The inputs in the order a schedule file says they arrived, with the clock's moves of
    the output among them (see the module text). Every input row must name an input of
    ``items`` (by source and stamp); inputs without a row never arrived."""
    p = Path(path)
    by_key: dict[tuple[str, float], deque[Item]] = defaultdict(deque)
    for it in items:
        by_key[(source_of(it), it.t)].append(it)
    rows: list[tuple[float, int, str, Item | ClockTick]] = []
    try:
        fh = p.open(newline="", encoding="utf-8")
    except OSError as exc:
        raise DataError(p, None, f"cannot read the arrival schedule: {exc}") from None
    with fh:
        reader = csv.reader(fh)
        header = next(reader, None)
        if header is None or tuple(h.strip() for h in header) != HEADER:
            raise DataError(p, 1, f"expected the header {','.join(HEADER)}")
        for line, row in enumerate(reader, start=2):
            if len(row) != 3:
                raise DataError(p, line, f"expected 3 columns, got {len(row)}")
            src = row[0].strip()
            try:
                stamp, at = float(row[1]), float(row[2])
            except ValueError:
                raise DataError(p, line, "stamp and arrival must be numbers") from None
            if src not in (*SOURCES, CLOCK) or not (math.isfinite(stamp) and math.isfinite(at)):
                raise DataError(p, line, f"bad row {row!r}")
            if src == CLOCK:
                rows.append((at, line, src, ClockTick(stamp)))
                continue
            queue = by_key.get((src, stamp))
            if not queue:
                raise DataError(p, line, f"no {src} input of the flight is stamped {stamp!r}")
            rows.append((at, line, src, queue.popleft()))
    rows.sort(key=lambda r: (r[0], r[1]))
    return [(src, it) for _, _, src, it in rows]


def write_schedule(path: str | Path, rows: Iterable[tuple[str, float, float]]) -> Path:
    """Write (source, stamp, arrival) rows as a schedule file."""
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    with p.open("w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh)
        w.writerow(HEADER)
        for src, stamp, at in rows:
            w.writerow((src, repr(float(stamp)), repr(float(at))))
    return p
