"""The twin's radar scene: the reflectors the radar sees besides the UAVs.

Persistent clutter sites (stationary reflectors with a moving part, switching on and off over
minutes), cars driving along the site's roads and bird flocks flying erratically; each scan
:meth:`Scene.step` moves them, switches clutter sites, retires what has left, and spawns new
cars and flocks at the configured rates times the plan's ``scene_scale``. Every object is a
:class:`SceneObject`, the UAVs and their multipath ghosts included (those are placed by
:mod:`uav_fusion.core.twin.radar_model`, which also decides what the radar detects).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from uav_fusion.core.site import RadarSite
from uav_fusion.core.twin.config import BirdModel, ClassifierModel, ClutterModel, VehicleModel

FloatArray = npt.NDArray[np.float64]

# the kinds of object (SimTrackReport.kind)
UAV = "uav"
BIRD = "bird"
CLUTTER = "clutter"
VEHICLE = "vehicle"
GHOST = "ghost"
KINDS = (UAV, GHOST, BIRD, CLUTTER, VEHICLE)


@dataclass
class SceneObject:
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
class Flock:
    centre: FloatArray
    heading: float
    speed: float
    vz: float
    end: float
    logit: float
    members: list[int] = field(default_factory=list)


def _random_fov_point(
    rng: np.random.Generator, radar: RadarSite, rpos: FloatArray, r_lo: float, r_hi: float
) -> tuple[float, float]:
    az = math.radians(radar.boresight_az_deg + float(rng.uniform(-0.5, 0.5)) * radar.fov_az_deg)
    r = float(rng.uniform(r_lo, r_hi))
    return float(rpos[0]) + r * math.sin(az), float(rpos[1]) + r * math.cos(az)


class Scene:
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
        self.objects: list[SceneObject] = []
        self.flocks: list[Flock] = []
        n_sites = int(rng.poisson(clutter.sites * scale)) if clutter.sites * scale > 0 else 0
        p_on = clutter.mean_on_s / max(clutter.mean_on_s + clutter.mean_off_s, 1e-9)
        for _ in range(n_sites):
            e, n = _random_fov_point(rng, radar, rpos, clutter.range_min_m, clutter.range_max_m)
            h = float(rng.uniform(clutter.height_min_m, clutter.height_max_m))
            med = clutter.rcs_median_m2 * 10.0 ** (
                float(rng.normal(0.0, clutter.site_rcs_sigma_db)) / 10.0
            )
            ob = SceneObject(
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
        ob = SceneObject(
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
        fl = Flock(
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
            ob = SceneObject(
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
        keep: list[SceneObject] = []
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

    def _drive(self, ob: SceneObject, dt: float, a_c: float) -> bool:
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
