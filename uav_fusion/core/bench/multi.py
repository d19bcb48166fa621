"""The multi-UAV benchmark: the multi-UAV tracker over flights with several UAVs.

One task runs :class:`~uav_fusion.core.estimators.multi.MultiTracker` over one cached flight
(``run_multi`` on the grid of the definition's ``grid_hz`` over the span of every UAV's truth)
and scores its confirmed tracks as a set (:func:`~uav_fusion.core.scoring.gospa.score_flight`:
GOSPA with p 2, c 100 m, alpha 2; per-UAV coverage, errors, ID switches, fragmentations;
false-track seconds). It adds what only the twin knows:

* **radar-observable coverage** per UAV: the share of its airborne epochs with a radar report
  on it (the twin's labels) within ``observable_window_s`` that have a track assigned; for a
  silent UAV (no control link, radar only) this is the figure that matters;
* **crossings**: the times two airborne UAVs pass within ``CROSSING_M`` of each other (a local
  minimum of their 3D distance, from the truth; minima closer than ``CROSSING_GAP_S`` are one
  crossing), so that ID switches can be read per crossing. A crossing's *span* runs from the
  time the two UAVs came within ``CROSSING_SPAN_M`` (GOSPA's cut-off) of each other to the
  time they were that far apart again: a track that swaps UAVs at the crossing leaves its UAV
  by the cut-off there at the latest, so the kept (CLEAR MOT) correspondence counts the swap
  then. An ID switch of a UAV inside the span of one of its crossings, widened by
  ``CROSSING_WINDOW_S`` on each side, counts for that crossing (the one with the nearest
  closest approach if several; :func:`crossing_switches`); a crossing with more than one (a
  swap of two tracks is two: one per UAV) is one the tracker did not get through cleanly.

Pooled per profile (:func:`pool_multi`): mean GOSPA over all epochs, coverage over all
(UAV, airborne epoch) pairs and its worst single UAV of a single flight, radar-observable
coverage (all UAVs, and the silent ones), ID switches, crossings and the crossings with more
than one ID switch (on GOSPA's per-epoch assignment and on the kept CLEAR MOT
correspondence), false-track seconds as a
share of the flights' time, and the tracker's run time.
"""

from __future__ import annotations

import csv
import math
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
import numpy.typing as npt
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from uav_fusion.core.bench.cache import CachedFlight, read_vehicle_labels
from uav_fusion.core.bench.radar_baseline import NAME as RADAR_BASELINE
from uav_fusion.core.bench.radar_baseline import radar_epochs
from uav_fusion.core.data import load_flight
from uav_fusion.core.errors import DataError
from uav_fusion.core.estimators.multi import MultiTracker, run_multi
from uav_fusion.core.estimators.selection import frames_input
from uav_fusion.core.profiles.model import Profile
from uav_fusion.core.records import Flight
from uav_fusion.core.scoring.gospa import (
    EpochLike,
    MultiScoreSettings,
    UavTruth,
    pool,
    score_flight,
)
from uav_fusion.core.scoring.metrics import interpolate_truth
from uav_fusion.core.scoring.outcomes import FlightSamples
from uav_fusion.core.site import Site
from uav_fusion.core.twin.writers import read_manifest

FloatArray = npt.NDArray[np.float64]

CROSSING_M = 50.0  # two UAVs passing closer than this cross
CROSSING_GAP_S = 20.0  # closest approaches of one pair closer in time than this are one
CROSSING_SPAN_M = 100.0  # a crossing's span: the two UAVs closer than this (module text)
CROSSING_WINDOW_S = 10.0  # ... widened by this on each side for its ID switches
CSV_FILE = "per_flight_multi.csv"
FIGURE_FILE = "bench_multi.png"
FIGURE_DPI = 110


class Crossing(NamedTuple):
    """Two airborne UAVs passing each other (module text)."""

    a: str
    b: str
    t: float  # closest approach
    t_close: float  # the span: from the last time before ``t`` they were CROSSING_SPAN_M apart
    t_apart: float  # ... to the first time after ``t`` they were that far apart again


@dataclass(frozen=True)
class MultiScoreTask:
    flight: CachedFlight
    profile: Profile
    site: Site
    grid_hz: float
    airborne_min_m: float
    observable_window_s: float
    excuse_grounded: bool = True  # see MultiScoreSettings
    baseline: bool = False  # the radar's own tracks (radar_baseline.py) instead of the profile


@dataclass(frozen=True)
class UavOutcome:
    """One UAV of one flight: its link and its radar-observable epochs."""

    name: str
    silent: bool
    observable: int  # airborne epochs with a radar report on it nearby
    observable_covered: int  # ... with a track assigned


@dataclass(frozen=True)
class MultiFlightResult:
    flight_id: str
    plan: str
    seed: int
    split: str
    profile: str
    samples: FlightSamples
    uavs: tuple[UavOutcome, ...]
    crossings: tuple[Crossing, ...]
    flight_s: float  # the scored span (epochs x grid step)
    run_s: float  # wall time of the tracker run alone


def silent_vehicles(folder: Path) -> set[str]:
    """The UAVs of a twin flight without a control link (from its manifest)."""
    doc = read_manifest(folder)
    if doc is None:
        return set()
    out: set[str] = set()
    for v in doc.get("vehicles", []) or []:
        if isinstance(v, dict) and v.get("center_frequency_hz", 0) is None:
            out.add(str(v.get("name")))
    return out


def crossings(
    flight: Flight, step_s: float = 0.5, within_m: float = CROSSING_M
) -> list[Crossing]:
    """Closest approaches of two airborne UAVs below ``within_m``, with their spans (see the
    module text)."""
    names = list(flight.vehicles)
    tracks = {v: flight.truth_arrays(v) for v in names}
    spans = [t for t, _ in tracks.values() if t.size >= 2]
    if len(spans) < 2:
        return []
    grid = np.arange(max(t[0] for t in spans), min(t[-1] for t in spans), step_s)
    pos: dict[str, FloatArray] = {}
    air: dict[str, npt.NDArray[np.bool_]] = {}
    for v in names:
        t, enu = tracks[v]
        if t.size < 2:
            continue
        pos[v] = interpolate_truth(t, enu, grid, max_gap_s=2.0)
        with np.errstate(invalid="ignore"):
            air[v] = np.asarray(pos[v][:, 2] - enu[0, 2] > 5.0, dtype=bool)
    out: list[Crossing] = []
    live = list(pos)
    for i, a in enumerate(live):
        for b in live[i + 1 :]:
            d = np.linalg.norm(pos[a] - pos[b], axis=1)
            ok = air[a] & air[b] & np.isfinite(d)
            last = -math.inf
            for k in range(1, d.size - 1):
                if not ok[k] or not d[k] < within_m:
                    continue
                if d[k] <= d[k - 1] and d[k] <= d[k + 1]:
                    tk = float(grid[k])
                    if tk - last >= CROSSING_GAP_S:
                        lo, hi = _span(ok & (d < CROSSING_SPAN_M), k)
                        out.append(Crossing(a, b, tk, float(grid[lo]), float(grid[hi])))
                    last = tk
    return out


def _span(near: npt.NDArray[np.bool_], k: int) -> tuple[int, int]:
    """The run of ``near`` around index ``k`` (``near[k]`` true), as first and last index."""
    lo, hi = k, k
    while lo > 0 and near[lo - 1]:
        lo -= 1
    while hi < near.size - 1 and near[hi + 1]:
        hi += 1
    return lo, hi


def multi_score_task(
    task: MultiScoreTask, make_tracker: Callable[[Flight], MultiTracker] | None = None
) -> MultiFlightResult:
    """Run the multi-UAV tracker over the cached flight and score its tracks as a set.

    ``make_tracker`` builds the tracker for the loaded flight instead of
    ``MultiTracker(task.profile, task.site)`` (a script's variant, scored the same way)."""
    cf = task.flight
    flight = load_flight(cf.folder, task.site)
    truths: dict[str, UavTruth] = {}
    for v in flight.vehicles:
        t, enu = flight.truth_arrays(v)
        if t.size >= 2:
            truths[v] = UavTruth(t=t, enu=enu)
    if not truths:
        raise DataError(cf.folder, None, "no UAV has two truth samples")
    t0 = min(float(tr.t[0]) for tr in truths.values())
    t1 = max(float(tr.t[-1]) for tr in truths.values())
    epochs: Sequence[EpochLike]
    if task.baseline:
        start = time.perf_counter()
        epochs = radar_epochs(flight, task.site, task.grid_hz, t0, t1)
    else:
        stream = list(frames_input(flight, task.profile))  # built before the timed run
        start = time.perf_counter()
        tracker = (
            MultiTracker(task.profile, task.site) if make_tracker is None else make_tracker(flight)
        )
        epochs = run_multi(tracker, stream, task.grid_hz, t0, t1)
    run_s = time.perf_counter() - start
    settings = MultiScoreSettings(
        step_s=1.0 / task.grid_hz,
        airborne_min_m=task.airborne_min_m,
        excuse_grounded=task.excuse_grounded,
    )
    samples = score_flight(truths, epochs, settings)
    labels = read_vehicle_labels(cf.folder)
    silent = silent_vehicles(cf.folder)
    outcomes = []
    for u in samples.uavs:
        lab = np.sort(labels.get(u.name, np.zeros(0)))
        obs = near_labels(u.times, lab, task.observable_window_s)
        cov = u.covered()
        outcomes.append(
            UavOutcome(u.name, u.name in silent, int(obs.sum()), int((obs & cov).sum()))
        )
    return MultiFlightResult(
        flight_id=cf.flight_id,
        plan=cf.flight.plan.name,
        seed=cf.flight.seed,
        split=cf.flight.split,
        profile=RADAR_BASELINE if task.baseline else task.profile.name,
        samples=samples,
        uavs=tuple(outcomes),
        crossings=tuple(crossings(flight)),
        flight_s=samples.epochs * settings.step_s,
        run_s=run_s,
    )


def crossing_switches(
    r: MultiFlightResult, kept: bool, window_s: float = CROSSING_WINDOW_S
) -> tuple[list[int], int]:
    """Per crossing of the flight (in ``r.crossings`` order), the ID switches attributed to it,
    and the number of switches at no crossing: each switch of a UAV (GOSPA's per-epoch
    assignment, or with ``kept`` the CLEAR MOT correspondence) goes to the crossing of that
    UAV whose span, widened by ``window_s`` on each side, holds it (the one with the nearest
    closest approach if several)."""
    counts = [0] * len(r.crossings)
    away = 0
    for u in r.samples.uavs:
        times = u.switch_times_kept if kept else u.switch_times
        mine = [(i, c) for i, c in enumerate(r.crossings) if u.name in (c.a, c.b)]
        for ts in times.tolist():
            near = [
                (abs(ts - c.t), i)
                for i, c in mine
                if c.t_close - window_s <= ts <= c.t_apart + window_s
            ]
            if near:
                counts[min(near)[1]] += 1
            else:
                away += 1
    return counts, away


def near_labels(times: FloatArray, labels: FloatArray, window: float) -> npt.NDArray[np.bool_]:
    """Per time: a label lies within ``window`` of it (``labels`` sorted)."""
    if times.size == 0 or labels.size == 0:
        return np.zeros(times.size, dtype=bool)
    i = np.searchsorted(labels, times)
    lo = np.abs(times - labels[np.clip(i - 1, 0, labels.size - 1)])
    hi = np.abs(labels[np.clip(i, 0, labels.size - 1)] - times)
    return np.asarray(np.minimum(lo, hi) <= window, dtype=bool)


# --- pooled figures ---------------------------------------------------------------------------


@dataclass(frozen=True)
class MultiBenchScore:
    """One profile's figures over the flights of a split (percentages in %)."""

    profile: str
    flights: int
    gospa_mean_m: float
    coverage_pct: float  # all (UAV, airborne epoch) pairs
    worst_uav_coverage_pct: float  # the lowest of any UAV in any single flight
    observable_coverage_pct: float  # radar-observable epochs, all UAVs
    silent_observable_coverage_pct: float  # ... the silent UAVs
    worst_silent_observable_pct: float
    err_mean_m: float
    err_p95_m: float
    id_switches: int  # on GOSPA's assignment per epoch
    id_switches_kept: int  # on the CLEAR MOT correspondence (core/scoring/continuity.py)
    crossings: int
    crossings_over_one: int  # crossings with more than one ID switch (per-epoch assignment)
    crossings_over_one_kept: int  # ... on the kept correspondence
    false_track_s: float
    false_track_pct: float  # of the flights' scored time
    run_s: float  # the tracker's wall time, all flights
    excused_track_pct: float = math.nan  # track time excused on UAVs not airborne (multiscore)
    # GOSPA's parts: the mean GOSPA of the assigned pairs alone (the localisation part's p-th
    # root per epoch), and the missed and false parts' shares of the summed p-th powers
    gospa_localisation_m: float = math.nan
    gospa_missed_share_pct: float = math.nan
    gospa_false_share_pct: float = math.nan

    def as_dict(self) -> dict[str, Any]:
        return asdict(self)


def _pct(num: int, den: int) -> float:
    return 100.0 * num / den if den > 0 else math.nan


def _uav_coverage(r: MultiFlightResult) -> list[float]:
    return [_pct(u.assigned, u.epochs) for u in r.samples.uavs if u.epochs > 0]


def _over_one(r: MultiFlightResult, kept: bool) -> int:
    return sum(n > 1 for n in crossing_switches(r, kept)[0])


def _gospa_parts(rs: Sequence[MultiFlightResult]) -> tuple[float, float, float]:
    """(mean GOSPA of the assigned pairs alone in m, missed share %, false share %)."""
    loc = np.concatenate([r.samples.localisation ** (1.0 / r.samples.p) for r in rs])
    tot = sum(float(np.sum(r.samples.distance**r.samples.p)) for r in rs)
    mis = sum(float(np.sum(r.samples.missed)) for r in rs)
    fal = sum(float(np.sum(r.samples.false)) for r in rs)
    mean = float(loc.mean()) if loc.size else math.nan
    return mean, _share(mis, tot), _share(fal, tot)


def _share(part: float, total: float) -> float:
    return 100.0 * part / total if total > 0 else math.nan


def pool_multi(results: Sequence[MultiFlightResult]) -> dict[str, MultiBenchScore]:
    """Per profile (in the order they first appear), the pooled figures."""
    by: dict[str, list[MultiFlightResult]] = {}
    for r in results:
        by.setdefault(r.profile, []).append(r)
    out: dict[str, MultiBenchScore] = {}
    for name, rs in by.items():
        sc = pool([r.samples for r in rs])
        outs = [u for r in rs for u in r.uavs]
        silent = [u for u in outs if u.silent]
        worst = min((c for r in rs for c in _uav_coverage(r)), default=math.nan)
        silent_each = [_pct(u.observable_covered, u.observable) for u in silent if u.observable]
        flight_s = sum(r.flight_s for r in rs)
        loc_m, mis_pct, fal_pct = _gospa_parts(rs)
        out[name] = MultiBenchScore(
            profile=name,
            flights=len(rs),
            gospa_mean_m=sc.gospa_mean_m,
            coverage_pct=sc.coverage_pct,
            worst_uav_coverage_pct=worst,
            observable_coverage_pct=_pct(
                sum(u.observable_covered for u in outs), sum(u.observable for u in outs)
            ),
            silent_observable_coverage_pct=_pct(
                sum(u.observable_covered for u in silent), sum(u.observable for u in silent)
            ),
            worst_silent_observable_pct=min(silent_each, default=math.nan),
            err_mean_m=sc.err_mean_m,
            err_p95_m=sc.err_p95_m,
            id_switches=sc.id_switches,
            id_switches_kept=sc.id_switches_kept,
            crossings=sum(len(r.crossings) for r in rs),
            crossings_over_one=sum(_over_one(r, kept=False) for r in rs),
            crossings_over_one_kept=sum(_over_one(r, kept=True) for r in rs),
            false_track_s=sc.false_track_s,
            false_track_pct=100.0 * sc.false_track_s / flight_s if flight_s > 0 else math.nan,
            run_s=sum(r.run_s for r in rs),
            excused_track_pct=100.0 * sc.excused_track_s / flight_s if flight_s > 0 else math.nan,
            gospa_localisation_m=loc_m,
            gospa_missed_share_pct=mis_pct,
            gospa_false_share_pct=fal_pct,
        )
    return out


_COLUMNS: tuple[tuple[str, str, str], ...] = (
    # (field, header, format)
    ("gospa_mean_m", "GOSPA mean (m)", "{:.1f}"),
    ("gospa_localisation_m", "GOSPA of the assigned pairs (m)", "{:.1f}"),
    ("gospa_missed_share_pct", "missed share of GOSPA^2 (%)", "{:.0f}"),
    ("gospa_false_share_pct", "false share of GOSPA^2 (%)", "{:.0f}"),
    ("coverage_pct", "coverage (%)", "{:.1f}"),
    ("worst_uav_coverage_pct", "worst UAV (%)", "{:.1f}"),
    ("observable_coverage_pct", "radar-obs. coverage (%)", "{:.1f}"),
    ("silent_observable_coverage_pct", "silent UAVs, radar-obs. (%)", "{:.1f}"),
    ("id_switches", "ID switches", "{}"),
    ("id_switches_kept", "ID switches, kept correspondence", "{}"),
    ("crossings", "crossings", "{}"),
    ("crossings_over_one", "crossings with > 1 ID switch", "{}"),
    ("crossings_over_one_kept", "crossings with > 1 ID switch, kept corr.", "{}"),
    ("false_track_pct", "false-track time (%)", "{:.2f}"),
    ("excused_track_pct", "tracks on grounded UAVs (%)", "{:.2f}"),
    ("err_mean_m", "error mean (m)", "{:.1f}"),
    ("err_p95_m", "error p95 (m)", "{:.1f}"),
    ("run_s", "run time (s)", "{:.2f}"),
)


def _fmt(fmt: str, v: Any) -> str:
    if isinstance(v, float) and not math.isfinite(v):
        return "–"
    return fmt.format(v)


def markdown_multi(scores: Mapping[str, MultiBenchScore], timing: bool = True) -> str:
    """The pooled row per profile; ``timing=False`` leaves the run time out."""
    cols = [c for c in _COLUMNS if timing or c[0] != "run_s"]
    head = "| profile | flights | " + " | ".join(h for _, h, _ in cols) + " |"
    sep = "|---|---:|" + "---:|" * len(cols)
    rows = [
        f"| {s.profile} | {s.flights} | "
        + " | ".join(_fmt(f, getattr(s, k)) for k, _, f in cols)
        + " |"
        for s in scores.values()
    ]
    return "\n".join([head, sep, *rows])


def text_multi(scores: Mapping[str, MultiBenchScore]) -> str:
    lines = []
    for s in scores.values():
        lines.append(f"{s.profile} ({s.flights} flights):")
        for k, h, f in _COLUMNS:
            lines.append(f"  {h:<42} {_fmt(f, getattr(s, k))}")
    return "\n".join(lines)


def markdown_multi_flights(results: Sequence[MultiFlightResult]) -> str:
    head = (
        "| profile | flight | GOSPA mean (m) | per-UAV coverage (%) | silent UAVs, radar-obs. "
        "(%) | ID switches (kept corr.) / crossings | false-track time (s) | run (s) |"
    )
    rows = [head, "|---|---|---:|---|---|---:|---:|---:|"]
    for r in results:
        sc = pool([r.samples])
        cov = ", ".join(
            f"{u.name} {_pct(u.assigned, u.epochs):.1f}" for u in r.samples.uavs if u.epochs
        )
        silent = ", ".join(
            f"{u.name} {_pct(u.observable_covered, u.observable):.1f}"
            for u in r.uavs
            if u.silent and u.observable
        )
        rows.append(
            f"| {r.profile} | {r.flight_id} | {sc.gospa_mean_m:.1f} | {cov} | {silent or '–'} | "
            f"{sc.id_switches} ({sc.id_switches_kept}) / {len(r.crossings)} | "
            f"{sc.false_track_s:.0f} | {r.run_s:.2f} |"
        )
    return "\n".join(rows)


def write_multi_csv(results: Sequence[MultiFlightResult], path: Path) -> Path:
    """One row per (profile, flight, UAV)."""
    with path.open("w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh)
        w.writerow(
            [
                "profile", "flight", "plan", "seed", "split", "uav", "silent", "airborne_epochs",
                "coverage_pct", "observable_epochs", "observable_coverage_pct", "err_mean_m",
                "err_p95_m", "id_switches", "id_switches_kept", "fragmentations",
                "flight_gospa_mean_m",
                "flight_false_track_s", "flight_excused_track_s", "flight_crossings",
                "flight_crossings_over_one", "flight_crossings_over_one_kept", "run_s",
            ]
        )  # fmt: skip
        for r in results:
            fl = pool([r.samples])
            per = {u.name: u for u in fl.uavs}
            over = (_over_one(r, kept=False), _over_one(r, kept=True))
            for u in r.uavs:
                us = per[u.name]
                w.writerow(
                    [
                        r.profile, r.flight_id, r.plan, r.seed, r.split, u.name, int(u.silent),
                        us.epochs, f"{us.coverage_pct:.3f}", u.observable,
                        f"{_pct(u.observable_covered, u.observable):.3f}",
                        f"{us.err_mean_m:.3f}", f"{us.err_p95_m:.3f}", us.id_switches,
                        us.id_switches_kept, us.fragmentations, f"{fl.gospa_mean_m:.3f}",
                        f"{fl.false_track_s:.1f}", f"{fl.excused_track_s:.1f}",
                        len(r.crossings), *over,
                        f"{r.run_s:.4f}",
                    ]
                )  # fmt: skip
    return path


def write_multi_figure(results: Sequence[MultiFlightResult], path: Path) -> Path:
    """GOSPA over time per flight (first profile) and per-UAV coverage per flight."""
    profiles = list(dict.fromkeys(r.profile for r in results))
    flights = list(dict.fromkeys(r.flight_id for r in results))
    fig = Figure(figsize=(11.0, 8.0), dpi=FIGURE_DPI)
    FigureCanvasAgg(fig)
    ax_g = fig.add_subplot(2, 1, 1)
    ax_c = fig.add_subplot(2, 1, 2)
    first = [r for r in results if r.profile == profiles[0]] if profiles else []
    for r in first:
        d = r.samples.distance
        (line,) = ax_g.plot(np.arange(d.size) * r.samples.step_s, d, lw=0.8, label=r.flight_id)
        # each crossing at its closest approach, with its ID switches on the kept correspondence
        if not r.samples.assignments:
            continue
        t0 = r.samples.assignments[0].t  # the first epoch: x = 0
        for c, sw in zip(r.crossings, crossing_switches(r, kept=True)[0], strict=True):
            xc = c.t - t0
            ax_g.axvline(xc, color=line.get_color(), lw=0.6, ls=":", alpha=0.8)
            if sw:
                ax_g.annotate(
                    f"{sw} sw", (xc, 1.0), xycoords=("data", "axes fraction"), fontsize=6,
                    color=line.get_color(), ha="center", va="bottom",
                )  # fmt: skip
    ax_g.set_xlabel(
        "time since the first truth sample (s); dotted: crossings, with their ID switches "
        "(kept correspondence)",
        fontsize=8,
    )
    ax_g.set_ylabel(f"GOSPA ({profiles[0] if profiles else ''}), m", fontsize=8)
    ax_g.grid(True, alpha=0.3)
    if first:
        ax_g.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.0, 1.0))
    labels: list[str] = []
    values: dict[str, list[float]] = {p: [] for p in profiles}
    for f in flights:
        rs = {r.profile: r for r in results if r.flight_id == f}
        names = [u.name for u in next(iter(rs.values())).samples.uavs]
        for n in names:
            labels.append(f"{f} {n}")
            for p in profiles:
                u = {x.name: x for x in rs[p].samples.uavs}.get(n) if p in rs else None
                values[p].append(_pct(u.assigned, u.epochs) if u and u.epochs else math.nan)
    x = np.arange(len(labels))
    width = 0.8 / max(1, len(profiles))
    for j, p in enumerate(profiles):
        ax_c.bar(x + (j - (len(profiles) - 1) / 2) * width, values[p], width, label=p)
    ax_c.set_xticks(x)
    ax_c.set_xticklabels(labels, rotation=60, ha="right", fontsize=6)
    ax_c.set_ylabel("coverage (% of the UAV's airborne epochs)", fontsize=8)
    ax_c.set_ylim(0, 100)
    ax_c.grid(True, axis="y", alpha=0.3)
    if profiles:
        ax_c.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.0, 1.0))
    fig.tight_layout()
    fig.savefig(path, format="png", dpi=FIGURE_DPI)
    return path
