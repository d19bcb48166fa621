"""Online radar registration: the mount's azimuth misalignment from the RF fixes credited to
the radar object the UAV track follows (core/estimators/registration.py)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from test_tracker import Scene

from uav_fusion.core.estimators import load_profile
from uav_fusion.core.estimators.offline import run_tracker
from uav_fusion.core.estimators.parts import RadarAlignment
from uav_fusion.core.estimators.registration import (
    GATE_SIGMAS,
    HUBER_K,
    MIN_RANGE_M,
    Registration,
)
from uav_fusion.core.estimators.tracker import Tracker
from uav_fusion.core.records import RadarFrame, RfAttempt
from uav_fusion.core.site import RadarCalibration, Site, load_site


@pytest.fixture(scope="module")
def site() -> Site:
    return load_site()


class WideLoop(Scene):
    """The UAV on a 1 km circle about the radar at 60 m: 0.5 deg is 8.7 m across the beam."""

    def uav(self, t: float) -> np.ndarray:
        a = 0.008 * t
        return self.r0 + np.array(
            [1000.0 * math.cos(a), 1000.0 * math.sin(a), 60.0], dtype=np.float64
        )


def _skewed(site: Site, seed: int, az_deg: float) -> list[RadarFrame | RfAttempt]:
    sc = WideLoop(site, seed=seed)
    sc.build(400.0)
    r0 = (float(sc.r0[0]), float(sc.r0[1]), float(sc.r0[2]))
    skew = RadarAlignment(r0, -az_deg, 0.0)  # the radar reads every azimuth az_deg too large
    return [skew.frame(x) if isinstance(x, RadarFrame) else x for x in sc.stream()]


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_registration_recovers_a_half_degree_mount_misalignment(site: Site, seed: int) -> None:
    tr = Tracker(load_profile("tracker"), site)  # the shipped site: uncalibrated, 0 +- 1 deg
    run_tracker(tr, _skewed(site, seed, 0.5))
    reg = tr.front.registration
    assert reg.used > 80 and reg.refused == 0  # about one fix every 4 s
    assert abs(reg.az_deg - 0.5) < 0.1
    # and it knows it: about 0.1 degree from ~96 fixes and the radar's 2-degree reports,
    # and the error lies within two of its sigmas
    assert reg.sigma_deg < 0.12 and abs(reg.az_deg - 0.5) < 2.0 * reg.sigma_deg
    # the correction follows the estimate, and /diagnostics shows it
    assert tr.front.align is not None and tr.front.align.az_bias_deg == reg.az_deg
    status = tr.status()
    assert status["registration_az_deg"] == f"{reg.az_deg:+.3f}"
    assert status["registration_fixes_used"] == reg.used


def test_an_unbiased_radar_stays_registered_at_zero(site: Site) -> None:
    tr = Tracker(load_profile("tracker"), site)
    run_tracker(tr, _skewed(site, 4, 0.0))
    assert abs(tr.front.registration.az_deg) < 0.1


def _pair(reg: Registration, az_deg: float, rng: np.random.Generator, rho: float = 800.0) -> bool:
    """An object and a fix 800 m north-east of the radar; the object's reports read ``az_deg``
    too far clockwise and are corrected by the current estimate (fix noise 5 m per axis)."""
    rx, ry, _ = reg.radar_enu
    b = math.radians(45.0)
    fe, fn = rng.normal(0.0, 5.0, 2)
    fix = (rx + rho * math.sin(b) + fe, ry + rho * math.cos(b) + fn)
    o = b + math.radians(az_deg - reg.az_deg)
    return reg.pair((rx + rho * math.sin(o), ry + rho * math.cos(o)), fix, 25.0, 1.0)


def test_a_fix_far_off_the_estimate_is_refused_and_changes_nothing() -> None:
    rng = np.random.default_rng(0)
    reg = Registration((0.0, 0.0, 10.0), RadarCalibration())
    for _ in range(100):
        assert _pair(reg, 0.8, rng)
    assert abs(reg.az_deg - 0.8) < 0.1
    before = (reg.az_deg, reg.var_deg2)
    # a non-line-of-sight fix 60 m off across the beam: over 10 sigmas
    assert not _pair(reg, 0.8 + math.degrees(60.0 / 800.0), rng)
    assert reg.refused == 1 and (reg.az_deg, reg.var_deg2) == before
    # the gate's edge: just inside three sigmas is used (down-weighted), just outside is not
    s = math.sqrt(reg.var_deg2 + math.degrees(1.0) ** 2 * 26.0 / 800.0**2)
    exact = Registration((0.0, 0.0, 10.0), RadarCalibration(0.0, 0.0, reg.sigma_deg))
    rx = 800.0 * math.sin(math.radians(45.0))
    fix = (rx, rx)

    def at(k: float) -> bool:
        o = math.radians(45.0 + k * s)
        return exact.pair((800.0 * math.sin(o), 800.0 * math.cos(o)), fix, 25.0, 1.0)

    assert not at(GATE_SIGMAS + 0.01) and at(GATE_SIGMAS - 0.01)


def test_a_surveyed_mount_is_not_refined_and_close_fixes_say_nothing() -> None:
    rng = np.random.default_rng(1)
    surveyed = Registration((0.0, 0.0, 10.0), RadarCalibration(0.3, 0.1, 0.0, 0.0))
    assert not _pair(surveyed, 1.0, rng) and surveyed.az_deg == 0.3 and surveyed.el_deg == 0.1
    reg = Registration((0.0, 0.0, 10.0), RadarCalibration())
    assert not _pair(reg, 1.0, rng, rho=MIN_RANGE_M - 5.0)
    assert reg.used == 0 and reg.az_deg == 0.0
    assert _pair(reg, 1.0, rng, rho=MIN_RANGE_M + 50.0)


def _run_errors(errors_m: np.ndarray, stated_sd_m: float, az_deg: float = 0.5) -> Registration:
    """Pairs 800 m out whose fixes are off across the beam by ``errors_m`` (one per pair),
    each stated with ``stated_sd_m`` per axis."""
    reg = Registration((0.0, 0.0, 10.0), RadarCalibration())
    rho, b = 800.0, math.radians(45.0)
    for err in errors_m:
        fa = b + float(err) / rho  # the fix's azimuth, off by err across the beam
        fix = (rho * math.sin(fa), rho * math.cos(fa))
        o = b + math.radians(az_deg - reg.az_deg)
        reg.pair((rho * math.sin(o), rho * math.cos(o)), fix, stated_sd_m**2, 1.0)
    return reg


def _ar1(rng: np.random.Generator, n: int, sd: float, r: float) -> np.ndarray:
    out = np.empty(n)
    out[0] = rng.normal(0.0, sd)
    for k in range(1, n):
        out[k] = r * out[k - 1] + rng.normal(0.0, sd * math.sqrt(1.0 - r * r))
    return out


def test_the_bound_is_the_sigma_for_independent_errors_and_wider_for_correlated_ones() -> None:
    rng = np.random.default_rng(5)
    # independent errors as stated: the bound is the estimate's own sigma, about
    reg = _run_errors(rng.normal(0.0, 8.0, 400), 8.0)
    ms, r = reg.residual_stats
    assert 0.8 < ms < 1.2 and abs(r) < 0.15
    assert reg.sigma_deg <= reg.bound_deg < 1.2 * reg.sigma_deg
    # errors twice as large as stated: Huber's weight widens the sigma part of the way, the
    # residuals' mean square the rest
    reg = _run_errors(rng.normal(0.0, 8.0, 400), 4.0)
    assert reg.residual_stats[0] > 1.3 and reg.bound_deg > 1.2 * reg.sigma_deg
    # errors correlated from fix to fix (lag-one 0.8): (1 + 0.8) / (1 - 0.8) = 9 in variance
    reg = _run_errors(_ar1(rng, 400, 8.0, 0.8), 8.0)
    assert 0.7 < reg.residual_stats[1] < 0.9
    assert 2.4 < reg.bound_deg / reg.sigma_deg < 3.6
    assert reg.status()["registration_az_bound_deg"] == f"{reg.bound_deg:.3f}"


def test_with_correlated_errors_the_bound_holds_the_truth_where_the_sigma_does_not() -> None:
    rng = np.random.default_rng(6)
    in_sigma = in_bound = 0
    for _ in range(40):
        reg = _run_errors(_ar1(rng, 200, 8.0, 0.9), 8.0)
        err = abs(reg.az_deg - 0.5)
        in_sigma += err <= 2.0 * reg.sigma_deg
        in_bound += err <= 2.0 * reg.bound_deg
    assert in_bound >= 34 and in_sigma <= 30  # 2 sigmas: 95 % if honest


def test_a_measurement_beyond_huber_k_sigmas_is_down_weighted() -> None:
    """Huber's weight at its edge: a measurement just inside ``HUBER_K`` sigmas of the
    estimate moves it by the plain Kalman gain; one just beyond moves it by the gain of a
    variance inflated by ``a / HUBER_K`` (``a`` its distance in sigmas)."""
    cal = RadarCalibration(0.0, 0.0, 0.2)
    rho = 800.0
    meas_var = math.degrees(1.0) ** 2 * 26.0 / rho**2  # fix 25 m^2 + object 1 m^2 per axis
    s = math.sqrt(meas_var + 0.2**2)
    rx = rho * math.sin(math.radians(45.0))
    for k, inflated in ((HUBER_K - 0.01, False), (HUBER_K + 0.01, True)):
        reg = Registration((0.0, 0.0, 10.0), cal)
        o = math.radians(45.0 + k * s)
        assert reg.pair((rho * math.sin(o), rho * math.cos(o)), (rx, rx), 25.0, 1.0)
        var = meas_var * (k / HUBER_K if inflated else 1.0)
        want = 0.2**2 / (var + 0.2**2) * k * s
        assert reg.az_deg == pytest.approx(want, rel=1e-6)
