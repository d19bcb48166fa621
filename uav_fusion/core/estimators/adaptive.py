"""Adaptive measurement noise: each sensor's R estimated online, inside bounds set by the
sensor's specification.

**White noise, from the UAV track's own innovations (covariance matching).** For an update
with innovation ``nu = z - H x-`` and predicted position covariance ``P-``, the innovation
covariance is ``H P- H^T + R``, so along a unit vector ``u`` of one of the sensor's error axes
``(u . nu)^2 - u^T P- u`` is an unbiased sample of that axis's measurement variance. A channel
averages its samples (a running mean over the first ``window``, the specification counting
as one sample, then an exponential average over ``window``); its sigma is the square root,
held within ``[spec, spec * bound]``. ``spec`` is the profile's value (the sensor's specified
accuracy). The estimate may show a sensor worse than specified, never better: errors that are
correlated from report to report make the innovations smaller than the errors (the track
follows them), so a sensor that looks better than its datasheet is one whose errors the
innovations cannot see.

- **Radar** (:class:`AdaptiveRadarR`): three channels of the polar model, the range in
  metres and the azimuth and elevation in radians (a sample across the line of sight is
  divided by the horizontal range, or by the slant range).
- **RF** (:class:`AdaptiveRfR`): one channel, the scale of each fix's CEP-derived sigma (the
  mean of the east and north samples divided by the fix's unit variance ``(CEP /
  1.1774)^2``), from fixes that update a track the radar does not hold.

**Errors correlated over seconds, from an independent sensor.** The radar's reports come from
its onboard tracker, and their errors persist for seconds (smoothing, glint); a filter that
takes them as independent becomes overconfident. The polar R carries a per-axis allowance
``f`` for them (what a fixed ``floor_m`` was), which the RF fixes check: a fix that updates
a track the radar holds (a 3D radar update within the radar's longest update interval, 1.3 s
by its datasheet) has independent errors, so its normalised innovation squared should be 2
on average. Each such fix moves ``log f`` by ``0.1 (min(NIS / 2, 5) - 1)``, within ``[f0 /
bound, f0 * bound]``; ``f0``, the start, is the specified azimuth sigma's cross-range error at
the edge of the 3D range gate. The RF fixes are 2D: the same ``f`` serves the vertical.

Only updates inside the NIS gate feed the estimates, so a wrong association or a
non-line-of-sight fix the gate refuses does not inflate them.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING

from uav_fusion.core.estimators.kalman import UPPER_INDEX, MotionFilter

if TYPE_CHECKING:
    from uav_fusion.core.estimators.parts import CepRfR, PolarRadarR

# the CEP of a circular Gaussian is 1.1774 sigma (sqrt(2 ln 2))
CEP_PER_SIGMA = math.sqrt(2.0 * math.log(2.0))

#: a 3D radar update this recent (s) makes the track the radar's: the radar's longest track
#: update interval (datasheet: 64 ms - 1.3 s)
HELD_S = 1.3

_PE, _PN, _PU = UPPER_INDEX[0][0], UPPER_INDEX[1][1], UPPER_INDEX[2][2]
_PEN, _PEU, _PNU = UPPER_INDEX[0][1], UPPER_INDEX[0][2], UPPER_INDEX[1][2]


@dataclass
class NoiseChannel:
    """The online variance of one error axis (see the module text)."""

    spec: float  # the specified sigma: the prior and the lower bound
    bound: float  # sigma stays within [spec, spec * bound]
    window: int  # samples averaged (a running mean up to here, then an exponential one)
    var: float = field(init=False)
    n: int = 0

    def __post_init__(self) -> None:
        self.var = self.spec * self.spec  # the specification counts as one sample

    def observe(self, sample: float) -> None:
        """One sample of the variance (may be negative: only the average is meaningful)."""
        if not math.isfinite(sample):
            return
        self.n += 1
        self.var += (sample - self.var) / min(self.n + 1, self.window)

    @property
    def sigma(self) -> float:
        return min(self.spec * self.bound, max(self.spec, math.sqrt(max(self.var, 0.0))))

    @property
    def held(self) -> bool:
        """Whether the estimate is at one of its bounds."""
        s = math.sqrt(max(self.var, 0.0))
        return not self.spec < s < self.spec * self.bound


def _axis_var(p: Sequence[float], a: tuple[float, float, float]) -> float:
    """``a^T P a`` of the position block of a packed 6-state covariance."""
    a0, a1, a2 = a
    return (
        a0 * a0 * p[_PE] + a1 * a1 * p[_PN] + a2 * a2 * p[_PU]
        + 2.0 * (a0 * a1 * p[_PEN] + a0 * a2 * p[_PEU] + a1 * a2 * p[_PNU])
    )  # fmt: skip


class AdaptiveRadarR:
    """The polar radar R with online sigmas and an RF-checked allowance (see the module
    text); reads like :class:`~uav_fusion.core.estimators.parts.PolarRadarR` (``r_at``)."""

    #: the allowance's step per RF check, in log units per unit of excess NIS / 2
    GAIN = 0.1

    def __init__(self, spec: PolarRadarR, window: int, bound: float, gate_m: float) -> None:
        self.range = NoiseChannel(spec.sigma_range_m, bound, window)
        self.az = NoiseChannel(spec.sigma_az_rad, bound, window)
        self.el = NoiseChannel(spec.sigma_el_rad, bound, window)
        f0 = spec.sigma_az_rad * gate_m
        self._log_f = math.log(f0)
        self._log_bounds = (math.log(f0 / bound), math.log(f0 * bound))
        self.checks = 0
        self.model = replace(spec, floor_m=f0)
        self.r_at = self.model.r_at

    @property
    def floor_m(self) -> float:
        """The current allowance for correlated errors (m per axis)."""
        return self.model.floor_m

    def check(self, nis: float, dim: int) -> None:
        """An RF fix updated a track the radar holds, with this NIS (before the update)."""
        if not math.isfinite(nis):
            return
        lo, hi = self._log_bounds
        self._log_f = min(hi, max(lo, self._log_f + self.GAIN * (min(nis / dim, 5.0) - 1.0)))
        self.checks += 1
        self.model = replace(self.model, floor_m=math.exp(self._log_f))
        self.r_at = self.model.r_at

    def observe(self, z: Sequence[float], x: Sequence[float], p: Sequence[float]) -> None:
        """A 3D update of the UAV track with report ``z`` (aligned ENU), from the predicted
        state ``x`` (position first) and packed covariance ``p``."""
        m = self.model
        ce, cn, cu = m.radar_enu
        de, dn, du = z[0] - ce, z[1] - cn, z[2] - cu
        rho = math.hypot(de, dn)
        r = math.sqrt(rho * rho + du * du)
        if rho < 1.0:  # overhead: azimuth and elevation axes undefined
            return
        k = -du / (rho * r)
        nu = (z[0] - x[0], z[1] - x[1], z[2] - x[2])
        axes = (
            (self.range, (de / r, dn / r, du / r), 1.0),
            (self.az, (-dn / rho, de / rho, 0.0), rho),
            (self.el, (de * k, dn * k, rho / r), r),
        )
        for ch, a, scale in axes:
            d = a[0] * nu[0] + a[1] * nu[1] + a[2] * nu[2]
            ch.observe((d * d - _axis_var(p, a)) / (scale * scale))
        sr, sa, se = self.range.sigma, self.az.sigma, self.el.sigma
        if (sr, sa, se) != (m.sigma_range_m, m.sigma_az_rad, m.sigma_el_rad):
            self.model = replace(m, sigma_range_m=sr, sigma_az_rad=sa, sigma_el_rad=se)
            self.r_at = self.model.r_at

    def status(self) -> dict[str, object]:
        """The estimates, for /diagnostics."""
        return {
            "radar_sigma_range_m": round(self.range.sigma, 3),
            "radar_sigma_az_deg": round(math.degrees(self.az.sigma), 3),
            "radar_sigma_el_deg": round(math.degrees(self.el.sigma), 3),
            "radar_noise_samples": self.range.n,
            "radar_allowance_m": round(self.floor_m, 2),
            "radar_allowance_checks": self.checks,
        }


class AdaptiveRfR:
    """The CEP-based RF R with an online CEP scale (see the module text); reads like
    :class:`~uav_fusion.core.estimators.parts.CepRfR` (``r_for``)."""

    def __init__(self, spec: CepRfR, window: int, bound: float) -> None:
        self.scale = NoiseChannel(spec.scale, bound, window)
        self.model = spec
        self.r_for = spec.r_for

    def observe(
        self, z: Sequence[float], x: Sequence[float], p: Sequence[float], cep_m: float | None
    ) -> None:
        """An update of the UAV track with the fix ``z`` (east, north) of CEP ``cep_m``."""
        if cep_m is None or not (math.isfinite(cep_m) and cep_m > 0):
            return
        ne, nn = z[0] - x[0], z[1] - x[1]
        var = 0.5 * (ne * ne - p[_PE] + nn * nn - p[_PN])
        unit = cep_m / CEP_PER_SIGMA
        scale = self.scale
        # the channel holds the variance of the scale: sigma = scale * CEP / 1.1774
        scale.observe(var / (unit * unit))
        if scale.sigma != self.model.scale:
            self.model = replace(self.model, scale=scale.sigma)
            self.r_for = self.model.r_for

    def status(self) -> dict[str, object]:
        return {"rf_cep_scale": round(self.scale.sigma, 3), "rf_noise_samples": self.scale.n}


def observe_rf_fix(
    radar: AdaptiveRadarR | None,
    rf: AdaptiveRfR | None,
    last_radar_t: float | None,
    t: float,
    f: MotionFilter,
    z: Sequence[float],
    nis: float,
    cep_m: float | None,
) -> None:
    """An RF fix about to update a confirmed UAV track (filter ``f``, the fix's NIS ``nis``):
    while the radar holds the track (an update within HELD_S) the fix checks the radar's
    allowance for correlated errors; otherwise its innovation is a sample of the RF noise."""
    if last_radar_t is not None and t - last_radar_t <= HELD_S:
        if radar is not None:
            radar.check(nis, 2)
    elif rf is not None:
        rf.observe(z, *f.mean(), cep_m)


def rf_status(rf: AdaptiveRfR | None) -> dict[str, object]:
    """The RF noise estimate's status, or nothing without one."""
    return rf.status() if rf is not None else {}


__all__ = [
    "CEP_PER_SIGMA", "HELD_S", "AdaptiveRadarR", "AdaptiveRfR", "NoiseChannel", "observe_rf_fix",
    "rf_status",
]
