"""Online registration of the radar against the RF fixes: the mount's azimuth misalignment.

A radar whose array normal is turned by ``b`` reads every azimuth ``b`` too large. The site
file gives the misalignment the deployment was calibrated with and how well it is known
(:class:`~uav_fusion.core.site.RadarCalibration`, 0 +- 1 degree uncalibrated); the trackers
correct every report by the current estimate (:class:`~uav_fusion.core.estimators.parts.
RadarAlignment`). :class:`Registration` refines the azimuth within the flight: every RF fix
credited to the radar object the UAV track follows (the fix and the object agree within the
object table's gate) is a measurement of the remaining misalignment,

    b  ~  b_applied + (az(object) - az(fix))      (both seen from the radar),

with variance ``(sigma_rf^2 + sigma_obj^2) / rho^2`` at horizontal range ``rho``
(``sigma_rf`` the fix's own, from its CEP; ``sigma_obj`` the object's own position variance
across the line of sight, from its filter, and never below what one report's azimuth sigma
averaged over the object's reports allows). A scalar Kalman filter (a constant: a mount does not
move) fuses them; a measurement more than three sigmas from the estimate is refused (an RF fix
bent by a non-line-of-sight path). Fixes within ``MIN_RANGE_M`` of the radar say nothing of an
angle and are not used. The variance of the estimate is the Cramér-Rao bound of the measurements
it used if their errors were independent. They are not: a fix's error comes from the
sensors' geometry and the paths around them, which change slowly along a flight. The bound of
the data the flight actually gave (:attr:`Registration.bound_deg`) widens that variance by
what the used measurements themselves show about the end estimate ``b``: their normalised
residuals ``e_i = (z_i - b) / s_i`` (``s_i`` the sigma each was used with) have a mean square
``m`` (above 1: noisier than their stated variances) and a lag-one autocorrelation ``r``,
and for errors correlated as a first-order autoregression the variance of the mean of ``n``
of them is ``(1 + r) / (1 - r)`` times that of independent ones, so

    bound^2 = var * max(1, m) * (1 + r) / (1 - r)      (r within [0, RHO_MAX]).

Running sums keep it exact at constant memory (expanded about ``b``).

The elevation has no second sensor to be registered against (the RF fixes are 2D): it stays
at the site file's calibration.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from uav_fusion.core.site import RadarCalibration

#: Horizontal distance from the radar below which a fix says nothing of an azimuth (m).
MIN_RANGE_M = 100.0
#: Refuse a measurement further than this many sigmas from the estimate.
GATE_SIGMAS = 3.0
#: Beyond this many sigmas a measurement is down-weighted (Huber's weight).
HUBER_K = 1.5
#: The largest lag-one autocorrelation the bound takes (its factor is then 39).
RHO_MAX = 0.95


@dataclass
class Registration:
    """The mount's azimuth misalignment, estimated online (see the module text)."""

    radar_enu: tuple[float, float, float]
    calibration: RadarCalibration
    az_deg: float = 0.0
    var_deg2: float = 1.0
    used: int = 0
    refused: int = 0
    # running sums over the used measurements z (deg) with sigmas s: of 1/s^2, z/s^2, z^2/s^2
    # and, for consecutive pairs (i, i+1), of 1/(s_i s_j), (z_i + z_j)/(s_i s_j), z_i z_j/(s_i s_j)
    _sums: tuple[float, float, float, float, float, float] = (0.0,) * 6
    _last: tuple[float, float] | None = None  # the last used (z, s)

    def __post_init__(self) -> None:
        self.az_deg = self.calibration.az_bias_deg
        self.var_deg2 = self.calibration.az_sigma_deg**2

    @property
    def el_deg(self) -> float:
        """The elevation misalignment: the site's calibration."""
        return self.calibration.el_bias_deg

    @property
    def sigma_deg(self) -> float:
        return math.sqrt(self.var_deg2)

    def pair(
        self,
        object_en: tuple[float, float],
        fix_en: tuple[float, float],
        fix_var_m2: float,
        object_var_m2: float,
    ) -> bool:
        """One RF fix (east, north; its variance per axis) and the horizontal position the
        radar object it belongs to had then, corrected by the current estimate, with that
        position's variance across the line of sight; True when it was used."""
        if self.var_deg2 <= 0.0:  # the site states it exactly: nothing to refine
            return False
        rx, ry, _ = self.radar_enu
        oe, on = object_en[0] - rx, object_en[1] - ry
        fe, fn = fix_en[0] - rx, fix_en[1] - ry
        rho = math.hypot(fe, fn)
        if rho < MIN_RANGE_M or math.hypot(oe, on) < MIN_RANGE_M:
            return False
        resid = math.atan2(oe, on) - math.atan2(fe, fn)
        resid = (resid + math.pi) % (2.0 * math.pi) - math.pi
        z = self.az_deg + math.degrees(resid)
        var = math.degrees(1.0) ** 2 * (fix_var_m2 + object_var_m2) / rho**2
        y = z - self.az_deg
        s = var + self.var_deg2
        if y * y > GATE_SIGMAS**2 * s:
            self.refused += 1
            return False
        a = abs(y) / math.sqrt(s)
        if a > HUBER_K:  # heavy tails (a fix bent by its path): down-weighted, Huber
            var *= a / HUBER_K
            s = var + self.var_deg2
        k = self.var_deg2 / s
        self.az_deg += k * y
        self.var_deg2 *= 1.0 - k
        self.used += 1
        self._remember(z, math.sqrt(var))
        return True

    def _remember(self, z: float, sd: float) -> None:
        w0, w1, w2, p0, p1, p2 = self._sums
        w = 1.0 / (sd * sd)
        w0, w1, w2 = w0 + w, w1 + z * w, w2 + z * z * w
        if self._last is not None:
            zl, sl = self._last
            c = 1.0 / (sl * sd)
            p0, p1, p2 = p0 + c, p1 + (zl + z) * c, p2 + zl * z * c
        self._sums = (w0, w1, w2, p0, p1, p2)
        self._last = (z, sd)

    @property
    def residual_stats(self) -> tuple[float, float]:
        """The used measurements' normalised residuals about the estimate: their mean square
        and lag-one autocorrelation (nan with fewer than three)."""
        if self.used < 3:
            return math.nan, math.nan
        w0, w1, w2, p0, p1, p2 = self._sums
        b = self.az_deg
        sq = w2 - 2.0 * b * w1 + b * b * w0  # sum of e_i^2
        lag = p2 - b * p1 + b * b * p0  # sum of e_i e_(i+1)
        if not sq > 0.0:
            return 0.0, 0.0
        return sq / self.used, lag / sq

    @property
    def bound_deg(self) -> float:
        """The bound of this flight's data on the azimuth (module text): the estimate's
        sigma widened for residuals noisier and more correlated than independent ones."""
        ms, rho = self.residual_stats
        if not math.isfinite(ms):
            return self.sigma_deg
        rho = min(max(rho, 0.0), RHO_MAX)
        return math.sqrt(self.var_deg2 * max(1.0, ms) * (1.0 + rho) / (1.0 - rho))

    def status(self) -> dict[str, object]:
        """For /diagnostics."""
        return {
            "registration_az_deg": f"{self.az_deg:+.3f}",
            "registration_az_sigma_deg": f"{self.sigma_deg:.3f}",
            "registration_az_bound_deg": f"{self.bound_deg:.3f}",
            "registration_el_deg": f"{self.el_deg:+.3f}",
            "registration_fixes_used": self.used,
            "registration_fixes_refused": self.refused,
        }
