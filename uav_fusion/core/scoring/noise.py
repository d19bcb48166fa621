"""Empirical measurement covariances R from a flight: errors against interpolated truth.

The paper: "Measurement errors were computed relative to the UAV ground-truth, and MATLAB's
cov function was used". MATLAB's ``cov`` is the sample covariance with the mean removed and
normalised by N-1; :func:`sample_cov` is exactly that (``numpy.cov(E, rowvar=False, ddof=1)``).

Which errors go in:

* radar (3D, east/north/up): by default the reports the paper's filter fuses candidates from,
  i.e. the largest track inside the range gate (``radar_select="largest_gated"``); ``largest``
  drops the range gate, ``all`` takes every report of every track (clutter included);
* RF (2D, east/north): every successful fix (``ok``); failed attempts carry no position.

Robust option: raw RF errors are heavy-tailed (NLOS fixes kilometres off), and their plain
sample covariance is dominated by a handful of outliers. ``method="trim"`` iterates a
chi-square trim: compute the covariance of the current inliers, keep the errors whose squared
Mahalanobis distance (about the inliers' mean) is within ``chi2.ppf(trim_probability, d)``,
repeat until the set stops changing; the result is scaled by ``F_d(k) / F_{d+2}(k)``, the
consistency factor that makes a trimmed Gaussian sample covariance unbiased. ``method="all"``
is the paper's literal procedure.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from scipy.stats import chi2

from uav_fusion.core.errors import DataError
from uav_fusion.core.estimators.selection import largest_track_id
from uav_fusion.core.records import Flight
from uav_fusion.core.scoring.metrics import interpolate_truth
from uav_fusion.core.site import Site

FloatArray = npt.NDArray[np.float64]

METHODS = ("all", "trim")
RADAR_SELECTS = ("largest_gated", "largest", "all")


def sample_cov(errors: FloatArray) -> FloatArray:
    """MATLAB ``cov``: mean removed, normalised by N-1 (rows are samples)."""
    e = np.asarray(errors, dtype=float)
    return np.atleast_2d(np.cov(e, rowvar=False, ddof=1))


def trimmed_cov(
    errors: FloatArray, probability: float = 0.99, max_iter: int = 50
) -> tuple[FloatArray, FloatArray, int]:
    """Chi-square trimmed covariance (consistency-corrected); returns (cov, mean, n_inliers)."""
    e = np.asarray(errors, dtype=float)
    d = e.shape[1]
    med = np.median(e, axis=0)
    mad = 1.4826 * np.median(np.abs(e - med), axis=0)
    mad = np.where(mad > 0, mad, 1.0)
    k = float(chi2.ppf(probability, d))
    keep = np.sum(((e - med) / mad) ** 2, axis=1) <= k
    for _ in range(max_iter):
        if keep.sum() <= d + 1:
            break
        mu = e[keep].mean(axis=0)
        C = sample_cov(e[keep])
        diff = e - mu
        m2 = np.einsum("ij,jk,ik->i", diff, np.linalg.inv(C), diff)
        new = m2 <= k
        if np.array_equal(new, keep):
            break
        keep = new
    if keep.sum() <= d + 1:
        raise ValueError("too few inliers for a trimmed covariance")
    factor = float(chi2.cdf(k, d) / chi2.cdf(k, d + 2))
    return sample_cov(e[keep]) * factor, e[keep].mean(axis=0), int(keep.sum())


@dataclass(frozen=True)
class RNoiseEstimate:
    """Estimated R of one source with the sample it came from."""

    source: str
    R: FloatArray
    mean: FloatArray  # mean error (bias) of the samples used
    n_samples: int  # errors with truth available
    n_used: int  # errors in the final covariance (= n_samples for method "all")
    method: str
    selection: str

    def describe(self) -> str:
        sd = np.sqrt(np.diag(self.R))
        return (
            f"{self.source}: {self.n_used}/{self.n_samples} errors ({self.selection}, "
            f"method {self.method}); std {', '.join(f'{v:.2f}' for v in sd)} m; "
            f"mean {', '.join(f'{v:.2f}' for v in self.mean)} m"
        )


def radar_errors(
    flight: Flight,
    site: Site,
    select: str = "largest_gated",
    range_gate_m: float | None = None,
    max_truth_gap_s: float = 2.0,
) -> FloatArray:
    """(N, 3) radar report errors (report minus interpolated truth), rows without truth dropped."""
    if select not in RADAR_SELECTS:
        raise ValueError(f"radar selection must be one of {RADAR_SELECTS}, got {select!r}")
    tid = largest_track_id(flight.radar) if select != "all" else None
    gate = site.radar.range_gate_m if range_gate_m is None else range_gate_m
    rp = np.asarray(site.radar.enu, float)
    rows = [
        (trk.t, trk.e, trk.n, trk.u)
        for fr in flight.radar
        for trk in fr.tracks
        if select == "all" or trk.track_id == tid
    ]
    if not rows:
        return np.zeros((0, 3))
    a = np.asarray(rows, dtype=float)
    if select == "largest_gated":
        a = a[np.linalg.norm(a[:, 1:4] - rp, axis=1) <= gate]
    t, enu = flight.truth_arrays()
    ref = interpolate_truth(t, enu, a[:, 0], max_gap_s=max_truth_gap_s)
    err = a[:, 1:4] - ref
    return err[np.all(np.isfinite(err), axis=1)]


def rf_errors(flight: Flight, max_truth_gap_s: float = 2.0) -> FloatArray:
    """(N, 2) RF fix errors (east, north) against interpolated truth; failed attempts skipped."""
    rows = [(a.t, a.e, a.n) for a in flight.rf if a.ok and np.isfinite(a.e) and np.isfinite(a.n)]
    if not rows:
        return np.zeros((0, 2))
    a = np.asarray(rows, dtype=float)
    t, enu = flight.truth_arrays()
    ref = interpolate_truth(t, enu, a[:, 0], max_gap_s=max_truth_gap_s)
    err = a[:, 1:3] - ref[:, :2]
    return err[np.all(np.isfinite(err), axis=1)]


def _estimate(
    source: str, err: FloatArray, method: str, selection: str, prob: float, flight: Flight
) -> RNoiseEstimate:
    d = err.shape[1]
    if err.shape[0] < d + 2:
        where = flight.folder if flight.folder is not None else flight.name
        raise DataError(
            where,
            None,
            f"only {err.shape[0]} {source} errors with truth; need at least {d + 2} to estimate R",
        )
    if method == "all":
        return RNoiseEstimate(
            source, sample_cov(err), err.mean(axis=0), err.shape[0], err.shape[0], method, selection
        )
    if method == "trim":
        C, mu, n = trimmed_cov(err, prob)
        return RNoiseEstimate(source, C, mu, err.shape[0], n, f"trim@{prob:g}", selection)
    raise ValueError(f"method must be one of {METHODS}, got {method!r}")


def estimate_r(
    flight: Flight,
    site: Site,
    *,
    radar_method: str = "all",
    rf_method: str = "trim",
    radar_select: str = "largest_gated",
    range_gate_m: float | None = None,
    trim_probability: float = 0.99,
    max_truth_gap_s: float = 2.0,
) -> tuple[RNoiseEstimate, RNoiseEstimate]:
    """(radar, RF) covariance estimates of a flight; see the module text for the choices."""
    rad = radar_errors(flight, site, radar_select, range_gate_m, max_truth_gap_s)
    rf = rf_errors(flight, max_truth_gap_s)
    return (
        _estimate("radar", rad, radar_method, radar_select, trim_probability, flight),
        _estimate("rf", rf, rf_method, "ok fixes", trim_probability, flight),
    )


def estimate_q_from_truth(flight: Flight, horizon_s: float = 4.0) -> FloatArray:
    """Per-axis white-acceleration spectral density suggested by the truth's velocities.

    Under the continuous white-noise acceleration model a velocity increment over ``dt`` has
    variance ``q~ dt``; this returns ``mean(dv^2) / mean(dt)`` per ENU axis for increments over
    about ``horizon_s`` (real manoeuvres are not white, so the value depends on the horizon:
    use the typical interval between accepted measurements). Truth velocity is NED.
    """
    fixes = sorted(flight.truth, key=lambda f: f.t)
    if len(fixes) < 3:
        where = flight.folder if flight.folder is not None else flight.name
        raise DataError(where, None, "too few truth samples to estimate q")
    t = np.array([f.t for f in fixes])
    ned = np.array([f.vel_ned for f in fixes], dtype=float)
    v = np.column_stack([ned[:, 1], ned[:, 0], -ned[:, 2]])
    step = max(1, round(horizon_s / float(np.median(np.diff(t)))))
    dt = t[step:] - t[:-step]
    dv = v[step:] - v[:-step]
    ok = np.all(np.isfinite(dv), axis=1) & (dt > 0)
    return np.asarray(np.mean(dv[ok] ** 2, axis=0) / np.mean(dt[ok]), dtype=float)
