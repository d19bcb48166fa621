"""The radar's own tracks passed through: the baseline a tracker has to beat.

A radar with an onboard tracker already outputs tracks with a class. A user who takes them
as they come, keeping the ones the classifier calls a UAV, has a tracker for free; fusion
earns its keep only where it does better. At each epoch of the benchmark's grid the
baseline takes the reports of the latest radar frame at or before the epoch (if that frame
is at most :data:`~uav_fusion.core.estimators.adaptive.HELD_S` old, the radar's longest
update interval) whose own class probability is at least ``min_uav_prob`` (0.5, the paper's
raw radar row), each moved to the epoch with its reported velocity. The site file's mount
calibration corrects the positions, as it does for the trackers.

* **Multi-UAV** (:func:`radar_epochs`): every such report is a track, under the radar's
  track id. The multi-UAV benchmark scores it as the profile ``radar``.
* **Single-UAV** (:func:`radar_grid`): the one report the classifier finds most UAV-like
  (the highest class probability; the lower track id on a tie) is the UAV, published with
  no covariance (no NEES). The single-UAV benchmark scores it as the profile ``radar`` on
  the profiles' grid, and :func:`against_radar_single` compares each profile with it on the
  epochs both cover.
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from uav_fusion.core.data.uav_class import DEFAULT_MIN_MEAN_UAV_PROB
from uav_fusion.core.estimators.adaptive import HELD_S
from uav_fusion.core.estimators.parts import alignment_from_site
from uav_fusion.core.records import RADAR, Flight, RadarTrack
from uav_fusion.core.scoring.fixed_rate import Grid
from uav_fusion.core.scoring.gospa import EpochTracks, PublishedTrack, pool
from uav_fusion.core.scoring.outcomes import UavSamples
from uav_fusion.core.site import Site

if TYPE_CHECKING:
    from uav_fusion.core.bench.multi import MultiFlightResult
    from uav_fusion.core.bench.single import FlightResult

#: the baseline's name where the benchmark lists profiles
NAME = "radar"

FloatArray = npt.NDArray[np.float64]


def _epoch_reports(
    flight: Flight, site: Site, grid_hz: float, t0: float, t1: float, min_uav_prob: float
) -> Iterator[tuple[float, list[tuple[RadarTrack, FloatArray]]]]:
    """Every epoch ``k / grid_hz`` in ``[t0, t1]`` with the reports the baseline passes on
    then (module text): each report with its corrected state ``(e, n, u, ve, vn, vu)`` moved
    to the epoch."""
    frames = sorted(flight.radar, key=lambda fr: fr.t)
    align = alignment_from_site(site)
    j = -1
    k = math.ceil(t0 * grid_hz)
    while k / grid_hz < t0:
        k += 1
    while (t := k / grid_hz) <= t1:
        while j + 1 < len(frames) and frames[j + 1].t <= t:
            j += 1
        reports: list[tuple[RadarTrack, FloatArray]] = []
        if j >= 0 and t - frames[j].t <= HELD_S:
            for trk in frames[j].tracks:
                p = trk.uav_prob
                if p is None or not p >= min_uav_prob:
                    continue
                e, n, u = trk.e, trk.n, trk.u
                if align is not None:
                    e, n, u = align.point(e, n, u)
                v = trk.vel_ned
                ve, vn, vu = (v[1], v[0], -v[2]) if v is not None else (0.0, 0.0, 0.0)
                dt = t - trk.t
                x = np.array([e + ve * dt, n + vn * dt, u + vu * dt, ve, vn, vu], dtype=float)
                if np.all(np.isfinite(x)):
                    reports.append((trk, x))
        yield t, reports
        k += 1


def radar_epochs(
    flight: Flight,
    site: Site,
    grid_hz: float,
    t0: float,
    t1: float,
    min_uav_prob: float = DEFAULT_MIN_MEAN_UAV_PROB,
) -> list[EpochTracks]:
    """The multi-UAV baseline's tracks at every epoch ``k / grid_hz`` in ``[t0, t1]`` (see
    the module text)."""
    return [
        EpochTracks(t, tuple(PublishedTrack(trk.track_id, x) for trk, x in reports))
        for t, reports in _epoch_reports(flight, site, grid_hz, t0, t1, min_uav_prob)
    ]


def radar_grid(
    flight: Flight,
    site: Site,
    grid_hz: float,
    t0: float,
    t1: float,
    min_uav_prob: float = DEFAULT_MIN_MEAN_UAV_PROB,
) -> Grid:
    """The single-UAV baseline's output on the grid ``k / grid_hz`` in ``[t0, t1]`` (see the
    module text): the most UAV-like report, its age, its radar track id; a new "track"
    whenever that id changes (so ``restarts`` counts the hand-overs between radar tracks)."""
    ts: list[float] = []
    xs: list[FloatArray] = []
    ages: list[float] = []
    ids: list[int] = []
    runs = 0
    last = -1
    nan6 = np.full(6, math.nan)
    for t, reports in _epoch_reports(flight, site, grid_hz, t0, t1, min_uav_prob):
        ts.append(t)
        if not reports:
            xs.append(nan6)
            ages.append(math.nan)
            ids.append(-1)
            last = -1
            continue
        trk, x = max(reports, key=lambda r: (r[0].uav_prob or 0.0, -r[0].track_id))
        if trk.track_id != last:
            runs += 1
        last = trk.track_id
        xs.append(x)
        ages.append(t - trk.t)
        ids.append(trk.track_id)
    n = len(ts)
    has = np.array([i >= 0 for i in ids], dtype=bool)
    return Grid(
        frequency_hz=grid_hz,
        max_coast_s=HELD_S,
        t=np.array(ts, dtype=float),
        x=np.array(xs, dtype=float).reshape(n, 6),
        P=np.full((n, 6, 6), math.nan),
        has_track=has,
        published=has.copy(),
        age_s=np.array(ages, dtype=float),
        track_id=np.array(ids, dtype=np.int64),
        last_source=np.array([RADAR if h else "" for h in has], dtype=np.str_),
        confirmed_tracks=runs,
    )


def _common_mean(a: UavSamples, b: UavSamples) -> tuple[int, float, float]:
    """The epochs both cover and each one's mean error over them."""
    ca, cb = a.covered(), b.covered()
    if ca.size != cb.size or not np.array_equal(a.times, b.times):
        return 0, math.nan, math.nan
    both = ca & cb
    ea = np.full(ca.size, np.nan)
    eb = np.full(cb.size, np.nan)
    ea[ca] = a.errors
    eb[cb] = b.errors
    n = int(both.sum())
    if n == 0:
        return 0, math.nan, math.nan
    return n, float(ea[both].mean()), float(eb[both].mean())


def against_radar(results: Sequence[MultiFlightResult]) -> str:
    """Each profile against the baseline: per flight its mean GOSPA and the baseline's; per
    UAV the mean error of each over the epochs both cover; and the counts of flights with a
    lower GOSPA and of UAVs with an error at most the baseline's."""
    radar = {r.flight_id: r for r in results if r.profile == NAME}
    rows = [
        "profile | flight | GOSPA m (radar) | UAV: epochs both cover, mean error m (radar)",
    ]
    counts: dict[str, list[int]] = {}
    for r in results:
        base = radar.get(r.flight_id)
        if r.profile == NAME or base is None:
            continue
        c = counts.setdefault(r.profile, [0, 0, 0, 0])
        g, gb = pool([r.samples]).gospa_mean_m, pool([base.samples]).gospa_mean_m
        c[0] += g < gb
        c[1] += 1
        theirs = {u.name: u for u in base.samples.uavs}
        cells = []
        for u in r.samples.uavs:
            n, mine, other = _common_mean(u, theirs[u.name]) if u.name in theirs else (0, 0, 0)
            if n:
                c[2] += mine <= other
                c[3] += 1
                cells.append(f"{u.name} {n}, {mine:.1f} ({other:.1f})")
            else:
                cells.append(f"{u.name} -")
        rows.append(f"{r.profile} | {r.flight_id} | {g:.1f} ({gb:.1f}) | {'; '.join(cells)}")
    for name, (lo, flights, ok, uavs) in counts.items():
        rows.append(
            f"{name}: GOSPA below the radar's on {lo} of {flights} flights; mean error at most "
            f"the radar's on {ok} of {uavs} UAVs (epochs both cover)"
        )
    return "\n".join(rows)


def _common_errors(a: FlightResult, b: FlightResult) -> tuple[FloatArray, FloatArray]:
    """The errors of two single-UAV runs of one flight on the epochs both cover."""
    ia, ib = a.samples.epoch_index, b.samples.epoch_index
    _, ka, kb = np.intersect1d(ia, ib, assume_unique=True, return_indices=True)
    return a.samples.errors[ka], b.samples.errors[kb]


@dataclass(frozen=True)
class FlightComparison:
    """One single-UAV run against the baseline on the epochs both cover."""

    flight_id: str
    epochs: int
    mean_m: float  # NaN without a common epoch
    radar_mean_m: float


@dataclass(frozen=True)
class RadarComparison:
    """A single-UAV profile against the baseline, per flight and pooled over the epochs both
    cover (``flights`` with a common epoch; ``at_most``: those with a mean error at most the
    radar's)."""

    profile: str
    per_flight: tuple[FlightComparison, ...]
    epochs: int
    mean_m: float
    radar_mean_m: float

    @property
    def flights(self) -> int:
        return sum(1 for f in self.per_flight if f.epochs > 0)

    @property
    def above(self) -> tuple[FlightComparison, ...]:
        """The flights where the profile's mean error is above the radar's."""
        return tuple(f for f in self.per_flight if f.epochs > 0 and f.mean_m > f.radar_mean_m)

    @property
    def at_most(self) -> int:
        return self.flights - len(self.above)

    def as_dict(self) -> dict[str, object]:
        """For the summary JSON (no NaN: a flight without a common epoch has nulls)."""

        def num(v: float) -> float | None:
            return round(v, 3) if math.isfinite(v) else None

        return {
            "flights": self.flights,
            "at_most": self.at_most,
            "epochs": self.epochs,
            "mean_m": num(self.mean_m),
            "radar_mean_m": num(self.radar_mean_m),
            "per_flight": {
                f.flight_id: {
                    "epochs": f.epochs, "mean_m": num(f.mean_m), "radar_mean_m": num(f.radar_mean_m)
                }
                for f in self.per_flight
            },
        }  # fmt: skip

    def line(self) -> str:
        """The summary line the command prints."""
        out = (
            f"{self.profile}: mean error at most the radar's own track's on {self.at_most} of "
            f"{self.flights} flights (epochs both cover)"
        )
        if self.epochs:
            out += (
                f"; pooled over {self.epochs} epochs {self.mean_m:.1f} m against "
                f"{self.radar_mean_m:.1f} m"
            )
        if self.above:
            cells = (f"{f.flight_id} {f.mean_m:.1f} ({f.radar_mean_m:.1f})" for f in self.above)
            out += "; above it: " + ", ".join(cells)
        return out


def against_radar_single(results: Sequence[FlightResult]) -> list[RadarComparison]:
    """Each single-UAV profile against the baseline on the epochs both cover, in the order
    the profiles first appear."""
    radar = {r.flight_id: r for r in results if r.profile == NAME}
    per: dict[str, list[FlightComparison]] = {}
    pooled: dict[str, tuple[list[FloatArray], list[FloatArray]]] = {}
    for r in results:
        base = radar.get(r.flight_id)
        if r.profile == NAME or base is None:
            continue
        mine, theirs = _common_errors(r, base)
        n = int(mine.size)
        per.setdefault(r.profile, []).append(
            FlightComparison(
                r.flight_id,
                n,
                float(mine.mean()) if n else math.nan,
                float(theirs.mean()) if n else math.nan,
            )
        )
        pa, pb = pooled.setdefault(r.profile, ([], []))
        pa.append(mine)
        pb.append(theirs)
    out = []
    for prof, flights in per.items():
        a = np.concatenate(pooled[prof][0])
        b = np.concatenate(pooled[prof][1])
        out.append(
            RadarComparison(
                prof,
                tuple(flights),
                int(a.size),
                float(a.mean()) if a.size else math.nan,
                float(b.mean()) if b.size else math.nan,
            )
        )
    return out


def markdown_against_radar(comparisons: Sequence[RadarComparison]) -> str:
    """The per-flight comparison as a Markdown table (profile, flight, epochs both cover,
    mean error and the radar's)."""
    rows = [
        "| profile | flight | epochs both cover | mean m | radar's mean m |",
        "|---|---|---:|---:|---:|",
    ]
    for c in comparisons:
        for f in c.per_flight:
            cells = f"{f.mean_m:.1f} | {f.radar_mean_m:.1f}" if f.epochs else "- | -"
            rows.append(f"| {c.profile} | {f.flight_id} | {f.epochs} | {cells} |")
    return "\n".join(rows)
