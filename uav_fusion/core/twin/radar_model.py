"""Radar model of the twin: an R20-like Ku-band radar with an onboard tracker.

Per scan (every ``scan_interval_s``) the UAV is visible when it is inside the field of view,
within ``max_range_m``, at least ``min_agl_m`` above ground and moving radially faster than the
Doppler notch. Its radar cross-section is drawn per look from a lognormal law clipped to the
paper's measured span; the SNR follows the radar equation (R^-4) from ``snr_ref_db`` and a
look is detected when the SNR, with a little per-look fluctuation, beats the threshold. A
detection measures range (1 m resolution), azimuth and elevation with Gaussian noise and is
converted to ENU.

The onboard tracker is a constant-velocity Kalman filter with a small white-acceleration
process noise (so it lags and overshoots through turns), a distance gate, M-of-N confirmation
and deletion after a coasting time that grows with range. A confirmed track is reported every
scan, also while it coasts on its prediction. A detection outside every gate starts a new
track (a new ID): that is how sharp turns and weak far returns fragment the UAV's track.

Bird and clutter tracks are born at random (Poisson) inside the field of view and carry a low
UAV class probability.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from uav_fusion.core.site import RadarSite
from uav_fusion.core.twin.config import RadarModel
from uav_fusion.core.twin.trajectory import Trajectory

FloatArray = npt.NDArray[np.float64]

UAV = "uav"
BIRD = "bird"
CLUTTER = "clutter"


@dataclass(frozen=True)
class SimTrackReport:
    """One track in one radar frame, in ENU (converted to lla by the writer)."""

    track_id: int
    kind: str  # UAV, BIRD or CLUTTER (the twin's label; not written to the file)
    pos: tuple[float, float, float]
    vel: tuple[float, float, float]
    cat_prob: tuple[float, float, float, float]  # uav, bird, clutter, other
    range_m: float
    radial_velocity: float
    num_inliers: int
    rcs_dbsm: float


@dataclass(frozen=True)
class SimRadarFrame:
    t: float  # seconds since the start of the recording
    tracks: tuple[SimTrackReport, ...]


@dataclass
class _Track:
    track_id: int
    x: FloatArray  # [e, n, u, ve, vn, vu]
    P: FloatArray
    t: float  # time of x
    born: float
    last_update: float
    hits: list[bool] = field(default_factory=list)
    confirmed: bool = False
    rcs_dbsm: float = -10.0


@dataclass
class _Object:
    """A bird or a clutter source."""

    track_id: int
    kind: str
    pos: FloatArray
    vel: FloatArray
    end: float
    uav_prob: float
    rcs_dbsm: float


def _polar(rel: FloatArray) -> tuple[float, float, float]:
    e, n, u = float(rel[0]), float(rel[1]), float(rel[2])
    r = math.sqrt(e * e + n * n + u * u)
    az = math.degrees(math.atan2(e, n)) % 360.0
    el = math.degrees(math.atan2(u, math.hypot(e, n)))
    return r, az, el


def _from_polar(r: float, az_deg: float, el_deg: float) -> FloatArray:
    az, el = math.radians(az_deg), math.radians(el_deg)
    return np.array(
        [r * math.cos(el) * math.sin(az), r * math.cos(el) * math.cos(az), r * math.sin(el)]
    )


def _polar_cov(r: float, az_deg: float, el_deg: float, cfg: RadarModel) -> FloatArray:
    """ENU covariance of a detection from its range/azimuth/elevation noise."""
    az, el = math.radians(az_deg), math.radians(el_deg)
    ca, sa, ce, se = math.cos(az), math.sin(az), math.cos(el), math.sin(el)
    J = np.array(
        [
            [ce * sa, r * ce * ca, -r * se * sa],
            [ce * ca, -r * ce * sa, -r * se * ca],
            [se, 0.0, r * ce],
        ]
    )
    s_az = math.hypot(cfg.sigma_az_deg, cfg.glint_sigma_deg)
    s_el = math.hypot(cfg.sigma_el_deg, cfg.glint_sigma_deg)
    D = np.diag([cfg.sigma_range_m**2, math.radians(s_az) ** 2, math.radians(s_el) ** 2])
    return np.asarray(J @ D @ J.T, dtype=float)


def _angle_diff(a: float, b: float) -> float:
    return (a - b + 180.0) % 360.0 - 180.0


def _in_fov(az: float, el: float, site: RadarSite) -> bool:
    return (
        abs(_angle_diff(az, site.boresight_az_deg)) <= 0.5 * site.fov_az_deg
        and abs(el - site.boresight_el_deg) <= 0.5 * site.fov_el_deg
    )


def _cv_predict(tr: _Track, t: float, q: float) -> None:
    dt = t - tr.t
    if dt <= 0:
        return
    F = np.eye(6)
    F[0:3, 3:6] = dt * np.eye(3)
    Q1 = q * np.array([[dt**3 / 3, dt**2 / 2], [dt**2 / 2, dt]])
    Q = np.zeros((6, 6))
    for k in range(3):
        Q[np.ix_([k, k + 3], [k, k + 3])] = Q1
    tr.x = F @ tr.x
    tr.P = F @ tr.P @ F.T + Q
    tr.t = t


_REST_ALPHA = {UAV: (2.0, 2.0, 3.0), BIRD: (6.0, 1.0, 1.0), CLUTTER: (1.0, 6.0, 1.0)}


def _cat_prob(
    rng: np.random.Generator, uav: float, kind: str = UAV
) -> tuple[float, float, float, float]:
    """Class probabilities [uav, bird, clutter, other]; the rest shared by kind."""
    uav = float(np.clip(uav, 0.01, 0.99))
    rest = rng.dirichlet(_REST_ALPHA[kind]) * (1.0 - uav)
    vals = [uav, float(rest[0]), float(rest[1]), float(rest[2])]
    return (round(vals[0], 4), round(vals[1], 4), round(vals[2], 4), round(vals[3], 4))


def simulate_radar(
    traj: Trajectory, radar: RadarSite, cfg: RadarModel, rng: np.random.Generator
) -> list[SimRadarFrame]:
    """Radar frames over the whole recording (UAV tracks, birds and clutter)."""
    rpos = np.asarray(radar.enu, dtype=float)
    ground_u = traj.ground_u
    H = np.hstack([np.eye(3), np.zeros((3, 3))])
    next_id = int(rng.integers(100, 900))
    tracks: list[_Track] = []
    objects: list[_Object] = []
    frames: list[SimRadarFrame] = []
    n_scans = int(traj.duration / cfg.scan_interval_s)
    t_first = float(rng.uniform(0.0, cfg.scan_interval_s))
    dt_scan = cfg.scan_interval_s
    g_a = math.exp(-dt_scan / cfg.glint_tau_s)
    g_b = cfg.glint_sigma_deg * math.sqrt(1.0 - g_a * g_a)
    glint_az = float(rng.normal(0.0, cfg.glint_sigma_deg))
    glint_el = float(rng.normal(0.0, cfg.glint_sigma_deg))
    for k in range(n_scans):
        t = t_first + k * dt_scan + float(rng.normal(0.0, cfg.scan_jitter_s))
        if t > traj.duration or t < 0:
            continue
        p = traj.position(t)[0]
        v = traj.velocity(t)[0]
        rel = p - rpos
        r, az, el = _polar(rel)
        radial = float(np.dot(v, rel) / max(r, 1e-6))
        visible = (
            r <= cfg.max_range_m
            and _in_fov(az, el, radar)
            and p[2] - ground_u >= cfg.min_agl_m
            and abs(radial) >= cfg.min_radial_speed_mps
        )
        rcs = float(np.exp(rng.normal(math.log(cfg.rcs_median_m2), cfg.rcs_sigma_ln)))
        rcs = min(max(rcs, cfg.rcs_min_m2), cfg.rcs_max_m2)
        snr_db = (
            cfg.snr_ref_db
            + 10.0 * math.log10(rcs)
            - 40.0 * math.log10(max(r, 1.0) / cfg.snr_ref_range_m)
            + float(rng.normal(0.0, cfg.detect_noise_db))
        )
        glint_az = g_a * glint_az + g_b * float(rng.standard_normal())
        glint_el = g_a * glint_el + g_b * float(rng.standard_normal())
        det: FloatArray | None = None
        R = np.eye(3)
        if visible and snr_db >= cfg.detect_threshold_db:
            mp = 1.0 + cfg.multipath_gain * math.exp(-max(el, 0.0) / cfg.multipath_el_deg)
            rm = r + float(rng.normal(0.0, cfg.sigma_range_m))
            azm = az + cfg.az_bias_deg + glint_az + float(rng.normal(0.0, cfg.sigma_az_deg))
            elm = el + cfg.el_bias_deg + mp * (glint_el + float(rng.normal(0.0, cfg.sigma_el_deg)))
            det = rpos + _from_polar(rm, azm, elm)
            R = _polar_cov(rm, azm, elm, cfg)

        # --- onboard tracker ---------------------------------------------------------------
        for tr in tracks:
            _cv_predict(tr, t, cfg.tracker_q_mps2)
        used = False
        if det is not None:
            best: _Track | None = None
            best_d = math.inf
            # confirmed tracks first, then tentative ones
            for tr in sorted(tracks, key=lambda x: (not x.confirmed, x.born)):
                S = H @ tr.P @ H.T + R
                y = det - H @ tr.x
                gate = cfg.tracker_gate_sigma * math.sqrt(float(np.trace(S)) / 3.0)
                gate += cfg.tracker_gate_min_m
                d = float(np.linalg.norm(y))
                if d <= gate and d < best_d:
                    best, best_d = tr, d
                if best is not None and best.confirmed:
                    break
            if best is not None:
                S = H @ best.P @ H.T + R
                K = best.P @ H.T @ np.linalg.inv(S)
                best.x = best.x + K @ (det - H @ best.x)
                speed = float(np.linalg.norm(best.x[3:6]))
                if speed > cfg.tracker_max_speed_mps:
                    best.x[3:6] *= cfg.tracker_max_speed_mps / speed
                best.P = (np.eye(6) - K @ H) @ best.P
                best.last_update = t
                best.hits.append(True)
                best.rcs_dbsm = 10.0 * math.log10(rcs)
                used = True
        for tr in tracks:
            if tr.last_update != t:
                tr.hits.append(False)
        if det is not None and not used:
            P0 = np.zeros((6, 6))
            P0[0:3, 0:3] = R
            P0[3:6, 3:6] = np.eye(3) * 15.0**2
            x0 = np.concatenate([det, np.zeros(3)])
            tracks.append(_Track(next_id, x0, P0, t, t, t, [True], False, 10.0 * math.log10(rcs)))
            next_id += 1
        keep: list[_Track] = []
        for tr in tracks:
            if not tr.confirmed:
                recent = tr.hits[-cfg.confirm_window :]
                if sum(recent) >= cfg.confirm_hits:
                    tr.confirmed = True
                elif len(tr.hits) >= cfg.confirm_window:
                    continue  # tentative track that failed confirmation
            rng_tr = float(np.linalg.norm(tr.x[0:3] - rpos))
            frac = min(1.0, rng_tr / cfg.max_coast_ref_range_m)
            max_coast = cfg.max_coast_s + frac * (cfg.max_coast_far_s - cfg.max_coast_s)
            if t - tr.last_update > max_coast:
                continue
            keep.append(tr)
        tracks = keep

        reports: list[SimTrackReport] = []
        for tr in tracks:
            if not tr.confirmed:
                continue
            pos = tr.x[0:3]
            vel = tr.x[3:6]
            relt = pos - rpos
            rt = float(np.linalg.norm(relt))
            age = t - tr.born
            uprob = cfg.uav_prob_start + (cfg.uav_prob_final - cfg.uav_prob_start) * (
                1.0 - math.exp(-age / cfg.uav_prob_tau_s)
            )
            uprob += float(rng.normal(0.0, 0.03))
            reports.append(
                SimTrackReport(
                    tr.track_id,
                    UAV,
                    (float(pos[0]), float(pos[1]), float(pos[2])),
                    (float(vel[0]), float(vel[1]), float(vel[2])),
                    _cat_prob(rng, uprob),
                    rt,
                    float(np.dot(vel, relt) / max(rt, 1e-6)),
                    int(sum(tr.hits[-16:])),
                    tr.rcs_dbsm,
                )
            )

        # --- birds and clutter -------------------------------------------------------------
        for kind, rate, life in (
            (BIRD, cfg.bird_rate_per_min, cfg.bird_life_s),
            (CLUTTER, cfg.clutter_rate_per_min, cfg.clutter_life_s),
        ):
            for _ in range(int(rng.poisson(rate * dt_scan / 60.0))):
                az_o = radar.boresight_az_deg + float(rng.uniform(-0.5, 0.5)) * radar.fov_az_deg
                r_o = float(rng.uniform(120.0, 1600.0 if kind == BIRD else 2200.0))
                agl = float(rng.uniform(8.0, 70.0)) if kind == BIRD else float(rng.uniform(0, 12))
                horiz = math.sqrt(max(r_o**2 - agl**2, 1.0))
                a = math.radians(az_o)
                pos0 = np.array(
                    [rpos[0] + horiz * math.sin(a), rpos[1] + horiz * math.cos(a), ground_u + agl]
                )
                if kind == BIRD:
                    hd = float(rng.uniform(0, 2 * math.pi))
                    sp = max(1.0, float(rng.normal(cfg.bird_speed_mps, 2.0)))
                    vel0 = np.array(
                        [sp * math.sin(hd), sp * math.cos(hd), float(rng.normal(0, 0.5))]
                    )
                    uav_p = float(rng.uniform(0.03, 0.3))
                    rcs_o = float(rng.normal(-22.0, 4.0))
                else:
                    vel0 = rng.normal(0.0, 0.6, size=3)
                    vel0[2] = 0.0
                    uav_p = float(rng.uniform(0.01, 0.12))
                    rcs_o = float(rng.normal(-5.0, 6.0))
                objects.append(
                    _Object(
                        next_id, kind, pos0, vel0, t + float(rng.exponential(life)), uav_p, rcs_o
                    )
                )
                next_id += 1
        alive: list[_Object] = []
        for ob in objects:
            if t > ob.end:
                continue
            if ob.kind == BIRD:
                turn = float(rng.normal(0.0, 0.08))
                c, s = math.cos(turn), math.sin(turn)
                ve, vn = ob.vel[0], ob.vel[1]
                ob.vel = np.array([c * ve + s * vn, -s * ve + c * vn, 0.9 * ob.vel[2]])
            ob.pos = ob.pos + ob.vel * dt_scan
            ob.pos[2] = max(ob.pos[2], ground_u + 1.0)
            alive.append(ob)
            relo = ob.pos - rpos
            ro = float(np.linalg.norm(relo))
            noisy = ob.pos + rng.normal(0.0, 0.004 * ro + 1.0, size=3)
            reports.append(
                SimTrackReport(
                    ob.track_id,
                    ob.kind,
                    (float(noisy[0]), float(noisy[1]), float(noisy[2])),
                    (float(ob.vel[0]), float(ob.vel[1]), float(ob.vel[2])),
                    _cat_prob(rng, ob.uav_prob + float(rng.normal(0.0, 0.02)), ob.kind),
                    ro,
                    float(np.dot(ob.vel, relo) / max(ro, 1e-6)),
                    int(rng.integers(2, 9)),
                    ob.rcs_dbsm + float(rng.normal(0.0, 1.0)),
                )
            )
        objects = alive
        frames.append(SimRadarFrame(t, tuple(reports)))
    return frames
