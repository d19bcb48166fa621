"""Run the twin: fly the plan, sense it with the radar and the RF network, log the truth.

:func:`generate_twin` returns a :class:`TwinFlight` holding everything in memory, in the exact
values that :mod:`uav_fusion.core.twin.writers` puts into the files (geodetic coordinates are
computed once here, the written text reproduces them bit for bit). :func:`twin_to_flight` gives
the same content as the typed records the dataset readers produce from those files.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from datetime import UTC, datetime

import numpy as np
import numpy.typing as npt

from uav_fusion.core.errors import ConfigError
from uav_fusion.core.records import Flight, RadarFrame, RadarTrack, RfAttempt, TruthFix
from uav_fusion.core.site import RadarSite, Site
from uav_fusion.core.twin.config import RfModel, TwinConfig
from uav_fusion.core.twin.radar_model import SimRadarFrame, SimTrackReport, simulate_radar
from uav_fusion.core.twin.rf_model import SimRfAttempt, simulate_rf
from uav_fusion.core.twin.trajectory import Emitter, FlightPlan, Trajectory, fly
from uav_fusion.core.twin.worlds import World, WorldFamily, apply_config, apply_site, draw_world
from uav_fusion.core.twin.writers import radar_line_layout

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]

GPS_EPOCH_UNIX = 315_964_800  # 1980-01-06 00:00:00 UTC
GPS_LEAP_S = 18  # GPS - UTC since 2017


@dataclass(frozen=True)
class TruthLog:
    """The vehicle log rows, valid or not (invalid rows are written as -999)."""

    t_us: IntArray  # UTC microseconds since the epoch
    lat: FloatArray
    lon: FloatArray
    alt: FloatArray  # relative to the take-off height
    att: FloatArray  # [N, 3] pitch, yaw, roll (rad)
    vel_ned: FloatArray  # [N, 3]
    battery_v: FloatArray
    fix_type: IntArray
    num_sats: IntArray

    @property
    def valid(self) -> npt.NDArray[np.bool_]:
        return self.fix_type >= 2


@dataclass(frozen=True)
class RadarTrackOut:
    report: SimTrackReport
    lat: float
    lon: float
    h: float


@dataclass(frozen=True)
class RadarFrameOut:
    t_unix: float
    tracks: tuple[RadarTrackOut, ...]


@dataclass(frozen=True)
class RfAttemptOut:
    attempt: SimRfAttempt
    t_unix: float
    lat: float  # 0 when failed
    lon: float
    h: float


@dataclass(frozen=True)
class OtherUav:
    """Another UAV of a multi-UAV flight: its plan, its flight and its truth log."""

    vehicle: str
    plan: FlightPlan
    traj: Trajectory
    truth: TruthLog


@dataclass(frozen=True)
class TwinFlight:
    site: Site  # with the radar and RF sensor set actually used
    config: TwinConfig
    plan: FlightPlan
    seed: int
    start_unix: float
    traj: Trajectory
    truth: TruthLog
    radar: tuple[RadarFrameOut, ...]
    rf: tuple[RfAttemptOut, ...]
    radar_sim: tuple[SimRadarFrame, ...]
    scene_scale: float = 1.0  # the radar scene's rate multiplier used
    others: tuple[OtherUav, ...] = ()  # the other UAVs of a multi-UAV flight
    world: World | None = None  # the drawn world (``config`` and ``site`` have it applied)

    @property
    def start_datetime(self) -> datetime:
        return datetime.fromtimestamp(self.start_unix, tz=UTC)

    @property
    def vehicles(self) -> list[tuple[str, TruthLog]]:
        """(vehicle, truth log) of every UAV, the first one first."""
        return [(self.plan.vehicle, self.truth), *((o.vehicle, o.truth) for o in self.others)]


def parse_utc(text: str, where: str = "recording.start_utc") -> float:
    """``YYYY-MM-DD HH:MM:SS`` (UTC) to unix seconds."""
    for fmt in ("%Y-%m-%d %H:%M:%S", "%Y-%m-%dT%H:%M:%S", "%Y-%m-%d %H:%M:%S.%f"):
        try:
            return datetime.strptime(text, fmt).replace(tzinfo=UTC).timestamp()
        except ValueError:
            continue
    raise ConfigError(f"{where}: cannot read UTC time {text!r} (want YYYY-MM-DD HH:MM:SS)")


def site_with_sensors(
    site: Site, plan: FlightPlan, radar_tower: str | None, sensors: list[str] | None
) -> Site:
    """The site with the radar moved to ``radar_tower`` and/or another RF sensor set.

    A radar moved away from its configured tower stands on the new tower's ground point with
    the same mast, and its boresight azimuth points at the centroid of the plan's waypoints.
    """
    out = site
    if sensors is not None:
        unknown = [s for s in sensors if s not in site.towers]
        if unknown:
            raise ConfigError(
                f"unknown RF sensor tower(s) {', '.join(unknown)}; "
                f"the site has {', '.join(sorted(site.towers))}"
            )
        if len(set(sensors)) < 3:
            raise ConfigError(f"TDOA needs at least 3 distinct RF sensors, got {len(set(sensors))}")
        out = dataclasses.replace(out, rf_sensors=tuple(dict.fromkeys(sensors)))
    if radar_tower is not None and radar_tower != site.radar.tower:
        if radar_tower not in site.towers:
            raise ConfigError(
                f"unknown radar tower {radar_tower!r}; "
                f"the site has {', '.join(sorted(site.towers))}"
            )
        tw = site.towers[radar_tower]
        r = site.radar
        e, n, u = site.to_enu(tw.lat, tw.lon, tw.ground_h + r.mast_agl)
        ce = float(np.mean([w.e for w in plan.waypoints]))
        cn = float(np.mean([w.n for w in plan.waypoints]))
        bore = math.degrees(math.atan2(ce - float(e), cn - float(n))) % 360.0
        radar = RadarSite(
            tower=radar_tower,
            lat=tw.lat,
            lon=tw.lon,
            ground_h=tw.ground_h,
            mast_agl=r.mast_agl,
            boresight_az_deg=bore,
            boresight_el_deg=r.boresight_el_deg,
            fov_az_deg=r.fov_az_deg,
            fov_el_deg=r.fov_el_deg,
            range_gate_m=r.range_gate_m,
            enu=(float(e), float(n), float(u)),
        )
        out = dataclasses.replace(out, radar=radar)
    return out


def _truth_log(
    traj: Trajectory, site: Site, cfg: TwinConfig, rng: np.random.Generator, start_unix: float
) -> TruthLog:
    tc = cfg.truth
    step_us = round(1e6 / tc.rate_hz)
    n = math.floor(traj.duration * 1e6 / step_us) + 1
    rel_us = np.arange(n, dtype=np.int64) * step_us
    t_rel = rel_us / 1e6
    pos = traj.position(t_rel)
    airborne = pos[:, 2] > traj.ground_u + 0.05
    noise = np.column_stack(
        [
            rng.normal(0.0, tc.sigma_h_m, n),
            rng.normal(0.0, tc.sigma_h_m, n),
            rng.normal(0.0, tc.sigma_v_m, n),
        ]
    )
    noisy = pos + noise
    noisy[:, 2] = np.where(airborne, noisy[:, 2], traj.ground_u + np.abs(noise[:, 2]))
    lat, lon, h = site.to_geodetic(noisy[:, 0], noisy[:, 1], noisy[:, 2])
    # the file stores the height relative to take-off: the round trip must be exact
    ground_h = float(site.to_geodetic(0.0, 0.0, traj.ground_u)[2])
    alt = h - ground_h
    alt = np.where(np.abs(alt) < 1e-9, 0.0, alt)
    vel = traj.velocity(t_rel)
    vel_ned = np.column_stack([vel[:, 1], vel[:, 0], -vel[:, 2]])
    att = traj.attitude(t_rel)
    minutes = t_rel / 60.0
    battery = (
        tc.battery_full_v
        - tc.battery_drop_v_per_min * minutes
        + rng.normal(0.0, tc.battery_noise_v, n)
    )
    fix = np.full(n, tc.fix_type, dtype=np.int64)
    sats = rng.integers(tc.num_sats_min, tc.num_sats_max + 1, n).astype(np.int64)
    fix[: min(tc.no_fix_rows_start, n)] = 1
    if tc.no_fix_dropouts > 0 and n > 20:
        drop = rng.choice(
            np.arange(10, n - 10), size=min(tc.no_fix_dropouts, n - 20), replace=False
        )
        fix[drop] = 1
    sats = np.where(fix < 2, np.minimum(sats, 5), sats)
    t_us = np.int64(round(start_unix * 1e6)) + rel_us
    return TruthLog(
        t_us=t_us,
        lat=np.asarray(lat, float),
        lon=np.asarray(lon, float),
        alt=np.asarray(alt, float),
        att=att,
        vel_ned=vel_ned,
        battery_v=np.round(battery, 3),
        fix_type=fix,
        num_sats=sats,
    )


def _radar_out(
    frames: list[SimRadarFrame], site: Site, start_unix: float
) -> tuple[RadarFrameOut, ...]:
    reports = [r for f in frames for r in f.tracks]
    if reports:
        enu = np.array([r.pos for r in reports], dtype=float)
        lat, lon, h = site.to_geodetic(enu[:, 0], enu[:, 1], enu[:, 2])
    else:
        lat = lon = h = np.zeros(0)
    out: list[RadarFrameOut] = []
    i = 0
    for f in frames:
        trs = []
        for r in f.tracks:
            trs.append(RadarTrackOut(r, float(lat[i]), float(lon[i]), float(h[i])))
            i += 1
        out.append(RadarFrameOut(round(start_unix + f.t, 6), tuple(trs)))
    return tuple(out)


def _rf_out(
    attempts: list[SimRfAttempt], site: Site, cfg: TwinConfig, start_unix: float
) -> tuple[RfAttemptOut, ...]:
    out: list[RfAttemptOut] = []
    for a in attempts:
        t_unix = round(start_unix + a.t, 3)
        if a.ok:
            lat, lon, h = site.to_geodetic(a.e, a.n, cfg.rf.assumed_height_m)
            out.append(RfAttemptOut(a, t_unix, float(lat), float(lon), float(h)))
        else:
            out.append(RfAttemptOut(a, t_unix, 0.0, 0.0, 0.0))
    return tuple(out)


def generate_twin(
    site: Site,
    config: TwinConfig,
    plan: FlightPlan,
    seed: int | None = None,
    duration_s: float | None = None,
    radar_tower: str | None = None,
    sensors: list[str] | None = None,
    scene_scale: float | None = None,
    world: WorldFamily | None = None,
) -> TwinFlight:
    """Simulate one flight. Deterministic for a given (site, config, plan, seed, options).

    ``scene_scale`` multiplies the rates of the radar scene's clutter sites, vehicles and
    bird flocks (default: the plan's ``scene_scale``, 1 unless the plan sets it). ``world``:
    a world family; the flight's physics are drawn from it with the seed
    (:mod:`uav_fusion.core.twin.worlds`) and applied to ``config`` and the radar site.
    """
    seed = config.seed if seed is None else seed
    if seed < 0:
        raise ConfigError(f"seed must be >= 0, got {seed}")
    if duration_s is not None and not (10.0 <= duration_s <= 6 * 3600.0):
        raise ConfigError(f"duration must lie in [10 s, 6 h], got {duration_s}")
    used_site = site_with_sensors(site, plan, radar_tower, sensors)
    drawn = None
    if world is not None:
        drawn = draw_world(world, seed, plan.name)
        config = apply_config(drawn, config)
        used_site = dataclasses.replace(used_site, radar=apply_site(drawn, used_site.radar))
    start_unix = parse_utc(config.recording.start_utc)
    root = np.random.SeedSequence(seed)
    s_traj, s_truth, s_radar, s_rf, s_outage = root.spawn(5)
    # the other UAVs draw from streams of their own: the first UAV's flight and the scene are
    # those of the same seed without them
    s_others = [ss.spawn(5) for ss in root.spawn(len(plan.others))]
    plans = plan.all_vehicles
    streams = [(s_traj, s_truth, s_radar, s_rf, s_outage), *s_others]

    def fly_all(length: float | None) -> list[Trajectory]:
        return [
            fly(
                p,
                used_site,
                config.dynamics,
                np.random.default_rng(ss[0]),
                config.recording.tail_s,
                length,
            )
            for p, ss in zip(plans, streams, strict=True)
        ]

    trajs = fly_all(duration_s)
    if duration_s is None and len(trajs) > 1:
        # every log covers the whole recording: the shorter flights wait on their pads
        longest = max(tr.duration for tr in trajs)
        trajs = fly_all(longest)
    traj = trajs[0]
    truths = [
        _truth_log(tr, used_site, config, np.random.default_rng(ss[1]), start_unix)
        for tr, ss in zip(trajs, streams, strict=True)
    ]
    truth = truths[0]
    scale = plan.scene_scale if scene_scale is None else scene_scale
    if not 0.0 <= scale <= 10.0:
        raise ConfigError(f"scene scale must lie in [0, 10], got {scale}")
    frames = simulate_radar(
        traj,
        used_site.radar,
        config.radar,
        np.random.default_rng(s_radar),
        clutter=config.clutter,
        vehicles=config.vehicles,
        birds=config.birds,
        ghosts=config.ghosts,
        classifier=config.classifier,
        scene_scale=scale,
        others=[
            (tr, np.random.default_rng(ss[2]))
            for tr, ss in zip(trajs[1:], streams[1:], strict=True)
        ],
    )
    per_emitter = [
        simulate_rf(
            tr,
            used_site,
            _link(config.rf, p.emitter),
            np.random.default_rng(ss[3]),
            outage=config.rf_outage,
            outage_rng=np.random.default_rng(ss[4]),
            vehicle=p.vehicle,
        )
        for p, tr, ss in zip(plans, trajs, streams, strict=True)
        if p.emitter is not None
    ]
    attempts = _merge_attempts(per_emitter)
    return TwinFlight(
        site=used_site,
        config=config,
        plan=plan,
        seed=seed,
        start_unix=start_unix,
        traj=traj,
        truth=truth,
        radar=_radar_out(frames, used_site, start_unix),
        rf=_rf_out(attempts, used_site, config, start_unix),
        radar_sim=tuple(frames),
        scene_scale=scale,
        others=tuple(
            OtherUav(p.vehicle, p, tr, tl)
            for p, tr, tl in zip(plans[1:], trajs[1:], truths[1:], strict=True)
        ),
        world=drawn,
    )


def _link(rf: RfModel, emitter: Emitter | None) -> RfModel:
    """The twin's RF settings for one emitter's link."""
    if emitter is None:
        return rf
    out = rf
    if emitter.center_frequency_hz is not None:
        out = dataclasses.replace(out, center_frequency_hz=emitter.center_frequency_hz)
    if emitter.interval_s is not None:
        jitter = min(rf.interval_jitter_s, 0.5 * emitter.interval_s)
        out = dataclasses.replace(out, interval_s=emitter.interval_s, interval_jitter_s=jitter)
    return out


def _merge_attempts(per_emitter: list[list[SimRfAttempt]]) -> list[SimRfAttempt]:
    """Every emitter's attempts in one log, by time, numbered in order from the first id.

    One emitter's attempts are kept as they are (a single-UAV flight is unchanged).
    """
    if len(per_emitter) <= 1:
        return per_emitter[0] if per_emitter else []
    merged = sorted((a for lst in per_emitter for a in lst), key=lambda a: a.t)
    first = min((lst[0].meas_id for lst in per_emitter if lst), default=1000)
    return [dataclasses.replace(a, meas_id=first + i) for i, a in enumerate(merged)]


def twin_to_flight(twin: TwinFlight, rf_height: float | None = None) -> Flight:
    """The twin's content as the typed records a reader of its files returns.

    Truth and radar ENU come from the written geodetic values; RF fixes are put into ENU at
    ``rf_height`` (default the site origin's height), the filter only uses their east/north.
    """
    site = twin.site
    vehicles = {name: _truth_fixes(tl, site) for name, tl in twin.vehicles}
    truth = vehicles[twin.plan.vehicle]
    all_tracks = [tr for f in twin.radar for tr in f.tracks]
    if all_tracks:
        re_, rn_, ru_ = site.to_enu(
            [x.lat for x in all_tracks], [x.lon for x in all_tracks], [x.h for x in all_tracks]
        )
    else:
        re_ = rn_ = ru_ = np.zeros(0)
    radar: list[RadarFrame] = []
    k = 0
    offset_radar = site.clock_offset_s("radar")
    layout = radar_line_layout(twin)
    frame_line = {idx: line for line, idx in enumerate(layout, start=1) if idx >= 0}
    for i, f in enumerate(twin.radar):
        line = frame_line[i]
        ft = f.t_unix - offset_radar
        trs = []
        for tr in f.tracks:
            r = tr.report
            vn, ve, vd = r.vel[1], r.vel[0], -r.vel[2]
            trs.append(
                RadarTrack(
                    t=ft,
                    track_id=r.track_id,
                    lat=tr.lat,
                    lon=tr.lon,
                    h=tr.h,
                    e=float(re_[k]),
                    n=float(rn_[k]),
                    u=float(ru_[k]),
                    vel_ned=(vn, ve, vd),
                    uav_prob=r.cat_prob[0],
                    range_m=r.range_m,
                    rcs_dbsm=r.rcs_dbsm,
                    radial_velocity=r.radial_velocity,
                    num_inliers=r.num_inliers,
                    line=line,
                )
            )
            k += 1
        radar.append(RadarFrame(ft, tuple(trs), line))
    hh = site.h0 if rf_height is None else rf_height
    rf: list[RfAttempt] = []
    offset_rf = site.clock_offset_s("rf")
    for line, a in enumerate(twin.rf, start=2):
        if a.attempt.ok:
            fe, fn, _ = site.to_enu(a.lat, a.lon, hh)
            ee, nn = float(fe), float(fn)
        else:
            ee = nn = math.nan
        rf.append(
            RfAttempt(
                t=a.t_unix - offset_rf,
                meas_id=a.attempt.meas_id,
                ok=a.attempt.ok,
                lat=a.lat,
                lon=a.lon,
                e=ee,
                n=nn,
                cep=a.attempt.cep_m,
                valid_sensors=a.attempt.valid_sensors,
                total_sensors=a.attempt.total_sensors,
                line=line,
                center_freq_hz=float(
                    f"{a.attempt.center_frequency_hz or twin.config.rf.center_frequency_hz:.0f}"
                ),
                rho=float(f"{a.attempt.rho:.4f}") if a.attempt.ok else 0.0,
            )
        )
    return Flight(name=twin.plan.name, truth=truth, radar=radar, rf=rf, vehicles=vehicles)


def _truth_fixes(tl: TruthLog, site: Site) -> list[TruthFix]:
    """The valid rows of a truth log as the truth reader returns them."""
    ok = tl.valid
    t = tl.t_us[ok] / 1e6
    h = site.takeoff_h + tl.alt[ok]
    e, n, u = site.to_enu(tl.lat[ok], tl.lon[ok], h)
    lines = np.flatnonzero(ok) + 1
    truth = [
        TruthFix(
            t=float(t[i]),
            lat=float(tl.lat[ok][i]),
            lon=float(tl.lon[ok][i]),
            h=float(h[i]),
            e=float(e[i]),
            n=float(n[i]),
            u=float(u[i]),
            vel_ned=(
                float(tl.vel_ned[ok][i, 0]),
                float(tl.vel_ned[ok][i, 1]),
                float(tl.vel_ned[ok][i, 2]),
            ),
            fix_type=int(tl.fix_type[ok][i]),
            num_sats=int(tl.num_sats[ok][i]),
            line=int(lines[i]),
        )
        for i in range(t.size)
    ]
    return truth
