"""Worlds: the twin's physics drawn per flight from documented ranges.

A **world family** (``config/worlds.yaml``) is a set of ranges, one per drawn parameter: a
well-calibrated clean site, a misaligned radar mount, heavy multipath, NLOS-heavy RF with an
overconfident CEP, and so on. A **world** is one draw from a family: the values a flight is
generated with. The draw is seeded from the flight's seed (with the family's and the plan's
names, so two flights of one family differ and a flight is reproducible), and every parameter
draws from a stream of its own (adding a parameter to a family leaves the others' draws as
they were).

A drawn parameter is a twin configuration key by its section and name (``radar.az_bias_deg``,
``rf.cep_nlos_weight``, ``classifier.rotating_logit``; any number of a section of
``config/twin_default.yaml`` but ``recording``) or one of the radar site's pointing keys:
``site_radar.boresight_az_offset_deg`` (added to the site's boresight azimuth),
``site_radar.boresight_el_deg``, ``site_radar.fov_az_deg`` and ``site_radar.fov_el_deg``.
A family's ``draw`` mapping gives each parameter as:

* a number: fixed;
* ``[lo, hi]`` or ``{uniform: [lo, hi]}``: uniform;
* ``{log_uniform: [lo, hi]}``: uniform in the logarithm (rates, RCS), ``0 < lo``;
* ``{symmetric: [lo, hi]}``: magnitude uniform in ``[lo, hi]``, sign + or - with equal odds
  (a misalignment);
* ``{choice: [a, b, ...]}``: one of the values, with equal odds.

The file's ``base`` mapping holds the ranges every family draws unless it gives its own.
Drawn values are rounded to 4 decimals (integer keys to integers) before use, so the flight's
``world.yaml`` (:func:`world_doc`) holds exactly the values it was generated with. Keys the
family does not draw keep the twin configuration's value.
"""

from __future__ import annotations

import dataclasses
import math
import zlib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from uav_fusion.core.errors import ConfigError
from uav_fusion.core.site import RadarSite
from uav_fusion.core.twin.config import TwinConfig, validate_twin_config
from uav_fusion.core.yamlio import read_yaml_file
from uav_fusion.resources import config_path

DEFAULT_WORLDS = "worlds.yaml"
WORLD_FILE = "world.yaml"
SITE_RADAR = "site_radar"
SITE_KEYS = ("boresight_az_offset_deg", "boresight_el_deg", "fov_az_deg", "fov_el_deg")
DRAW_KINDS = ("fixed", "uniform", "log_uniform", "symmetric", "choice")
DECIMALS = 4
# the world's random streams: SeedSequence(seed, spawn_key=(_STREAM, family, plan, key)); the
# twin's own streams are spawned from SeedSequence(seed) with small spawn keys
_STREAM = 0x574F524C
# twin sections a world may not draw (times and names of the recording)
_FIXED_SECTIONS = ("recording",)
# keys that may be negative (biases, logits, offsets, elevation); the others stay >= 0
_SIGNED = ("bias", "logit", "offset", "boresight_el")
_SITE_LIMITS = {
    "boresight_az_offset_deg": (-180.0, 180.0),
    "boresight_el_deg": (-90.0, 90.0),
    "fov_az_deg": (1.0, 360.0),
    "fov_el_deg": (1.0, 180.0),
}


@dataclass(frozen=True)
class Draw:
    """How one parameter is drawn (see the module text)."""

    kind: str
    values: tuple[float, ...]

    def sample(self, rng: np.random.Generator) -> float:
        if self.kind == "fixed":
            return self.values[0]
        if self.kind == "choice":
            return self.values[int(rng.integers(0, len(self.values)))]
        lo, hi = self.values
        if self.kind == "log_uniform":
            return math.exp(float(rng.uniform(math.log(lo), math.log(hi))))
        x = float(rng.uniform(lo, hi))
        if self.kind == "symmetric" and rng.random() < 0.5:
            return -x
        return x

    @property
    def bounds(self) -> tuple[float, float]:
        """The smallest and the largest value the draw can give."""
        if self.kind == "symmetric":
            return -self.values[1], self.values[1]
        return min(self.values), max(self.values)

    def describe(self) -> str:
        """The range in words, as docs/twin.md writes it."""
        if self.kind == "fixed":
            return f"{self.values[0]:g}"
        if self.kind == "choice":
            return "one of " + ", ".join(f"{v:g}" for v in self.values)
        lo, hi = self.values
        if self.kind == "symmetric":
            return f"±({lo:g}–{hi:g})"
        return f"{lo:g}–{hi:g}" + (" (log-uniform)" if self.kind == "log_uniform" else "")


@dataclass(frozen=True)
class WorldFamily:
    """A set of ranges: the base's, with the family's own in their place."""

    name: str
    description: str
    draws: dict[str, Draw]  # by key, sorted
    source: Path


@dataclass(frozen=True)
class WorldFamilies:
    families: dict[str, WorldFamily]
    source: Path

    def family(self, name: str) -> WorldFamily:
        if name not in self.families:
            raise ConfigError(
                f"{self.source}: unknown world family {name!r} "
                f"(known: {', '.join(self.families)})"
            )
        return self.families[name]


@dataclass(frozen=True)
class World:
    """One draw of a family: the values one flight is generated with."""

    family: str
    description: str
    seed: int
    plan: str
    values: dict[str, float | int]  # by key, sorted
    source: str  # the families file's name


def _default_value(key: str) -> float | int | None:
    """The twin configuration's default for ``section.field``, or None if it is not a number
    a world may draw."""
    section, _, name = key.partition(".")
    if section == SITE_RADAR:
        return 0.0 if name in SITE_KEYS else None
    if section in _FIXED_SECTIONS:
        return None
    sections = {f.name for f in dataclasses.fields(TwinConfig)}
    if section not in sections or section in ("seed", "source"):
        return None
    value = getattr(getattr(TwinConfig(), section), name, None)
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return None
    return value


def drawable_keys() -> list[str]:
    """Every key a world may draw."""
    out = [f"{SITE_RADAR}.{k}" for k in SITE_KEYS]
    cfg = TwinConfig()
    for f in dataclasses.fields(TwinConfig):
        sec = getattr(cfg, f.name)
        if f.name in _FIXED_SECTIONS or not dataclasses.is_dataclass(sec):
            continue
        for g in dataclasses.fields(sec):
            if _default_value(f"{f.name}.{g.name}") is not None:
                out.append(f"{f.name}.{g.name}")
    return out


def _number(v: Any, where: str) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        raise ConfigError(f"{where}: expected a finite number, got {v!r}")
    return float(v)


def _draw(raw: Any, where: str) -> Draw:
    if isinstance(raw, (int, float)) and not isinstance(raw, bool):
        return Draw("fixed", (_number(raw, where),))
    kind = "uniform"
    body = raw
    if isinstance(raw, dict):
        if len(raw) != 1:
            raise ConfigError(
                f"{where}: expected one of {', '.join(DRAW_KINDS[1:])} with its values, got {raw!r}"
            )
        kind, body = next(iter(raw.items()))
        if kind not in DRAW_KINDS[1:]:
            raise ConfigError(
                f"{where}: unknown draw {kind!r} (known: {', '.join(DRAW_KINDS[1:])})"
            )
    if not isinstance(body, list) or not body:
        raise ConfigError(f"{where}: expected a number, [lo, hi] or a mapping such as "
                          f"{{log_uniform: [lo, hi]}}, got {raw!r}")
    values = tuple(_number(v, f"{where}[{i}]") for i, v in enumerate(body))
    if kind != "choice":
        if len(values) != 2 or not values[0] <= values[1]:
            raise ConfigError(f"{where}: expected [lo, hi] with lo <= hi, got {body!r}")
        if kind == "log_uniform" and not values[0] > 0:
            raise ConfigError(f"{where}: a log-uniform range needs lo > 0, got {body!r}")
        if kind == "symmetric" and values[0] < 0:
            raise ConfigError(f"{where}: a symmetric range gives magnitudes: lo >= 0, got {body!r}")
    return Draw(kind, values)


def _check_key(key: Any, draw: Draw, where: str) -> None:
    if not isinstance(key, str) or _default_value(key) is None:
        raise ConfigError(
            f"{where}: unknown world parameter {key!r} (a number of a twin configuration "
            f"section as section.key, e.g. radar.az_bias_deg, or site_radar."
            f"{{{','.join(SITE_KEYS)}}})"
        )
    lo, hi = draw.bounds
    section, _, name = key.partition(".")
    if section == SITE_RADAR:
        a, b = _SITE_LIMITS[name]
        if lo < a or hi > b:
            raise ConfigError(f"{where}: {key} must lie in [{a:g}, {b:g}], the range reaches "
                              f"[{lo:g}, {hi:g}]")
    elif lo < 0 and not any(s in name for s in _SIGNED):
        raise ConfigError(f"{where}: {key} must be >= 0, the range reaches {lo:g}")


def worlds_from_dict(doc: Any, source: Path) -> WorldFamilies:
    """Validate a parsed families file; errors name the file, the family and the key."""
    src = str(source)
    if not isinstance(doc, dict):
        raise ConfigError(f"{src}: expected a mapping at top level")
    unknown = sorted(set(doc) - {"base", "families"})
    if unknown:
        raise ConfigError(f"{src}: unknown key(s) {', '.join(unknown)} (allowed: base, families)")
    base_raw = doc.get("base") or {}
    if not isinstance(base_raw, dict):
        raise ConfigError(f"{src}: base: expected a mapping of parameter -> range")
    base: dict[str, Draw] = {}
    for k, v in base_raw.items():
        base[k] = _draw(v, f"{src}: base.{k}")
        _check_key(k, base[k], f"{src}: base")
    fams_raw = doc.get("families")
    if not isinstance(fams_raw, dict) or not fams_raw:
        raise ConfigError(f"{src}: families: expected a mapping of family name -> family")
    families: dict[str, WorldFamily] = {}
    for name, body in fams_raw.items():
        where = f"{src}: families.{name}"
        if not isinstance(name, str) or not name.replace("_", "").isalnum():
            raise ConfigError(f"{where}: a family name is letters, digits and '_'")
        if not isinstance(body, dict):
            raise ConfigError(f"{where}: expected a mapping with description and draw")
        extra = sorted(set(body) - {"description", "draw"})
        if extra:
            raise ConfigError(f"{where}: unknown key(s) {', '.join(extra)} "
                              "(allowed: description, draw)")
        own_raw = body.get("draw") or {}
        if not isinstance(own_raw, dict):
            raise ConfigError(f"{where}.draw: expected a mapping of parameter -> range")
        draws = dict(base)
        for k, v in own_raw.items():
            draws[k] = _draw(v, f"{where}.draw.{k}")
            _check_key(k, draws[k], f"{where}.draw")
        fam = WorldFamily(
            name, str(body.get("description", "") or "").strip(),
            dict(sorted(draws.items())), source,
        )  # fmt: skip
        _check_corners(fam, where)
        families[name] = fam
    return WorldFamilies(families, source)


def _check_corners(fam: WorldFamily, where: str) -> None:
    """Every parameter at the low and at the high end of its range makes a valid twin."""
    cfg = TwinConfig()
    for end in (0, 1):
        values = {k: d.bounds[end] for k, d in fam.draws.items()}
        world = World(fam.name, "", 0, "", values, "")
        try:
            validate_twin_config(apply_config(world, cfg), f"{where} (every range at its "
                                 f"{'low' if end == 0 else 'high'} end)")
        except (TypeError, ValueError) as exc:
            raise ConfigError(f"{where}: {exc}") from None


def load_worlds(path: str | Path | None = None) -> WorldFamilies:
    """Load the world families (default: the shipped ``config/worlds.yaml``)."""
    p = Path(path) if path is not None else config_path(DEFAULT_WORLDS)
    return worlds_from_dict(read_yaml_file(p, "world families file"), p)


def _crc(text: str) -> int:
    return zlib.crc32(text.encode("utf-8"))


def draw_world(family: WorldFamily, seed: int, plan: str) -> World:
    """The world of the flight of ``plan`` with ``seed`` in ``family`` (deterministic)."""
    if seed < 0:
        raise ConfigError(f"seed must be >= 0, got {seed}")
    values: dict[str, float | int] = {}
    for key, d in family.draws.items():
        ss = np.random.SeedSequence(
            seed, spawn_key=(_STREAM, _crc(family.name), _crc(plan), _crc(key))
        )
        x = d.sample(np.random.default_rng(ss))
        default = _default_value(key)
        values[key] = round(x) if isinstance(default, int) else round(x, DECIMALS) + 0.0
    return World(family.name, family.description, seed, plan, values, family.source.name)


def apply_config(world: World, cfg: TwinConfig) -> TwinConfig:
    """``cfg`` with the world's twin configuration values."""
    by_section: dict[str, dict[str, float | int]] = {}
    for key, v in world.values.items():
        section, _, name = key.partition(".")
        if section != SITE_RADAR:
            by_section.setdefault(section, {})[name] = v
    changes = {
        sec: dataclasses.replace(getattr(cfg, sec), **kv) for sec, kv in by_section.items()
    }
    return dataclasses.replace(cfg, **changes) if changes else cfg


def apply_site(world: World, radar: RadarSite) -> RadarSite:
    """The radar site with the world's pointing and field of view."""
    v = {k.partition(".")[2]: x for k, x in world.values.items() if k.startswith(SITE_RADAR + ".")}
    if not v:
        return radar
    return dataclasses.replace(
        radar,
        boresight_az_deg=(radar.boresight_az_deg + float(v.get("boresight_az_offset_deg", 0.0)))
        % 360.0,
        boresight_el_deg=float(v.get("boresight_el_deg", radar.boresight_el_deg)),
        fov_az_deg=float(v.get("fov_az_deg", radar.fov_az_deg)),
        fov_el_deg=float(v.get("fov_el_deg", radar.fov_el_deg)),
    )


def world_doc(world: World, cfg: TwinConfig, radar: RadarSite) -> dict[str, Any]:
    """The flight's ``world.yaml``: the family, the drawn values, and the radar's true mount
    (``cfg`` and ``radar`` as the flight was generated with: the world applied)."""
    return {
        "family": world.family,
        "description": world.description,
        "seed": world.seed,
        "plan": world.plan,
        "families_file": world.source,
        "drawn": dict(world.values),
        # a report's azimuth (elevation) is the true one plus the bias, seen from the radar
        "radar_mount": {
            "az_bias_deg": cfg.radar.az_bias_deg,
            "el_bias_deg": cfg.radar.el_bias_deg,
            "boresight_az_deg": radar.boresight_az_deg,
            "boresight_el_deg": radar.boresight_el_deg,
            "fov_az_deg": radar.fov_az_deg,
            "fov_el_deg": radar.fov_el_deg,
        },
    }


def write_world(doc: dict[str, Any], path: Path) -> Path:
    head = (
        "# The world this flight was generated in: its family, every drawn parameter and the\n"
        "# radar's true mount (uav_fusion/core/twin/worlds.py, docs/twin.md \"Worlds\").\n"
    )
    path.write_text(head + yaml.safe_dump(doc, sort_keys=False), encoding="utf-8")
    return path


def read_world(folder: str | Path) -> dict[str, Any] | None:
    """A flight folder's ``world.yaml`` (None when the flight was not generated in a world)."""
    p = Path(folder) / WORLD_FILE
    if not p.is_file():
        return None
    doc = read_yaml_file(p, "world file")
    if not isinstance(doc, dict) or "drawn" not in doc or "radar_mount" not in doc:
        raise ConfigError(f"{p}: not a world file (drawn and radar_mount expected)")
    return doc
