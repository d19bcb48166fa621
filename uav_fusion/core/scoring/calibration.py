"""Raw ("before fusion") sensor statistics of a flight against its truth.

This is the paper's first block of Table II, plus the breakdowns used to calibrate the digital
twin: radar error by distance from the radar, and RF error in the northern and southern halves
of the flight.

Definitions (all errors against truth linearly interpolated at the measurement time with
:func:`uav_fusion.core.scoring.metrics.interpolate_truth`):

- radar error is 3D (east, north, up); RF error is 2D (east, north);
- the UAV's radar reports are the reports of the tracks whose mean UAV class probability
  (``catProb[0]``) over the whole track is at least ``uav_prob_threshold`` (0.5 by default); a
  track without class probabilities counts as the UAV's (:mod:`uav_fusion.core.data.uav_class`,
  the same rule as the raw radar row of ``uav_fusion evaluate``). Bird and clutter tracks are
  counted separately and never scored. Coverage is count-based: scored reports / UAV reports;
- RF coverage is fixes / attempts (a failed attempt, latitude = longitude = 0, is an attempt);
- distance bins use the 3D distance from the radar to the truth position at the report time;
- the RF north/south split is by the truth north coordinate at each attempt's time, against the
  median of that coordinate over all attempts: "north half" = attempts at or above the median.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from uav_fusion.core.data import uav_class
from uav_fusion.core.records import Flight
from uav_fusion.core.scoring.metrics import (
    ErrorStats,
    error_stats,
    interpolate_truth,
    position_errors,
)
from uav_fusion.core.site import RadarCalibration

FloatArray = npt.NDArray[np.float64]

DEFAULT_RANGE_BINS: tuple[float, ...] = (0.0, 200.0, 400.0, 600.0, 800.0, 1000.0, 1400.0)


@dataclass(frozen=True)
class RangeBinStats:
    lo: float
    hi: float  # inf for the last bin
    stats: ErrorStats

    @property
    def label(self) -> str:
        return f">{self.lo:.0f} m" if math.isinf(self.hi) else f"{self.lo:.0f}-{self.hi:.0f} m"


@dataclass(frozen=True)
class CalibrationResult:
    flight: str
    uav_prob_threshold: float
    radar: ErrorStats  # UAV reports, 3D
    radar_frames: int
    radar_reports_all: int
    radar_uav_reports: int
    radar_uav_tracks: int
    radar_other_tracks: int
    radar_other_reports: int
    radar_interval_median_s: float
    radar_in_gate: ErrorStats
    radar_beyond_gate: ErrorStats
    range_gate_m: float
    radar_bins: tuple[RangeBinStats, ...]
    radar_rcs_m2: tuple[float, float, float]  # min, mean, max over UAV reports with RCS
    rf: ErrorStats  # 2D, denominator = attempts
    rf_attempts: int
    rf_fixes: int
    rf_interval_mean_s: float
    rf_split_north_m: float
    rf_north: ErrorStats
    rf_south: ErrorStats
    rf_north_median_m: float
    rf_south_median_m: float
    notes: list[str] = field(default_factory=list)


def calibrate(
    flight: Flight,
    radar_enu: tuple[float, float, float],
    range_gate_m: float = 800.0,
    uav_prob_threshold: float = 0.5,
    range_bins: tuple[float, ...] = DEFAULT_RANGE_BINS,
    max_truth_gap_s: float = 2.0,
) -> CalibrationResult:
    """Score a flight's raw radar and RF measurements against its truth."""
    notes: list[str] = []
    tt, tenu = flight.truth_arrays()
    order = np.argsort(tt, kind="stable")
    tt, tenu = tt[order], tenu[order]
    if tt.size < 2:
        notes.append("fewer than two truth samples: nothing can be scored")

    # --- radar ------------------------------------------------------------------------------
    uav_ids, other_ids = uav_class.uav_track_ids(flight.radar, uav_prob_threshold)
    rt: list[float] = []
    rpos: list[tuple[float, float, float]] = []
    rcs: list[float] = []
    n_all = 0
    for fr in flight.radar:
        for tr in fr.tracks:
            n_all += 1
            if tr.track_id in uav_ids:
                rt.append(tr.t)
                rpos.append((tr.e, tr.n, tr.u))
                if tr.rcs_dbsm is not None and math.isfinite(tr.rcs_dbsm):
                    rcs.append(10.0 ** (tr.rcs_dbsm / 10.0))
    rt_a = np.asarray(rt, dtype=float)
    rpos_a = np.asarray(rpos, dtype=float).reshape(-1, 3)
    ref = interpolate_truth(tt, tenu, rt_a, max_truth_gap_s)
    rerr = position_errors(rpos_a, ref, 3) if rt_a.size else np.zeros(0)
    dist = np.linalg.norm(ref - np.asarray(radar_enu, dtype=float), axis=1)
    n_uav = int(rt_a.size)
    radar_stats = error_stats(rerr, n_uav)
    inside = dist <= range_gate_m
    beyond = dist > range_gate_m
    edges = [*range_bins, math.inf]
    bins = []
    for lo, hi in itertools.pairwise(edges):
        m = (dist >= lo) & (dist < hi)
        bins.append(RangeBinStats(lo, hi, error_stats(rerr[m], int(np.sum(m)))))
    frame_t = np.array([fr.t for fr in flight.radar if fr.tracks], dtype=float)
    uav_frame_t = np.unique(rt_a)
    interval = float(np.median(np.diff(uav_frame_t))) if uav_frame_t.size > 1 else math.nan
    n_other = sum(1 for fr in flight.radar for tr in fr.tracks if tr.track_id in other_ids)
    rcs_a = np.asarray(rcs, dtype=float)
    rcs_t = (
        (float(rcs_a.min()), float(rcs_a.mean()), float(rcs_a.max()))
        if rcs_a.size
        else (math.nan,) * 3
    )
    if frame_t.size == 0:
        notes.append("no radar frame carries a track")

    # --- RF ---------------------------------------------------------------------------------
    at = np.array([a.t for a in flight.rf], dtype=float)
    fix = np.array([(a.e, a.n) if a.ok else (math.nan, math.nan) for a in flight.rf], dtype=float)
    fix = fix.reshape(-1, 2)
    ok = np.array([a.ok for a in flight.rf], dtype=bool)
    aref = interpolate_truth(tt, tenu, at, max_truth_gap_s)
    ferr = np.full(at.size, math.nan)
    if at.size:
        ferr[ok] = position_errors(fix[ok], aref[ok], 2)
    rf_stats = error_stats(ferr[ok], int(at.size))
    north = aref[:, 1]
    has_truth = np.isfinite(north)
    split = float(np.median(north[has_truth])) if np.any(has_truth) else math.nan
    is_n = has_truth & (north >= split)
    is_s = has_truth & (north < split)
    rf_n = error_stats(ferr[is_n & ok], int(np.sum(is_n)))
    rf_s = error_stats(ferr[is_s & ok], int(np.sum(is_s)))
    med_n = float(np.nanmedian(ferr[is_n & ok])) if np.any(is_n & ok) else math.nan
    med_s = float(np.nanmedian(ferr[is_s & ok])) if np.any(is_s & ok) else math.nan
    rf_interval = float(np.mean(np.diff(np.sort(at)))) if at.size > 1 else math.nan

    return CalibrationResult(
        flight=flight.name,
        uav_prob_threshold=uav_prob_threshold,
        radar=radar_stats,
        radar_frames=len(flight.radar),
        radar_reports_all=n_all,
        radar_uav_reports=n_uav,
        radar_uav_tracks=len(uav_ids),
        radar_other_tracks=len(other_ids),
        radar_other_reports=n_other,
        radar_interval_median_s=interval,
        radar_in_gate=error_stats(rerr[inside], int(np.sum(inside))),
        radar_beyond_gate=error_stats(rerr[beyond], int(np.sum(beyond))),
        range_gate_m=range_gate_m,
        radar_bins=tuple(bins),
        radar_rcs_m2=rcs_t,
        rf=rf_stats,
        rf_attempts=int(at.size),
        rf_fixes=int(np.sum(ok)),
        rf_interval_mean_s=rf_interval,
        rf_split_north_m=split,
        rf_north=rf_n,
        rf_south=rf_s,
        rf_north_median_m=med_n,
        rf_south_median_m=med_s,
        notes=notes,
    )


@dataclass(frozen=True)
class AngleResiduals:
    """Azimuth and elevation residuals (report minus truth, degrees) of a flight's UAV radar
    reports, seen from the radar (see :func:`angle_residuals`)."""

    flight: str
    az_deg: FloatArray  # clockwise from north, wrapped to (-180, 180]
    el_deg: FloatArray


@dataclass(frozen=True)
class RadarAlignment:
    """The radar's mounting misalignment estimated against truth: the median azimuth and
    elevation residual of the UAV's radar reports (the site file's ``radar.calibration``
    corrects it: :func:`site_calibration`)."""

    az_bias_deg: float
    el_bias_deg: float
    n_reports: int
    n_flights: int
    # per-flight medians: smallest and largest (the spread between flights)
    az_flight_range_deg: tuple[float, float]
    el_flight_range_deg: tuple[float, float]


def angle_residuals(
    flight: Flight,
    radar_enu: tuple[float, float, float],
    uav_prob_threshold: float = 0.5,
    max_error_m: float = 100.0,
    min_horizontal_m: float = 50.0,
    max_truth_gap_s: float = 2.0,
) -> AngleResiduals:
    """Angle residuals of the UAV's radar reports (the class rule of :func:`calibrate`).

    Only reports within ``max_error_m`` of truth count (a UAV track that took a ghost's or a
    clutter site's detection is not an angle error of the radar), and only where the truth
    lies at least ``min_horizontal_m`` from the radar horizontally (the azimuth of a target
    straight above the radar means nothing).
    """
    uav_ids, _ = uav_class.uav_track_ids(flight.radar, uav_prob_threshold)
    rows = [
        (tr.t, tr.e, tr.n, tr.u)
        for fr in flight.radar
        for tr in fr.tracks
        if tr.track_id in uav_ids
    ]
    empty = np.zeros(0)
    if not rows:
        return AngleResiduals(flight.name, empty, empty)
    a = np.asarray(rows, dtype=float)
    tt, tenu = flight.truth_arrays()
    order = np.argsort(tt, kind="stable")
    ref = interpolate_truth(tt[order], tenu[order], a[:, 0], max_truth_gap_s)
    z = a[:, 1:] - np.asarray(radar_enu, dtype=float)
    x = ref - np.asarray(radar_enu, dtype=float)
    with np.errstate(invalid="ignore"):
        ok = (
            np.all(np.isfinite(x), axis=1)
            & (np.linalg.norm(z - x, axis=1) <= max_error_m)
            & (np.hypot(x[:, 0], x[:, 1]) >= min_horizontal_m)
        )
    z, x = z[ok], x[ok]
    daz = np.degrees(np.arctan2(z[:, 0], z[:, 1]) - np.arctan2(x[:, 0], x[:, 1]))
    daz = (daz + 180.0) % 360.0 - 180.0
    del_ = np.degrees(
        np.arctan2(z[:, 2], np.hypot(z[:, 0], z[:, 1]))
        - np.arctan2(x[:, 2], np.hypot(x[:, 0], x[:, 1]))
    )
    return AngleResiduals(flight.name, daz, del_)


def radar_alignment(residuals: list[AngleResiduals]) -> RadarAlignment | None:
    """The pooled median of one or more flights' angle residuals (None without any)."""
    used = [r for r in residuals if r.az_deg.size]
    if not used:
        return None
    az = np.concatenate([r.az_deg for r in used])
    el = np.concatenate([r.el_deg for r in used])
    maz = [float(np.median(r.az_deg)) for r in used]
    mel = [float(np.median(r.el_deg)) for r in used]
    return RadarAlignment(
        float(np.median(az)),
        float(np.median(el)),
        int(az.size),
        len(used),
        (min(maz), max(maz)),
        (min(mel), max(mel)),
    )


def format_alignment(al: RadarAlignment | None, hint: bool = True) -> str:
    """One Markdown paragraph on the radar's misalignment (``hint``: and how a profile
    corrects it)."""
    if al is None:
        return "Radar alignment: no UAV report within 100 m of truth; nothing to estimate."
    text = (
        f"Radar alignment (median UAV report minus truth, {al.n_reports} reports within 100 m"
        f" of truth): azimuth {al.az_bias_deg:+.2f} deg, elevation {al.el_bias_deg:+.2f} deg"
    )
    if al.n_flights > 1:
        lo, hi = al.az_flight_range_deg
        elo, ehi = al.el_flight_range_deg
        text += (
            f" over {al.n_flights} flights (per-flight medians: azimuth {lo:+.2f} to {hi:+.2f},"
            f" elevation {elo:+.2f} to {ehi:+.2f} deg)"
        )
    if not hint:
        return text + "."
    return (
        text + ". The site file's radar.calibration corrects it "
        "(uav_fusion calibrate --write-site FILE writes it)."
    )


#: Reports of one radar track are correlated over seconds: at ~4 reports a second, about this
#: many reports make one independent measurement of an angle (for the standard error below).
CORRELATED_REPORTS = 20


def site_calibration(
    al: RadarAlignment, residuals: list[AngleResiduals], note: str = ""
) -> RadarCalibration:
    """The site file's calibration from a pooled alignment: the pooled medians, and their
    standard errors (from the spread of the flights' medians with several flights, else from
    the spread of the reports, counting ``CORRELATED_REPORTS`` reports as one)."""

    def sigma(values: list[FloatArray]) -> float:
        if len(values) >= 2:
            med = [float(np.median(v)) for v in values]
            return float(np.std(med, ddof=1) / np.sqrt(len(med)))
        v = np.concatenate(values)
        mad = float(np.median(np.abs(v - np.median(v))))
        n_eff = max(1.0, v.size / CORRELATED_REPORTS)
        # the standard error of a median: 1.2533 sigma / sqrt(n); sigma from the MAD
        return 1.2533 * 1.4826 * mad / float(np.sqrt(n_eff))

    used = [r for r in residuals if r.az_deg.size]
    if not used:
        raise ValueError("no UAV report near truth: nothing to calibrate")
    return RadarCalibration(
        az_bias_deg=al.az_bias_deg,
        el_bias_deg=al.el_bias_deg,
        az_sigma_deg=max(sigma([r.az_deg for r in used]), 0.01),
        el_sigma_deg=max(sigma([r.el_deg for r in used]), 0.01),
        note=note[:200],
    )


def _row(name: str, s: ErrorStats) -> str:
    def f(x: float) -> str:
        return "-" if not math.isfinite(x) else f"{x:.1f}"

    return (
        f"| {name} | {s.count} | {f(s.min)} | {f(s.max)} | {f(s.mean)} | {f(s.std)} "
        f"| {f(s.coverage_pct)} |"
    )


def format_calibration(res: CalibrationResult) -> str:
    """A readable Markdown report of a :class:`CalibrationResult`."""
    head = (
        "| stage | count | min m | max m | mean m | std m | coverage % |\n"
        "|---|---|---|---|---|---|---|"
    )
    lines = [
        f"## Raw sensor errors before fusion: {res.flight}",
        "",
        head,
        _row("RF raw (2D)", res.rf),
        _row("Radar raw (3D)", res.radar),
        "",
        f"RF: {res.rf_attempts} attempts, {res.rf_fixes} fixes, mean interval "
        f"{res.rf_interval_mean_s:.2f} s.",
        f"Radar: {res.radar_frames} frames, {res.radar_reports_all} track reports; "
        f"{res.radar_uav_reports} UAV reports in {res.radar_uav_tracks} track(s) "
        f"(tracks with mean catProb[0] >= {res.uav_prob_threshold:g}), "
        f"{res.radar_other_reports} bird/clutter reports in {res.radar_other_tracks} track(s); "
        f"median UAV report interval {res.radar_interval_median_s:.3f} s.",
    ]
    rmin, rmean, rmax = res.radar_rcs_m2
    if math.isfinite(rmean):
        lines.append(f"Radar UAV RCS: min {rmin:.4f} m², mean {rmean:.3f} m², max {rmax:.3f} m².")
    lines += [
        "",
        "### Radar error by 3D distance from the radar (truth position)",
        "",
        head.replace("| stage |", "| distance |"),
        *[_row(b.label, b.stats) for b in res.radar_bins],
        _row(f"within {res.range_gate_m:.0f} m", res.radar_in_gate),
        _row(f"beyond {res.range_gate_m:.0f} m", res.radar_beyond_gate),
        "",
        "### RF error, north vs south half of the flight",
        "",
        f"Halves split at the median truth north coordinate over the RF attempts "
        f"(N = {res.rf_split_north_m:.1f} m from LW1); coverage = fixes / attempts in the half.",
        "",
        head.replace("| stage |", "| half |"),
        _row("north (N >= split)", res.rf_north),
        _row("south (N < split)", res.rf_south),
        "",
        f"Median RF error: north {res.rf_north_median_m:.1f} m, "
        f"south {res.rf_south_median_m:.1f} m.",
    ]
    for n in res.notes:
        lines.append(f"Note: {n}")
    return "\n".join(lines)
