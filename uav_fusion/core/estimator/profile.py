"""Estimator profiles: every tunable choice of the filter, loaded from YAML.

A profile names the motion model's process noise, the measurement covariances, the gates, the
radar track handling and the track life-cycle rules. ``config/profiles/paper.yaml`` is the
paper's estimator; other files in that folder (or any path) can be loaded the same way.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from uav_fusion.core.errors import ConfigError
from uav_fusion.core.radar_class import DEFAULT_MIN_MEAN_UAV_PROB
from uav_fusion.core.records import RADAR, RF
from uav_fusion.core.yamlio import read_yaml_file
from uav_fusion.resources import config_path

FloatArray = npt.NDArray[np.float64]

SELECTIONS = ("largest_track", "online")
SOURCES = (RADAR, RF)


@dataclass(frozen=True)
class Profile:
    """The estimator's configuration (see ``config/profiles/README.md`` for each key)."""

    name: str
    q: tuple[float, float, float]  # CWNA spectral density per axis, m^2/s^3
    r_radar: FloatArray  # 3x3, m^2
    r_rf: FloatArray  # 2x2, m^2
    range_gate_m: float | None = 800.0  # None: the site's radar.range_gate_m
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
    # the raw radar row's UAV-track rule (core/radar_class.py)
    raw_radar_min_mean_uav_prob: float | None = DEFAULT_MIN_MEAN_UAV_PROB
    description: str = ""
    r_note: str = ""
    source: Path | None = field(default=None, compare=False)

    def with_changes(self, **changes: Any) -> Profile:
        """A copy with some fields replaced (validated again)."""
        p = replace(self, **changes)
        _validate(p, str(self.source or self.name))
        return p

    def as_dict(self) -> dict[str, Any]:
        """The profile as the YAML document :func:`profile_from_dict` reads."""
        return {
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
    ),
    "motion": ("model", "q"),
    "measurement": ("radar", "rf", "note"),
    "measurement.radar": ("R",),
    "measurement.rf": ("R",),
    "gating": ("range_gate_m", "nis_probability", "min_uav_prob"),
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


def profile_from_dict(doc: Any, source: Path | None = None) -> Profile:
    """Build and validate a :class:`Profile` from a parsed YAML document."""
    where = str(source) if source else "<profile>"
    if not isinstance(doc, dict):
        raise ConfigError(f"{where}: expected a mapping at top level")
    _check_keys(doc, "", where)
    motion = _section(doc, "motion", where)
    model = str(motion.get("model", "cv"))
    if model != "cv":
        raise ConfigError(f"{where}: motion.model {model!r} is not supported (only 'cv')")
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
    for name, sec in (
        ("motion", motion),
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
    p = Profile(
        name=str(doc.get("name", source.stem if source else "profile")),
        q=(q[0], q[1], q[2]),
        r_radar=_matrix(radar["R"], 3, f"{where}: measurement.radar.R"),
        r_rf=_matrix(rf["R"], 2, f"{where}: measurement.rf.R"),
        range_gate_m=_opt_float(gating, "range_gate_m", f"{where}: gating", 800.0),
        nis_probability=_float(gating, "nis_probability", f"{where}: gating", 0.95),
        min_uav_prob=min_prob,
        radar_selection=str(doc.get("radar_selection", "largest_track")),
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
    )
    _validate(p, where)
    return p


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
