"""Site description: the shipped YAML loads, ENU offsets match the published geometry."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
import yaml

from uav_fusion.core.errors import ConfigError
from uav_fusion.core.site import RadarCalibration, load_site, site_from_dict, write_calibration

# E, N of each tower from LW1 (DESIGN §3).
EXPECTED_EN = {
    "LW1": (0.0, 0.0),
    "LW2": (-447.8, 78.1),
    "LW3": (367.2, -288.2),
    "LW4": (-217.7, 629.6),
    "LW5": (-332.1, 1712.2),
}


def test_tower_enu_offsets_match_published_geometry() -> None:
    site = load_site()
    for name, (e, n) in EXPECTED_EN.items():
        t = site.towers[name]
        assert t.enu[0] == pytest.approx(e, abs=0.1), name
        assert t.enu[1] == pytest.approx(n, abs=0.1), name


def test_radar_and_sensor_set() -> None:
    site = load_site()
    assert site.rf_sensors == ("LW2", "LW3", "LW4", "LW5")
    assert site.radar.fov_az_deg == 120.0 and site.radar.fov_el_deg == 60.0
    assert site.radar.range_gate_m == 800.0
    lw3 = site.towers["LW3"].enu
    d = ((site.radar.enu[0] - lw3[0]) ** 2 + (site.radar.enu[1] - lw3[1]) ** 2) ** 0.5
    assert d < 20.0  # on a mast beside LW3
    assert site.radar.enu[2] == pytest.approx(10.0, abs=0.05)
    assert site.clock_offset_s("truth") == -4 * 3600.0
    assert site.clock_offset_s("rf") == 0.0


def test_enu_round_trip() -> None:
    site = load_site()
    lat, lon, h = site.to_geodetic([100.0, -2000.0], [250.0, 1500.0], [30.0, 120.0])
    e, n, u = site.to_enu(lat, lon, h)
    assert e.tolist() == pytest.approx([100.0, -2000.0], abs=1e-6)
    assert n.tolist() == pytest.approx([250.0, 1500.0], abs=1e-6)
    assert u.tolist() == pytest.approx([30.0, 120.0], abs=1e-6)


def _doc() -> dict[str, Any]:
    doc: dict[str, Any] = yaml.safe_load(Path(load_site().source or "").read_text())
    return doc


@pytest.mark.parametrize(
    ("mutate", "message"),
    [
        (lambda d: d.pop("origin"), "missing key 'origin'"),
        (lambda d: d["towers"]["LW2"].update(lat=95.0), "towers.LW2: lat 95.0 outside"),
        (lambda d: d["radar"].update(range_gate_m=-1), "range_gate_m must be > 0"),
        (lambda d: d.update(rf_sensors=["LW2", "LW9", "LW4"]), "unknown tower 'LW9'"),
        (lambda d: d.update(rf_sensors=["LW2", "LW3"]), "at least 3 RF sensors"),
        (lambda d: d["takeoff"].update(h="high"), "'h' must be a number"),
        (
            lambda d: d["radar"].update(calibration={"az_bias_deg": 12.0}),
            r"site\.yaml: radar\.calibration\.az_bias_deg: a mounting misalignment of at most "
            r"10 degrees, got 12\.0",
        ),
        (
            lambda d: d["radar"].update(calibration={"el_bias_deg": float("nan")}),
            r"site\.yaml: radar\.calibration: 'el_bias_deg' must be finite, got nan",
        ),
        (
            lambda d: d["radar"].update(calibration={"az_sigma_deg": -0.1}),
            r"radar\.calibration\.az_sigma_deg: must lie in \[0, 10\] \(0: known exactly\)",
        ),
        (
            lambda d: d["radar"].update(calibration={"roll_deg": 1.0}),
            r"radar\.calibration: unknown key 'roll_deg'",
        ),
        (lambda d: d["radar"].update(calibration=[0.5]), r"radar\.calibration: must be a mapping"),
    ],
)
def test_bad_site_is_rejected_with_a_clear_message(
    mutate: Callable[[dict[str, Any]], object], message: str
) -> None:
    doc = _doc()
    mutate(doc)
    with pytest.raises(ConfigError, match=message):
        site_from_dict(doc, Path("site.yaml"))


def test_missing_site_file(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="site file not found"):
        load_site(tmp_path / "nope.yaml")


def test_the_radar_calibration_is_read_and_defaults_to_uncalibrated() -> None:
    site = load_site()
    cal = site.radar.calibration
    assert (cal.az_bias_deg, cal.el_bias_deg, cal.az_sigma_deg, cal.el_sigma_deg) == (0, 0, 1, 1)
    doc = _doc()
    doc["radar"]["calibration"] = {"az_bias_deg": 0.4, "el_sigma_deg": 0.0, "note": "surveyed"}
    cal = site_from_dict(doc, Path("site.yaml")).radar.calibration
    assert (cal.az_bias_deg, cal.el_bias_deg, cal.az_sigma_deg, cal.el_sigma_deg) == (
        0.4, 0.0, 1.0, 0.0,
    )  # fmt: skip
    assert cal.note == "surveyed"


def test_write_calibration_changes_only_the_calibration(tmp_path: Path) -> None:
    src = Path(load_site().source or "")
    first = write_calibration(src, tmp_path / "a.yaml", RadarCalibration(0.5, -0.25, 0.1, 0.2))
    again = write_calibration(first, tmp_path / "b.yaml", RadarCalibration(-1.0, 0.0, 0.3, 0.3))
    for path, az in ((first, 0.5), (again, -1.0)):
        site = load_site(path)
        assert site.radar.calibration.az_bias_deg == az
        assert site.towers == load_site().towers and site.radar.enu == load_site().radar.enu
        # every other line, comments included, as it was; one calibration block
        added = [ln for ln in path.read_text().splitlines() if ln not in src.read_text()]
        assert len(added) == 6 and path.read_text().count("\n  calibration:") == 1
    with pytest.raises(ConfigError, match="no top-level 'radar:' section"):
        (tmp_path / "bare.yaml").write_text("name: x\n")
        write_calibration(tmp_path / "bare.yaml", tmp_path / "c.yaml", RadarCalibration())
