"""What the multi-target scoring keeps and reports (:mod:`uav_fusion.core.scoring.gospa`).

A flight's per-epoch samples (:class:`FlightSamples`: the GOSPA of every epoch and each UAV's
:class:`UavSamples`) are kept whole, so that :func:`~uav_fusion.core.scoring.gospa.pool` pools
flights exactly; the pooled figures are a :class:`MultiScore`, all UAVs together and then each
(:class:`UavScore`).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True)
class UavSamples:
    """One UAV's per-epoch outcomes in one flight (kept so flights can be pooled exactly)."""

    name: str
    epochs: int  # airborne epochs
    assigned: int  # ... with an assigned track
    errors: FloatArray  # 3D error at each assigned epoch
    track_ids: tuple[int | None, ...]  # per airborne epoch: the assigned track id, or None
    id_switches: int
    fragmentations: int
    times: FloatArray = field(default_factory=lambda: np.zeros(0))  # the airborne epochs
    id_switches_kept: int = 0  # on the CLEAR MOT correspondence (module text)
    switch_times: FloatArray = field(default_factory=lambda: np.zeros(0))  # of id_switches
    switch_times_kept: FloatArray = field(default_factory=lambda: np.zeros(0))  # ... of the kept

    def covered(self) -> npt.NDArray[np.bool_]:
        """Per airborne epoch: a track was assigned within the cut-off."""
        return np.array([tid is not None for tid in self.track_ids], dtype=bool)


@dataclass(frozen=True)
class EpochAssignment:
    """One epoch's optimal assignment: (UAV name, track id) pairs and the false track ids."""

    t: float
    pairs: tuple[tuple[str, int], ...]
    false_ids: tuple[int, ...]
    excused: tuple[tuple[str, int], ...] = ()  # (UAV not airborne, track id) pairs


@dataclass(frozen=True)
class FlightSamples:
    """One flight's per-epoch GOSPA and per-UAV outcomes."""

    step_s: float
    distance: FloatArray  # GOSPA per epoch, metres
    localisation: FloatArray  # its parts per epoch (p-th powers of metres)
    missed: FloatArray
    false: FloatArray
    false_estimates: int  # unassigned estimates summed over the epochs
    uavs: tuple[UavSamples, ...]
    assignments: tuple[EpochAssignment, ...]
    excused_estimates: int = 0  # estimates excused on a UAV not airborne, over the epochs
    p: float = 2.0  # the GOSPA exponent (the parts are p-th powers of metres)

    @property
    def epochs(self) -> int:
        return int(self.distance.size)


@dataclass(frozen=True)
class UavScore:
    """One UAV's figures over one or several flights (percentages in %)."""

    name: str
    flights: int
    epochs: int
    coverage_pct: float
    err_mean_m: float
    err_p50_m: float
    err_p95_m: float
    err_max_m: float
    id_switches: int
    fragmentations: int
    id_switches_kept: int = 0

    def as_dict(self) -> dict[str, str | float | int]:
        return asdict(self)


@dataclass(frozen=True)
class MultiScore:
    """The figures of one flight or of a pool of flights: all UAVs together, then each."""

    flights: int
    epochs: int  # grid epochs scored
    uav_epochs: int  # airborne (UAV, epoch) pairs
    coverage_pct: float
    err_mean_m: float
    err_p50_m: float
    err_p95_m: float
    err_max_m: float
    id_switches: int
    fragmentations: int
    false_track_s: float
    gospa_mean_m: float  # mean of the per-epoch GOSPA distance
    localisation_mean: float  # means of its parts (p-th powers of metres)
    missed_mean: float
    false_mean: float
    uavs: tuple[UavScore, ...]
    id_switches_kept: int = 0
    excused_track_s: float = 0.0  # track time excused on UAVs not airborne


def multi_summary(sc: MultiScore) -> str:
    """One line of a multi-target score (for reports and logs)."""
    per = "; ".join(
        f"{u.name} {u.coverage_pct:.1f} % of {u.epochs} epochs, {u.id_switches} id switches "
        f"({u.id_switches_kept} on kept correspondences)"
        for u in sc.uavs
    )
    return (
        f"GOSPA mean {sc.gospa_mean_m:.1f} m over {sc.epochs} epochs; coverage "
        f"{sc.coverage_pct:.1f} %, error mean {sc.err_mean_m:.1f} m; false-track time "
        f"{sc.false_track_s:.1f} s; {per}"
    )
