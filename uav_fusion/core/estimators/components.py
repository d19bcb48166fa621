"""Tracker components: measurement models that own their R, gating, robust weights, the
Markov transition matrix of an IMM, track initiation (M-of-N) and deletion.

Each family has a small typed protocol so that a profile can choose an implementation by name
(:func:`radar_model_from_profile`, :func:`rf_model_from_profile`,
:func:`robust_from_profile`). Covariances are returned packed as upper triangles
(:data:`~uav_fusion.core.estimators.kalman.PackedR`), the form the hand-unrolled kernels of
:class:`~uav_fusion.core.estimators.kalman.CvKalman` take, so no component builds a numpy
array on the per-measurement path.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Protocol

import numpy as np
import numpy.typing as npt

from uav_fusion.core.estimators.kalman import PackedR, pack_r
from uav_fusion.core.records import RadarFrame, RadarTrack

FloatArray = npt.NDArray[np.float64]

# the CEP of a circular Gaussian is 1.1774 sigma (sqrt(2 ln 2))
CEP_PER_SIGMA = math.sqrt(2.0 * math.log(2.0))


# --- measurement models -------------------------------------------------------------------
class RadarRModel(Protocol):
    """R (3x3, packed) of a radar position report at ENU ``(e, n, u)``."""

    def r_at(self, e: float, n: float, u: float) -> PackedR: ...


class RfRModel(Protocol):
    """R (2x2, packed) of an RF fix with its CEP (m) and number of valid sensors."""

    def r_for(self, cep_m: float | None, valid_sensors: int | None) -> PackedR: ...


@dataclass(frozen=True)
class FixedRadarR:
    """The paper's model: one R for every radar report."""

    r: PackedR

    def r_at(self, e: float, n: float, u: float) -> PackedR:
        del e, n, u
        return self.r


@dataclass(frozen=True)
class FixedRfR:
    """The paper's model: one R for every RF fix."""

    r: PackedR

    def r_for(self, cep_m: float | None, valid_sensors: int | None) -> PackedR:
        del cep_m, valid_sensors
        return self.r


@dataclass(frozen=True)
class PolarRadarR:
    """R from the radar's polar errors, rotated into ENU at the report's position.

    With ``d`` the report minus the radar's phase centre, ``r = |d|`` and ``rho`` its
    horizontal length, the unit vectors along range ``u_r``, azimuth ``u_az`` (horizontal,
    perpendicular to ``u_r``) and elevation ``u_el`` give

        R = s_r^2 u_r u_r^T + (rho s_az)^2 u_az u_az^T + (r s_el)^2 u_el u_el^T + f^2 I

    (angle errors in radians become cross-range errors that grow with range; ``f`` is a floor
    for what the polar model leaves out, e.g. the onboard tracker's smoothing). Near the
    horizon the ground reflection interferes with the direct return and spoils the elevation
    measurement: ``s_el`` is multiplied by ``1 + low_el_gain * exp(-|el| / low_el_deg)``
    (``low_el_gain`` 0: no inflation).
    """

    radar_enu: tuple[float, float, float]
    sigma_range_m: float
    sigma_az_rad: float
    sigma_el_rad: float
    floor_m: float = 0.0
    low_el_gain: float = 0.0
    low_el_deg: float = 4.0
    # (radar east, north, up, floor^2, sigma_range^2): read once per report
    _consts: tuple[float, float, float, float, float] = field(
        init=False, repr=False, compare=False
    )

    def __post_init__(self) -> None:
        e0, n0, u0 = self.radar_enu
        consts = (e0, n0, u0, self.floor_m * self.floor_m, self.sigma_range_m * self.sigma_range_m)
        object.__setattr__(self, "_consts", consts)

    def r_at(self, e: float, n: float, u: float) -> PackedR:
        ce, cn, cu, f2, sr2 = self._consts  # the radar's position, floor^2, sigma_range^2
        de = e - ce
        dn = n - cn
        du = u - cu
        rho = math.hypot(de, dn)
        r = math.sqrt(rho * rho + du * du)
        if r < 1e-6:
            v = sr2 + f2
            return (v, 0.0, 0.0, v, 0.0, v)
        u0, u1, u2 = de / r, dn / r, du / r
        if rho > 1e-9:
            a0, a1 = -dn / rho, de / rho  # azimuth direction (horizontal)
            k = -du / (rho * r)
            l0, l1, l2 = de * k, dn * k, rho / r  # elevation direction
        else:  # straight above: azimuth undefined, use east/north as the cross axes
            a0, a1 = 1.0, 0.0
            l0, l1, l2 = 0.0, 1.0, 0.0
        saz = rho * self.sigma_az_rad
        sel = r * self.sigma_el_rad
        if self.low_el_gain:
            el_deg = math.degrees(math.atan2(abs(du), rho))
            sel *= 1.0 + self.low_el_gain * math.exp(-el_deg / self.low_el_deg)
        a2 = saz * saz
        e2 = sel * sel
        ra0, ra1, ra2 = sr2 * u0, sr2 * u1, sr2 * u2
        aa0, aa1 = a2 * a0, a2 * a1
        el0, el1, el2 = e2 * l0, e2 * l1, e2 * l2
        return (
            ra0 * u0 + aa0 * a0 + el0 * l0 + f2,
            ra0 * u1 + aa0 * a1 + el0 * l1,
            ra0 * u2 + el0 * l2,
            ra1 * u1 + aa1 * a1 + el1 * l1 + f2,
            ra1 * u2 + el1 * l2,
            ra2 * u2 + el2 * l2 + f2,
        )


@dataclass(frozen=True)
class RadarAlignment:
    """Correct the radar's mounting misalignment: every report is turned about the radar's
    phase centre by ``-az_bias_deg`` in azimuth (clockwise from north, as the radar measures
    it) and lowered by ``el_bias_deg`` in elevation, at its own range.

    The biases are what :func:`uav_fusion.core.scoring.calibration.radar_alignment` measures against
    RTK truth (median report-minus-truth azimuth and elevation). Only the position changes:
    the velocity is left as reported (a turn of half a degree moves a 15 m/s velocity by
    0.13 m/s, far inside its noise) and the geodetic fields keep the radar's own report. The
    trackers correct each report's position on the fly (:meth:`point`, no new report
    object); :meth:`track` and :meth:`frame` give the corrected reports themselves.
    """

    radar_enu: tuple[float, float, float]
    az_bias_deg: float
    el_bias_deg: float
    # (cos, sin) of the azimuth and of the elevation correction: read once per report
    _trig: tuple[float, float, float, float] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        a = math.radians(self.az_bias_deg)
        b = math.radians(self.el_bias_deg)
        object.__setattr__(self, "_trig", (math.cos(a), math.sin(a), math.cos(b), math.sin(b)))

    @property
    def active(self) -> bool:
        return bool(self.az_bias_deg or self.el_bias_deg)

    def point(self, e: float, n: float, u: float) -> tuple[float, float, float]:
        """A reported ENU position, corrected."""
        e0, n0, u0 = self.radar_enu
        ca, sa, cb, sb = self._trig
        de = e - e0
        dn = n - n0
        du = u - u0
        rho = math.sqrt(de * de + dn * dn)
        # the elevation lowered by el_bias at the same slant range: (rho, du) turned down
        k = (rho * cb + du * sb) / rho if rho > 1e-9 else 0.0
        return e0 + (de * ca - dn * sa) * k, n0 + (dn * ca + de * sa) * k, u0 + du * cb - rho * sb

    def track(self, trk: RadarTrack) -> RadarTrack:
        """One report, corrected (what the trackers see of it)."""
        e, n, u = self.point(trk.e, trk.n, trk.u)
        return replace(trk, e=e, n=n, u=u)

    def frame(self, frame: RadarFrame) -> RadarFrame:
        """Every report of a frame, corrected (the frame itself when there is nothing to do)."""
        if not frame.tracks or not self.active:
            return frame
        one = self.track
        return RadarFrame(frame.t, tuple([one(t) for t in frame.tracks]), frame.line)


@dataclass(frozen=True)
class CepRfR:
    """R of an RF fix from its CEP and its number of valid sensors.

    ``sigma = max(floor_m, scale * CEP / 1.1774) * (ref_sensors / valid_sensors) ** exponent``
    per axis (``R = sigma^2 I``): the CEP of the solver's geometry says how well the fix is
    conditioned; a fix from fewer sensors has no redundancy to catch a non-line-of-sight
    range, so it is trusted less. A fix without a CEP uses ``fallback``.
    """

    scale: float
    floor_m: float
    ref_sensors: int
    exponent: float
    fallback: PackedR

    def r_for(self, cep_m: float | None, valid_sensors: int | None) -> PackedR:
        if cep_m is None or not math.isfinite(cep_m) or cep_m <= 0:
            return self.fallback
        s = max(self.floor_m, self.scale * cep_m / CEP_PER_SIGMA)
        if valid_sensors is not None and valid_sensors > 0 and self.exponent != 0.0:
            s *= (self.ref_sensors / valid_sensors) ** self.exponent
        v = s * s
        return (v, 0.0, v)


def scale_packed(r: PackedR, factor: float) -> PackedR:
    """``factor * R`` of a packed covariance."""
    return tuple(factor * v for v in r)


def packed_to_array(r: PackedR) -> FloatArray:
    """Full symmetric array of a packed 2x2 (3 values) or 3x3 (6 values) covariance."""
    if len(r) == 3:
        return np.array([[r[0], r[1]], [r[1], r[2]]], dtype=float)
    if len(r) == 6:
        return np.array(
            [[r[0], r[1], r[2]], [r[1], r[3], r[4]], [r[2], r[4], r[5]]], dtype=float
        )
    raise ValueError(f"packed covariance must have 3 or 6 values, got {len(r)}")


# --- robust update ------------------------------------------------------------------------
class RobustWeight(Protocol):
    """Weight ``w`` in (0, 1] of a measurement from its NIS; the update then uses ``R / w``."""

    def weight(self, nis: float, dim: int) -> float: ...


@dataclass(frozen=True)
class NoRobust:
    """Plain Kalman update (w = 1)."""

    def weight(self, nis: float, dim: int) -> float:
        del nis, dim
        return 1.0


@dataclass(frozen=True)
class StudentTWeight:
    """Student-t scale-mixture weight ``w = (nu + m) / (nu + NIS)`` (m: measurement dimension).

    It is the expected precision scale of a Gaussian scale mixture with a Gamma(nu/2, nu/2)
    mixing density given the innovation, the single-iteration variational update of a
    Student-t measurement noise: ``w = 1`` at ``NIS = m`` (a typical innovation), smaller
    for larger innovations (an outlier is down-weighted, not only rejected), capped at
    ``max_weight`` so that an exceptionally small innovation does not over-trust the report.
    """

    dof: float
    max_weight: float = 1.0

    def weight(self, nis: float, dim: int) -> float:
        return min(self.max_weight, (self.dof + dim) / (self.dof + nis))


@dataclass(frozen=True)
class HuberWeight:
    """Huber weight on the Mahalanobis distance ``d = sqrt(NIS)``: 1 for ``d <= k``, ``k / d``
    beyond (the M-estimator's influence is bounded)."""

    k: float

    def weight(self, nis: float, dim: int) -> float:
        del dim
        d = math.sqrt(nis) if nis > 0 else 0.0
        return 1.0 if d <= self.k else self.k / d


# --- IMM transition matrix ----------------------------------------------------------------
def validate_transition(m: object, n_modes: int, where: str) -> tuple[tuple[float, ...], ...]:
    """A Markov transition matrix: ``n_modes`` x ``n_modes``, entries in [0, 1], rows summing
    to 1 (within 1e-9). Raises ValueError naming ``where`` and the fault."""
    try:
        a = np.asarray(m, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"{where}: must be a {n_modes}x{n_modes} matrix of numbers") from None
    if a.shape != (n_modes, n_modes):
        raise ValueError(f"{where}: must be {n_modes}x{n_modes} (one row per mode), got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{where}: entries must be finite")
    if np.any(a < 0) or np.any(a > 1):
        raise ValueError(f"{where}: entries must lie in [0, 1]")
    sums = a.sum(axis=1)
    bad = np.flatnonzero(np.abs(sums - 1.0) > 1e-9)
    if bad.size:
        i = int(bad[0])
        raise ValueError(f"{where}: row {i} sums to {sums[i]:.12g}, not 1")
    return tuple(tuple(float(v) for v in row) for row in a)


# --- track life cycle ---------------------------------------------------------------------
class MofN:
    """M-of-N confirmation: a candidate is confirmed by ``m`` hits among its first ``n``
    tests (the one that started it counts as a hit) and fails once that is out of reach."""

    __slots__ = ("hits", "m", "n", "tested")

    def __init__(self, m: int, n: int) -> None:
        if not 1 <= m <= n:
            raise ValueError(f"M-of-N needs 1 <= m <= n, got {m} of {n}")
        self.m = m
        self.n = n
        self.hits = 1
        self.tested = 1

    def record(self, hit: bool) -> str:
        """Record one test; returns ``confirmed``, ``failed`` or ``pending``."""
        self.tested += 1
        if hit:
            self.hits += 1
        if self.hits >= self.m:
            return "confirmed"
        if self.hits + (self.n - self.tested) < self.m:
            return "failed"
        return "pending"

    @property
    def confirmed(self) -> bool:
        return self.hits >= self.m


@dataclass(frozen=True)
class Deleter:
    """When a confirmed track is dropped: nothing accepted for ``max_coast_s`` or
    ``max_consecutive_rejections`` gate failures in a row (None: no limit)."""

    max_coast_s: float | None
    max_consecutive_rejections: int | None

    def coast_expired(self, t: float, last_used_t: float | None) -> bool:
        return (
            self.max_coast_s is not None
            and last_used_t is not None
            and t - last_used_t > self.max_coast_s
        )

    def too_many_rejections(self, consecutive: int) -> bool:
        n = self.max_consecutive_rejections
        return n is not None and consecutive >= n


def packed_r(R: FloatArray | Sequence[Sequence[float]]) -> PackedR:
    """``pack_r`` re-exported for callers that build a fixed model from a matrix."""
    return pack_r(np.asarray(R, dtype=float))
