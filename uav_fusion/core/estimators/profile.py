"""Estimator profiles: every tunable choice of the filter, loaded from YAML.

A profile names the motion model's process noise, the measurement covariances, the gates, the
radar track handling and the track life-cycle rules. ``config/profiles/paper.yaml`` is the
paper's estimator; other files in that folder (or any path) can be loaded the same way.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from uav_fusion.core.data.uav_class import DEFAULT_MIN_MEAN_UAV_PROB
from uav_fusion.core.errors import ConfigError
from uav_fusion.core.estimators.components import validate_transition
from uav_fusion.core.estimators.multi_settings import (
    MultiSettings,
    multi_keys,
    multi_settings_from_dict,
)
from uav_fusion.core.estimators.objects import ScoreConfig, score_keys
from uav_fusion.core.records import RADAR, RF
from uav_fusion.core.yamlio import read_yaml_file
from uav_fusion.resources import config_path

FloatArray = npt.NDArray[np.float64]

SELECTIONS = ("largest_track", "online")
ASSOCIATIONS = (*SELECTIONS, "track_score")
MOTION_MODELS = ("cv", "imm")
RADAR_MODELS = ("fixed", "polar")
MAX_RADAR_BIAS_DEG = 10.0  # measurement.radar.az_bias_deg / el_bias_deg
RF_MODELS = ("fixed", "cep")
ROBUST = ("none", "student_t", "huber")
SOURCES = (RADAR, RF)
Q3 = tuple[float, float, float]


@dataclass(frozen=True)
class Profile:
    """The estimator's configuration (see ``config/profiles/README.md`` for each key)."""

    name: str
    q: tuple[float, float, float]  # CWNA spectral density per axis, m^2/s^3
    r_radar: FloatArray  # 3x3, m^2
    r_rf: FloatArray  # 2x2, m^2
    range_gate_m: float | None = 800.0  # None: the site's radar.range_gate_m
    far_gate_m: float | None = None  # horizontal-only radar updates out to this range
    nis_probability: float = 0.95
    min_uav_prob: float | None = None
    radar_selection: str = "largest_track"
    use_radar: bool = True
    use_rf: bool = True
    init_sources: tuple[str, ...] = (RADAR, RF)
    init_velocity_std_mps: float = 15.0
    rf_init_altitude_m: float = 40.0  # ENU up assumed when an RF fix starts a track
    rf_init_altitude_std_m: float = 40.0
    max_consecutive_rejections: int | None = None
    max_coast_s: float | None = None
    tentative_sources: tuple[str, ...] = ()
    confirm_m: int = 1  # a tentative track is confirmed by confirm_m hits ...
    confirm_n: int = 1  # ... among its first confirm_n measurements (the start included)
    max_speed_mps: float | None = None  # speed plausibility bound while tentative
    # the raw radar row's UAV-track rule (core/data/uav_class.py)
    raw_radar_min_mean_uav_prob: float | None = DEFAULT_MIN_MEAN_UAV_PROB
    description: str = ""
    r_note: str = ""
    # --- tracker components (the paper's estimator uses none of these) ---
    motion_model: str = "cv"  # cv | imm
    imm_q: tuple[Q3, ...] = ()  # per mode
    imm_transition: tuple[tuple[float, ...], ...] = ()  # Markov matrix, row i: from mode i
    imm_initial: tuple[float, ...] = ()
    radar_model: str = "fixed"  # fixed (r_radar) | polar
    radar_sigma_range_m: float = 1.0
    radar_sigma_az_deg: float = 1.5
    radar_sigma_el_deg: float = 1.5
    radar_floor_m: float = 0.0
    radar_low_el_gain: float = 0.0
    radar_low_el_deg: float = 4.0
    radar_az_bias_deg: float = 0.0  # mounting misalignment, corrected on every report
    radar_el_bias_deg: float = 0.0
    rf_model: str = "fixed"  # fixed (r_rf) | cep
    rf_cep_scale: float = 1.0
    rf_floor_m: float = 5.0
    rf_ref_sensors: int = 4
    rf_sensor_exponent: float = 0.0
    rf_max_cep_m: float | None = None  # RF fixes with a larger CEP are discarded
    robust: str = "none"  # none | student_t | huber
    robust_dof: float = 4.0
    robust_huber_k: float = 1.5
    vz_hold_after_s: float | None = None  # RF-only: pseudo-measurement vz = 0 after this long
    vz_hold_sigma_mps: float = 1.0
    # no radar update for this long with the track inside notch_range_m of the radar:
    # pseudo-measurement radial speed = 0 (the UAV hovers in the Doppler notch); None: off
    notch_after_s: float | None = None
    notch_sigma_mps: float = 1.0
    notch_range_m: float = 1000.0
    association: str | None = None  # None: radar_selection (paper); "track_score": tracker
    score: ScoreConfig = field(default_factory=ScoreConfig)
    smoother_lag_s: float | None = None  # fixed-lag smoothing of the tracker's steps
    # the multi-UAV tracker's own settings (the ``multi`` section; multi_settings.py)
    multi: MultiSettings = field(default_factory=MultiSettings)
    source: Path | None = field(default=None, compare=False)

    @property
    def association_mode(self) -> str:
        """``largest_track`` / ``online`` (the paper's estimator) or ``track_score``."""
        return self.association or self.radar_selection

    @property
    def estimator(self) -> str:
        """The estimator the profile names: ``paper`` or ``tracker``."""
        return "tracker" if self.association == "track_score" else "paper"

    @property
    def uses_tracker(self) -> bool:
        """Run by :class:`~uav_fusion.core.estimators.tracker.Tracker` (every radar object)
        rather than the paper's :class:`~uav_fusion.core.estimators.paper.FusionEstimator`."""
        return self.association == "track_score"

    def with_changes(self, **changes: Any) -> Profile:
        """A copy with some fields replaced (validated again)."""
        p = replace(self, **changes)
        _validate(p, str(self.source or self.name))
        return p

    def as_dict(self) -> dict[str, Any]:
        """The profile as the YAML document :func:`profile_from_dict` reads."""
        out: dict[str, Any] = {
            "name": self.name,
            "description": self.description,
            "motion": {"model": "cv", "q": [float(v) for v in self.q]},
            "measurement": {
                "radar": {"R": np.asarray(self.r_radar, float).tolist()},
                "rf": {"R": np.asarray(self.r_rf, float).tolist()},
                "note": self.r_note,
            },
            "gating": {
                "range_gate_m": self.range_gate_m,
                "far_gate_m": self.far_gate_m,
                "nis_probability": self.nis_probability,
                "min_uav_prob": self.min_uav_prob,
            },
            "radar_selection": self.radar_selection,
            "sources": {RADAR: self.use_radar, RF: self.use_rf},
            "track": {
                "init_sources": list(self.init_sources),
                "init_velocity_std_mps": self.init_velocity_std_mps,
                "rf_init_altitude_m": self.rf_init_altitude_m,
                "rf_init_altitude_std_m": self.rf_init_altitude_std_m,
                "max_consecutive_rejections": self.max_consecutive_rejections,
                "max_coast_s": self.max_coast_s,
                "tentative_sources": list(self.tentative_sources),
                "confirm_m": self.confirm_m,
                "confirm_n": self.confirm_n,
                "max_speed_mps": self.max_speed_mps,
            },
            "evaluation": {"raw_radar_min_mean_uav_prob": self.raw_radar_min_mean_uav_prob},
        }
        if self.uses_tracker:
            d = out
            d["motion"]["model"] = self.motion_model
            if self.motion_model == "imm":
                d["motion"]["imm"] = {
                    "q": [list(q) for q in self.imm_q],
                    "transition": [list(r) for r in self.imm_transition],
                    "initial": list(self.imm_initial),
                }
            d["measurement"]["radar"].update(
                model=self.radar_model,
                sigma_range_m=self.radar_sigma_range_m,
                sigma_az_deg=self.radar_sigma_az_deg,
                sigma_el_deg=self.radar_sigma_el_deg,
                floor_m=self.radar_floor_m,
                low_el_gain=self.radar_low_el_gain,
                low_el_deg=self.radar_low_el_deg,
                az_bias_deg=self.radar_az_bias_deg,
                el_bias_deg=self.radar_el_bias_deg,
            )
            d["measurement"]["rf"].update(
                model=self.rf_model,
                cep_scale=self.rf_cep_scale,
                floor_m=self.rf_floor_m,
                ref_sensors=self.rf_ref_sensors,
                sensor_exponent=self.rf_sensor_exponent,
                max_cep_m=self.rf_max_cep_m,
            )
            d["update"] = {
                "robust": self.robust,
                "dof": self.robust_dof,
                "huber_k": self.robust_huber_k,
                "vz_hold_after_s": self.vz_hold_after_s,
                "vz_hold_sigma_mps": self.vz_hold_sigma_mps,
                "notch_after_s": self.notch_after_s,
                "notch_sigma_mps": self.notch_sigma_mps,
                "notch_range_m": self.notch_range_m,
            }
            score = asdict(self.score)
            d["association"] = {"mode": "track_score", **{k: score[k] for k in score_keys()}}
            del d["radar_selection"]
            d["smoother"] = {"lag_s": self.smoother_lag_s}
        if self.uses_tracker or self.multi != MultiSettings():
            out["multi"] = asdict(self.multi)
        return out


_KEYS: dict[str, tuple[str, ...]] = {
    "": (
        "name",
        "description",
        "motion",
        "measurement",
        "gating",
        "radar_selection",
        "sources",
        "track",
        "evaluation",
        "update",
        "association",
        "smoother",
        "multi",
    ),
    "motion": ("model", "q", "imm"),
    "motion.imm": ("q", "transition", "initial"),
    "measurement": ("radar", "rf", "note"),
    "measurement.radar": (
        "R", "model", "sigma_range_m", "sigma_az_deg", "sigma_el_deg", "floor_m",
        "low_el_gain", "low_el_deg", "az_bias_deg", "el_bias_deg",
    ),
    "measurement.rf": (
        *("R", "model", "cep_scale", "floor_m", "ref_sensors", "sensor_exponent", "max_cep_m"),
    ),
    "update": (
        "robust",
        "dof",
        "huber_k",
        "vz_hold_after_s",
        "vz_hold_sigma_mps",
        "notch_after_s",
        "notch_sigma_mps",
        "notch_range_m",
    ),
    "association": ("mode", *score_keys()),
    "smoother": ("lag_s",),
    "multi": multi_keys(),
    "gating": ("range_gate_m", "far_gate_m", "nis_probability", "min_uav_prob"),
    "sources": (RADAR, RF),
    "track": (
        "init_sources",
        "init_velocity_std_mps",
        "rf_init_altitude_m",
        "rf_init_altitude_std_m",
        "tentative_sources",
        "confirm_m",
        "confirm_n",
        "max_speed_mps",
        "max_consecutive_rejections",
        "max_coast_s",
    ),
    "evaluation": ("raw_radar_min_mean_uav_prob",),
}


def _check_keys(d: dict[str, Any], section: str, where: str) -> None:
    allowed = _KEYS[section]
    for k in d:
        if k not in allowed:
            at = f"{section}.{k}" if section else str(k)
            raise ConfigError(f"{where}: unknown key '{at}' (allowed: {', '.join(allowed)})")


def _section(doc: dict[str, Any], key: str, where: str) -> dict[str, Any]:
    v = doc.get(key, {})
    if v is None:
        return {}
    if not isinstance(v, dict):
        raise ConfigError(f"{where}: '{key}' must be a mapping")
    return v


def _float(d: dict[str, Any], key: str, where: str, default: Any) -> float:
    v = d.get(key, default)
    try:
        x = float(v)
    except (TypeError, ValueError):
        raise ConfigError(f"{where}: '{key}' must be a number, got {v!r}") from None
    except OverflowError:  # an integer beyond the float range
        raise ConfigError(f"{where}: '{key}' must be finite, got a number beyond 1e308") from None
    if not np.isfinite(x):
        raise ConfigError(f"{where}: '{key}' must be finite, got {v!r}")
    return x


def _opt_float(d: dict[str, Any], key: str, where: str, default: Any) -> float | None:
    v = d.get(key, default)
    return None if v is None else _float({key: v}, key, where, None)


def _matrix(v: Any, n: int, where: str) -> FloatArray:
    try:
        a = np.asarray(v, dtype=float)
    except (TypeError, ValueError, OverflowError):
        raise ConfigError(f"{where}: must be a {n}x{n} matrix of numbers") from None
    if a.shape != (n, n):
        raise ConfigError(f"{where}: must be a {n}x{n} matrix, got shape {a.shape}")
    return a


def _validate(p: Profile, where: str) -> None:
    if len(p.q) != 3 or any(not np.isfinite(v) or v < 0 for v in p.q):
        raise ConfigError(f"{where}: motion.q must be three finite values >= 0, got {p.q}")
    for name, R, n in (("radar", p.r_radar, 3), ("rf", p.r_rf, 2)):
        w = f"{where}: measurement.{name}.R"
        R = _matrix(R, n, w)
        if not np.all(np.isfinite(R)):
            raise ConfigError(f"{w}: must be finite")
        if not np.allclose(R, R.T, rtol=1e-9, atol=1e-9):
            raise ConfigError(f"{w}: must be symmetric")
        if np.min(np.linalg.eigvalsh(R)) <= 0:
            raise ConfigError(f"{w}: must be positive definite")
    if p.range_gate_m is not None and not p.range_gate_m > 0:
        raise ConfigError(f"{where}: gating.range_gate_m must be > 0 or null")
    if p.far_gate_m is not None:
        if not p.far_gate_m > 0:
            raise ConfigError(f"{where}: gating.far_gate_m must be > 0 or null")
        if p.range_gate_m is not None and not p.far_gate_m > p.range_gate_m:
            raise ConfigError(
                f"{where}: gating.far_gate_m ({p.far_gate_m:g}) must exceed "
                f"gating.range_gate_m ({p.range_gate_m:g})"
            )
        if not p.uses_tracker:
            raise ConfigError(f"{where}: gating.far_gate_m needs association.mode track_score")
    if not 0 < p.nis_probability < 1:
        raise ConfigError(f"{where}: gating.nis_probability must lie in (0, 1)")
    if p.min_uav_prob is not None and not 0 <= p.min_uav_prob <= 1:
        raise ConfigError(f"{where}: gating.min_uav_prob must lie in [0, 1] or be null")
    if p.radar_selection not in SELECTIONS:
        raise ConfigError(
            f"{where}: radar_selection must be one of {', '.join(SELECTIONS)}, "
            f"got {p.radar_selection!r}"
        )
    for key, srcs in (("init_sources", p.init_sources), ("tentative_sources", p.tentative_sources)):
        for src in srcs:
            if src not in SOURCES:
                raise ConfigError(f"{where}: track.{key}: unknown source {src!r}")
    if not 1 <= p.confirm_m <= p.confirm_n:
        raise ConfigError(
            f"{where}: track.confirm_m and confirm_n need 1 <= confirm_m <= confirm_n, "
            f"got {p.confirm_m} and {p.confirm_n}"
        )
    if p.max_speed_mps is not None and not p.max_speed_mps > 0:
        raise ConfigError(f"{where}: track.max_speed_mps must be > 0 or null")
    raw = p.raw_radar_min_mean_uav_prob
    if raw is not None and not 0 <= raw <= 1:
        raise ConfigError(
            f"{where}: evaluation.raw_radar_min_mean_uav_prob must lie in [0, 1] or be null"
        )
    if not p.init_velocity_std_mps > 0 or not p.rf_init_altitude_std_m > 0:
        raise ConfigError(f"{where}: track initial standard deviations must be > 0")
    max_rej = p.max_consecutive_rejections
    if max_rej is not None and max_rej < 1:
        raise ConfigError(f"{where}: track.max_consecutive_rejections must be >= 1 or null")
    if p.max_coast_s is not None and not p.max_coast_s > 0:
        raise ConfigError(f"{where}: track.max_coast_s must be > 0 or null")
    _validate_tracker(p, where)


def _validate_tracker(p: Profile, where: str) -> None:
    for field_name, value in (
        ("motion_model", p.motion_model),
        ("radar_model", p.radar_model),
        ("rf_model", p.rf_model),
        ("robust", p.robust),
    ):
        allowed = {
            "motion_model": MOTION_MODELS,
            "radar_model": RADAR_MODELS,
            "rf_model": RF_MODELS,
            "robust": ROBUST,
        }[field_name]
        if value not in allowed:
            raise ConfigError(f"{where}: {field_name} {value!r} is not one of {allowed}")
    if p.association is not None and p.association != "track_score":
        raise ConfigError(f"{where}: association.mode {p.association!r} is not track_score")
    for key, v in (
        ("measurement.radar.sigma_range_m", p.radar_sigma_range_m),
        ("measurement.radar.sigma_az_deg", p.radar_sigma_az_deg),
        ("measurement.radar.sigma_el_deg", p.radar_sigma_el_deg),
        ("measurement.radar.floor_m", p.radar_floor_m),
        ("measurement.radar.low_el_gain", p.radar_low_el_gain),
        ("measurement.rf.floor_m", p.rf_floor_m),
    ):
        if not v >= 0:
            raise ConfigError(f"{where}: {key} must be >= 0 (a standard deviation), got {v}")
    for key, v in (
        ("measurement.radar.az_bias_deg", p.radar_az_bias_deg),
        ("measurement.radar.el_bias_deg", p.radar_el_bias_deg),
    ):
        if not abs(v) <= MAX_RADAR_BIAS_DEG:
            raise ConfigError(
                f"{where}: {key} must be a finite angle of at most {MAX_RADAR_BIAS_DEG:g} "
                f"degrees (a mounting misalignment), got {v}"
            )
    if p.rf_max_cep_m is not None and not p.rf_max_cep_m > 0:
        raise ConfigError(f"{where}: measurement.rf.max_cep_m must be > 0 or null")
    if not p.rf_cep_scale > 0:
        raise ConfigError(f"{where}: measurement.rf.cep_scale must be > 0")
    if p.rf_ref_sensors < 1:
        raise ConfigError(f"{where}: measurement.rf.ref_sensors must be >= 1")
    if p.radar_model == "polar" and p.radar_sigma_range_m + p.radar_floor_m <= 0:
        raise ConfigError(
            f"{where}: measurement.radar: the polar R needs sigma_range_m or floor_m > 0"
        )
    if not p.robust_dof > 0:
        raise ConfigError(f"{where}: update.dof must be > 0")
    if not p.robust_huber_k > 0:
        raise ConfigError(f"{where}: update.huber_k must be > 0")
    if p.vz_hold_after_s is not None and not p.vz_hold_after_s >= 0:
        raise ConfigError(f"{where}: update.vz_hold_after_s must be >= 0 or null")
    if not p.vz_hold_sigma_mps > 0:
        raise ConfigError(f"{where}: update.vz_hold_sigma_mps must be > 0")
    if p.notch_after_s is not None and not p.notch_after_s >= 0:
        raise ConfigError(f"{where}: update.notch_after_s must be >= 0 or null")
    if not p.notch_sigma_mps > 0:
        raise ConfigError(f"{where}: update.notch_sigma_mps must be > 0")
    if not p.notch_range_m > 0:
        raise ConfigError(f"{where}: update.notch_range_m must be > 0")
    if p.motion_model == "imm":
        n = len(p.imm_q)
        if n < 2:
            raise ConfigError(f"{where}: motion.imm.q needs at least 2 modes")
        for i, q in enumerate(p.imm_q):
            if len(q) != 3 or any(not np.isfinite(v) or v < 0 for v in q):
                raise ConfigError(f"{where}: motion.imm.q[{i}] must be three finite values >= 0")
        try:
            validate_transition(p.imm_transition, n, f"{where}: motion.imm.transition")
        except ValueError as exc:
            raise ConfigError(str(exc)) from None
        if len(p.imm_initial) != n or any(v < 0 for v in p.imm_initial) or not (
            abs(sum(p.imm_initial) - 1.0) <= 1e-9
        ):
            raise ConfigError(
                f"{where}: motion.imm.initial must be {n} probabilities >= 0 summing to 1"
            )
    if p.smoother_lag_s is not None and not p.smoother_lag_s >= 0:
        raise ConfigError(f"{where}: smoother.lag_s must be >= 0 or null")
    if p.smoother_lag_s is not None and not p.uses_tracker:
        raise ConfigError(f"{where}: smoother.lag_s needs association.mode track_score")
    sc = p.score
    for key in score_keys():
        v = getattr(sc, key)
        if key in (
            "follow_min",
            "init_min",
            "bird_rcs_dbsm",
            "large_rcs_dbsm",
            "vehicle_min_rcs_dbsm",
            "skip_radar_coasts",
            "class_prior_logit",
        ):
            continue
        if not v >= 0:
            raise ConfigError(f"{where}: association.{key} must be >= 0, got {v}")
    if not 0.0 < sc.class_min_weight <= 1.0:
        raise ConfigError(
            f"{where}: association.class_min_weight must be in (0, 1], got {sc.class_min_weight}"
        )
    if not sc.class_age_tau_s > 0.0:
        raise ConfigError(
            f"{where}: association.class_age_tau_s must be > 0, got {sc.class_age_tau_s}"
        )


def profile_from_dict(doc: Any, source: Path | None = None) -> Profile:
    """Build and validate a :class:`Profile` from a parsed YAML document."""
    where = str(source) if source else "<profile>"
    if not isinstance(doc, dict):
        raise ConfigError(f"{where}: expected a mapping at top level")
    _check_keys(doc, "", where)
    motion = _section(doc, "motion", where)
    model = str(motion.get("model", "cv"))
    if model not in MOTION_MODELS:
        raise ConfigError(
            f"{where}: motion.model {model!r} is not supported "
            f"(known components: {', '.join(MOTION_MODELS)})"
        )
    q_raw = motion.get("q")
    if isinstance(q_raw, int | float):
        q_list = [q_raw] * 3
    elif isinstance(q_raw, list) and len(q_raw) == 3:
        q_list = q_raw
    else:
        raise ConfigError(f"{where}: motion.q must be a number or a list of 3 numbers")
    q = tuple(_float({"q": v}, "q", f"{where}: motion", None) for v in q_list)
    meas = _section(doc, "measurement", where)
    radar = _section(meas, "radar", f"{where}: measurement")
    rf = _section(meas, "rf", f"{where}: measurement")
    if "R" not in radar or "R" not in rf:
        raise ConfigError(f"{where}: measurement.radar.R and measurement.rf.R are required")
    gating = _section(doc, "gating", where)
    sources = _section(doc, "sources", where)
    track = _section(doc, "track", where)
    evaluation = _section(doc, "evaluation", where)
    update = _section(doc, "update", where)
    assoc = _section(doc, "association", where)
    smoother = _section(doc, "smoother", where)
    multi = _section(doc, "multi", where)
    imm = _section(motion, "imm", f"{where}: motion")
    for name, sec in (
        ("motion", motion),
        ("motion.imm", imm),
        ("update", update),
        ("association", assoc),
        ("smoother", smoother),
        ("multi", multi),
        ("measurement", meas),
        ("measurement.radar", radar),
        ("measurement.rf", rf),
        ("gating", gating),
        ("sources", sources),
        ("track", track),
        ("evaluation", evaluation),
    ):
        _check_keys(sec, name, where)
    init_sources = track.get("init_sources", [RADAR, RF])
    tentative = track.get("tentative_sources", []) or []
    if not isinstance(init_sources, list) or not isinstance(tentative, list):
        raise ConfigError(f"{where}: track.init_sources / tentative_sources must be lists")
    confirm = {}
    for key in ("confirm_m", "confirm_n"):
        v = track.get(key, 1)
        if not isinstance(v, int) or isinstance(v, bool):
            raise ConfigError(f"{where}: track.{key} must be an integer, got {v!r}")
        confirm[key] = v
    max_rej = track.get("max_consecutive_rejections")
    if max_rej is not None and (not isinstance(max_rej, int) or isinstance(max_rej, bool)):
        raise ConfigError(f"{where}: track.max_consecutive_rejections must be an integer or null")
    min_prob = _opt_float(gating, "min_uav_prob", f"{where}: gating", None)
    extra = _tracker_fields(model, imm, radar, rf, update, assoc, smoother, where)
    selection = str(doc.get("radar_selection", "largest_track"))
    if extra.get("association") == "track_score":
        if "radar_selection" in doc:
            raise ConfigError(
                f"{where}: radar_selection and association.mode track_score exclude each other"
            )
        selection = "online"
    elif "mode" in assoc:
        selection = str(assoc["mode"])
    p = Profile(
        name=str(doc.get("name", source.stem if source else "profile")),
        q=(q[0], q[1], q[2]),
        r_radar=_matrix(radar["R"], 3, f"{where}: measurement.radar.R"),
        r_rf=_matrix(rf["R"], 2, f"{where}: measurement.rf.R"),
        range_gate_m=_opt_float(gating, "range_gate_m", f"{where}: gating", 800.0),
        far_gate_m=_opt_float(gating, "far_gate_m", f"{where}: gating", None),
        nis_probability=_float(gating, "nis_probability", f"{where}: gating", 0.95),
        min_uav_prob=min_prob,
        radar_selection=selection,
        use_radar=bool(sources.get(RADAR, True)),
        use_rf=bool(sources.get(RF, True)),
        init_sources=tuple(str(s) for s in init_sources),
        init_velocity_std_mps=_float(track, "init_velocity_std_mps", f"{where}: track", 15.0),
        rf_init_altitude_m=_float(track, "rf_init_altitude_m", f"{where}: track", 40.0),
        rf_init_altitude_std_m=_float(track, "rf_init_altitude_std_m", f"{where}: track", 40.0),
        max_consecutive_rejections=max_rej,
        max_coast_s=_opt_float(track, "max_coast_s", f"{where}: track", None),
        tentative_sources=tuple(str(x) for x in tentative),
        confirm_m=confirm["confirm_m"],
        confirm_n=confirm["confirm_n"],
        max_speed_mps=_opt_float(track, "max_speed_mps", f"{where}: track", None),
        raw_radar_min_mean_uav_prob=_opt_float(
            evaluation,
            "raw_radar_min_mean_uav_prob",
            f"{where}: evaluation",
            DEFAULT_MIN_MEAN_UAV_PROB,
        ),
        description=str(doc.get("description", "") or ""),
        r_note=str(meas.get("note", "") or ""),
        source=source,
        multi=multi_settings_from_dict(multi, where),
        **extra,
    )
    _validate(p, where)
    return p


def _choice(d: dict[str, Any], key: str, allowed: tuple[str, ...], default: str, at: str) -> str:
    v = str(d.get(key, default))
    if v not in allowed:
        raise ConfigError(
            f"{at}.{key}: {v!r} is not a known component (one of {', '.join(allowed)})"
        )
    return v


def _q3(v: Any, at: str) -> Q3:
    if isinstance(v, int | float) and not isinstance(v, bool):
        v = [v] * 3
    if not isinstance(v, list) or len(v) != 3:
        raise ConfigError(f"{at}: must be a number or a list of 3 numbers")
    q = tuple(_float({"q": x}, "q", at, None) for x in v)
    return (q[0], q[1], q[2])


def _tracker_fields(
    model: str,
    imm: dict[str, Any],
    radar: dict[str, Any],
    rf: dict[str, Any],
    update: dict[str, Any],
    assoc: dict[str, Any],
    smoother: dict[str, Any],
    where: str,
) -> dict[str, Any]:
    """The tracker's component choices (keys absent: the paper's defaults)."""
    out: dict[str, Any] = {"motion_model": model}
    if model == "imm":
        qs = imm.get("q")
        if not isinstance(qs, list) or len(qs) < 2:
            raise ConfigError(f"{where}: motion.imm.q must list one q per mode (at least 2)")
        out["imm_q"] = tuple(_q3(q, f"{where}: motion.imm.q[{i}]") for i, q in enumerate(qs))
        n = len(qs)
        try:
            out["imm_transition"] = validate_transition(
                imm.get("transition"), n, f"{where}: motion.imm.transition"
            )
        except ValueError as exc:
            raise ConfigError(str(exc)) from None
        init = imm.get("initial", [1.0 / n] * n)
        if not isinstance(init, list) or len(init) != n:
            raise ConfigError(f"{where}: motion.imm.initial must list {n} probabilities")
        out["imm_initial"] = tuple(
            _float({"initial": v}, "initial", f"{where}: motion.imm", None) for v in init
        )
    elif imm:
        raise ConfigError(f"{where}: motion.imm is set but motion.model is {model!r}")
    at_r = f"{where}: measurement.radar"
    out["radar_model"] = _choice(radar, "model", RADAR_MODELS, "fixed", at_r)
    for key, name, default in (
        ("sigma_range_m", "radar_sigma_range_m", 1.0),
        ("sigma_az_deg", "radar_sigma_az_deg", 1.5),
        ("sigma_el_deg", "radar_sigma_el_deg", 1.5),
        ("floor_m", "radar_floor_m", 0.0),
        ("low_el_gain", "radar_low_el_gain", 0.0),
        ("low_el_deg", "radar_low_el_deg", 4.0),
        ("az_bias_deg", "radar_az_bias_deg", 0.0),
        ("el_bias_deg", "radar_el_bias_deg", 0.0),
    ):
        out[name] = _float(radar, key, at_r, default)
    if not out["radar_low_el_deg"] > 0:
        raise ConfigError(
            f"{at_r}.low_el_deg must be > 0 (an elevation scale), got {out['radar_low_el_deg']}"
        )
    at_f = f"{where}: measurement.rf"
    out["rf_model"] = _choice(rf, "model", RF_MODELS, "fixed", at_f)
    out["rf_cep_scale"] = _float(rf, "cep_scale", at_f, 1.0)
    out["rf_floor_m"] = _float(rf, "floor_m", at_f, 5.0)
    out["rf_sensor_exponent"] = _float(rf, "sensor_exponent", at_f, 0.0)
    out["rf_max_cep_m"] = _opt_float(rf, "max_cep_m", at_f, None)
    ref = rf.get("ref_sensors", 4)
    if not isinstance(ref, int) or isinstance(ref, bool):
        raise ConfigError(f"{at_f}.ref_sensors: must be an integer, got {ref!r}")
    out["rf_ref_sensors"] = ref
    at_u = f"{where}: update"
    out["robust"] = _choice(update, "robust", ROBUST, "none", at_u)
    out["robust_dof"] = _float(update, "dof", at_u, 4.0)
    out["robust_huber_k"] = _float(update, "huber_k", at_u, 1.5)
    out["vz_hold_after_s"] = _opt_float(update, "vz_hold_after_s", at_u, None)
    out["vz_hold_sigma_mps"] = _float(update, "vz_hold_sigma_mps", at_u, 1.0)
    out["notch_after_s"] = _opt_float(update, "notch_after_s", at_u, None)
    out["notch_sigma_mps"] = _float(update, "notch_sigma_mps", at_u, 1.0)
    out["notch_range_m"] = _float(update, "notch_range_m", at_u, 1000.0)
    mode = _choice(assoc, "mode", ASSOCIATIONS, "largest_track", f"{where}: association")
    if mode == "track_score":
        out["association"] = mode
        vals: dict[str, Any] = {}
        defaults = ScoreConfig()
        for key in score_keys():
            if key in assoc:
                if key == "init_min_reports":
                    v = assoc[key]
                    if not isinstance(v, int) or isinstance(v, bool):
                        raise ConfigError(f"{where}: association.{key} must be an integer")
                    vals[key] = v
                elif key == "class_prior_logit":
                    vals[key] = _opt_float(assoc, key, f"{where}: association", None)
                elif isinstance(getattr(defaults, key), bool):
                    v = assoc[key]
                    if not isinstance(v, bool):
                        raise ConfigError(f"{where}: association.{key} must be true or false")
                    vals[key] = v
                else:
                    vals[key] = _float(assoc, key, f"{where}: association", getattr(defaults, key))
        out["score"] = ScoreConfig(**vals)
    elif len(assoc) > 1:
        raise ConfigError(f"{where}: association score keys need association.mode track_score")
    lag = smoother.get("lag_s")
    if isinstance(lag, float) and lag == float("inf"):
        out["smoother_lag_s"] = lag  # .inf: offline RTS over each track segment
    else:
        out["smoother_lag_s"] = _opt_float(smoother, "lag_s", f"{where}: smoother", None)
    return out


def profile_path(path_or_name: str | Path) -> Path:
    """A profile name (``paper``) maps to ``config/profiles/<name>.yaml``; paths stay paths."""
    s = str(path_or_name)
    p = Path(s)
    if p.suffix in (".yaml", ".yml") or p.is_file() or "/" in s:
        return p
    return config_path(f"profiles/{s}.yaml")


def load_profile(path_or_name: str | Path = "paper") -> Profile:
    """Load a profile by name (``config/profiles/<name>.yaml``) or from a YAML file path."""
    p = profile_path(path_or_name)
    return profile_from_dict(read_yaml_file(p, "profile file"), p)
