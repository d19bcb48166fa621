"""Parameters of the digital twin, loaded from ``config/twin_default.yaml``.

Each section of the YAML file maps onto one dataclass below; a key the dataclass does not know,
or a value of the wrong type, is a :class:`~uav_fusion.core.errors.ConfigError` naming the file
and the key. Missing keys keep the defaults written here (which equal the shipped file).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TypeVar

from uav_fusion.core.errors import ConfigError
from uav_fusion.core.yamlio import read_yaml_file
from uav_fusion.resources import config_path

DEFAULT_TWIN_CONFIG = "twin_default.yaml"
DEFAULT_WAYPOINTS = "waypoints/lake_wheeler_default.yaml"


@dataclass(frozen=True)
class FlightDynamics:
    """Point-mass multirotor following waypoints (guidance + acceleration limits)."""

    dt_s: float = 0.02  # integration step
    accel_max_mps2: float = 2.5  # horizontal acceleration limit
    vert_accel_max_mps2: float = 1.5
    climb_rate_mps: float = 3.0  # vertical speed limit (up and down)
    land_rate_mps: float = 1.2  # vertical speed of the last (landing) leg
    response_s: float = 0.8  # time constant of the velocity loop
    accept_radius_m: float = 6.0  # waypoint is reached inside this distance
    corner_min_speed_mps: float = 2.0  # speed floor through a sharp corner
    wind_gust_mps: float = 0.35  # std of the gust velocity (Ornstein-Uhlenbeck)
    wind_gust_tau_s: float = 4.0  # correlation time of the gusts


@dataclass(frozen=True)
class TruthModel:
    """RTK GNSS log of the vehicle (dronekit-style vehicleOut file)."""

    rate_hz: float = 5.0
    sigma_h_m: float = 0.012  # RTK noise, horizontal, per axis
    sigma_v_m: float = 0.02  # RTK noise, vertical
    fix_type: int = 6  # RTK fixed
    num_sats_min: int = 14
    num_sats_max: int = 21
    no_fix_rows_start: int = 3  # -999 rows (fix type 1) before the first fix
    no_fix_dropouts: int = 2  # isolated -999 rows during the flight
    battery_full_v: float = 25.1
    battery_drop_v_per_min: float = 0.18
    battery_noise_v: float = 0.02


@dataclass(frozen=True)
class RadarModel:
    """Ku-band radar (R20-like): detections, onboard CV tracker, clutter and birds."""

    scan_interval_s: float = 0.25  # track report interval
    scan_jitter_s: float = 0.004  # std of the report time jitter
    sigma_range_m: float = 1.0  # range noise (1 m resolution)
    sigma_az_deg: float = 1.1  # white azimuth noise per detection
    sigma_el_deg: float = 1.0  # white elevation noise per detection
    angle_snr_deg: float = 7.0  # thermal angle noise: this / sqrt(SNR as a power ratio)
    glint_sigma_deg: float = 1.1  # slowly varying (glint) angle error, az and el alike
    glint_tau_s: float = 3.0  # its correlation time
    az_bias_deg: float = 0.5  # residual mounting misalignment in azimuth
    el_bias_deg: float = 0.3  # ... and in elevation
    multipath_el_deg: float = 4.0  # below about this elevation ground multipath ...
    multipath_gain: float = 1.0  # ... inflates the elevation noise by up to (1 + gain)
    max_range_m: float = 3000.0  # no detection beyond
    min_radial_speed_mps: float = 0.15  # Doppler clutter notch
    min_agl_m: float = 4.0  # below this the ground clutter's Doppler spread masks a target ...
    snr_ref_db: float = 31.0  # SNR of a 1 m^2 target at ref range
    snr_ref_range_m: float = 1000.0
    detect_threshold_db: float = 13.0  # SNR needed for a detection (Pfa ~1e-6)
    detect_noise_db: float = 1.5  # per-look fluctuation of the SNR besides the RCS draw
    pd_max: float = 1.0  # a look above the threshold is detected with this probability
    rcs_median_m2: float = 0.07  # lognormal RCS per look
    rcs_sigma_ln: float = 0.85
    rcs_min_m2: float = 0.0066
    rcs_max_m2: float = 0.549
    tracker_q_mps2: float = 0.04  # white-acceleration PSD of the onboard CV filter (m^2/s^3)
    tracker_gate_sigma: float = 4.0  # association gate in innovation sigmas
    tracker_gate_min_m: float = 25.0  # plus this floor
    tracker_max_speed_mps: float = 30.0  # the tracker clips its velocity to this
    confirm_hits: int = 3  # M-of-N confirmation of a new track
    confirm_window: int = 5
    max_coast_s: float = 4.0  # delete after this long without update, near the radar
    max_coast_far_s: float = 8.0  # ... and this long at max_coast_ref_range_m or more
    max_coast_ref_range_m: float = 1200.0
    low_target_min_radial_mps: float = 1.0  # below min_agl_m a target needs this radial speed
    status_every_s: float = 30.0  # a status line this often
    params_track_every: int = 7  # every n-th frame carries trackData inside params


@dataclass(frozen=True)
class RfModel:
    """Passive TDOA sensor network (N6841A-like) and its multilateration."""

    interval_s: float = 3.88  # mean time between localisation attempts
    interval_jitter_s: float = 0.25  # uniform +- jitter on that interval
    center_frequency_hz: float = 3.32e9
    sample_rate_hz: float = 6.25e6
    num_samples: int = 32768
    sigma_timing_ns: float = 50.0  # time-of-arrival noise per sensor (GPS + TOA estimate)
    los_multipath_m: float = 3.0  # mean excess path on a line-of-sight link (exponential)
    nlos_el50_deg: float = 0.4  # elevation at which a link is NLOS with probability 1/2
    nlos_el_width_deg: float = 0.3  # softness of that transition
    nlos_far_km: float = 1.4  # beyond this distance the NLOS probability rises further
    nlos_far_gain_per_km: float = 0.7
    nlos_excess_m: float = 120.0  # mean NLOS excess path (exponential) ...
    nlos_excess_per_km_m: float = 260.0  # ... plus this per km of link length
    detect_snr_ref_db: float = 30.0  # SNR at 1 km (free space, LOS)
    nlos_loss_db: float = 12.0
    detect_snr_min_db: float = 8.0  # a sensor below this SNR is not valid
    sensor_dropout: float = 0.09  # independent per-sensor dropout per attempt
    overload_range_m: float = 60.0  # a sensor this close is overloaded (and invalid)
    assumed_height_m: float = 40.0  # height above the origin used by the 2D solver
    max_iterations: int = 100  # function evaluations of the least-squares refinement
    converge_m: float = 0.05
    max_residual_m: float = 1500.0  # RMS TDOA residual (m) above which a fix is rejected
    search_margin_m: float = 3000.0  # the solver searches the sensors' box widened by this
    max_solution_range_m: float = 6000.0  # a solution farther from the sensors is a failure
    cep_nlos_weight: float = 0.0  # share of the NLOS excess-path error the reported CEP includes


@dataclass(frozen=True)
class ClassifierModel:
    """The radar's target classifier: catProb[0] of a track from several weak cues.

    Per track a class logit relaxes (``response_s``) towards the cue of the object the track
    currently follows: ``initial + reliability * (base + cues - initial)`` with reliability
    ``(1 - exp(-age / age_tau_s)) * exp(-range / range_scale_m)`` (a young or far track has few
    features, so its probability stays near 0.5); a UAV slower than ``hover_speed_mps`` loses
    its body Doppler (``hover_penalty``); an AR(1) logit noise is added per report.
    """

    initial_logit: float = -1.0  # a new track's logit: unclassified, leaning "not a UAV"
    uav_logit: float = 2.8  # base logit of a UAV (rotor micro-Doppler, size, motion)
    ghost_logit: float = 1.6  # a multipath image carries the UAV's signature, weaker
    bird_logit_mean: float = -0.9  # per flock, normal (wing beats give some micro-Doppler)
    bird_logit_sigma: float = 0.5
    clutter_logit_mean: float = -1.9  # per clutter site, normal ...
    clutter_logit_sigma: float = 0.8
    rotating_fraction: float = 0.3  # ... except this share of sites (fans, wind pumps) ...
    rotating_logit: float = -0.5  # ... whose blades give a rotor-like micro-Doppler
    vehicle_logit: float = -2.6
    hover_speed_mps: float = 1.5  # below this speed a UAV has little body Doppler ...
    hover_penalty: float = 2.6  # ... and its logit drops by this
    age_tau_s: float = 5.0  # features accumulate with track age
    range_scale_m: float = 3000.0  # and fade with range
    response_s: float = 2.0  # the track's belief follows the cue with this time constant
    noise_logit: float = 0.45  # std of the AR(1) logit noise
    noise_tau_s: float = 4.0  # its correlation time


@dataclass(frozen=True)
class ClutterModel:
    """Persistent clutter: stationary reflectors with a rotating or fluttering part.

    ``sites`` reflectors (Poisson count) stand at random in the field of view. Each switches on
    and off as a two-state Markov process (mean times ``mean_on_s`` / ``mean_off_s``: a fan or
    wind pump that runs for minutes, a door, a flag in gusts). The structure itself has zero
    Doppler and sits in the radar's notch; what the radar sees is its moving part, a rotating
    or fluttering component of tip speed ``tip_speed`` whose instantaneous radial speed
    ``tip * |sin(phase)|`` (phase uniform per scan) must clear the Doppler notch, with a
    lognormal RCS (median ``rcs_median_m2``).
    """

    sites: float = 5.0  # mean number of reflectors (Poisson)
    range_min_m: float = 250.0
    range_max_m: float = 2500.0
    height_min_m: float = 3.0  # height of the moving part above ground
    height_max_m: float = 25.0
    mean_on_s: float = 300.0
    mean_off_s: float = 240.0
    tip_speed_min_mps: float = 1.0
    tip_speed_max_mps: float = 12.0
    rcs_median_m2: float = 1.5
    rcs_sigma_ln: float = 1.0
    site_rcs_sigma_db: float = 4.0  # spread of the median RCS between sites


@dataclass(frozen=True)
class VehicleModel:
    """Cars on the roads near the site (polylines in ENU metres about the origin).

    Vehicles enter at a random end of a random road (Poisson, ``rate_per_min``), cruise at a
    normal speed, brake for corners (``lateral_accel_mps2`` on a ``corner_radius_m`` bend) with
    ``accel_mps2`` and leave at the other end; ``height_m`` above ground (0-2 m).
    """

    rate_per_min: float = 0.6
    speed_mean_mps: float = 13.0
    speed_sigma_mps: float = 2.5
    accel_mps2: float = 2.0
    lateral_accel_mps2: float = 2.5
    corner_radius_m: float = 25.0
    height_m: float = 1.2
    rcs_median_m2: float = 8.0
    rcs_sigma_ln: float = 1.2
    roads: tuple[tuple[tuple[float, float], ...], ...] = (
        ((-900.0, 150.0), (-300.0, 185.0), (200.0, 120.0), (650.0, 210.0)),
        ((-700.0, -420.0), (-660.0, 300.0), (-600.0, 900.0), (-540.0, 1600.0)),
        ((-1100.0, -250.0), (-420.0, -330.0), (0.0, -430.0), (260.0, -620.0)),
    )


@dataclass(frozen=True)
class BirdModel:
    """Bird flocks: erratic flight (random-walk heading and speed), small RCS per bird."""

    flock_rate_per_min: float = 0.8
    flock_life_s: float = 60.0  # mean (exponential)
    members_min: int = 1
    members_max: int = 5
    spread_m: float = 12.0  # members' offsets about the flock centre (std per axis)
    speed_mean_mps: float = 9.0
    speed_sigma_mps: float = 2.0
    turn_sigma_dps: float = 25.0  # heading random walk (std per sqrt(s))
    height_min_m: float = 10.0
    height_max_m: float = 80.0
    range_min_m: float = 120.0
    range_max_m: float = 1500.0
    rcs_median_m2: float = 0.006
    rcs_sigma_ln: float = 0.9


@dataclass(frozen=True)
class GhostModel:
    """Multipath ghost: the UAV's mirror image in the ground, below its true elevation.

    Seen when the image is resolved from the UAV (elevation difference >= ``min_separation_deg``)
    and strong enough: its RCS is the UAV's look times the ground's specular reflection loss,
    ``fresnel_loss_db`` plus the Rayleigh roughness loss
    ``20 log10(e) * 2 * (2 pi roughness sin(grazing) / wavelength)^2`` dB, so only low grazing
    angles (a UAV low on the horizon or far away) give a ghost.
    """

    min_separation_deg: float = 2.0
    fresnel_loss_db: float = 3.0  # reflection coefficient of the soil at grazing incidence
    surface_roughness_m: float = 0.05  # std of the terrain height within the reflecting zone
    wavelength_m: float = 0.0182  # Ku band (16.5 GHz)


@dataclass(frozen=True)
class RfOutage:
    """Runs of failed RF attempts: a two-state Markov link outage (good / bad per attempt)."""

    enter_prob: float = 0.003  # per attempt, good -> bad (interference, emitter pause)
    mean_run: float = 2.5  # mean length of a bad run, in attempts


@dataclass(frozen=True)
class Recording:
    """Where the recording sits in time and what the files are called."""

    start_utc: str = "2025-10-07 19:40:00"
    tail_s: float = 40.0  # recording continues this long after landing


@dataclass(frozen=True)
class TwinConfig:
    dynamics: FlightDynamics = field(default_factory=FlightDynamics)
    truth: TruthModel = field(default_factory=TruthModel)
    radar: RadarModel = field(default_factory=RadarModel)
    rf: RfModel = field(default_factory=RfModel)
    classifier: ClassifierModel = field(default_factory=ClassifierModel)
    clutter: ClutterModel = field(default_factory=ClutterModel)
    vehicles: VehicleModel = field(default_factory=VehicleModel)
    birds: BirdModel = field(default_factory=BirdModel)
    ghosts: GhostModel = field(default_factory=GhostModel)
    rf_outage: RfOutage = field(default_factory=RfOutage)
    recording: Recording = field(default_factory=Recording)
    seed: int = 1
    source: Path | None = None


_PHENOMENA: dict[str, type] = {
    "classifier": ClassifierModel,
    "clutter": ClutterModel,
    "vehicles": VehicleModel,
    "birds": BirdModel,
    "ghosts": GhostModel,
    "rf_outage": RfOutage,
}

T = TypeVar("T")


def _section(cls: type[T], raw: Any, where: str) -> T:
    if raw is None:
        return cls()
    if not isinstance(raw, dict):
        raise ConfigError(f"{where}: expected a mapping")
    known = {f.name: f for f in dataclasses.fields(cls)}  # type: ignore[arg-type]
    kwargs: dict[str, Any] = {}
    for key, value in raw.items():
        if key not in known:
            raise ConfigError(f"{where}: unknown key '{key}' (known: {', '.join(sorted(known))})")
        default = getattr(cls(), key)
        if key == "roads":
            kwargs[key] = _roads(value, f"{where}: roads")
            continue
        if isinstance(default, bool) or not isinstance(default, (int, float, str)):
            raise ConfigError(f"{where}: key '{key}' cannot be set here")
        if isinstance(default, str):
            kwargs[key] = str(value)
            continue
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ConfigError(f"{where}: '{key}' must be a number, got {value!r}")
        try:
            x = float(value)
        except OverflowError:  # an integer beyond the float range
            raise ConfigError(
                f"{where}: '{key}' must be finite, got a number beyond 1e308"
            ) from None
        if not math.isfinite(x):
            raise ConfigError(f"{where}: '{key}' must be finite")
        if isinstance(default, int) and not isinstance(default, bool):
            if x != int(x):
                raise ConfigError(f"{where}: '{key}' must be an integer, got {value!r}")
            kwargs[key] = int(value)
        else:
            kwargs[key] = x
    return cls(**kwargs)


def _roads(value: Any, where: str) -> tuple[tuple[tuple[float, float], ...], ...]:
    """Roads: a list of polylines, each a list of at least two [east, north] points (m)."""
    if not isinstance(value, list):
        raise ConfigError(f"{where}: expected a list of polylines")
    out = []
    for i, line in enumerate(value):
        if not isinstance(line, list) or len(line) < 2:
            raise ConfigError(f"{where}[{i}]: expected a list of at least two [east, north]")
        pts = []
        for j, pt in enumerate(line):
            ok = isinstance(pt, list) and len(pt) == 2
            if ok and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in pt):
                pts.append((float(pt[0]), float(pt[1])))
            else:
                raise ConfigError(
                    f"{where}[{i}][{j}]: expected [east, north] in metres, got {pt!r}"
                )
        out.append(tuple(pts))
    return tuple(out)


def twin_config_from_dict(doc: Any, source: Path | None = None) -> TwinConfig:
    """Build a :class:`TwinConfig` from a parsed YAML document."""
    src = str(source) if source else "<twin config>"
    if doc is None:
        doc = {}
    if not isinstance(doc, dict):
        raise ConfigError(f"{src}: expected a mapping at top level")
    sections = {"dynamics", "truth", "radar", "rf", "recording", "seed", *_PHENOMENA}
    for key in doc:
        if key not in sections:
            raise ConfigError(
                f"{src}: unknown section '{key}' (known: {', '.join(sorted(sections))})"
            )
    seed = doc.get("seed", 1)
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise ConfigError(f"{src}: 'seed' must be a non-negative integer, got {seed!r}")
    cfg = TwinConfig(
        dynamics=_section(FlightDynamics, doc.get("dynamics"), f"{src}: dynamics"),
        truth=_section(TruthModel, doc.get("truth"), f"{src}: truth"),
        radar=_section(RadarModel, doc.get("radar"), f"{src}: radar"),
        rf=_section(RfModel, doc.get("rf"), f"{src}: rf"),
        recording=_section(Recording, doc.get("recording"), f"{src}: recording"),
        **{k: _section(c, doc.get(k), f"{src}: {k}") for k, c in _PHENOMENA.items()},
        seed=seed,
        source=source,
    )
    validate_twin_config(cfg, src)
    return cfg


def validate_twin_config(cfg: TwinConfig, src: str) -> None:
    """Stop with a ConfigError naming ``src`` and the key when ``cfg`` is inconsistent."""
    positive = {
        "dynamics.dt_s": cfg.dynamics.dt_s,
        "dynamics.accel_max_mps2": cfg.dynamics.accel_max_mps2,
        "dynamics.climb_rate_mps": cfg.dynamics.climb_rate_mps,
        "dynamics.response_s": cfg.dynamics.response_s,
        "truth.rate_hz": cfg.truth.rate_hz,
        "radar.scan_interval_s": cfg.radar.scan_interval_s,
        "radar.sigma_az_deg": cfg.radar.sigma_az_deg,
        "radar.max_range_m": cfg.radar.max_range_m,
        "radar.rcs_median_m2": cfg.radar.rcs_median_m2,
        "rf.interval_s": cfg.rf.interval_s,
        "rf.sigma_timing_ns": cfg.rf.sigma_timing_ns,
    }
    for key, value in positive.items():
        if value <= 0:
            raise ConfigError(f"{src}: {key} must be > 0, got {value}")
    if not 0.0 < cfg.radar.pd_max <= 1.0:
        raise ConfigError(f"{src}: radar.pd_max must lie in (0, 1], got {cfg.radar.pd_max}")
    if not 0.0 <= cfg.rf.cep_nlos_weight <= 1.0:
        raise ConfigError(
            f"{src}: rf.cep_nlos_weight must lie in [0, 1], got {cfg.rf.cep_nlos_weight}"
        )
    if cfg.rf.interval_jitter_s >= cfg.rf.interval_s:
        raise ConfigError(f"{src}: rf.interval_jitter_s must be smaller than rf.interval_s")
    if cfg.birds.members_min < 1 or cfg.birds.members_max < cfg.birds.members_min:
        raise ConfigError(f"{src}: birds.members_min must be >= 1 and <= birds.members_max")
    if not 0.0 <= cfg.rf_outage.enter_prob <= 1.0 or cfg.rf_outage.mean_run < 1.0:
        raise ConfigError(f"{src}: rf_outage.enter_prob must lie in [0, 1], mean_run >= 1")
    for key in ("sites", "range_min_m", "mean_on_s", "mean_off_s", "rcs_median_m2"):
        if getattr(cfg.clutter, key) < 0:
            raise ConfigError(f"{src}: clutter.{key} must be >= 0")
    if cfg.radar.confirm_hits > cfg.radar.confirm_window:
        raise ConfigError(f"{src}: radar.confirm_hits must not exceed radar.confirm_window")


def load_twin_config(path: str | Path | None = None) -> TwinConfig:
    """Load twin parameters (default: the shipped ``config/twin_default.yaml``)."""
    p = Path(path) if path is not None else config_path(DEFAULT_TWIN_CONFIG)
    return twin_config_from_dict(read_yaml_file(p, "twin configuration file"), p)
