"""The published covariance's consider term for the radar's elevation error.

The radar's reports come from its onboard tracking filter (as the paper notes of the R20), so
their elevation errors are correlated over seconds, and part of them varies slowly or not at
all (ground multipath, a tilted mount). The filter treats the reports as independent, and its
stiff vertical averages many of them, so its vertical variance shrinks far below the error
that averaging cannot remove. The filter does not estimate that error (nothing but the radar
measures height), so, as in a consider (Schmidt) covariance analysis, the covariance it
*publishes* adds the variance that error gives the height, and the state, the gain and
every decision stay as they are:

    P_up,up  +=  (sigma_el * r)^2

``sigma_el`` is the radar's elevation accuracy (``measurement.radar.sigma_el_deg``, the
datasheet's) and ``r`` the horizontal distance from the radar to the estimate: an
elevation error ``d`` moves a report's height by ``r * d``. It applies to the trackers'
outputs with the polar radar model, the only one that knows the radar's angles; the paper's
filter (a fixed R) publishes its own covariance.

Pure Python, no ROS.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from uav_fusion.core.estimators.kalman import UPPER_INDEX
from uav_fusion.core.profiles.model import Profile
from uav_fusion.core.site import Site

FloatArray = npt.NDArray[np.float64]
#: Index of the up-up variance in a step's packed values (6 state values, then P's upper
#: triangle row by row).
UP_UP = 6 + UPPER_INDEX[2][2]


@dataclass(frozen=True)
class ElevationConsider:
    """Adds the height variance of the radar's elevation error to a published covariance."""

    east_m: float  # the radar's position (ENU)
    north_m: float
    sigma_el_rad: float

    def variance(self, east: float, north: float) -> float:
        """The height variance an elevation error of ``sigma_el`` gives at (east, north)."""
        r = math.hypot(east - self.east_m, north - self.north_m)
        return (self.sigma_el_rad * r) ** 2

    def cov(self, x: FloatArray, P: FloatArray) -> FloatArray:
        """``P`` (6x6, or its 3x3 position block) with the term on its up-up variance; a
        copy, ``P`` itself is left as it is. NaN states (no track) pass through."""
        out = np.array(P, dtype=float)
        out[2, 2] += self.variance(float(x[0]), float(x[1]))
        return out

    def values(self, v: tuple[float, ...]) -> tuple[float, ...]:
        """A step's packed values (state, then the upper triangle of P) with the term."""
        out = list(v)
        out[UP_UP] += self.variance(v[0], v[1])
        return tuple(out)


def consider_for(profile: Profile, site: Site) -> ElevationConsider | None:
    """The consider term of ``profile``'s outputs at ``site``: None for the paper's filter or
    a fixed radar R, and for an elevation sigma of 0."""
    if not profile.uses_tracker or profile.radar_model != "polar":
        return None
    sigma = math.radians(profile.radar_sigma_el_deg)
    if not sigma > 0:
        return None
    e, n, _ = site.radar.enu
    return ElevationConsider(float(e), float(n), sigma)


def published_cov(
    profile: Profile, site: Site
) -> Callable[[FloatArray, FloatArray], FloatArray] | None:
    """``consider(x, P)`` for a fixed-rate output of ``profile`` at ``site`` (None: none)."""
    c = consider_for(profile, site)
    return c.cov if c is not None else None
