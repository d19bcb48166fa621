"""Site geometry: towers, radar, RF sensor set, take-off point, clock offsets, ENU frame.

Loaded from a YAML file (see ``config/site_lake_wheeler.yaml``); no site fact lives in code.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
import pymap3d

from uav_fusion.core.errors import ConfigError
from uav_fusion.core.yamlio import read_yaml_file
from uav_fusion.resources import DEFAULT_SITE, config_path

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True)
class Tower:
    name: str
    lat: float
    lon: float
    ground_h: float
    antenna_agl: float
    enu: tuple[float, float, float]  # ENU of the antenna


#: Largest mounting misalignment a site file may state (degrees).
MAX_BIAS_DEG = 10.0
CALIBRATION_KEYS = ("az_bias_deg", "el_bias_deg", "az_sigma_deg", "el_sigma_deg", "note")


@dataclass(frozen=True)
class RadarCalibration:
    """The radar mount's measured misalignment (what a report's azimuth and elevation read
    above the truth) and how well it is known (one-sigma). A deployment's calibration: the
    trackers correct every report by it and refine the azimuth online from RF fixes
    (:mod:`uav_fusion.core.estimators.registration`); ``uav_fusion calibrate --write-site``
    measures it from a flight with truth. Uncalibrated: 0 +- 1 degree; a sigma of 0 says the
    value is known exactly (a surveyed mount) and is not refined online."""

    az_bias_deg: float = 0.0
    el_bias_deg: float = 0.0
    az_sigma_deg: float = 1.0
    el_sigma_deg: float = 1.0
    note: str = ""


@dataclass(frozen=True)
class RadarSite:
    tower: str
    lat: float
    lon: float
    ground_h: float
    mast_agl: float
    boresight_az_deg: float
    boresight_el_deg: float
    fov_az_deg: float
    fov_el_deg: float
    range_gate_m: float
    enu: tuple[float, float, float]  # ENU of the radar's phase centre
    calibration: RadarCalibration = RadarCalibration()

    @property
    def h(self) -> float:
        """Ellipsoidal height of the radar antenna."""
        return self.ground_h + self.mast_agl


@dataclass(frozen=True)
class Site:
    name: str
    frame_id: str
    lat0: float
    lon0: float
    h0: float
    towers: dict[str, Tower]
    radar: RadarSite
    rf_sensors: tuple[str, ...]
    takeoff_lat: float
    takeoff_lon: float
    takeoff_h: float
    clock_offsets_h: dict[str, float] = field(default_factory=dict)
    source: Path | None = None

    def calibrated(self, cal: RadarCalibration) -> Site:
        """This site with the radar mount's calibration ``cal``."""
        return replace(self, radar=replace(self.radar, calibration=cal))

    # --- geodesy -------------------------------------------------------------------------
    def to_enu(self, lat: Any, lon: Any, h: Any) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Geodetic (deg, deg, m HAE) to ENU metres about the site origin (arrays welcome)."""
        e, n, u = pymap3d.geodetic2enu(
            np.asarray(lat, dtype=float),
            np.asarray(lon, dtype=float),
            np.asarray(h, dtype=float),
            self.lat0,
            self.lon0,
            self.h0,
        )
        return np.asarray(e, float), np.asarray(n, float), np.asarray(u, float)

    def to_geodetic(self, e: Any, n: Any, u: Any) -> tuple[FloatArray, FloatArray, FloatArray]:
        """ENU metres about the site origin to geodetic (deg, deg, m HAE)."""
        lat, lon, h = pymap3d.enu2geodetic(
            np.asarray(e, dtype=float),
            np.asarray(n, dtype=float),
            np.asarray(u, dtype=float),
            self.lat0,
            self.lon0,
            self.h0,
        )
        return np.asarray(lat, float), np.asarray(lon, float), np.asarray(h, float)

    def clock_offset_s(self, source: str) -> float:
        """Seconds to add to UTC to obtain ``source``'s clock reading (0 if not configured)."""
        return 3600.0 * float(self.clock_offsets_h.get(source, 0.0))

    def rf_sensor_towers(self) -> list[Tower]:
        return [self.towers[n] for n in self.rf_sensors]


def _need(d: dict[str, Any], key: str, where: str) -> Any:
    if not isinstance(d, dict) or key not in d:
        raise ConfigError(f"{where}: missing key '{key}'")
    return d[key]


def _num(d: dict[str, Any], key: str, where: str) -> float:
    v = _need(d, key, where)
    try:
        x = float(v)
    except (TypeError, ValueError):
        raise ConfigError(f"{where}: '{key}' must be a number, got {v!r}") from None
    except OverflowError:  # an integer beyond the float range
        raise ConfigError(f"{where}: '{key}' must be finite, got a number beyond 1e308") from None
    if not np.isfinite(x):
        raise ConfigError(f"{where}: '{key}' must be finite, got {v!r}")
    return x


def _latlon(d: dict[str, Any], where: str) -> tuple[float, float]:
    lat, lon = _num(d, "lat", where), _num(d, "lon", where)
    if not -90.0 <= lat <= 90.0:
        raise ConfigError(f"{where}: lat {lat} outside [-90, 90]")
    if not -180.0 <= lon <= 180.0:
        raise ConfigError(f"{where}: lon {lon} outside [-180, 180]")
    return lat, lon


def _calibration(d: Any, where: str) -> RadarCalibration:
    """``radar.calibration`` (absent: uncalibrated)."""
    if d is None:
        return RadarCalibration()
    if not isinstance(d, dict):
        raise ConfigError(f"{where}: must be a mapping of {', '.join(CALIBRATION_KEYS)}")
    for k in d:
        if k not in CALIBRATION_KEYS:
            raise ConfigError(
                f"{where}: unknown key '{k}' (allowed: {', '.join(CALIBRATION_KEYS)})"
            )
    base = RadarCalibration()
    vals: dict[str, float] = {}
    for key in CALIBRATION_KEYS[:4]:
        v = _num(d, key, where) if key in d else float(getattr(base, key))
        if key.endswith("bias_deg") and not abs(v) <= MAX_BIAS_DEG:
            raise ConfigError(
                f"{where}.{key}: a mounting misalignment of at most {MAX_BIAS_DEG:g} degrees, "
                f"got {v}"
            )
        if key.endswith("sigma_deg") and not 0.0 <= v <= MAX_BIAS_DEG:
            raise ConfigError(
                f"{where}.{key}: must lie in [0, {MAX_BIAS_DEG:g}] (0: known exactly), got {v}"
            )
        vals[key] = v
    return RadarCalibration(note=str(d.get("note", "") or ""), **vals)


def site_from_dict(doc: dict[str, Any], source: Path | None = None) -> Site:
    """Build a :class:`Site` from a parsed YAML document, validating every field."""
    src = str(source) if source else "<site>"
    if not isinstance(doc, dict):
        raise ConfigError(f"{src}: expected a mapping at top level")
    origin = _need(doc, "origin", src)
    lat0, lon0 = _latlon(origin, f"{src}: origin")
    h0 = _num(origin, "h", f"{src}: origin")

    def enu(lat: float, lon: float, h: float) -> tuple[float, float, float]:
        e, n, u = pymap3d.geodetic2enu(lat, lon, h, lat0, lon0, h0)
        return float(e), float(n), float(u)

    towers: dict[str, Tower] = {}
    raw_towers = _need(doc, "towers", src)
    if not isinstance(raw_towers, dict) or not raw_towers:
        raise ConfigError(f"{src}: 'towers' must be a non-empty mapping")
    for name, t in raw_towers.items():
        w = f"{src}: towers.{name}"
        lat, lon = _latlon(t, w)
        gh, agl = _num(t, "ground_h", w), _num(t, "antenna_agl", w)
        towers[str(name)] = Tower(str(name), lat, lon, gh, agl, enu(lat, lon, gh + agl))

    r = _need(doc, "radar", src)
    w = f"{src}: radar"
    rlat, rlon = _latlon(r, w)
    rgh, mast = _num(r, "ground_h", w), _num(r, "mast_agl", w)
    fov_az, fov_el = _num(r, "fov_az_deg", w), _num(r, "fov_el_deg", w)
    gate = _num(r, "range_gate_m", w)
    if not (0 < fov_az <= 360 and 0 < fov_el <= 180):
        raise ConfigError(f"{w}: field of view must be positive (az <= 360, el <= 180)")
    if gate <= 0:
        raise ConfigError(f"{w}: range_gate_m must be > 0, got {gate}")
    radar = RadarSite(
        tower=str(r.get("tower", "")),
        lat=rlat,
        lon=rlon,
        ground_h=rgh,
        mast_agl=mast,
        boresight_az_deg=_num(r, "boresight_az_deg", w),
        boresight_el_deg=_num(r, "boresight_el_deg", w),
        fov_az_deg=fov_az,
        fov_el_deg=fov_el,
        range_gate_m=gate,
        enu=enu(rlat, rlon, rgh + mast),
        calibration=_calibration(r.get("calibration"), f"{w}.calibration"),
    )
    raw_rf = _need(doc, "rf_sensors", src)
    if not isinstance(raw_rf, list):
        raise ConfigError(f"{src}: 'rf_sensors' must be a list of tower names, got {raw_rf!r}")
    rf = tuple(str(x) for x in raw_rf)
    for n in rf:
        if n not in towers:
            raise ConfigError(f"{src}: rf_sensors names unknown tower '{n}'")
    if len(rf) < 3:
        raise ConfigError(f"{src}: rf_sensors: TDOA needs at least 3 RF sensors, got {len(rf)}")
    to = _need(doc, "takeoff", src)
    tlat, tlon = _latlon(to, f"{src}: takeoff")
    clocks = doc.get("clock_offsets_h", {}) or {}
    if not isinstance(clocks, dict):
        raise ConfigError(f"{src}: clock_offsets_h must be a mapping")
    offsets = {str(k): _num(clocks, k, f"{src}: clock_offsets_h") for k in clocks}
    return Site(
        name=str(doc.get("name", "site")),
        frame_id=str(doc.get("frame_id", "enu")),
        lat0=lat0,
        lon0=lon0,
        h0=h0,
        towers=towers,
        radar=radar,
        rf_sensors=rf,
        takeoff_lat=tlat,
        takeoff_lon=tlon,
        takeoff_h=_num(to, "h", f"{src}: takeoff"),
        clock_offsets_h=offsets,
        source=source,
    )


def load_site(path: str | Path | None = None) -> Site:
    """Load a site YAML file (default: the shipped Lake Wheeler description)."""
    p = Path(path) if path is not None else config_path(DEFAULT_SITE)
    return site_from_dict(read_yaml_file(p, "site file"), p)


def write_calibration(site_path: str | Path, out: str | Path, cal: RadarCalibration) -> Path:
    """A copy of the site file ``site_path`` at ``out`` whose ``radar.calibration`` is
    ``cal`` (the rest of the file, comments included, as it was). The copy is read back and
    checked before it is kept."""
    src = Path(site_path)
    text = src.read_text(encoding="utf-8")
    lines = text.splitlines()
    try:
        start = next(i for i, ln in enumerate(lines) if ln.rstrip() == "radar:")
    except StopIteration:
        raise ConfigError(f"{src}: no top-level 'radar:' section to calibrate") from None
    end = start + 1
    while end < len(lines) and (not lines[end].strip() or lines[end].startswith(" ")):
        end += 1
    while end > start + 1 and not lines[end - 1].strip():
        end -= 1
    block = lines[start + 1 : end]
    kept: list[str] = []
    skipping = False
    for ln in block:  # drop an existing calibration sub-block
        if ln.startswith("  calibration:"):
            skipping = True
            continue
        if skipping and ln.startswith("    "):
            continue
        skipping = False
        kept.append(ln)
    note = cal.note.replace('"', "'")
    new = [
        "  calibration:               # the mount's misalignment (uav_fusion calibrate)",
        f"    az_bias_deg: {cal.az_bias_deg:.4f}",
        f"    el_bias_deg: {cal.el_bias_deg:.4f}",
        f"    az_sigma_deg: {cal.az_sigma_deg:.4f}",
        f"    el_sigma_deg: {cal.el_sigma_deg:.4f}",
        f'    note: "{note}"',
    ]
    lines[start + 1 : end] = kept + new
    dst = Path(out)
    dst.parent.mkdir(parents=True, exist_ok=True)
    dst.write_text("\n".join(lines) + "\n", encoding="utf-8")
    back = load_site(dst).radar.calibration
    if abs(back.az_bias_deg - cal.az_bias_deg) > 1e-4:
        raise ConfigError(f"{dst}: the written calibration does not read back")
    return dst
