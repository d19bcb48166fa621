"""The published covariance's consider term (uav_fusion.core.estimators.consider): the height
variance of the radar's elevation error, added to what the trackers publish, with the state,
the filter and every decision left as they are."""

from __future__ import annotations

import math

import numpy as np
import pytest

from uav_fusion.core.data import load_flight
from uav_fusion.core.estimators import load_profile, run_flight
from uav_fusion.core.estimators.consider import (
    UP_UP,
    ElevationConsider,
    consider_for,
    published_cov,
)
from uav_fusion.core.estimators.kalman import UPPER_INDEX
from uav_fusion.core.scoring.fixed_rate import FlightTruth, grid_from_steps
from uav_fusion.core.site import load_site
from uav_fusion.resources import DEFAULT_FLIGHT, data_path

SIG = math.radians(2.0)


def _packed(x: np.ndarray, P: np.ndarray) -> tuple[float, ...]:
    upper = [0.0] * 21
    for i in range(6):
        for j in range(i, 6):
            upper[UPPER_INDEX[i][j]] = float(P[i, j])
    return (*x.tolist(), *upper)


def test_the_term_is_the_height_variance_of_the_elevation_sigma_at_the_ground_range() -> None:
    c = ElevationConsider(100.0, -50.0, SIG)
    x = np.array([100.0 + 600.0, -50.0 + 800.0, 70.0, 5.0, -3.0, 0.5])  # 1000 m away
    rng = np.random.default_rng(1)
    A = rng.normal(size=(6, 6))
    P = A @ A.T + np.eye(6)
    before = P.copy()
    out = c.cov(x, P)
    want = (SIG * 1000.0) ** 2  # 34.9 m: an elevation error of 2 deg at 1 km
    assert out[2, 2] == pytest.approx(P[2, 2] + want, rel=1e-12)
    mask = np.ones((6, 6), dtype=bool)
    mask[2, 2] = False
    assert np.array_equal(out[mask], P[mask])  # nothing else moves
    assert np.array_equal(P, before)  # a copy: the filter's P is left as it is
    # the height does not enter: only the ground range does; at the radar the term is 0
    assert c.variance(100.0, -50.0) == 0.0
    assert c.variance(100.0, 450.0) == pytest.approx((SIG * 500.0) ** 2)
    # a step's packed values get the same term, in the same place
    v = c.values(_packed(x, P))
    assert v[UP_UP] == pytest.approx(out[2, 2], rel=1e-12)
    assert v[:UP_UP] + v[UP_UP + 1 :] == _packed(x, P)[:UP_UP] + _packed(x, P)[UP_UP + 1 :]


def test_only_the_trackers_with_the_polar_radar_model_publish_the_term() -> None:
    site = load_site()
    tracker = load_profile("tracker")
    c = consider_for(tracker, site)
    assert c is not None
    assert (c.east_m, c.north_m) == (site.radar.enu[0], site.radar.enu[1])
    assert c.sigma_el_rad == pytest.approx(math.radians(tracker.radar_sigma_el_deg))
    assert consider_for(load_profile("paper"), site) is None  # the paper's own covariance
    no_el = tracker.with_changes(adaptive_window=None, radar_sigma_el_deg=0.0)
    assert consider_for(no_el, site) is None


def test_the_fixed_rate_output_keeps_its_states_and_adds_the_term_to_the_filter_cov() -> None:
    site = load_site()
    prof = load_profile("tracker")
    flight = load_flight(data_path(DEFAULT_FLIGHT), site)
    steps = run_flight(flight, prof, site).steps
    t0, t1 = FlightTruth.from_flight(flight, site).span
    t1 = min(t1, t0 + 300.0)
    plain = grid_from_steps(steps, prof, 10.0, t0, t1)
    pub = grid_from_steps(steps, prof, 10.0, t0, t1, consider=published_cov(prof, site))
    ok = pub.published
    assert ok.sum() > 1000 and np.array_equal(ok, plain.published)
    assert np.array_equal(pub.x[ok], plain.x[ok])  # the estimate is the filter's
    c = consider_for(prof, site)
    assert c is not None
    want = np.array([c.variance(e, n) for e, n in pub.x[ok, :2]])
    assert np.allclose(pub.P[ok, 2, 2] - plain.P[ok, 2, 2], want, rtol=1e-9)
    assert np.array_equal(pub.P[ok][:, :2, :], plain.P[ok][:, :2, :])
    # the term dominates the stiff vertical's variance: what the filter cannot average away
    assert np.median(want) > 4.0 * np.median(plain.P[ok, 2, 2])
