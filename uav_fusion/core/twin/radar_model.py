"""Radar model of the twin: an R20-like Ku-band radar with one onboard multi-target tracker.

Every object in the scene goes through the same chain, scan by scan (``scan_interval_s``):

1. **Objects**: the UAV (its trajectory); its multipath ghost (the mirror image in the ground,
   below the UAV's elevation, when the UAV is low on the radar's horizon); persistent clutter
   sites (stationary reflectors with a rotating/fluttering part, switching on and off over
   minutes); cars on the roads near the site; bird flocks with erratic flight
   (:mod:`uav_fusion.core.twin.scene`).
2. **Detection**: an object is detectable inside the field of view and ``max_range_m`` when its
   radial speed clears the Doppler notch (below ``min_agl_m`` a target must clear the ground
   clutter's wider Doppler spread, ``low_target_min_radial_mps``). A clutter site's structure
   has no Doppler; its moving part has the instantaneous radial speed ``tip * |sin(phase)|``
   (phase uniform per scan), which passes the notch on most scans. The RCS is drawn per look
   (lognormal, per object kind), the SNR follows the radar equation (R^-4) from ``snr_ref_db``
   with a per-look fluctuation, and the look is detected when the SNR beats the threshold.
3. **Measurement**: range, azimuth and elevation with white noise, a per-object glint error
   correlated over ``glint_tau_s``, the mount's misalignment and ground-multipath inflation of
   the elevation noise at low elevation; converted to ENU with its polar covariance.
4. **Onboard tracker** (one for all objects): constant-velocity Kalman filters; global nearest
   neighbour association (all track-detection pairs inside their gates, confirmed tracks
   first, then by distance, each track and detection used once); a detection outside every
   gate starts a tentative track, confirmed by M of N hits; tracks coast on their prediction
   and are deleted after a coasting time that grows with range. A confirmed track is reported
   every scan. Nothing tells the tracker which object a detection came from, so fragmentation,
   id changes, merges (a track absorbing another object's detections) and swaps happen to
   every object alike (:mod:`uav_fusion.core.twin.onboard_tracker`).
5. **Classifier**: per track a class logit relaxes towards the cue of the object whose
   detection the track last took (see :class:`~uav_fusion.core.twin.config.ClassifierModel`).

``SimTrackReport.kind`` is the kind of the object the track currently follows (its last
associated detection's object): UAV, GHOST, BIRD, CLUTTER or VEHICLE. The file does not carry
it; the benchmark uses ``kind == UAV`` to know when the UAV is observable by the radar.

A multi-UAV flight passes the other UAVs' trajectories as ``others``: each is an object of kind
UAV with its own ghost, drawing from its own random stream (so the first UAV's and the scene's
draws are those of the same flight without them). ``SimTrackReport.object_id`` tells the UAVs
apart: :func:`uav_object_id` of the UAV's index (0 for the first).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from uav_fusion.core.site import RadarSite
from uav_fusion.core.twin.config import (
    BirdModel,
    ClassifierModel,
    ClutterModel,
    GhostModel,
    RadarModel,
    VehicleModel,
)
from uav_fusion.core.twin.onboard_tracker import Detection, OnboardTracker
from uav_fusion.core.twin.scene import (
    BIRD,
    CLUTTER,
    GHOST,
    KINDS,
    UAV,
    VEHICLE,
    Scene,
    SceneObject,
)
from uav_fusion.core.twin.trajectory import Trajectory

__all__ = [
    "BIRD",
    "CLUTTER",
    "GHOST",
    "KINDS",
    "UAV",
    "VEHICLE",
    "SimRadarFrame",
    "SimTrackReport",
    "ghost_object_id",
    "simulate_radar",
    "uav_object_id",
]

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True)
class SimTrackReport:
    """One track in one radar frame, in ENU (converted to lla by the writer)."""

    track_id: int
    kind: str  # kind of the object the track currently follows (not written to the file)
    pos: tuple[float, float, float]
    vel: tuple[float, float, float]
    cat_prob: tuple[float, float, float, float]  # uav, bird, clutter, other
    range_m: float
    radial_velocity: float
    num_inliers: int
    rcs_dbsm: float
    object_id: int = 0  # twin diagnostics: which object (0 = the UAV)


@dataclass(frozen=True)
class SimRadarFrame:
    t: float  # seconds since the start of the recording
    tracks: tuple[SimTrackReport, ...]


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


def _polar_cov(
    r: float, az_deg: float, el_deg: float, cfg: RadarModel, thermal_deg: float = 0.0
) -> FloatArray:
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
    s_az = math.sqrt(cfg.sigma_az_deg**2 + cfg.glint_sigma_deg**2 + thermal_deg**2)
    s_el = math.sqrt(cfg.sigma_el_deg**2 + cfg.glint_sigma_deg**2 + thermal_deg**2)
    D = np.diag([cfg.sigma_range_m**2, math.radians(s_az) ** 2, math.radians(s_el) ** 2])
    return np.asarray(J @ D @ J.T, dtype=float)


def _angle_diff(a: float, b: float) -> float:
    return (a - b + 180.0) % 360.0 - 180.0


def _in_fov(az: float, el: float, site: RadarSite) -> bool:
    return (
        abs(_angle_diff(az, site.boresight_az_deg)) <= 0.5 * site.fov_az_deg
        and abs(el - site.boresight_el_deg) <= 0.5 * site.fov_el_deg
    )


_REST_ALPHA = {
    UAV: (2.0, 2.0, 3.0),
    GHOST: (2.0, 2.0, 3.0),
    BIRD: (6.0, 1.0, 1.0),
    CLUTTER: (1.0, 6.0, 1.0),
    VEHICLE: (1.0, 2.0, 6.0),
}


def _cat_prob(
    rng: np.random.Generator, uav: float, kind: str = UAV
) -> tuple[float, float, float, float]:
    """Class probabilities [uav, bird, clutter, other]; the rest shared by kind."""
    uav = float(np.clip(uav, 0.01, 0.99))
    rest = rng.dirichlet(_REST_ALPHA[kind]) * (1.0 - uav)
    vals = [uav, float(rest[0]), float(rest[1]), float(rest[2])]
    return (round(vals[0], 4), round(vals[1], 4), round(vals[2], 4), round(vals[3], 4))


def uav_object_id(index: int) -> int:
    """``object_id`` of the UAV at ``index`` of the flight's vehicles (0: the first UAV)."""
    return 0 if index == 0 else -index


def ghost_object_id(index: int) -> int:
    """``object_id`` of that UAV's multipath ghost."""
    return 1 if index == 0 else -(100 + index)


def _ghost(
    uav: SceneObject,
    ghost: SceneObject,
    rpos: FloatArray,
    ground_u: float,
    cfg: RadarModel,
    gm: GhostModel,
) -> bool:
    """Place ``ghost`` as ``uav``'s mirror image in the ground; False when it is not seen."""
    u_el = _polar(uav.pos - rpos)[2]
    g_pos = np.array([uav.pos[0], uav.pos[1], 2.0 * ground_u - uav.pos[2]])
    g_el = _polar(g_pos - rpos)[2]
    if uav.pos[2] - ground_u > 1.0 and u_el - g_el >= gm.min_separation_deg:
        graze = math.radians(abs(g_el))
        x = 2.0 * math.pi * gm.surface_roughness_m * math.sin(graze) / gm.wavelength_m
        loss = gm.fresnel_loss_db + 20.0 * math.log10(math.e) * 2.0 * x * x
        if loss < 40.0:
            ghost.pos = g_pos
            ghost.vel = np.array([uav.vel[0], uav.vel[1], -uav.vel[2]])
            ghost.rcs_median_m2 = cfg.rcs_median_m2 * 10.0 ** (-loss / 10.0)
            return True
    return False


def _sigmoid(x: float) -> float:
    return 1.0 / (1.0 + math.exp(-x))


class _Sensor:
    """Detection and measurement of one object at one scan (steps 2 and 3 of the module text)."""

    def __init__(
        self, radar: RadarSite, cfg: RadarModel, rpos: FloatArray, ground_u: float
    ) -> None:
        self.radar, self.cfg, self.rpos, self.ground_u = radar, cfg, rpos, ground_u
        # the glint's first-order Gauss-Markov step over one scan
        self.g_a = math.exp(-cfg.scan_interval_s / cfg.glint_tau_s)
        self.g_b = cfg.glint_sigma_deg * math.sqrt(1.0 - self.g_a * self.g_a)
        self.known: set[int] = set()  # objects whose glint has been drawn

    def look(self, ob: SceneObject, r_det: np.random.Generator) -> Detection | None:
        """``ob``'s detection at this scan, drawn from ``r_det``, or None when it is not
        detected (its glint moves on either way)."""
        cfg, rpos = self.cfg, self.rpos
        if ob.oid not in self.known:
            self.known.add(ob.oid)
            ob.glint_az = float(r_det.normal(0.0, cfg.glint_sigma_deg))
            ob.glint_el = float(r_det.normal(0.0, cfg.glint_sigma_deg))
        ob.glint_az = self.g_a * ob.glint_az + self.g_b * float(r_det.standard_normal())
        ob.glint_el = self.g_a * ob.glint_el + self.g_b * float(r_det.standard_normal())
        if ob.kind == CLUTTER and not ob.on:
            return None
        rel = ob.pos - rpos
        r, az, el = _polar(rel)
        if r > cfg.max_range_m or not _in_fov(az, el, self.radar):
            return None
        if ob.kind == CLUTTER:
            radial = ob.tip_mps * abs(math.sin(float(r_det.uniform(0.0, math.pi))))
        else:
            radial = abs(float(np.dot(ob.vel, rel)) / max(r, 1e-6))
        agl = ob.pos[2] - self.ground_u
        notch = cfg.min_radial_speed_mps
        if ob.kind != GHOST and agl < cfg.min_agl_m:
            notch = max(notch, cfg.low_target_min_radial_mps)
        if radial < notch:
            return None
        if ob.kind == UAV:
            rcs = float(np.exp(r_det.normal(math.log(cfg.rcs_median_m2), cfg.rcs_sigma_ln)))
            rcs = min(max(rcs, cfg.rcs_min_m2), cfg.rcs_max_m2)
        else:
            rcs = float(np.exp(r_det.normal(math.log(ob.rcs_median_m2), ob.rcs_sigma_ln)))
        snr_db = (
            cfg.snr_ref_db
            + 10.0 * math.log10(rcs)
            - 40.0 * math.log10(max(r, 1.0) / cfg.snr_ref_range_m)
            + float(r_det.normal(0.0, cfg.detect_noise_db))
        )
        if snr_db < cfg.detect_threshold_db:
            return None
        if cfg.pd_max < 1.0 and float(r_det.random()) >= cfg.pd_max:
            return None  # a scan loss (beam schedule, interference): drawn only when modelled
        mp = 1.0 + cfg.multipath_gain * math.exp(-abs(el) / cfg.multipath_el_deg)
        # thermal angle noise of a monopulse measurement grows as the SNR falls
        th = cfg.angle_snr_deg / math.sqrt(10.0 ** (snr_db / 10.0))
        s_az = math.hypot(cfg.sigma_az_deg, th)
        s_el = math.hypot(cfg.sigma_el_deg, th)
        rm = r + float(r_det.normal(0.0, cfg.sigma_range_m))
        azm = az + cfg.az_bias_deg + ob.glint_az + float(r_det.normal(0.0, s_az))
        elm = el + cfg.el_bias_deg + mp * (ob.glint_el + float(r_det.normal(0.0, s_el)))
        cov = _polar_cov(rm, azm, elm, cfg, th)
        return Detection(rpos + _from_polar(rm, azm, elm), cov, 10.0 * math.log10(rcs), ob)


class _Classifier:
    """The radar's classifier (step 5 of the module text) and the frame it reports."""

    def __init__(self, cls: ClassifierModel, dt_scan: float, rng: np.random.Generator) -> None:
        self.cls, self.rng = cls, rng
        self.n_a = math.exp(-dt_scan / cls.noise_tau_s)
        self.n_b = cls.noise_logit * math.sqrt(1.0 - self.n_a * self.n_a)
        self.resp = 1.0 - math.exp(-dt_scan / cls.response_s)

    def frame(self, t: float, tracker: OnboardTracker, rpos: FloatArray) -> SimRadarFrame:
        """Every track's class logit moved on one scan; the confirmed tracks reported."""
        cls, r_cls = self.cls, self.rng
        reports: list[SimTrackReport] = []
        for i, m in enumerate(tracker.meta):
            pos = tracker.X[i, 0:3]
            vel = tracker.X[i, 3:6]
            relt = pos - rpos
            rt = float(np.linalg.norm(relt))
            ob = m.obj
            age = t - m.born
            rel_o = float(np.linalg.norm(ob.pos - rpos))
            reliab = (1.0 - math.exp(-age / cls.age_tau_s)) * math.exp(-rel_o / cls.range_scale_m)
            cue = ob.logit
            if ob.kind in (UAV, GHOST) and float(np.linalg.norm(ob.vel)) < cls.hover_speed_mps:
                cue -= cls.hover_penalty
            target = cls.initial_logit + reliab * (cue - cls.initial_logit)
            m.logit += (target - m.logit) * self.resp
            m.noise = self.n_a * m.noise + self.n_b * float(r_cls.standard_normal())
            if not m.confirmed:
                continue
            reports.append(
                SimTrackReport(
                    m.track_id,
                    ob.kind,
                    (float(pos[0]), float(pos[1]), float(pos[2])),
                    (float(vel[0]), float(vel[1]), float(vel[2])),
                    _cat_prob(r_cls, _sigmoid(m.logit + m.noise), ob.kind),
                    rt,
                    float(np.dot(vel, relt) / max(rt, 1e-6)),
                    int(sum(m.hits[-16:])),
                    m.rcs_dbsm,
                    ob.oid,
                )
            )
        return SimRadarFrame(t, tuple(reports))


def simulate_radar(
    traj: Trajectory,
    radar: RadarSite,
    cfg: RadarModel,
    rng: np.random.Generator,
    clutter: ClutterModel | None = None,
    vehicles: VehicleModel | None = None,
    birds: BirdModel | None = None,
    ghosts: GhostModel | None = None,
    classifier: ClassifierModel | None = None,
    scene_scale: float = 1.0,
    others: Sequence[tuple[Trajectory, np.random.Generator]] = (),
) -> list[SimRadarFrame]:
    """Radar frames over the whole recording: every object through detection and tracker.

    ``scene_scale`` multiplies the rates of clutter sites, vehicles and bird flocks (0: the UAV
    and its ghost only). ``others``: the other UAVs of the flight, each with its own random
    generator for its detections.
    """
    clutter = clutter or ClutterModel()
    vehicles = vehicles or VehicleModel()
    birds = birds or BirdModel()
    ghosts = ghosts or GhostModel()
    cls = classifier or ClassifierModel()
    rpos = np.asarray(radar.enu, dtype=float)
    ground_u = traj.ground_u
    seeds = rng.integers(0, 2**62, size=5)
    r_uav, r_obj, r_scene, r_cls, r_misc = (np.random.default_rng(int(s)) for s in seeds)
    scene = Scene(radar, rpos, ground_u, clutter, vehicles, birds, cls, r_scene, scene_scale)
    tracker = OnboardTracker(cfg, rpos, cls.initial_logit, int(r_misc.integers(100, 900)))
    sensor = _Sensor(radar, cfg, rpos, ground_u)
    dt_scan = cfg.scan_interval_s
    classify = _Classifier(cls, dt_scan, r_cls)
    uavs = [
        SceneObject(
            uav_object_id(i),
            UAV,
            np.zeros(3),
            np.zeros(3),
            cls.uav_logit,
            cfg.rcs_median_m2,
            cfg.rcs_sigma_ln,
        )
        for i in range(1 + len(others))
    ]
    ghosts_ = [
        SceneObject(
            ghost_object_id(i),
            GHOST,
            np.zeros(3),
            np.zeros(3),
            cls.ghost_logit,
            0.0,
            cfg.rcs_sigma_ln,
        )
        for i in range(1 + len(others))
    ]
    # whose random stream draws an object's detections: the first UAV's, another UAV's (for
    # it and its ghost), or the scene's
    own_rng = {uav_object_id(i + 1): r for i, (_, r) in enumerate(others)}
    own_rng.update({ghost_object_id(i + 1): r for i, (_, r) in enumerate(others)})
    own_rng[uav_object_id(0)] = r_uav
    frames: list[SimRadarFrame] = []
    n_scans = int(traj.duration / dt_scan)
    t_first = float(r_misc.uniform(0.0, dt_scan))
    times = t_first + dt_scan * np.arange(n_scans) + r_misc.normal(0.0, cfg.scan_jitter_s, n_scans)
    ok_t = (times >= 0) & (times <= traj.duration)
    times = times[ok_t]
    paths = [(traj.position(times), traj.velocity(times))]
    paths += [(tr.position(times), tr.velocity(times)) for tr, _ in others]
    for k, t in enumerate(times):
        t = float(t)
        scene.step(t, dt_scan)
        objs: list[SceneObject] = []
        for uav, ghost, (upos, uvel) in zip(uavs, ghosts_, paths, strict=True):
            uav.pos, uav.vel = upos[k], uvel[k]
            objs.append(uav)
            # the ghost: the UAV mirrored in the ground plane
            if _ghost(uav, ghost, rpos, ground_u, cfg, ghosts):
                objs.append(ghost)
        objs.extend(scene.objects)
        dets: list[Detection] = []
        for ob in objs:
            # a UAV's own draws do not depend on how many other objects the scene holds
            det = sensor.look(ob, own_rng.get(ob.oid, r_obj))
            if det is not None:
                dets.append(det)
        tracker.scan(t, dets)
        frames.append(classify.frame(t, tracker, rpos))
    return frames
