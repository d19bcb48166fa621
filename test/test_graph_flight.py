"""A short synthetic flight in the Dataset-28 file formats, for the node tests.

``write_flight`` writes truth, radar JSON Lines and an RF CSV for a ~``seconds`` long
straight-and-turn flight near the radar: the UAV's radar track (with an ID change halfway,
so track selection matters), a clutter track with a low UAV probability, a second
UAV-classed fragment in some frames (frames with several candidates), and RF fixes every
3.88 s with a few failed attempts and a gross outlier (so the NIS gate rejects
something). The UAV's first track id is the largest track.
"""

from __future__ import annotations

import json
import math
from datetime import UTC, datetime
from pathlib import Path

import numpy as np

from uav_fusion.core.data import load_flight
from uav_fusion.core.estimators import largest_track_id
from uav_fusion.core.site import Site, load_site

T0 = 1759866140.0  # 2025-10-07T19:42:20Z


def _fmt(t: float, offset_h: float) -> str:
    return datetime.fromtimestamp(t + 3600.0 * offset_h, UTC).strftime("%Y-%m-%d %H:%M:%S.%f")


def write_flight(folder: Path, seconds: float = 40.0, seed: int = 3) -> Path:
    """Write a flight folder and return it."""
    site = load_site()
    rng = np.random.default_rng(seed)
    folder.mkdir(parents=True, exist_ok=True)
    r = np.array(site.radar.enu)

    def pos(t: float) -> np.ndarray:
        s = t - T0
        # 150 m north-west of the radar, flying west at 8 m/s, then turning north
        e = r[0] - 150.0 - 8.0 * min(s, 20.0)
        n = r[1] + 150.0 + 8.0 * max(0.0, s - 20.0)
        return np.array([e, n, 60.0 + 0.2 * s])

    def lla(enu: np.ndarray) -> tuple[float, float, float]:
        lat, lon, h = site.to_geodetic(*enu)
        return float(lat), float(lon), float(h)

    # truth at 5 Hz (local clock, altitude relative to take-off)
    lines = []
    for k, t in enumerate(np.arange(T0 - 2.0, T0 + seconds + 2.0, 0.2)):
        lat, lon, h = lla(pos(float(t)))
        lines.append(
            f'{k},{lon:.9f},{lat:.9f},{h - site.takeoff_h:.4f},"(0.0,0.0,0.0)","(0.0,-8.0,0.0)",'
            f"15.1,{_fmt(float(t), site.clock_offsets_h.get('truth', 0.0))},6,20"
        )
    (folder / "2025-10-07_15_42_00_vehicleOut.txt").write_text("\n".join(lines) + "\n")

    # radar frames at 4 Hz
    out = ['{"error":{"code":200,"message":"ok"}}']
    for k, t in enumerate(np.arange(T0, T0 + seconds, 0.25)):
        t = float(t)
        p = pos(t) + rng.normal(0.0, 3.0, 3)
        tracks = [
            {
                "id": 11 if t - T0 < 0.7 * seconds else 12,
                "lla": list(lla(p)),
                "velocityNed": [0.0, -8.0, 0.0],
                "catProb": [0.9, 0.1],
                "range": float(np.linalg.norm(p - r)),
                "rcsDbsm": -12.0,
            },
        ]
        if k % 3 == 0:  # clutter, in a third of the frames
            tracks.append(
                {
                    "id": 90,
                    "lla": list(lla(r + np.array([50.0, 300.0, 20.0]) + rng.normal(0, 2, 3))),
                    "catProb": [0.05, 0.95],
                    "range": 305.0,
                    "rcsDbsm": -25.0,
                }
            )
        if k % 7 == 3:  # a short UAV-classed fragment near the UAV
            tracks.append(
                {
                    "id": 500 + k,
                    "lla": list(lla(p + np.array([30.0, -20.0, 5.0]))),
                    "catProb": [0.7, 0.3],
                    "range": float(np.linalg.norm(p - r)) + 20.0,
                }
            )
        out.append(json.dumps({"params": {"globalTime": t}, "trackData": tracks}))
    (folder / "radar_data_test.json").write_text("\n".join(out) + "\n")

    # RF attempts every 3.88 s
    rows = [
        "Meas ID,Algorithm,Center Frequency,Sample Rate,Num Samples,Latitude,Longitude,"
        "Elevation,RHO,CEP,Total Sensors,Valid Sensors,Overloaded Sensors,Sensor Names,Time,"
        "Comment"
    ]
    for k, t in enumerate(np.arange(T0 + 0.13, T0 + seconds, 3.88)):
        t = float(t)
        if k % 5 == 2:
            lat = lon = 0.0
        else:
            p = pos(t) + np.append(rng.normal(0.0, 15.0, 2), 0.0)
            if k % 5 == 4:
                p[:2] += 400.0  # NLOS outlier
            lat, lon, _ = lla(p)
        rows.append(
            f"{k},TDOA,2.4e9,1e6,1024,{lat:.9f},{lon:.9f},0,0.9,20,4,4,0,LW2;LW3;LW4;LW5,"
            f"{_fmt(t, site.clock_offsets_h.get('rf', 0.0))[:-3]},"
        )
    (folder / "AADM.csv").write_text("\n".join(rows) + "\n")
    return folder


def test_written_flight_loads_cleanly(tmp_path: Path) -> None:
    site: Site = load_site()
    flight = load_flight(write_flight(tmp_path / "f", seconds=20.0), site)
    assert len(flight.radar) == 80
    assert sum(len(f.tracks) for f in flight.radar) > 100
    assert len(flight.rf) == 6 and sum(not a.ok for a in flight.rf) == 1
    assert len(flight.truth) > 100
    for rep in flight.reports.values():
        assert not rep.skipped or set(rep.skipped) <= {"status"}, rep.summary()
    assert largest_track_id(flight.radar) == 11
    # truth positions agree with the radar's UAV track within its noise
    t, enu = flight.truth_arrays()
    tr = flight.radar[10].tracks[0]
    k = int(np.argmin(np.abs(t - tr.t)))
    assert math.dist(enu[k], (tr.e, tr.n, tr.u)) < 20.0
