"""Typed records shared by the readers, the twin, the estimator and the evaluator.

Every time ``t`` is UTC in seconds since the Unix epoch (float64), whatever clock the source
file used: readers apply the site's per-source clock offsets. ENU coordinates are metres in
the site frame (origin LW1, see :mod:`uav_fusion.core.site`).
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]

RADAR = "radar"
RF = "rf"


@dataclass(frozen=True, slots=True)
class TruthFix:
    """One RTK ground-truth sample."""

    t: float
    lat: float
    lon: float
    h: float  # ellipsoidal height (take-off height + relative altitude)
    e: float
    n: float
    u: float
    vel_ned: tuple[float, float, float]
    fix_type: int
    num_sats: int
    line: int = 0  # 1-based line in the source file (0 = not from a file)


@dataclass(frozen=True, slots=True)
class RadarTrack:
    """One track report inside a radar frame."""

    t: float
    track_id: int
    lat: float
    lon: float
    h: float
    e: float
    n: float
    u: float
    vel_ned: tuple[float, float, float] | None
    uav_prob: float | None  # catProb[0]
    range_m: float | None
    rcs_dbsm: float | None
    radial_velocity: float | None = None
    num_inliers: int | None = None
    line: int = 0
    # the report's ENU covariance as sent with it (upper triangle xx, xy, xz, yy, yz, zz;
    # ``radar/pose`` carries one), or None
    cov: tuple[float, float, float, float, float, float] | None = None


@dataclass(frozen=True, slots=True)
class RadarFrame:
    """One radar JSON line carrying track data (possibly zero tracks)."""

    t: float
    tracks: tuple[RadarTrack, ...]
    line: int = 0


@dataclass(frozen=True, slots=True)
class RfAttempt:
    """One RF localisation attempt; ``ok`` False is a failed attempt (lat = lon = 0)."""

    t: float
    meas_id: int
    ok: bool
    lat: float
    lon: float
    e: float  # NaN when not ok
    n: float  # NaN when not ok
    cep: float | None
    valid_sensors: int | None
    total_sensors: int | None
    line: int = 0
    center_freq_hz: float | None = None  # the emitter channel's centre frequency
    rho: float | None = None  # correlation quality of the TDOA solution


@dataclass
class LoadReport:
    """What a reader did with one file: rows seen, used, and skipped by reason."""

    path: Path
    rows: int = 0
    used: int = 0
    skipped: Counter[str] = field(default_factory=Counter)
    notes: list[str] = field(default_factory=list)

    def skip(self, reason: str) -> None:
        self.skipped[reason] += 1

    @property
    def n_skipped(self) -> int:
        return sum(self.skipped.values())

    def summary(self) -> str:
        parts = [f"{self.path.name}: {self.rows} rows, {self.used} used"]
        if self.skipped:
            parts.append(
                "skipped " + ", ".join(f"{k}={v}" for k, v in sorted(self.skipped.items()))
            )
        parts.extend(self.notes)
        return "; ".join(parts)


@dataclass(eq=False, slots=True)
class Measurement:
    """A position measurement handed to the estimator.

    ``z`` is ENU position: 3 values for radar, 2 (east, north) for RF. ``R`` is the
    measurement covariance, or None to use the profile's configured R for the source.
    ``seq`` breaks ties between equal times deterministically (lower first).
    """

    t: float
    source: str
    z: FloatArray
    R: FloatArray | None = None
    track_id: int | None = None
    uav_prob: float | None = None
    range_m: float | None = None
    seq: int = 0

    @property
    def dim(self) -> int:
        return int(self.z.shape[0])


#: Name of the first (or only) UAV of a flight.
FIRST_VEHICLE = "uav1"


@dataclass
class Flight:
    """One flight: truth, radar frames and RF attempts on one UTC timeline, plus load reports.

    ``truth`` is the first UAV's log (vehicle :data:`FIRST_VEHICLE`); ``vehicles`` holds every
    UAV's log by vehicle name, the first UAV first (a single-UAV flight: just ``uav1``; left
    empty by a caller, it is filled with ``{"uav1": truth}``).
    """

    name: str
    truth: list[TruthFix]
    radar: list[RadarFrame]
    rf: list[RfAttempt]
    reports: dict[str, LoadReport] = field(default_factory=dict)
    folder: Path | None = None
    vehicles: dict[str, list[TruthFix]] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if not self.vehicles:
            self.vehicles = {FIRST_VEHICLE: self.truth}

    def truth_arrays(self, vehicle: str | None = None) -> tuple[FloatArray, FloatArray]:
        """(t[N], enu[N, 3]) of one UAV's truth samples (default: the first UAV's)."""
        fixes = self.truth if vehicle is None else self.vehicles[vehicle]
        t = np.array([f.t for f in fixes], dtype=float)
        enu = np.array([(f.e, f.n, f.u) for f in fixes], dtype=float).reshape(-1, 3)
        return t, enu
