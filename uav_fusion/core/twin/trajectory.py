"""Waypoint flight plans and the multirotor flight they produce.

A flight plan (YAML, see ``config/waypoints/``) lists waypoints in ENU metres about the site
origin (``e``, ``n``) or in geodetic degrees (``lat``, ``lon``), each with an altitude ``alt``
above the take-off point and an optional leg speed. The vehicle starts on the ground at the
site's take-off point, waits ``hold_before_s``, then flies the waypoints in order with a
point-mass model: a velocity command towards the active waypoint (capped by the leg speed,
slowed so that it can take the next corner, and braked before the last one), tracked by a
first-order velocity loop with acceleration limits, plus correlated wind gusts. A waypoint
with ``alt`` 0 as the last one is a landing.

A multi-UAV plan lists its vehicles under ``vehicles``: each entry is a plan of its own (its
``waypoints``, ``speed_mps``, ``hold_before_s``) plus ``name`` (``uav1`` first; the others name
their truth files, ``<stamp>_<name>_vehicleOut.txt``), an optional ``pad`` (``e``/``n`` or
``lat``/``lon``: where it takes off and sits before and after its flight; default the site's
take-off point) and an optional ``rf`` (``silent: true`` for a UAV without a control link, or
its link's ``center_frequency_mhz`` and ``interval_s``; default the twin configuration's link).
The top level keeps ``name`` and ``scene_scale``. The first vehicle is returned as the plan,
the others in its ``others``.
"""

from __future__ import annotations

import dataclasses
import math
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from uav_fusion.core.errors import ConfigError
from uav_fusion.core.site import Site
from uav_fusion.core.twin.config import FlightDynamics
from uav_fusion.core.yamlio import read_yaml_file

FloatArray = npt.NDArray[np.float64]
G = 9.80665


@dataclass(frozen=True)
class Waypoint:
    e: float
    n: float
    alt: float  # metres above the take-off point
    speed: float  # leg speed towards this waypoint, m/s
    hold: float = 0.0  # seconds spent hovering at this waypoint once reached


@dataclass(frozen=True)
class Emitter:
    """A UAV's control link: its centre frequency and the sensors' attempt interval.

    ``None`` fields take the twin configuration's ``rf`` values.
    """

    center_frequency_hz: float | None = None
    interval_s: float | None = None


DEFAULT_EMITTER = Emitter()


@dataclass(frozen=True)
class FlightPlan:
    name: str
    waypoints: tuple[Waypoint, ...]
    hold_before_s: float
    source: Path | None = None
    scene_scale: float = 1.0  # multiplies the radar scene's clutter, vehicle and bird rates
    vehicle: str = "uav1"  # the truth file's vehicle name
    pad: tuple[float, float] | None = None  # take-off point (ENU e, n); None: the site's
    emitter: Emitter | None = DEFAULT_EMITTER  # the control link the RF sensors hear; None: silent
    others: tuple[FlightPlan, ...] = ()  # the other UAVs of a multi-UAV plan

    @property
    def all_vehicles(self) -> tuple[FlightPlan, ...]:
        """Every UAV of the plan, the first one first."""
        return (self, *self.others)


def _num(d: dict[str, Any], key: str, where: str, default: float | None = None) -> float:
    if key not in d:
        if default is None:
            raise ConfigError(f"{where}: missing key '{key}'")
        return default
    v = d[key]
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not _finite(v):
        raise ConfigError(f"{where}: '{key}' must be a finite number, got {_short(v)}")
    return float(v)


def _finite(v: float) -> bool:
    """A finite number that fits a float (a YAML integer may hold 400 digits)."""
    try:
        return math.isfinite(float(v))
    except OverflowError:
        return False


def _short(v: Any) -> str:
    text = repr(v)
    return text if len(text) <= 40 else f"{text[:20]}… ({len(text)} characters)"


VEHICLE_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9-]*$")


def _enu_point(w: dict[str, Any], site: Site, where: str) -> tuple[float, float]:
    has_enu = "e" in w or "n" in w
    has_geo = "lat" in w or "lon" in w
    if has_enu == has_geo:
        raise ConfigError(f"{where}: give either e/n (ENU metres) or lat/lon (degrees)")
    if has_enu:
        e, n = _num(w, "e", where), _num(w, "n", where)
    else:
        lat, lon = _num(w, "lat", where), _num(w, "lon", where)
        if not (-90 <= lat <= 90 and -180 <= lon <= 180):
            raise ConfigError(f"{where}: lat/lon out of range")
        ee, nn, _ = site.to_enu(lat, lon, site.takeoff_h)
        e, n = float(ee), float(nn)
    if math.hypot(e, n) > 20000.0:
        raise ConfigError(f"{where}: more than 20 km from the site origin")
    return e, n


def _emitter(raw: Any, where: str) -> Emitter | None:
    if raw is None:
        return DEFAULT_EMITTER
    if not isinstance(raw, dict):
        raise ConfigError(f"{where}: expected a mapping (silent, center_frequency_mhz, interval_s)")
    unknown = set(raw) - {"silent", "center_frequency_mhz", "interval_s"}
    if unknown:
        raise ConfigError(f"{where}: unknown key(s) {', '.join(sorted(unknown))}")
    silent = raw.get("silent", False)
    if not isinstance(silent, bool):
        raise ConfigError(f"{where}: 'silent' must be true or false, got {_short(silent)}")
    if silent:
        if len(raw) > 1:
            raise ConfigError(f"{where}: a silent UAV has no link settings")
        return None
    freq = interval = None
    if "center_frequency_mhz" in raw:
        mhz = _num(raw, "center_frequency_mhz", where)
        if not 30.0 <= mhz <= 10000.0:
            raise ConfigError(f"{where}: center_frequency_mhz must lie in [30, 10000], got {mhz}")
        freq = mhz * 1e6
    if "interval_s" in raw:
        interval = _num(raw, "interval_s", where)
        if not 0.5 <= interval <= 60.0:
            raise ConfigError(f"{where}: interval_s must lie in [0.5, 60], got {interval}")
    return Emitter(freq, interval)


def flight_plan_from_dict(doc: Any, site: Site, source: Path | None = None) -> FlightPlan:
    """Validate a parsed flight-plan document and convert its waypoints to ENU."""
    src = str(source) if source else "<flight plan>"
    if not isinstance(doc, dict):
        raise ConfigError(f"{src}: expected a mapping at top level")
    if "vehicles" in doc:
        return _multi_plan(doc, site, source, src)
    return _single_plan(doc, site, source, src)


def _multi_plan(doc: dict[str, Any], site: Site, source: Path | None, src: str) -> FlightPlan:
    unknown = set(doc) - {"name", "scene_scale", "vehicles"}
    if unknown:
        raise ConfigError(
            f"{src}: unknown top-level key(s) {', '.join(sorted(unknown))} in a multi-UAV plan "
            "(name, scene_scale, vehicles; each vehicle holds its own waypoints)"
        )
    raw = doc["vehicles"]
    if not isinstance(raw, list) or not raw:
        raise ConfigError(f"{src}: 'vehicles' must be a non-empty list")
    if len(raw) > 8:
        raise ConfigError(f"{src}: at most 8 vehicles, got {len(raw)}")
    name = str(doc.get("name", source.stem if source else "flight"))
    scene = _num(doc, "scene_scale", src, 1.0)
    if not 0.0 <= scene <= 10.0:
        raise ConfigError(f"{src}: scene_scale must lie in [0, 10], got {scene}")
    plans: list[FlightPlan] = []
    seen: set[str] = set()
    for i, v in enumerate(raw, start=1):
        where = f"{src}: vehicle {i}"
        if not isinstance(v, dict):
            raise ConfigError(f"{where}: expected a mapping")
        vname = v.get("name")
        if not isinstance(vname, str) or VEHICLE_NAME.match(vname) is None:
            raise ConfigError(
                f"{where}: 'name' must be letters, digits and '-', got {_short(vname)}"
            )
        if (i == 1) != (vname == "uav1"):
            raise ConfigError(f"{where}: the first vehicle, and only it, is named 'uav1'")
        if vname.lower() in seen:
            raise ConfigError(f"{where}: vehicle {vname!r} is listed twice")
        seen.add(vname.lower())
        where = f"{src}: vehicle {vname}"
        pad_raw = v.get("pad")
        pad = None
        if pad_raw is not None:
            if not isinstance(pad_raw, dict):
                raise ConfigError(f"{where}: pad: expected a mapping (e/n or lat/lon)")
            unknown = set(pad_raw) - {"e", "n", "lat", "lon"}
            if unknown:
                raise ConfigError(f"{where}: pad: unknown key(s) {', '.join(sorted(unknown))}")
            pad = _enu_point(pad_raw, site, f"{where}: pad")
        emitter = _emitter(v.get("rf"), f"{where}: rf")
        body = {k: x for k, x in v.items() if k not in ("name", "pad", "rf")}
        body["name"] = name
        body["scene_scale"] = scene
        p = _single_plan(body, site, source, where)
        plans.append(dataclasses.replace(p, vehicle=vname, pad=pad, emitter=emitter))
    return dataclasses.replace(plans[0], others=tuple(plans[1:]))


def _single_plan(doc: dict[str, Any], site: Site, source: Path | None, src: str) -> FlightPlan:
    unknown = set(doc) - {"name", "speed_mps", "hold_before_s", "waypoints", "scene_scale"}
    if unknown:
        raise ConfigError(f"{src}: unknown key(s) {', '.join(sorted(unknown))}")
    speed = _num(doc, "speed_mps", src, 10.0)
    if not 0.5 <= speed <= 30.0:
        raise ConfigError(f"{src}: speed_mps must lie in [0.5, 30], got {speed}")
    hold = _num(doc, "hold_before_s", src, 0.0)
    if hold < 0:
        raise ConfigError(f"{src}: hold_before_s must be >= 0")
    raw = doc.get("waypoints")
    if not isinstance(raw, list) or not raw:
        raise ConfigError(f"{src}: 'waypoints' must be a non-empty list")
    wps: list[Waypoint] = []
    for i, w in enumerate(raw, start=1):
        where = f"{src}: waypoint {i}"
        if not isinstance(w, dict):
            raise ConfigError(f"{where}: expected a mapping")
        unknown = set(w) - {"e", "n", "lat", "lon", "alt", "speed", "hold_s", "note"}
        if unknown:
            raise ConfigError(f"{where}: unknown key(s) {', '.join(sorted(unknown))}")
        e, n = _enu_point(w, site, where)
        alt = _num(w, "alt", where)
        if not 0.0 <= alt <= 500.0:
            raise ConfigError(f"{where}: alt must lie in [0, 500] m, got {alt}")
        sp = _num(w, "speed", where, speed)
        if not 0.5 <= sp <= 30.0:
            raise ConfigError(f"{where}: speed must lie in [0.5, 30], got {sp}")
        hold_s = _num(w, "hold_s", where, 0.0)
        if not 0.0 <= hold_s <= 3600.0:
            raise ConfigError(f"{where}: hold_s must lie in [0, 3600] s, got {hold_s}")
        wps.append(Waypoint(e, n, alt, sp, hold_s))
    name = str(doc.get("name", source.stem if source else "flight"))
    scene = _num(doc, "scene_scale", src, 1.0)
    if not 0.0 <= scene <= 10.0:
        raise ConfigError(f"{src}: scene_scale must lie in [0, 10], got {scene}")
    return FlightPlan(name, tuple(wps), hold, source, scene)


def load_flight_plan(path: str | Path, site: Site) -> FlightPlan:
    p = Path(path)
    return flight_plan_from_dict(read_yaml_file(p, "waypoint file"), site, p)


@dataclass(frozen=True)
class Trajectory:
    """Densely sampled flight (times in seconds since the start of the recording)."""

    t: FloatArray  # [N]
    pos: FloatArray  # [N, 3] ENU
    vel: FloatArray  # [N, 3] ENU velocity
    acc: FloatArray  # [N, 3] ENU acceleration
    ground_u: float  # ENU up of the take-off point
    t_takeoff: float
    t_landed: float

    def _interp(self, arr: FloatArray, tq: FloatArray | float) -> FloatArray:
        q = np.atleast_1d(np.asarray(tq, dtype=float))
        return np.stack([np.interp(q, self.t, arr[:, k]) for k in range(3)], axis=1)

    def position(self, tq: FloatArray | float) -> FloatArray:
        return self._interp(self.pos, tq)

    def velocity(self, tq: FloatArray | float) -> FloatArray:
        return self._interp(self.vel, tq)

    def acceleration(self, tq: FloatArray | float) -> FloatArray:
        return self._interp(self.acc, tq)

    @property
    def duration(self) -> float:
        return float(self.t[-1])

    def attitude(self, tq: FloatArray | float) -> FloatArray:
        """(pitch, yaw, roll) in radians: yaw = heading, tilt from the acceleration."""
        v = self.velocity(tq)
        a = self.acceleration(tq)
        yaw = np.arctan2(v[:, 0], v[:, 1])
        fwd = np.stack([np.sin(yaw), np.cos(yaw)], axis=1)
        right = np.stack([np.cos(yaw), -np.sin(yaw)], axis=1)
        a_f = np.sum(a[:, :2] * fwd, axis=1)
        a_r = np.sum(a[:, :2] * right, axis=1)
        pitch = -np.arctan2(a_f, G)
        roll = np.arctan2(a_r, G)
        return np.stack([pitch, yaw, roll], axis=1)


def _leg_command(
    targets: list[tuple[float, float, float, float]],
    wi: int,
    d: tuple[float, float, float],
    dh: float,
    stop: bool,
    landing: bool,
    dyn: FlightDynamics,
) -> tuple[float, float, float]:
    """The velocity command towards waypoint ``wi`` at the offset ``d`` (``dh`` its horizontal
    length): the leg speed, slowed to take the corner at ``wi`` (to a stop when ``stop``: the
    last waypoint or one with a hover) and capped near the last one; a climb or descent that
    ends with the leg, or, when ``landing`` on the last leg, the landing rate over the spot."""
    dx, dy, dz = d
    tx, ty, _, sp = targets[wi]
    last = wi == len(targets) - 1
    if stop:
        v_corner = 0.0
    else:
        nx, ny = targets[wi + 1][0] - tx, targets[wi + 1][1] - ty
        nh = math.hypot(nx, ny)
        if nh < 1e-6 or dh < 1e-6:
            v_corner = dyn.corner_min_speed_mps
        else:
            cosang = (dx * nx + dy * ny) / (dh * nh)
            half = 0.5 * math.acos(max(-1.0, min(1.0, cosang)))
            v_corner = max(dyn.corner_min_speed_mps, sp * math.cos(half) ** 2)
        v_corner = min(v_corner, targets[wi + 1][3], sp)
    brake = 0.6 * dyn.accel_max_mps2
    v_h = min(sp, math.sqrt(v_corner**2 + 2.0 * brake * max(dh - dyn.accept_radius_m, 0.0)))
    if last:
        v_h = min(v_h, 0.8 * dh)
    if last and landing:
        # descend at the landing rate once over the spot (within 2 accept radii)
        v_z = -dyn.land_rate_mps if dh < 2.0 * dyn.accept_radius_m else 0.0
    else:
        t_h = dh / max(v_h, 0.5)
        v_z = math.copysign(min(dyn.climb_rate_mps, abs(dz) / max(t_h, 1.0)), dz)
    ux, uy = (dx / dh, dy / dh) if dh > 1e-9 else (0.0, 0.0)
    return (v_h * ux, v_h * uy, v_z)


def _follow(v: list[float], cmd: tuple[float, float, float], dyn: FlightDynamics) -> list[float]:
    """One step of the first-order velocity loop towards ``cmd``, acceleration-limited."""
    dt = dyn.dt_s
    ax = (cmd[0] - v[0]) / dyn.response_s
    ay = (cmd[1] - v[1]) / dyn.response_s
    az = (cmd[2] - v[2]) / dyn.response_s
    ah = math.hypot(ax, ay)
    if ah > dyn.accel_max_mps2:
        ax, ay = ax * dyn.accel_max_mps2 / ah, ay * dyn.accel_max_mps2 / ah
    az = max(-dyn.vert_accel_max_mps2, min(dyn.vert_accel_max_mps2, az))
    return [v[0] + ax * dt, v[1] + ay * dt, v[2] + az * dt]


def _trajectory(
    ts: list[float],
    ps: list[tuple[float, float, float]],
    vs: list[tuple[float, float, float]],
    dt: float,
    ground: float,
    t_takeoff: float,
    t_landed: float,
) -> Trajectory:
    """The integrated samples as a :class:`Trajectory` (never-reached events at the end)."""
    tt = np.asarray(ts, dtype=float)
    pos = np.asarray(ps, dtype=float)
    vel = np.asarray(vs, dtype=float)
    acc = np.gradient(vel, tt, axis=0) if tt.size > 1 else np.zeros_like(vel)
    # the airframe's tilt follows the acceleration smoothed over ~0.5 s, not each gust step
    width = max(1, round(0.5 / dt))
    if tt.size > width:
        kernel = np.ones(width) / width
        acc = np.stack([np.convolve(acc[:, k], kernel, mode="same") for k in range(3)], axis=1)
    if math.isnan(t_landed):
        t_landed = float(tt[-1])
    if math.isnan(t_takeoff):
        t_takeoff = float(tt[-1])
    return Trajectory(tt, pos, vel, acc, ground, t_takeoff, t_landed)


def fly(
    plan: FlightPlan,
    site: Site,
    dyn: FlightDynamics,
    rng: np.random.Generator,
    tail_s: float = 10.0,
    duration_s: float | None = None,
) -> Trajectory:
    """Integrate the flight of ``plan``; the recording ends ``tail_s`` after landing.

    With ``duration_s`` the recording has exactly that length: a longer one keeps the vehicle
    on the ground after landing (or hovering at its last waypoint), a shorter one cuts the
    flight off.
    """
    te, tn, tu = site.to_enu(site.takeoff_lat, site.takeoff_lon, site.takeoff_h)
    ground = float(tu)
    p = [float(te), float(tn), ground] if plan.pad is None else [*plan.pad, ground]
    v = [0.0, 0.0, 0.0]
    gust = [0.0, 0.0]
    dt = dyn.dt_s
    targets = [(w.e, w.n, ground + w.alt, w.speed) for w in plan.waypoints]
    holds = [w.hold for w in plan.waypoints]
    hold_until = math.nan  # end of the hover at waypoint ``wi`` (nan: not hovering)
    landing = plan.waypoints[-1].alt <= 0.5
    g_a = math.exp(-dt / dyn.wind_gust_tau_s)
    g_b = dyn.wind_gust_mps * math.sqrt(1.0 - g_a * g_a)
    max_t = duration_s if duration_s is not None else 6 * 3600.0

    ts: list[float] = []
    ps: list[tuple[float, float, float]] = []
    vs: list[tuple[float, float, float]] = []
    k = 0
    wi = 0
    t = 0.0
    t_takeoff = math.nan
    t_landed = math.nan
    t_end = math.inf
    while True:
        t = k * dt
        if t > max_t + 1e-9 or t > t_end + 1e-9:
            break
        airborne = p[2] > ground + 0.05
        if wi < len(targets) and t >= plan.hold_before_s:
            if math.isnan(t_takeoff):
                t_takeoff = t
            tx, ty, tz, _ = targets[wi]
            dx, dy, dz = tx - p[0], ty - p[1], tz - p[2]
            dh = math.hypot(dx, dy)
            last = wi == len(targets) - 1
            if math.isnan(hold_until):
                stop = last or holds[wi] > 0.0
                cmd = _leg_command(targets, wi, (dx, dy, dz), dh, stop, landing, dyn)
            else:
                # position hold over the waypoint: a gentle pull back to the spot
                cmd = (0.2 * dx, 0.2 * dy, 0.5 * dz)
            v = _follow(v, cmd, dyn)
            reached = math.sqrt(dh * dh + dz * dz) < (
                0.25 if (last and landing) else dyn.accept_radius_m
            )
            if last and landing and p[2] <= ground + 0.02 and dh < dyn.accept_radius_m:
                reached = True
            if reached and holds[wi] > 0.0 and math.isnan(hold_until):
                hold_until = t + holds[wi]
            if not math.isnan(hold_until):
                reached = t >= hold_until
            if reached:
                hold_until = math.nan
                wi += 1
                if wi == len(targets):
                    t_landed = t
                    if duration_s is None:
                        t_end = t + tail_s
        elif wi >= len(targets):
            # on the ground after landing, or hovering at the last waypoint
            v = [0.0, 0.0, 0.0] if landing or not airborne else [0.9 * x for x in v]
        if airborne:
            gust = [
                g_a * gust[0] + g_b * float(rng.standard_normal()),
                g_a * gust[1] + g_b * float(rng.standard_normal()),
            ]
        else:
            gust = [0.0, 0.0]
        # in a position hold the autopilot cancels most of the gusts' drift
        g = 0.2 if not math.isnan(hold_until) else 1.0
        vt = (v[0] + g * gust[0], v[1] + g * gust[1], v[2])
        ts.append(t)
        ps.append((p[0], p[1], p[2]))
        vs.append(vt)
        p = [p[0] + vt[0] * dt, p[1] + vt[1] * dt, max(ground, p[2] + vt[2] * dt)]
        if p[2] <= ground and v[2] < 0:
            v[2] = 0.0
        k += 1
        if duration_s is None and k * dt > 6 * 3600.0:
            raise ConfigError(
                f"{plan.source or plan.name}: flight did not finish within 6 h "
                f"(stuck before waypoint {wi + 1})"
            )
    return _trajectory(ts, ps, vs, dt, ground, t_takeoff, t_landed)
