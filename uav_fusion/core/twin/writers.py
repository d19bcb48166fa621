"""Write a twin flight in the formats of AERPAW Dataset-28 (see docs/dataset.md).

- ``AADM.csv``: Keysight RF localisation attempts (UTC times, failed attempts as 0, 0);
- ``radar_data_<YYYY-MM-DD_HH-MM-SS>.json``: Fortem radar JSON Lines (status lines and track
  frames, ``trackData`` at top level or inside ``params``);
- ``<YYYY-MM-DD>_<HH-MM-SS>_vehicleOut.txt``: the vehicle's RTK log, no header, local time;
  in a multi-UAV flight the other UAVs' logs are ``<same stamp>_<vehicle>_vehicleOut.txt``.

Coordinates and times that the loaders turn into ENU are written with ``repr`` precision, so
reading the files back reproduces the twin's values exactly.
"""

from __future__ import annotations

import csv
import json
from datetime import UTC, datetime, timedelta
from pathlib import Path
from typing import TYPE_CHECKING, Any

from uav_fusion.core.errors import DataError
from uav_fusion.core.twin.worlds import WORLD_FILE, world_doc, write_world

if TYPE_CHECKING:
    from uav_fusion.core.twin.generate import TwinFlight

RF_HEADER = [
    "Meas ID",
    "Algorithm",
    "Center Frequency",
    "Sample Rate",
    "Num Samples",
    "Latitude ",  # the real file carries stray spaces in a couple of names
    "Longitude",
    "Elevation",
    "RHO",
    "CEP",
    "Total Sensors",
    " Valid Sensors",
    "Overloaded Sensors",
    "Sensor Names",
    "Time",
    "Comment",
]
RF_FILE = "AADM.csv"
STATUS_LINE = {"error": {"code": 200, "message": "OK"}}
_EPOCH = datetime(1970, 1, 1, tzinfo=UTC)


def _stamp(t_us: int, fmt_ms: bool = False) -> str:
    dt = _EPOCH + timedelta(microseconds=int(t_us))
    s = dt.strftime("%Y-%m-%d %H:%M:%S.%f")
    return s[:-3] if fmt_ms else s


def file_names(twin: TwinFlight) -> dict[str, str]:
    """Names of the files of ``twin`` (radar in UTC, truth in the vehicle's local time).

    ``truth`` is the first UAV's log; another UAV's is ``truth:<vehicle>``, named
    ``<stamp>_<vehicle>_vehicleOut.txt`` with the same stamp.
    """
    start = twin.start_datetime
    local = start + timedelta(seconds=twin.site.clock_offset_s("truth"))
    stamp = f"{local:%Y-%m-%d_%H-%M-%S}"
    names = {
        "rf": RF_FILE,
        "radar": f"radar_data_{start:%Y-%m-%d_%H-%M-%S}.json",
        "truth": f"{stamp}_vehicleOut.txt",
    }
    for other in twin.others:
        names[f"truth:{other.vehicle}"] = f"{stamp}_{other.vehicle}_vehicleOut.txt"
    return names


def radar_line_layout(twin: TwinFlight) -> list[int]:
    """For each line of the radar file: -1 for a status line, else the frame index."""
    every = twin.config.radar.status_every_s
    layout: list[int] = []
    last_bucket = None
    for i, f in enumerate(twin.radar):
        bucket = int((f.t_unix - twin.start_unix) // every)
        if bucket != last_bucket:
            layout.append(-1)
            last_bucket = bucket
        layout.append(i)
    return layout


def write_rf_csv(twin: TwinFlight, path: Path) -> None:
    rf = twin.config.rf
    offset_us = round(twin.site.clock_offset_s("rf") * 1e6)
    with path.open("w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh, lineterminator="\r\n")
        w.writerow(RF_HEADER)
        for a in twin.rf:
            at = a.attempt
            t_us = round(a.t_unix * 1e3) * 1000 + offset_us
            if at.ok:
                lat, lon, elev = repr(a.lat), repr(a.lon), f"{a.h:.3f}"
                rho, cep = f"{at.rho:.4f}", f"{at.cep_m:.2f}"
            else:
                lat = lon = "0"
                elev, rho, cep = "0", "0", "0"
            w.writerow(
                [
                    at.meas_id,
                    "TDOA",
                    f"{at.center_frequency_hz or rf.center_frequency_hz:.0f}",
                    f"{rf.sample_rate_hz:.0f}",
                    rf.num_samples,
                    lat,
                    lon,
                    elev,
                    rho,
                    cep,
                    at.total_sensors,
                    at.valid_sensors,
                    at.overloaded_sensors,
                    ",".join(at.sensor_names),
                    _stamp(t_us, fmt_ms=True),
                    "" if at.ok else f"Localization failed: {at.reason}",
                ]
            )


def _r(x: float, nd: int = 3) -> float:
    v = round(float(x), nd)
    return 0.0 if v == 0 else v


def write_radar_jsonl(twin: TwinFlight, path: Path) -> None:
    every_params = max(1, twin.config.radar.params_track_every)
    offset = twin.site.clock_offset_s("radar")
    with path.open("w", encoding="utf-8") as fh:
        for idx in radar_line_layout(twin):
            if idx < 0:
                fh.write(json.dumps(STATUS_LINE, separators=(",", ":")) + "\n")
                continue
            f = twin.radar[idx]
            t_file = f.t_unix + offset
            gps = t_file - 315_964_800 + 18
            week = int(gps // 604_800)
            params: dict[str, Any] = {
                "globalTime": t_file,
                "gpsWeek": week,
                "gpsSeconds": round(gps - week * 604_800, 6),
            }
            tracks = []
            for tr in f.tracks:
                r = tr.report
                tracks.append(
                    {
                        "id": r.track_id,
                        "lla": [tr.lat, tr.lon, tr.h],
                        "velocityNed": [_r(r.vel[1]), _r(r.vel[0]), _r(-r.vel[2])],
                        "catProb": list(r.cat_prob),
                        "range": _r(r.range_m, 2),
                        "radialVelocity": _r(r.radial_velocity),
                        "numInliers": r.num_inliers,
                        "rcsDbsm": _r(r.rcs_dbsm, 3),
                    }
                )
            if idx % every_params == every_params - 1:
                params["trackData"] = tracks
                doc: dict[str, Any] = {"params": params}
            else:
                doc = {"params": params, "trackData": tracks}
            fh.write(json.dumps(doc, separators=(",", ":")) + "\n")


def _tuple(a: float, b: float, c: float) -> str:
    return f"({a!r},{b!r},{c!r})"


def write_truth(twin: TwinFlight, path: Path, vehicle: str | None = None) -> None:
    """One UAV's truth log (default: the first UAV's)."""
    tl = dict(twin.vehicles)[vehicle] if vehicle is not None else twin.truth
    offset_us = round(twin.site.clock_offset_s("truth") * 1e6)
    with path.open("w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh, lineterminator="\n", quoting=csv.QUOTE_MINIMAL)
        for i in range(tl.t_us.size):
            valid = tl.fix_type[i] >= 2
            lon = repr(float(tl.lon[i])) if valid else "-999"
            lat = repr(float(tl.lat[i])) if valid else "-999"
            alt = repr(float(tl.alt[i])) if valid else "-999"
            att = tl.att[i]
            vel = tl.vel_ned[i]
            w.writerow(
                [
                    i + 1,
                    lon,
                    lat,
                    alt,
                    _tuple(
                        round(float(att[0]), 4), round(float(att[1]), 4), round(float(att[2]), 4)
                    ),
                    _tuple(
                        round(float(vel[0]), 3), round(float(vel[1]), 3), round(float(vel[2]), 3)
                    ),
                    f"{tl.battery_v[i]:.3f}",
                    _stamp(int(tl.t_us[i]) + offset_us),
                    int(tl.fix_type[i]),
                    int(tl.num_sats[i]),
                ]
            )


def write_manifest(twin: TwinFlight, path: Path, names: dict[str, str]) -> None:
    """``twin_manifest.json``: how the folder was made (seed, plan, radar/sensors used)."""
    r = twin.site.radar
    counts = {
        "truth_rows": int(twin.truth.t_us.size),
        "radar_frames": len(twin.radar),
        "radar_reports": sum(len(f.tracks) for f in twin.radar),
        "rf_attempts": len(twin.rf),
        "rf_fixes": sum(1 for a in twin.rf if a.attempt.ok),
    }
    doc = {
        "generator": "uav_fusion digital twin",
        "seed": twin.seed,
        "flight_plan": twin.plan.name,
        "flight_plan_file": twin.plan.source.name if twin.plan.source else None,
        "twin_config_file": twin.config.source.name if twin.config.source else None,
        "start_utc": twin.start_datetime.strftime("%Y-%m-%d %H:%M:%S"),
        "duration_s": round(twin.traj.duration, 3),
        "scene_scale": twin.scene_scale,
        "radar": {
            "tower": r.tower,
            "lat": r.lat,
            "lon": r.lon,
            "h": r.h,
            "boresight_az_deg": r.boresight_az_deg,
        },
        # the misalignment the twin gave the radar's reports (the site file's calibration,
        # if any, is what a deployment believes; this is what is true)
        "radar_mount": {
            "az_bias_deg": twin.config.radar.az_bias_deg,
            "el_bias_deg": twin.config.radar.el_bias_deg,
        },
        "rf_sensors": list(twin.site.rf_sensors),
        "vehicles": [
            {
                "name": p.vehicle,
                "pad_enu": list(p.pad) if p.pad is not None else None,
                "center_frequency_hz": (
                    None
                    if p.emitter is None
                    else p.emitter.center_frequency_hz or twin.config.rf.center_frequency_hz
                ),
            }
            for p in twin.plan.all_vehicles
        ],
        "files": names,
        "counts": counts,
    }
    if twin.world is not None:  # only then: a flight of the default twin keeps its manifest
        doc["world"] = {"family": twin.world.family, "file": WORLD_FILE}
    path.write_text(json.dumps(doc, indent=2) + "\n", encoding="utf-8")


MANIFEST = "twin_manifest.json"


def read_manifest(folder: str | Path) -> dict[str, Any] | None:
    """A flight folder's ``twin_manifest.json`` (None when the folder has none: not a twin
    flight). An unreadable one is a :class:`~uav_fusion.core.errors.DataError` naming it."""
    path = Path(folder) / MANIFEST
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        return None
    except (OSError, ValueError) as exc:
        raise DataError(path, None, f"unreadable twin manifest: {exc}") from None
    if not isinstance(doc, dict):
        raise DataError(path, None, "unreadable twin manifest: not a JSON object")
    return doc


def write_twin(twin: TwinFlight, out_dir: str | Path) -> dict[str, Path]:
    """Write the data files and the manifest into ``out_dir`` (created if needed)."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    names = file_names(twin)
    paths = {k: out / v for k, v in names.items()}
    write_rf_csv(twin, paths["rf"])
    write_radar_jsonl(twin, paths["radar"])
    write_truth(twin, paths["truth"])
    for other in twin.others:
        write_truth(twin, paths[f"truth:{other.vehicle}"], other.vehicle)
    paths["manifest"] = out / MANIFEST
    write_manifest(twin, paths["manifest"], names)
    if twin.world is not None:
        paths["world"] = write_world(
            world_doc(twin.world, twin.config, twin.site.radar), out / WORLD_FILE
        )
    return paths
