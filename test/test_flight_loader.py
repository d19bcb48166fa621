"""Flight folder loader: file discovery, explicit variants, timeline overlap check."""

from __future__ import annotations

import dataclasses
import json
import shutil
from datetime import UTC, datetime, timedelta
from pathlib import Path

import numpy as np
import pytest

from uav_fusion.core.data import load_flight
from uav_fusion.core.errors import DataError
from uav_fusion.core.scoring.metrics import interpolate_truth, position_errors
from uav_fusion.core.site import Site, load_site
from uav_fusion.resources import data_path

T0 = 1759866140.0  # 2025-10-07 19:42:20 UTC
RF_HEADER = (
    "Meas ID,Algorithm,Center Frequency,Sample Rate,Num Samples,Latitude,Longitude,Elevation,"
    "RHO,CEP,Total Sensors,Valid Sensors,Overloaded Sensors,Sensor Names,Time,Comment"
)


@pytest.fixture(scope="module")
def site() -> Site:
    return load_site()


def path_enu(t: np.ndarray) -> np.ndarray:
    """A straight climb-and-cruise path north-east of LW1, ENU metres."""
    s = t - T0
    return np.stack([50.0 + 8.0 * s, 100.0 + 6.0 * s, 40.0 + 0.1 * s], axis=1)


def write_flight(
    folder: Path, site: Site, *, rf_name: str = "AADM.csv", truth_local_offset_h: float = -4.0
) -> None:
    """Write a consistent 60 s flight in the three real formats (sensors exact, no noise)."""
    folder.mkdir(parents=True, exist_ok=True)
    # truth at 5 Hz, local wall clock, alt relative to take-off
    tt = T0 + np.arange(0.0, 60.0, 0.2)
    lat, lon, h = site.to_geodetic(*path_enu(tt).T)
    rows = []
    for i, t in enumerate(tt):
        local = datetime.fromtimestamp(t, UTC) + timedelta(hours=truth_local_offset_h)
        ts = local.replace(tzinfo=None).isoformat(sep=" ")
        rows.append(
            f'{i + 1},{lon[i]:.9f},{lat[i]:.9f},{h[i] - site.takeoff_h:.4f},"(0.0,0.6,0.0)",'
            f'"(6.0,8.0,-0.1)",15.9,{ts},6,24'
        )
    (folder / "2025-10-07_15_40_00_vehicleOut.txt").write_text("\n".join(rows) + "\n")
    # radar at 4 Hz with a status line first
    rt = T0 + 1.0 + np.arange(0.0, 55.0, 0.25)
    rlat, rlon, rh = site.to_geodetic(*path_enu(rt).T)
    lines = ['{"error":{"code":200,"message":"OK"}}']
    for i, t in enumerate(rt):
        trk = {"id": 3, "lla": [rlat[i], rlon[i], rh[i]], "catProb": [0.95, 0.05]}
        lines.append(json.dumps({"params": {"globalTime": t}, "trackData": [trk]}))
    (folder / "radar_data_20251007.json").write_text("\n".join(lines) + "\n")
    # RF every 3.88 s, every fourth attempt failed
    ft = T0 + 2.0 + 3.88 * np.arange(14)
    flat, flon, _ = site.to_geodetic(*path_enu(ft).T)
    rf = [RF_HEADER]
    for i, t in enumerate(ft):
        stamp = datetime.fromtimestamp(t, UTC).isoformat(sep=" ", timespec="milliseconds")[:-6]
        la, lo = ("0", "0") if i % 4 == 3 else (f"{flat[i]:.9f}", f"{flon[i]:.9f}")
        rf.append(
            f'{i + 1},TDOA,2.44E+09,2.8E+07,16384,{la},{lo},0,0.9,30,4,4,0,"LW2,LW3",{stamp},'
        )
    (folder / rf_name).write_text("\n".join(rf) + "\n")


def test_loads_a_consistent_flight_on_one_timeline(tmp_path: Path, site: Site) -> None:
    folder = tmp_path / "Opt1"
    write_flight(folder, site)
    fl = load_flight(folder, site, strict=True)
    assert fl.name == "Opt1" and fl.folder == folder
    assert set(fl.reports) == {"rf", "radar", "truth"}
    assert (len(fl.truth), len(fl.radar), len(fl.rf)) == (300, 220, 14)
    assert sum(not a.ok for a in fl.rf) == 3
    assert fl.reports["radar"].skipped["status"] == 1
    assert not any("WARNING" in n for r in fl.reports.values() for n in r.notes)
    # every sensor position lands on the truth path at its own time
    tt, tenu = fl.truth_arrays()
    radar_t = np.array([f.t for f in fl.radar])
    radar_enu = np.array([(f.tracks[0].e, f.tracks[0].n, f.tracks[0].u) for f in fl.radar])
    err = position_errors(radar_enu, interpolate_truth(tt, tenu, radar_t))
    assert np.nanmax(err) < 1e-3
    ok = [a for a in fl.rf if a.ok]
    rf_en = np.array([(a.e, a.n) for a in ok])
    ref = interpolate_truth(tt, tenu, np.array([a.t for a in ok]))
    assert np.max(position_errors(rf_en, ref, dims=2)) < 0.01  # RF read at the origin height


def test_default_site(tmp_path: Path, site: Site) -> None:
    write_flight(tmp_path / "F", site)
    assert len(load_flight(tmp_path / "F").truth) == 300


def test_rf_variant_is_explicit(tmp_path: Path, site: Site) -> None:
    folder = tmp_path / "Opt2"
    write_flight(folder, site, rf_name="AADM_rerun.csv")
    (folder / "AADM_old.csv").write_text(RF_HEADER + "\n")
    with pytest.raises(DataError) as ei:
        load_flight(folder, site)
    assert str(ei.value) == (
        f"{folder}: RF file 'AADM.csv' not found; candidates: AADM_old.csv, AADM_rerun.csv; "
        "choose one with rf_file=<file name>"
    )
    fl = load_flight(folder, site, rf_file="AADM_rerun.csv")
    assert len(fl.rf) == 14 and fl.reports["rf"].path.name == "AADM_rerun.csv"


def test_no_rf_file_at_all(tmp_path: Path, site: Site) -> None:
    folder = tmp_path / "Opt3"
    write_flight(folder, site)
    (folder / "AADM.csv").unlink()
    with pytest.raises(DataError) as ei:
        load_flight(folder, site)
    assert str(ei.value) == (
        f"{folder}: RF file 'AADM.csv' not found and no file matches 'AADM*.csv'; files here: "
        "2025-10-07_15_40_00_vehicleOut.txt, radar_data_20251007.json"
    )


def test_ambiguous_and_missing_radar_or_truth(tmp_path: Path, site: Site) -> None:
    folder = tmp_path / "Opt4"
    write_flight(folder, site)
    extra = folder / "radar_data_20251008.json"
    extra.write_text('{"error":{"code":200}}\n')
    with pytest.raises(DataError) as ei:
        load_flight(folder, site)
    assert str(ei.value) == (
        f"{folder}: 2 radar files match 'radar_data_*.json' (radar_data_20251007.json, "
        "radar_data_20251008.json); choose one with radar_glob=<file name>"
    )
    fl = load_flight(folder, site, radar_glob="radar_data_20251007.json")
    assert len(fl.radar) == 220
    extra.unlink()
    (folder / "2025-10-07_15_40_00_vehicleOut.txt").unlink()
    with pytest.raises(DataError) as ei:
        load_flight(folder, site)
    assert str(ei.value) == (
        f"{folder}: no truth file matches '*vehicleOut.txt'; files here: AADM.csv, "
        "radar_data_20251007.json"
    )


def test_missing_folder(tmp_path: Path) -> None:
    with pytest.raises(DataError) as ei:
        load_flight(tmp_path / "nowhere")
    assert str(ei.value) == f"{tmp_path / 'nowhere'}: flight folder not found"


def test_wrong_truth_offset_is_loud(tmp_path: Path, site: Site) -> None:
    folder = tmp_path / "Opt5"
    write_flight(folder, site)
    utc_site = dataclasses.replace(site, clock_offsets_h={"truth": 0.0})  # wrong: file is EDT
    fl = load_flight(folder, utc_site)
    what_radar = (
        "truth (2025-10-07T15:42:20.000Z to 2025-10-07T15:43:19.800Z) and radar "
        "(2025-10-07T19:42:21.000Z to 2025-10-07T19:43:15.750Z) do not overlap in time: the "
        "radar data lie about +4.0 h from the truth; the truth clock offset "
        "(clock_offsets_h.truth = +0) is probably wrong by about 4.0 h "
        "(try clock_offsets_h.truth: -4)"
    )
    assert "WARNING: " + what_radar in fl.reports["truth"].notes
    assert fl.reports["radar"].notes[-1] == "WARNING: " + what_radar
    assert fl.reports["rf"].notes[-1].startswith("WARNING: truth (2025-10-07T15:42:20.000Z")
    with pytest.raises(DataError) as ei:
        load_flight(folder, utc_site, strict=True)
    assert ei.value.line is None and ei.value.what.startswith("truth (2025-10-07T15:42:20.000Z")
    assert ei.value.path is not None and ei.value.path.name.endswith("vehicleOut.txt")


def test_small_shift_is_reported_in_minutes(tmp_path: Path, site: Site) -> None:
    folder = tmp_path / "Opt6"
    write_flight(folder, site, truth_local_offset_h=-4.0 - 5.0 / 60.0)  # logger 5 min slow
    fl = load_flight(folder, site)
    note = fl.reports["radar"].notes[-1]
    assert note.startswith("WARNING: ") and "lie about +5 min from the truth" in note
    assert note.endswith("probably wrong by about 5 min")


def test_sensor_without_data_is_noted(tmp_path: Path, site: Site) -> None:
    folder = tmp_path / "Opt7"
    write_flight(folder, site)
    (folder / "radar_data_20251007.json").write_text('{"error":{"code":200}}\n')
    fl = load_flight(folder, site)
    assert fl.radar == []
    assert fl.reports["radar"].notes[-1] == (
        "WARNING: no data, the timeline could not be checked against truth"
    )


# --- several UAVs: the folder rules ---------------------------------------------------------
def _multi(tmp_path: Path) -> tuple[Path, str]:
    src = data_path("default_flight")
    folder = tmp_path / "multi"
    shutil.copytree(src, folder)
    base = next(folder.glob("*_vehicleOut.txt"))
    stamp = base.name[: -len("_vehicleOut.txt")]
    return folder, stamp


def test_one_truth_file_per_uav_by_the_naming_rule(tmp_path: Path, site: Site) -> None:
    folder, stamp = _multi(tmp_path)
    base = folder / f"{stamp}_vehicleOut.txt"
    lines = base.read_text().splitlines(keepends=True)
    # uav2: the same log cut short (a different vehicle, readable on its own)
    (folder / f"{stamp}_uav2_vehicleOut.txt").write_text("".join(lines[: len(lines) // 2]))
    (folder / f"{stamp}_scout-3_vehicleOut.txt").write_text("".join(lines))
    fl = load_flight(folder, site)
    assert list(fl.vehicles) == ["uav1", "scout-3", "uav2"]
    assert fl.truth is fl.vehicles["uav1"]
    single = load_flight(data_path("default_flight"), site)
    assert [f.t for f in fl.truth] == [f.t for f in single.truth]
    assert len(fl.vehicles["uav2"]) < len(fl.truth)
    assert {"truth", "truth:uav2", "truth:scout-3"} <= set(fl.reports)
    t2, enu2 = fl.truth_arrays("uav2")
    assert t2.shape[0] == enu2.shape[0] == len(fl.vehicles["uav2"])


def test_a_single_uav_folder_has_one_vehicle(site: Site) -> None:
    fl = load_flight(data_path("default_flight"), site)
    assert list(fl.vehicles) == ["uav1"] and fl.vehicles["uav1"] is fl.truth


@pytest.mark.parametrize(
    ("names", "message"),
    [
        (["uav2_vehicleOut.txt"], "this name breaks the rule"),
        (["{stamp}_uav 2_vehicleOut.txt"], "this name breaks the rule"),
        (["2024-01-01_00-00-00_uav2_vehicleOut.txt"], "different recording stamps"),
        (["{stamp}_uav1_vehicleOut.txt"], "vehicle 'uav1' is the file without a vehicle name"),
        (["{stamp}_uav2_vehicleOut.txt", "{stamp}_UAV2_vehicleOut.txt"], "more than one"),
    ],
)
def test_truth_files_breaking_the_rules_are_named(
    tmp_path: Path, site: Site, names: list[str], message: str
) -> None:
    folder, stamp = _multi(tmp_path)
    base = folder / f"{stamp}_vehicleOut.txt"
    for n in names:
        shutil.copy(base, folder / n.format(stamp=stamp))
    with pytest.raises(DataError, match=message) as ei:
        load_flight(folder, site)
    culprit = names[-1].format(stamp=stamp)
    if "stamps" not in message:
        assert culprit in str(ei.value) or str(folder) in str(ei.value)


def test_no_first_uav_among_several_files(tmp_path: Path, site: Site) -> None:
    folder, stamp = _multi(tmp_path)
    base = folder / f"{stamp}_vehicleOut.txt"
    shutil.copy(base, folder / f"{stamp}_uav2_vehicleOut.txt")
    base.rename(folder / f"{stamp}_uav3_vehicleOut.txt")
    with pytest.raises(DataError, match="0 truth files without a vehicle name"):
        load_flight(folder, site)


def test_an_unreadable_second_truth_file_is_named(tmp_path: Path, site: Site) -> None:
    folder, stamp = _multi(tmp_path)
    bad = folder / f"{stamp}_uav2_vehicleOut.txt"
    bad.write_text("this is not a vehicle log\n")
    with pytest.raises(DataError) as ei:
        load_flight(folder, site, strict=True)
    assert str(bad) in str(ei.value)
    fl = load_flight(folder, site)  # lenient: uav2 read as empty, its report says why
    assert fl.vehicles["uav2"] == [] and fl.reports["truth:uav2"].rows >= 0
    assert fl.reports["truth:uav2"].skipped or fl.reports["truth:uav2"].notes
