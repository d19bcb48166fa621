"""Radar model of the twin: an R20-like Ku-band radar with one onboard multi-target tracker.

Every object in the scene goes through the same chain, scan by scan (``scan_interval_s``):

1. **Objects**: the UAV (its trajectory); its multipath ghost (the mirror image in the ground,
   below the UAV's elevation, when the UAV is low on the radar's horizon); persistent clutter
   sites (stationary reflectors with a rotating/fluttering part, switching on and off over
   minutes); cars on the roads near the site; bird flocks with erratic flight.
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
   every object alike.
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
from dataclasses import dataclass, field

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
from uav_fusion.core.twin.trajectory import Trajectory

FloatArray = npt.NDArray[np.float64]

UAV = "uav"
BIRD = "bird"
CLUTTER = "clutter"
VEHICLE = "vehicle"
GHOST = "ghost"
KINDS = (UAV, GHOST, BIRD, CLUTTER, VEHICLE)


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


@dataclass
class _Obj:
    """One reflector in the scene (its state at the current scan)."""

    oid: int
    kind: str
    pos: FloatArray
    vel: FloatArray
    logit: float  # classifier's base logit for this object
    rcs_median_m2: float
    rcs_sigma_ln: float
    end: float = math.inf
    on: bool = True
    tip_mps: float = 0.0  # clutter: speed of the moving part
    glint_az: float = 0.0
    glint_el: float = 0.0
    # vehicles: road polyline, arc length, speed, cruise speed
    road: FloatArray | None = None
    s: float = 0.0
    speed: float = 0.0
    cruise: float = 0.0
    # birds: flock index and offset from the flock centre
    flock: int = -1
    offset: FloatArray | None = None


@dataclass
class _Flock:
    centre: FloatArray
    heading: float
    speed: float
    vz: float
    end: float
    logit: float
    members: list[int] = field(default_factory=list)


@dataclass
class _Det:
    pos: FloatArray
    R: FloatArray
    rcs_dbsm: float
    obj: _Obj


@dataclass
class _TrackMeta:
    track_id: int
    born: float
    last_update: float
    hits: list[bool]
    confirmed: bool
    rcs_dbsm: float
    obj: _Obj
    logit: float = 0.0
    noise: float = 0.0


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


def _random_fov_point(
    rng: np.random.Generator, radar: RadarSite, rpos: FloatArray, r_lo: float, r_hi: float
) -> tuple[float, float]:
    az = math.radians(radar.boresight_az_deg + float(rng.uniform(-0.5, 0.5)) * radar.fov_az_deg)
    r = float(rng.uniform(r_lo, r_hi))
    return float(rpos[0]) + r * math.sin(az), float(rpos[1]) + r * math.cos(az)


class _Scene:
    """Every object but the UAV's own trajectory: clutter, vehicles, birds, the ghost."""

    def __init__(
        self,
        radar: RadarSite,
        rpos: FloatArray,
        ground_u: float,
        clutter: ClutterModel,
        vehicles: VehicleModel,
        birds: BirdModel,
        cls: ClassifierModel,
        rng: np.random.Generator,
        scale: float,
    ) -> None:
        self.radar, self.rpos, self.ground_u = radar, rpos, ground_u
        self.cv, self.vm, self.bm, self.cls = clutter, vehicles, birds, cls
        self.rng = rng
        self.scale = scale
        self.next_oid = 1
        self.objects: list[_Obj] = []
        self.flocks: list[_Flock] = []
        n_sites = int(rng.poisson(clutter.sites * scale)) if clutter.sites * scale > 0 else 0
        p_on = clutter.mean_on_s / max(clutter.mean_on_s + clutter.mean_off_s, 1e-9)
        for _ in range(n_sites):
            e, n = _random_fov_point(rng, radar, rpos, clutter.range_min_m, clutter.range_max_m)
            h = float(rng.uniform(clutter.height_min_m, clutter.height_max_m))
            med = clutter.rcs_median_m2 * 10.0 ** (
                float(rng.normal(0.0, clutter.site_rcs_sigma_db)) / 10.0
            )
            ob = _Obj(
                self._oid(),
                CLUTTER,
                np.array([e, n, ground_u + h]),
                np.zeros(3),
                (
                    cls.rotating_logit
                    if rng.random() < cls.rotating_fraction
                    else float(rng.normal(cls.clutter_logit_mean, cls.clutter_logit_sigma))
                ),
                med,
                clutter.rcs_sigma_ln,
                on=bool(rng.random() < p_on),
                tip_mps=float(rng.uniform(clutter.tip_speed_min_mps, clutter.tip_speed_max_mps)),
            )
            self.objects.append(ob)
        self.roads = [np.asarray(r, dtype=float) for r in vehicles.roads]

    def _oid(self) -> int:
        self.next_oid += 1
        return self.next_oid

    # --- births ----------------------------------------------------------------------------
    def _spawn_vehicle(self) -> None:
        rng, vm = self.rng, self.vm
        road = self.roads[int(rng.integers(0, len(self.roads)))]
        if rng.random() < 0.5:
            road = road[::-1].copy()
        cruise = max(4.0, float(rng.normal(vm.speed_mean_mps, vm.speed_sigma_mps)))
        ob = _Obj(
            self._oid(),
            VEHICLE,
            np.array([road[0, 0], road[0, 1], self.ground_u + vm.height_m]),
            np.zeros(3),
            self.cls.vehicle_logit,
            vm.rcs_median_m2,
            vm.rcs_sigma_ln,
            road=road,
            speed=cruise * 0.6,
            cruise=cruise,
        )
        self.objects.append(ob)

    def _spawn_flock(self, t: float) -> None:
        rng, bm = self.rng, self.bm
        e, n = _random_fov_point(rng, self.radar, self.rpos, bm.range_min_m, bm.range_max_m)
        h = float(rng.uniform(bm.height_min_m, bm.height_max_m))
        fl = _Flock(
            np.array([e, n, self.ground_u + h]),
            float(rng.uniform(0.0, 2.0 * math.pi)),
            max(2.0, float(rng.normal(bm.speed_mean_mps, bm.speed_sigma_mps))),
            0.0,
            t + float(rng.exponential(bm.flock_life_s)),
            float(rng.normal(self.cls.bird_logit_mean, self.cls.bird_logit_sigma)),
        )
        k = len(self.flocks)
        for _ in range(int(rng.integers(bm.members_min, bm.members_max + 1))):
            off = rng.normal(0.0, bm.spread_m, size=3)
            off[2] *= 0.4
            ob = _Obj(
                self._oid(),
                BIRD,
                fl.centre + off,
                np.zeros(3),
                fl.logit,
                bm.rcs_median_m2,
                bm.rcs_sigma_ln,
                end=fl.end,
                flock=k,
                offset=off,
            )
            fl.members.append(ob.oid)
            self.objects.append(ob)
        self.flocks.append(fl)

    # --- motion ----------------------------------------------------------------------------
    def step(self, t: float, dt: float) -> None:
        rng = self.rng
        if self.roads and self.vm.rate_per_min * self.scale > 0:
            for _ in range(int(rng.poisson(self.vm.rate_per_min * self.scale * dt / 60.0))):
                self._spawn_vehicle()
        if self.bm.flock_rate_per_min * self.scale > 0:
            for _ in range(int(rng.poisson(self.bm.flock_rate_per_min * self.scale * dt / 60.0))):
                self._spawn_flock(t)
        # flocks: erratic heading/speed random walks, vertical OU
        turn = math.radians(self.bm.turn_sigma_dps) * math.sqrt(dt)
        for fl in self.flocks:
            if t > fl.end:
                continue
            fl.heading += float(rng.normal(0.0, turn))
            fl.speed = float(
                np.clip(
                    fl.speed + rng.normal(0.0, 0.6 * math.sqrt(dt)),
                    2.0,
                    2.5 * self.bm.speed_mean_mps,
                )
            )
            fl.vz = 0.9 * fl.vz + float(rng.normal(0.0, 0.3))
            v = np.array([fl.speed * math.sin(fl.heading), fl.speed * math.cos(fl.heading), fl.vz])
            fl.centre = fl.centre + v * dt
            fl.centre[2] = max(fl.centre[2], self.ground_u + 3.0)
        a_c = self.vm.lateral_accel_mps2 * self.vm.corner_radius_m
        keep: list[_Obj] = []
        for ob in self.objects:
            if t > ob.end:
                continue
            if ob.kind == CLUTTER:
                if ob.on and rng.random() < dt / max(self.cv.mean_on_s, 1e-9):
                    ob.on = False
                elif not ob.on and rng.random() < dt / max(self.cv.mean_off_s, 1e-9):
                    ob.on = True
            elif ob.kind == VEHICLE and ob.road is not None:
                if not self._drive(ob, dt, a_c):
                    continue
            elif ob.kind == BIRD and ob.offset is not None:
                fl = self.flocks[ob.flock]
                ob.offset = (
                    0.97 * ob.offset + rng.normal(0.0, 0.25 * self.bm.spread_m, size=3) * 0.25
                )
                new = fl.centre + ob.offset
                ob.vel = (new - ob.pos) / dt
                ob.pos = new
            keep.append(ob)
        self.objects = keep

    def _drive(self, ob: _Obj, dt: float, a_c: float) -> bool:
        """Advance a car along its road; False when it has left the road's end."""
        road = ob.road
        assert road is not None
        seg = np.diff(road, axis=0)
        lens = np.hypot(seg[:, 0], seg[:, 1])
        cum = np.concatenate([[0.0], np.cumsum(lens)])
        if ob.s >= cum[-1]:
            return False
        i = int(np.searchsorted(cum, ob.s, side="right") - 1)
        i = min(max(i, 0), len(lens) - 1)
        target = ob.cruise
        if i + 1 < len(lens):
            d1, d2 = seg[i] / lens[i], seg[i + 1] / lens[i + 1]
            ang = math.acos(float(np.clip(np.dot(d1, d2), -1.0, 1.0)))
            v_corner = math.sqrt(a_c / max(ang, 1e-3)) if ang > 0.05 else ob.cruise
            dist = cum[i + 1] - ob.s
            target = min(target, math.sqrt(v_corner**2 + 2.0 * self.vm.accel_mps2 * dist))
        dv = float(np.clip(target - ob.speed, -self.vm.accel_mps2 * dt, self.vm.accel_mps2 * dt))
        ob.speed = max(0.0, ob.speed + dv)
        ob.s += ob.speed * dt
        if ob.s >= cum[-1]:
            return False
        i = int(np.searchsorted(cum, ob.s, side="right") - 1)
        i = min(max(i, 0), len(lens) - 1)
        d = seg[i] / lens[i]
        xy = road[i] + d * (ob.s - cum[i])
        ob.pos = np.array([xy[0], xy[1], self.ground_u + self.vm.height_m])
        ob.vel = np.array([d[0] * ob.speed, d[1] * ob.speed, 0.0])
        return True


class _Tracker:
    """The onboard multi-target tracker (CV Kalman filters, GNN association, M-of-N)."""

    def __init__(self, cfg: RadarModel, rpos: FloatArray, initial_logit: float) -> None:
        self.cfg, self.rpos = cfg, rpos
        self.initial_logit = initial_logit
        self.X = np.zeros((0, 6))
        self.P = np.zeros((0, 6, 6))
        self.meta: list[_TrackMeta] = []
        self.t = math.nan

    def predict(self, t: float) -> None:
        if self.meta and math.isfinite(self.t) and t > self.t:
            dt = t - self.t
            F = np.eye(6)
            F[0:3, 3:6] = dt * np.eye(3)
            q = self.cfg.tracker_q_mps2
            Q = np.zeros((6, 6))
            for k in range(3):
                Q[k, k] = q * dt**3 / 3.0
                Q[k, k + 3] = Q[k + 3, k] = q * dt**2 / 2.0
                Q[k + 3, k + 3] = q * dt
            self.X = self.X @ F.T
            self.P = np.einsum("ij,njk,lk->nil", F, self.P, F) + Q
        self.t = t

    def associate(self, dets: list[_Det]) -> list[int]:
        """Track index for every detection (-1: none), global nearest neighbour."""
        cfg = self.cfg
        out = [-1] * len(dets)
        n_tr = len(self.meta)
        if not dets or n_tr == 0:
            return out
        D = np.array([d.pos for d in dets])
        trR = np.array([float(np.trace(d.R)) for d in dets])
        trP = np.trace(self.P[:, 0:3, 0:3], axis1=1, axis2=2)
        dist = np.linalg.norm(self.X[:, None, 0:3] - D[None, :, :], axis=2)
        gate = cfg.tracker_gate_sigma * np.sqrt((trP[:, None] + trR[None, :]) / 3.0)
        gate += cfg.tracker_gate_min_m
        ti, di = np.nonzero(dist <= gate)
        if ti.size == 0:
            return out
        conf = np.array([0 if self.meta[i].confirmed else 1 for i in ti])
        order = np.lexsort((dist[ti, di], conf))
        used_t: set[int] = set()
        for k in order:
            a, b = int(ti[k]), int(di[k])
            if a in used_t or out[b] >= 0:
                continue
            used_t.add(a)
            out[b] = a
        return out

    def update(self, i: int, det: _Det, t: float) -> None:
        P = self.P[i]
        S = P[0:3, 0:3] + det.R
        K = np.linalg.solve(S, P[0:3, :]).T
        x = self.X[i] + K @ (det.pos - self.X[i, 0:3])
        speed = float(np.linalg.norm(x[3:6]))
        if speed > self.cfg.tracker_max_speed_mps:
            x[3:6] *= self.cfg.tracker_max_speed_mps / speed
        self.X[i] = x
        P = P - K @ P[0:3, :]
        self.P[i] = 0.5 * (P + P.T)
        m = self.meta[i]
        m.last_update = t
        m.hits.append(True)
        m.rcs_dbsm = det.rcs_dbsm
        m.obj = det.obj

    def start(self, det: _Det, t: float, track_id: int) -> None:
        P0 = np.zeros((6, 6))
        P0[0:3, 0:3] = det.R
        P0[3:6, 3:6] = np.eye(3) * 15.0**2
        x0 = np.concatenate([det.pos, np.zeros(3)])
        self.X = np.vstack([self.X, x0[None, :]])
        self.P = np.concatenate([self.P, P0[None, :, :]])
        self.meta.append(
            _TrackMeta(track_id, t, t, [True], False, det.rcs_dbsm, det.obj, self.initial_logit)
        )

    def prune(self, t: float, updated: set[int]) -> None:
        cfg = self.cfg
        keep: list[int] = []
        for i, m in enumerate(self.meta):
            if i not in updated and m.born != t:
                m.hits.append(False)
            if not m.confirmed:
                recent = m.hits[-cfg.confirm_window :]
                if sum(recent) >= cfg.confirm_hits:
                    m.confirmed = True
                elif len(m.hits) >= cfg.confirm_window:
                    continue  # tentative track that failed confirmation
            rng_tr = float(np.linalg.norm(self.X[i, 0:3] - self.rpos))
            frac = min(1.0, rng_tr / cfg.max_coast_ref_range_m)
            max_coast = cfg.max_coast_s + frac * (cfg.max_coast_far_s - cfg.max_coast_s)
            if t - m.last_update > max_coast:
                continue
            if len(m.hits) > 32:
                del m.hits[:-16]
            keep.append(i)
        if len(keep) != len(self.meta):
            self.X = self.X[keep]
            self.P = self.P[keep]
            self.meta = [self.meta[i] for i in keep]


def uav_object_id(index: int) -> int:
    """``object_id`` of the UAV at ``index`` of the flight's vehicles (0: the first UAV)."""
    return 0 if index == 0 else -index


def ghost_object_id(index: int) -> int:
    """``object_id`` of that UAV's multipath ghost."""
    return 1 if index == 0 else -(100 + index)


def _ghost(
    uav: _Obj, ghost: _Obj, rpos: FloatArray, ground_u: float, cfg: RadarModel, gm: GhostModel
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
    scene = _Scene(radar, rpos, ground_u, clutter, vehicles, birds, cls, r_scene, scene_scale)
    tracker = _Tracker(cfg, rpos, cls.initial_logit)
    next_id = int(r_misc.integers(100, 900))
    uavs = [
        _Obj(
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
        _Obj(
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
    n_scans = int(traj.duration / cfg.scan_interval_s)
    t_first = float(r_misc.uniform(0.0, cfg.scan_interval_s))
    dt_scan = cfg.scan_interval_s
    g_a = math.exp(-dt_scan / cfg.glint_tau_s)
    g_b = cfg.glint_sigma_deg * math.sqrt(1.0 - g_a * g_a)
    n_a = math.exp(-dt_scan / cls.noise_tau_s)
    n_b = cls.noise_logit * math.sqrt(1.0 - n_a * n_a)
    resp = 1.0 - math.exp(-dt_scan / cls.response_s)
    known: set[int] = set()
    times = t_first + dt_scan * np.arange(n_scans) + r_misc.normal(0.0, cfg.scan_jitter_s, n_scans)
    ok_t = (times >= 0) & (times <= traj.duration)
    times = times[ok_t]
    paths = [(traj.position(times), traj.velocity(times))]
    paths += [(tr.position(times), tr.velocity(times)) for tr, _ in others]
    for k, t in enumerate(times):
        t = float(t)
        scene.step(t, dt_scan)
        objs: list[_Obj] = []
        for uav, ghost, (upos, uvel) in zip(uavs, ghosts_, paths, strict=True):
            uav.pos, uav.vel = upos[k], uvel[k]
            objs.append(uav)
            # the ghost: the UAV mirrored in the ground plane
            if _ghost(uav, ghost, rpos, ground_u, cfg, ghosts):
                objs.append(ghost)
        objs.extend(scene.objects)

        dets: list[_Det] = []
        for ob in objs:
            # a UAV's own draws do not depend on how many other objects the scene holds
            r_det = own_rng.get(ob.oid, r_obj)
            if ob.oid not in known:
                known.add(ob.oid)
                ob.glint_az = float(r_det.normal(0.0, cfg.glint_sigma_deg))
                ob.glint_el = float(r_det.normal(0.0, cfg.glint_sigma_deg))
            ob.glint_az = g_a * ob.glint_az + g_b * float(r_det.standard_normal())
            ob.glint_el = g_a * ob.glint_el + g_b * float(r_det.standard_normal())
            if ob.kind == CLUTTER and not ob.on:
                continue
            rel = ob.pos - rpos
            r, az, el = _polar(rel)
            if r > cfg.max_range_m or not _in_fov(az, el, radar):
                continue
            if ob.kind == CLUTTER:
                radial = ob.tip_mps * abs(math.sin(float(r_det.uniform(0.0, math.pi))))
            else:
                radial = abs(float(np.dot(ob.vel, rel)) / max(r, 1e-6))
            agl = ob.pos[2] - ground_u
            notch = cfg.min_radial_speed_mps
            if ob.kind != GHOST and agl < cfg.min_agl_m:
                notch = max(notch, cfg.low_target_min_radial_mps)
            if radial < notch:
                continue
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
                continue
            mp = 1.0 + cfg.multipath_gain * math.exp(-abs(el) / cfg.multipath_el_deg)
            # thermal angle noise of a monopulse measurement grows as the SNR falls
            th = cfg.angle_snr_deg / math.sqrt(10.0 ** (snr_db / 10.0))
            s_az = math.hypot(cfg.sigma_az_deg, th)
            s_el = math.hypot(cfg.sigma_el_deg, th)
            rm = r + float(r_det.normal(0.0, cfg.sigma_range_m))
            azm = az + cfg.az_bias_deg + ob.glint_az + float(r_det.normal(0.0, s_az))
            elm = el + cfg.el_bias_deg + mp * (ob.glint_el + float(r_det.normal(0.0, s_el)))
            cov = _polar_cov(rm, azm, elm, cfg, th)
            dets.append(_Det(rpos + _from_polar(rm, azm, elm), cov, 10.0 * math.log10(rcs), ob))

        # --- onboard tracker ---------------------------------------------------------------
        tracker.predict(t)
        assign = tracker.associate(dets)
        updated: set[int] = set()
        for det, i in zip(dets, assign, strict=True):
            if i >= 0:
                tracker.update(i, det, t)
                updated.add(i)
        for det, i in zip(dets, assign, strict=True):
            if i < 0:
                tracker.start(det, t, next_id)
                next_id += 1
        tracker.prune(t, updated)

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
            m.logit += (target - m.logit) * resp
            m.noise = n_a * m.noise + n_b * float(r_cls.standard_normal())
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
        frames.append(SimRadarFrame(t, tuple(reports)))
    return frames
