"""Estimator profiles: every tunable choice of the filter, loaded from YAML.

A profile names the estimator (``estimator: paper | tracker | multi``), the motion model's
process noise, the measurement covariances, the gates, the radar track handling, the track
life-cycle rules and, for the trackers, the UAV score of each radar object.
``config/profiles/paper.yaml`` is the paper's estimator; other files in that folder (or any
path) load the same way, and a profile may extend another (``inherit.py``). Every key, with
its type, bounds and meaning, is in the schema (``schema.py``), which the loader checks
against; the defaults are those of :class:`Profile`, :class:`ScoreConfig` and
:class:`MultiSettings`.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import MISSING, dataclass, field, fields, replace
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from uav_fusion.core.data.uav_class import DEFAULT_MIN_MEAN_UAV_PROB
from uav_fusion.core.errors import ConfigError
from uav_fusion.core.profiles.checks import (
    MULTI,
    PAPER,
    TRACKER,
    Key,
    check,
    convert,
    validate_transition,
)
from uav_fusion.core.profiles.inherit import profile_path, resolve, unknown_key
from uav_fusion.core.profiles.schema import BY_PATH, KEYS, find
from uav_fusion.core.profiles.settings import MultiSettings, ScoreConfig
from uav_fusion.core.records import RADAR, RF
from uav_fusion.core.yamlio import read_yaml_file

__all__ = ["SELECTIONS", "Profile", "load_profile", "profile_from_dict", "profile_path"]

FloatArray = npt.NDArray[np.float64]

SELECTIONS = BY_PATH["radar_selection"].choices
Q3 = tuple[float, float, float]
_IMM = ("motion.imm.q", "motion.imm.transition", "motion.imm.initial")


@dataclass(frozen=True)
class Profile:
    """The estimator's configuration (each key: ``schema.py``, ``config/profiles/README.md``)."""

    name: str
    q: tuple[float, float, float]  # CWNA spectral density per axis, m^2/s^3
    # 3x3 and 2x2, m^2; None: a tracker profile's polar radar model, and its RF fixes' CEP
    # (a fix without one counts as max_cep_m)
    r_radar: FloatArray | None = None
    r_rf: FloatArray | None = None
    range_gate_m: float | None = 800.0  # None: the site's radar.range_gate_m
    far_gate_m: float | None = None  # horizontal-only radar updates out to this range
    nis_probability: float = 0.95
    min_uav_prob: float | None = None
    radar_selection: str = "largest_track"
    use_radar: bool = True
    use_rf: bool = True
    init_sources: tuple[str, ...] = (RADAR, RF)
    rf_init_altitude_m: float = 40.0  # ENU up (+- as much) when an RF fix starts a track
    max_consecutive_rejections: int | None = None
    max_coast_s: float | None = None
    tentative_sources: tuple[str, ...] = ()
    confirm_m: int = 1  # a tentative track is confirmed by confirm_m hits ...
    confirm_n: int = 1  # ... among its first confirm_n measurements (the start included)
    max_speed_mps: float = 30.0  # a small UAV's top speed (tentative hits, start velocity)
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
    adaptive_window: int | None = None  # online R from the innovations over this many
    adaptive_bound: float = 2.0  # ... within [spec / bound, spec * bound]
    rf_model: str = "fixed"  # fixed (r_rf) | cep
    rf_cep_scale: float = 1.0
    rf_floor_m: float = 5.0
    rf_max_cep_m: float | None = None  # RF fixes with a larger CEP are discarded
    # no radar update for this long: pseudo-measurements hold what the radar no longer
    # measures (RF fixes: climb rate 0; inside the 3D range gate: radial speed 0, a hover in
    # the Doppler notch); None: never
    hold_after_s: float | None = None
    hold_sigma_mps: float = 1.0  # their standard deviation, and a new track's climb rate's
    estimator: str = "paper"  # paper | tracker | multi
    score: ScoreConfig = field(default_factory=ScoreConfig)
    smoother_lag_s: float | None = None  # fixed-lag smoothing of the tracker's steps
    # the multi-UAV tracker's own settings (the ``multi`` section; multi_settings.py)
    multi: MultiSettings = field(default_factory=MultiSettings)
    source: Path | None = field(default=None, compare=False)

    def __post_init__(self) -> None:
        # the trackers' RF evidence lasts as long as a track may coast (schema.DERIVED; a
        # tracker profile must set max_coast_s, the paper's estimator reads no RF support)
        tau = math.inf if self.max_coast_s is None else float(self.max_coast_s)
        # and an object needs as many reports to start a track as a tentative track needs hits
        # to be confirmed (track.confirm_m)
        if (self.score.rf_tau_s, self.score.init_min_reports) != (tau, self.confirm_m):
            score = replace(self.score, rf_tau_s=tau, init_min_reports=self.confirm_m)
            object.__setattr__(self, "score", score)

    @property
    def init_velocity_std_mps(self) -> float:
        """A new track's velocity standard deviation per axis: half the top speed, so that
        the top speed lies at 2 sigma."""
        return 0.5 * self.max_speed_mps

    @property
    def rf_init_altitude_std_m(self) -> float:
        """The standard deviation of a 2D RF start's height: as large as the height itself
        (the fix says only that the UAV is above the ground)."""
        return self.rf_init_altitude_m

    @property
    def uses_tracker(self) -> bool:
        """Run by a tracker (every radar object scored) rather than the paper's
        :class:`~uav_fusion.core.estimators.paper.FusionEstimator`."""
        return self.estimator != "paper"

    def with_changes(self, **changes: Any) -> Profile:
        """A copy with some fields replaced (validated again)."""
        p = replace(self, **changes)
        _validate(p, str(self.source or self.name))
        return p

    def with_keys(self, values: Mapping[str, Any]) -> Profile:
        """A copy with some keys set by their YAML path (``gating.nis_probability``,
        ``association.object.tau_s``, ``multi.merge_s``), each value as
        :func:`~uav_fusion.core.profiles.checks.convert` gives it (validated again)."""
        changes: dict[str, Any] = {}
        parts: dict[str, dict[str, Any]] = {"score": {}, "multi": {}}
        for path, value in values.items():
            key = find(path)
            if key is None or not key.attr:
                raise unknown_key(path, str(self.source or self.name))
            owner, _, name = key.attr.rpartition(".")
            (parts[owner] if owner else changes)[name] = value
        for owner, vals in parts.items():
            if vals:
                changes[owner] = replace(getattr(self, owner), **vals)
        return self.with_changes(**changes)

    def as_dict(self) -> dict[str, Any]:
        """The profile as the YAML document :func:`profile_from_dict` reads (resolved: no
        ``extends``)."""
        out: dict[str, Any] = {}
        for key in KEYS:
            if key.attr and self._writes(key):
                *sections, name = key.path.split(".")
                d = out
                for s in sections:
                    d = d.setdefault(s, {})
                d[name] = _plain(value_of(self, key))
        return out

    def _writes(self, key: Key) -> bool:
        """``as_dict`` writes a key the estimator reads, and any other that is not at its
        default (so that the document loads back into the same profile)."""
        if key.path in _IMM:
            return self.motion_model == "imm"
        if key.used_by == MULTI:
            return self.uses_tracker or self.multi != MultiSettings()
        if key.used_by == PAPER:
            return not self.uses_tracker
        if key.used_by == TRACKER and not self.uses_tracker:
            return bool(_plain(value_of(self, key)) != _plain(default_of(key)))
        return True


def _plain(v: Any) -> Any:
    """A value as YAML writes it (tuples and arrays as lists)."""
    if isinstance(v, np.ndarray):
        return v.tolist()
    if isinstance(v, tuple):
        return [_plain(x) for x in v]
    return v


def value_of(p: Profile, key: Key) -> Any:
    """The value of ``key`` in a profile."""
    obj: Any = p
    for part in key.attr.split("."):
        obj = getattr(obj, part)
    return obj


_HOLDERS: dict[str, Any] = {"": Profile, "score": ScoreConfig, "multi": MultiSettings}


def default_of(key: Key) -> Any:
    """The default of ``key``: its dataclass field's (``MISSING`` for a required key)."""
    owner, _, name = key.attr.rpartition(".")
    f = {f.name: f for f in fields(_HOLDERS[owner])}[name]
    if f.default_factory is not MISSING:
        return f.default_factory()
    return f.default


def profile_from_dict(doc: Any, source: Path | None = None) -> Profile:
    """Build and validate a :class:`Profile` from a parsed YAML document (merged over the
    profiles it extends, :mod:`~uav_fusion.core.profiles.inherit`)."""
    res = resolve(doc, source)
    return _build(res.doc, source, res.origin)


def load_profile(path_or_name: str | Path = "paper") -> Profile:
    """Load a profile by name (``config/profiles/<name>.yaml``) or from a YAML file path."""
    p = profile_path(path_or_name)
    return profile_from_dict(read_yaml_file(p, "profile file"), p)


def profile_files(path_or_name: str | Path) -> tuple[Path, ...]:
    """A profile's file and the files it extends: what the profile's values depend on."""
    p = profile_path(path_or_name)
    return resolve(read_yaml_file(p, "profile file"), p).files


def _lookup(doc: dict[str, Any], path: str) -> tuple[bool, Any]:
    """Whether ``path`` is set in ``doc`` (a section set to null holds nothing), and its value."""
    *sections, name = path.split(".")
    d: Any = doc
    for s in sections:
        d = d.get(s)
        if not isinstance(d, dict):
            return False, None
    return name in d, d.get(name)


def _build(doc: dict[str, Any], source: Path | None, origin: dict[str, str]) -> Profile:
    where = str(source) if source else "<profile>"

    def at(path: str) -> str:  # the file that set a key (a parent's, for an inherited one)
        return origin.get(path, where)

    vals: dict[str, dict[str, Any]] = {"": {}, "score": {}, "multi": {}}
    for key in KEYS:
        present, raw = _lookup(doc, key.path)
        if key.attr and key.path not in _IMM and present:
            owner, _, name = key.attr.rpartition(".")
            vals[owner][name] = convert(key, raw, at(key.path))
    top = vals[""]
    for key in KEYS:
        if key.attr and key.path not in _IMM and default_of(key) is MISSING:
            if key.attr == "name":
                top["name"] = top.get("name") or (source.stem if source else "profile")
            elif key.attr not in top:
                raise ConfigError(
                    f"{where}: {key.path} is required (here or in a profile this one extends)"
                )
    for text in ("description", "r_note"):
        top[text] = top.get(text) or ""
    estimator = top.get("estimator", "paper")
    check(BY_PATH["estimator"], estimator, at("estimator"))
    if estimator == "paper":
        assoc = [k for k in origin if k.startswith("association.") and _lookup(doc, k)[0]]
        if assoc:
            raise ConfigError(
                f"{at(assoc[0])}: {assoc[0]} needs 'estimator: tracker' or 'multi' (the "
                "paper's estimator scores no radar objects)"
            )
    else:
        if top.get("radar_selection") is not None:
            raise ConfigError(
                f"{at('radar_selection')}: radar_selection and 'estimator: {estimator}' "
                "exclude each other (a tracker takes every radar report)"
            )
        top["radar_selection"] = "online"
    top.update(_imm_fields(doc, top.get("motion_model", "cv"), at))
    p = Profile(
        **top,
        score=ScoreConfig(**vals["score"]),
        multi=MultiSettings(**vals["multi"]),
        source=source,
    )
    _validate(p, where, origin)
    return p


def _imm_fields(doc: dict[str, Any], model: str, at: Callable[[str], str]) -> dict[str, Any]:
    """The IMM's modes (``motion.imm``), read only with ``motion.model: imm``."""
    present, imm = _lookup(doc, "motion.imm")
    if model != "imm":
        if present and imm:
            raise ConfigError(
                f"{at('motion.imm')}: motion.imm is set but motion.model is {model!r}"
            )
        return {}
    out: dict[str, Any] = {}
    qs = _lookup(doc, "motion.imm.q")[1]
    if not isinstance(qs, list) or len(qs) < 2:
        raise ConfigError(
            f"{at('motion.imm.q')}: motion.imm.q must list one q per mode (at least 2)"
        )
    for path in _IMM:
        has, raw = _lookup(doc, path)
        if has:
            out[BY_PATH[path].attr] = convert(BY_PATH[path], raw, at(path))
    out.setdefault("imm_transition", None)  # required: validate_transition says so
    out.setdefault("imm_initial", (1.0 / len(qs),) * len(qs))
    return out


def _validate(p: Profile, where: str, origin: Mapping[str, str] | None = None) -> None:
    """Every key against the schema (type, bounds, choices), then the rules between keys."""
    origin = origin or {}
    for key in KEYS:
        if key.attr and key.path not in _IMM:
            check(key, value_of(p, key), origin.get(key.path, where))
    if p.motion_model == "imm":
        _validate_imm(p, origin.get("motion.imm.q", where))
    if p.far_gate_m is not None:
        if p.range_gate_m is not None and not p.far_gate_m > p.range_gate_m:
            raise ConfigError(
                f"{where}: gating.far_gate_m ({p.far_gate_m:g}) must exceed "
                f"gating.range_gate_m ({p.range_gate_m:g})"
            )
        if not p.uses_tracker:
            raise ConfigError(f"{where}: gating.far_gate_m needs 'estimator: tracker' or 'multi'")
    if p.smoother_lag_s is not None and not p.uses_tracker:
        raise ConfigError(f"{where}: smoother.lag_s needs 'estimator: tracker' or 'multi'")
    if not p.confirm_m <= p.confirm_n:
        raise ConfigError(
            f"{where}: track.confirm_m and confirm_n need 1 <= confirm_m <= confirm_n, "
            f"got {p.confirm_m} and {p.confirm_n}"
        )
    if p.adaptive_window is not None and p.radar_model == "polar" and p.radar_floor_m:
        raise ConfigError(
            f"{origin.get('measurement.radar.floor_m', where)}: measurement.radar.floor_m "
            f"({p.radar_floor_m:g}) must be 0 with measurement.adaptive (the online R "
            "replaces the floor)"
        )
    if p.adaptive_window is not None and p.radar_model == "polar" and min(
        p.radar_sigma_range_m, p.radar_sigma_az_deg, p.radar_sigma_el_deg
    ) <= 0:
        raise ConfigError(
            f"{origin.get('measurement.radar.sigma_az_deg', where)}: measurement.radar: "
            "with measurement.adaptive, sigma_range_m, sigma_az_deg and sigma_el_deg are the "
            "specification the online sigmas are bounded around, so each must be > 0"
        )
    if p.r_radar is None and (not p.uses_tracker or p.radar_model == "fixed"):
        raise ConfigError(
            f"{where}: measurement.radar.R is needed (by the paper's estimator and by the "
            "fixed radar model)"
        )
    if p.r_rf is None and (not p.uses_tracker or p.rf_model == "fixed" or p.rf_max_cep_m is None):
        raise ConfigError(
            f"{where}: measurement.rf.R is needed (by the paper's estimator, the fixed RF "
            "model, and the CEP model without max_cep_m: a fix without a CEP)"
        )
    if p.uses_tracker and p.max_coast_s is None:
        raise ConfigError(
            f"{origin.get('track.max_coast_s', where)}: track.max_coast_s is needed by "
            f"'estimator: {p.estimator}': it is also how long RF evidence lasts (an object's "
            "RF support, a fix waiting for an object)"
        )
    if p.radar_model == "polar" and p.radar_sigma_range_m + p.radar_floor_m <= 0:
        raise ConfigError(
            f"{where}: measurement.radar: the polar R needs sigma_range_m or floor_m > 0"
        )


def _validate_imm(p: Profile, where: str) -> None:
    n = len(p.imm_q)
    if n < 2:
        raise ConfigError(f"{where}: motion.imm.q needs at least 2 modes")
    check(BY_PATH["motion.imm.q"], p.imm_q, where)
    try:
        validate_transition(p.imm_transition, n, f"{where}: motion.imm.transition")
    except ValueError as exc:
        raise ConfigError(str(exc)) from None
    init = p.imm_initial
    if len(init) != n or any(not v >= 0 for v in init) or not abs(sum(init) - 1.0) <= 1e-9:
        raise ConfigError(
            f"{where}: motion.imm.initial must be {n} probabilities >= 0 summing to 1"
        )
