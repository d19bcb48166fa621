"""RF model of the twin: passive TDOA sensors and their multilateration.

Every ``interval_s`` (with jitter) the sensor network tries to localise the UAV's emission.
Each sensor-to-UAV link is line-of-sight or not: the NLOS probability rises as the elevation
angle from the sensor's antenna to the UAV falls below a few degrees and as the link gets
longer than ``nlos_far_km`` (trees and terrain across the field). The time of arrival at each
sensor is the geometric path plus an excess path (small exponential multipath on LOS links,
a much larger exponential NLOS excess growing with link length otherwise) plus Gaussian
GPS-timing noise. A sensor takes part only if its SNR (free-space loss, extra loss when NLOS)
clears a threshold, it did not drop out, and it is not overloaded by a nearby emitter.

The fix is a 2D Gauss-Newton (Levenberg-damped) least-squares solution of the TDOA equations
against the strongest sensor, at an assumed height. Fewer than three valid sensors, no
convergence, or a solution absurdly far from the network make a failed attempt (written as
latitude = longitude = 0). Because NLOS excess enters the TDOAs through the geometry's dilution
of precision, the errors are heavy-tailed: worst where the UAV is far from most sensors and
low on their horizon, i.e. in the south of the field, best among the sensors in the north.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from scipy.optimize import least_squares

from uav_fusion.core.site import Site
from uav_fusion.core.twin.config import RfModel, RfOutage
from uav_fusion.core.twin.trajectory import Trajectory

FloatArray = npt.NDArray[np.float64]
C_MPS = 299_792_458.0


@dataclass(frozen=True)
class SimRfAttempt:
    t: float  # seconds since the start of the recording
    meas_id: int
    ok: bool
    e: float  # ENU of the fix at the assumed height (NaN when not ok)
    n: float
    cep_m: float
    rho: float  # correlation coefficient of the fix's east/north uncertainty
    total_sensors: int
    valid_sensors: int
    overloaded_sensors: int
    sensor_names: tuple[str, ...]  # the valid sensors
    nlos_links: int  # twin diagnostics (not written) ...
    residual_m: float  # ... RMS TDOA residual of the solution (NaN without one)
    reason: str  # "" or why it failed
    center_frequency_hz: float = 0.0  # the emitter's link (0: the twin configuration's)
    vehicle: str = "uav1"  # twin diagnostics: whose emission (not written)


def grid_start(
    sensors: FloatArray,
    toa_m: FloatArray,
    height: float,
    margin_m: float = 2500.0,
    step_m: float = 50.0,
) -> FloatArray:
    """Best point of a coarse grid over the sensors' box (plus ``margin_m``) for the TDOAs."""
    lo = sensors[:, :2].min(axis=0) - margin_m
    hi = sensors[:, :2].max(axis=0) + margin_m
    ge = np.arange(lo[0], hi[0] + step_m, step_m)
    gn = np.arange(lo[1], hi[1] + step_m, step_m)
    E, N = np.meshgrid(ge, gn, indexing="xy")
    pts = np.stack([E.ravel(), N.ravel(), np.full(E.size, height)], axis=1)
    d = np.linalg.norm(pts[:, None, :] - sensors[None, :, :], axis=2)
    tdoa = toa_m[1:] - toa_m[0]
    r = (d[:, 1:] - d[:, :1]) - tdoa[None, :]
    best = int(np.argmin(np.sum(r * r, axis=1)))
    return np.asarray(pts[best, :2], dtype=float)


def solve_tdoa_2d(
    sensors: FloatArray,
    toa_m: FloatArray,
    height: float,
    max_iterations: int = 25,
    converge_m: float = 0.05,
    start: FloatArray | None = None,
    margin_m: float = 3000.0,
) -> tuple[FloatArray, bool, FloatArray, float]:
    """Least-squares 2D position from times of arrival (in metres) at ``sensors`` [K, 3].

    Differences are taken against sensor 0 (pass the reference first). The unknown is
    (east, north) at ENU up ``height``, searched inside the sensors' bounding box widened by
    ``margin_m``; the start is the best point of a coarse grid over that box, the refinement a
    bounded trust-region least-squares solve. Returns (xy, converged, (JᵀJ)⁻¹ at the
    solution, RMS TDOA residual in metres).
    """
    k = sensors.shape[0]
    if k < 3:
        raise ValueError("TDOA in 2D needs at least 3 sensors")
    tdoa = toa_m[1:] - toa_m[0]
    x0 = grid_start(sensors, toa_m, height, margin_m) if start is None else np.asarray(start, float)

    def resid(xy: FloatArray) -> FloatArray:
        p = np.array([xy[0], xy[1], height])
        d = np.maximum(np.linalg.norm(sensors - p, axis=1), 1e-6)
        return np.asarray((d[1:] - d[0]) - tdoa, dtype=float)

    def jac(xy: FloatArray) -> FloatArray:
        p = np.array([xy[0], xy[1], height])
        d = np.maximum(np.linalg.norm(sensors - p, axis=1), 1e-6)
        g = (p[:2] - sensors[:, :2]) / d[:, None]
        return np.asarray(g[1:] - g[0], dtype=float)

    lo = sensors[:, :2].min(axis=0) - margin_m
    hi = sensors[:, :2].max(axis=0) + margin_m
    sol = least_squares(
        resid,
        np.clip(x0, lo + 1e-3, hi - 1e-3),
        bounds=(lo, hi),
        jac=jac,
        method="trf",
        xtol=1e-6,
        ftol=1e-8,
        gtol=1e-8,
        x_scale=1.0,
        max_nfev=max_iterations,
    )
    x = np.asarray(sol.x, dtype=float)
    step = float(np.linalg.norm(x - x0))
    converged = bool(sol.status > 0) or step < converge_m
    J = jac(x)
    try:
        cov = np.asarray(np.linalg.inv(J.T @ J), dtype=float)
    except np.linalg.LinAlgError:
        cov = np.full((2, 2), np.inf)
    rms = float(np.sqrt(np.mean(sol.fun**2))) if sol.fun.size else 0.0
    return x, converged, cov, rms


def excess_cov(
    sensors: FloatArray, xy: FloatArray, height: float, mean_excess: FloatArray, cov: FloatArray
) -> FloatArray:
    """Mean-square error (2x2) of a 2D TDOA fix from the links' excess paths.

    Each link's excess path is exponential with mean ``mean_excess[i]`` (so its second-moment
    matrix is ``diag(mean^2) + mean mean^T``); the time differences against sensor 0 carry it
    through the linearised least-squares solution ``cov J^T`` (``cov`` = (J^T J)^-1 at ``xy``).
    """
    p = np.array([xy[0], xy[1], height])
    d = np.maximum(np.linalg.norm(sensors - p, axis=1), 1e-6)
    g = (p[:2] - sensors[:, :2]) / d[:, None]
    J = g[1:] - g[0]
    m = np.asarray(mean_excess, dtype=float)
    second = np.diag(m * m) + np.outer(m, m)
    D = np.hstack([-np.ones((m.size - 1, 1)), np.eye(m.size - 1)])
    A = cov @ J.T
    return np.asarray(A @ (D @ second @ D.T) @ A.T, dtype=float)


def simulate_rf(
    traj: Trajectory,
    site: Site,
    cfg: RfModel,
    rng: np.random.Generator,
    outage: RfOutage | None = None,
    outage_rng: np.random.Generator | None = None,
    vehicle: str = "uav1",
) -> list[SimRfAttempt]:
    """Every localisation attempt of the recording.

    ``outage`` adds runs of failed attempts: a two-state Markov chain over attempts (good ->
    bad with ``enter_prob``, bad -> good with ``1 / mean_run``); in the bad state no sensor
    captures the emission (interference, or the UAV's emitter pauses). The chain draws from
    ``outage_rng``, so the other draws do not depend on it.
    """
    outage = outage or RfOutage()
    r_out = outage_rng if outage_rng is not None else np.random.default_rng(0)
    bad = False
    towers = site.rf_sensor_towers()
    names = tuple(t.name for t in towers)
    S = np.array([t.enu for t in towers], dtype=float)
    height = cfg.assumed_height_m
    sigma_m = cfg.sigma_timing_ns * 1e-9 * C_MPS
    out: list[SimRfAttempt] = []
    t = float(rng.uniform(0.2, cfg.interval_s))
    meas_id = int(rng.integers(1000, 5000))
    while t <= traj.duration:
        t_ms = round(t, 3)  # the sensor log has millisecond times
        p = traj.position(t_ms)[0]
        rel = p - S
        dist = np.linalg.norm(rel, axis=1)
        dh = np.linalg.norm(rel[:, :2], axis=1)
        elev = np.degrees(np.arctan2(rel[:, 2], dh))
        p_nlos = 1.0 / (1.0 + np.exp((elev - cfg.nlos_el50_deg) / cfg.nlos_el_width_deg))
        p_nlos = p_nlos + cfg.nlos_far_gain_per_km * np.maximum(dist / 1000.0 - cfg.nlos_far_km, 0)
        p_nlos = np.clip(p_nlos, 0.0, 0.97)
        nlos = rng.random(len(towers)) < p_nlos
        excess = np.where(
            nlos,
            rng.exponential(cfg.nlos_excess_m + cfg.nlos_excess_per_km_m * dist / 1000.0),
            rng.exponential(cfg.los_multipath_m, size=len(towers)),
        )
        toa = dist + excess + rng.normal(0.0, sigma_m, size=len(towers))
        snr = (
            cfg.detect_snr_ref_db
            - 20.0 * np.log10(np.maximum(dist, 1.0) / 1000.0)
            - np.where(nlos, cfg.nlos_loss_db, 0.0)
            + rng.normal(0.0, 2.0, size=len(towers))
        )
        overloaded = dist < cfg.overload_range_m
        valid = (snr >= cfg.detect_snr_min_db) & ~overloaded
        valid &= rng.random(len(towers)) >= cfg.sensor_dropout
        idx = np.flatnonzero(valid)
        n_valid = int(idx.size)
        n_nlos = int(np.sum(nlos & valid))
        ok = False
        reason = ""
        e = n = math.nan
        cep = rho = 0.0
        rms = math.nan
        # two-state chain: leave a bad run with 1 / mean_run, enter one with enter_prob
        stay_or_enter = 1.0 - 1.0 / outage.mean_run if bad else outage.enter_prob
        bad = bool(r_out.random() < stay_or_enter)
        if bad:
            reason = "no signal captured"
            n_valid, n_nlos, idx = 0, 0, idx[:0]
        elif n_valid < 3:
            reason = "too few valid sensors"
        else:
            order = idx[np.argsort(-snr[idx])]
            xy, conv, cov, rms = solve_tdoa_2d(
                S[order],
                toa[order],
                height,
                cfg.max_iterations,
                cfg.converge_m,
                margin_m=cfg.search_margin_m,
            )
            far = float(np.min(np.linalg.norm(S[:, :2] - xy, axis=1)))
            if not conv:
                reason = "no convergence"
            elif rms > cfg.max_residual_m:
                reason = "inconsistent time differences"
            elif not np.all(np.isfinite(xy)) or far > cfg.max_solution_range_m:
                reason = "solution out of range"
            else:
                ok = True
                e, n = float(xy[0]), float(xy[1])
                c = cov * (2.0 * sigma_m**2)
                if cfg.cep_nlos_weight > 0.0:
                    mean_excess = np.where(
                        nlos,
                        cfg.nlos_excess_m + cfg.nlos_excess_per_km_m * dist / 1000.0,
                        cfg.los_multipath_m,
                    )
                    c = c + cfg.cep_nlos_weight * excess_cov(
                        S[order], xy, height, mean_excess[order], cov
                    )
                sx, sy = math.sqrt(max(c[0, 0], 0.0)), math.sqrt(max(c[1, 1], 0.0))
                cep = 0.59 * (sx + sy)
                rho = float(c[0, 1] / (sx * sy)) if sx > 0 and sy > 0 else 0.0
        out.append(
            SimRfAttempt(
                t_ms,
                meas_id,
                ok,
                e,
                n,
                cep,
                rho,
                len(towers),
                n_valid,
                int(np.sum(overloaded)),
                tuple(names[i] for i in idx),
                n_nlos,
                rms,
                reason,
                cfg.center_frequency_hz,
                vehicle,
            )
        )
        meas_id += 1
        t += cfg.interval_s + float(rng.uniform(-cfg.interval_jitter_s, cfg.interval_jitter_s))
    return out
