"""Scoring what a running graph published, from the messages a subscriber received.

The evaluator node collects the fusion node's outputs and the truth as they arrive; these
functions score them the way the benchmarks score an offline run: the single-UAV fixed-rate
output on its grid (:func:`score_published_grid`, like the accuracy benchmark:
:mod:`uav_fusion.core.scoring.fixed_rate`) and every confirmed track of the multi-UAV tracker
as a set against every UAV's truth (:func:`score_published_tracks`, like the multi-UAV
benchmark: :mod:`uav_fusion.core.scoring.gospa`). Also the gaps between the fused steps
(:func:`step_gaps`) and the radar reports' RCS read from a flight folder (:func:`rcs_lookup`;
the standard pose messages carry none).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import numpy.typing as npt

from uav_fusion.core.data import fmt_utc, load_flight
from uav_fusion.core.data.encoding import time_to_ns
from uav_fusion.core.scoring.fixed_rate import (
    FlightTruth,
    GridScore,
    grid_from_published,
    score_grid,
)
from uav_fusion.core.scoring.fixed_rate import pool as pool_grid
from uav_fusion.core.scoring.gospa import (
    MultiScoreSettings,
    UavTruth,
    epochs_from_published,
    score_flight,
)
from uav_fusion.core.scoring.gospa import pool as pool_multi
from uav_fusion.core.scoring.outcomes import MultiScore
from uav_fusion.core.site import Site

FloatArray = npt.NDArray[np.float64]

#: a truth message kept for the fixed-rate output: (t, e, n, u, h)
TruthRow = tuple[float, float, float, float, float]
#: a vehicle's truth message: (t, e, n, u)
VehicleRow = tuple[float, float, float, float]


def score_published_grid(
    truth: Sequence[TruthRow],
    published: Sequence[tuple[float, Any, Any]],
    frequency_hz: float,
    takeoff_h: float,
) -> GridScore | None:
    """The fixed-rate output received, (t, x, P) per message, scored on its grid against the
    truth (heights ``h`` above the take-off point's ``takeoff_h``); None with fewer than two
    truth messages."""
    rows = sorted(truth)
    msgs = sorted(published, key=lambda g: g[0])
    if len(rows) < 2:
        return None
    t = np.array([r[0] for r in rows])
    keep = np.concatenate(([True], np.diff(t) > 0))
    arr = np.array(rows)[keep]
    ft = FlightTruth(arr[:, 0], arr[:, 1:4], arr[:, 4] - takeoff_h)
    t0, t1 = ft.span
    grid = grid_from_published(
        [g[0] for g in msgs], [g[1] for g in msgs], [g[2] for g in msgs], frequency_hz, t0, t1
    )
    return pool_grid([score_grid(grid, ft)])


def score_published_tracks(
    truth: Mapping[str, Sequence[VehicleRow]],
    tracks: Sequence[tuple[float, int, Any]],
    frequency_hz: float,
    final: bool = True,
) -> MultiScore | None:
    """The track messages received, (t, track id, state) each, scored as a set against every
    vehicle's truth (None without a vehicle with two truth messages). ``final``: the epochs up
    to the last truth message; otherwise up to the last track message."""
    truths: dict[str, UavTruth] = {}
    for name, rows in truth.items():
        arr = np.array(sorted(rows), dtype=float).reshape(-1, 4)
        if arr.shape[0]:
            arr = arr[np.concatenate(([True], np.diff(arr[:, 0]) > 0))]
        if arr.shape[0] >= 2:
            truths[name] = UavTruth(t=arr[:, 0], enu=arr[:, 1:4])
    if not truths:
        return None
    t0 = min(float(tr.t[0]) for tr in truths.values())
    t1 = max(float(tr.t[-1]) for tr in truths.values())
    if not final:
        t1 = min(t1, max((t for t, _, _ in tracks), default=t0))
    epochs = epochs_from_published(tracks, frequency_hz, t0, t1)
    settings = MultiScoreSettings(step_s=1.0 / frequency_hz)
    return pool_multi([score_flight(truths, epochs, settings)])


def step_gaps(t: FloatArray, gap_s: float) -> list[tuple[float, float]]:
    """(start, end) of every gap longer than ``gap_s`` between the step times ``t``."""
    if t.size < 2:
        return []
    gaps = np.flatnonzero(np.diff(t) > gap_s)
    return [(float(t[i]), float(t[i + 1])) for i in gaps]


def gap_text(gaps: Sequence[tuple[float, float]], gap_s: float) -> str:
    """:func:`step_gaps` in a line of text."""
    if not gaps:
        return f"none longer than {gap_s:g} s"
    parts = [f"{b - a:.1f} s from {fmt_utc(a)} to {fmt_utc(b)}" for a, b in gaps]
    return f"{len(gaps)} longer than {gap_s:g} s: " + "; ".join(parts)


def rcs_key(t: float, e: float, n: float) -> tuple[int, int, int]:
    """A radar report's identity: its stamp (ns) and horizontal position (mm)."""
    return time_to_ns(t), round(float(e) * 1000.0), round(float(n) * 1000.0)


def rcs_lookup(flight_dir: str, site: Site) -> dict[tuple[int, int, int], float]:
    """RCS (dBsm) of every radar report of a flight folder, keyed by :func:`rcs_key`."""
    if not flight_dir:
        return {}
    flight = load_flight(flight_dir, site)
    return {
        rcs_key(trk.t, trk.e, trk.n): trk.rcs_dbsm
        for frame in flight.radar
        for trk in frame.tracks
        if trk.rcs_dbsm is not None
    }
