"""Adaptive measurement noise (core/estimators/adaptive.py): covariance matching converges to
a known sigma on a synthetic stream, stays inside its specification's bounds, and a profile
that asks for it with an inconsistent key stops with the file and the key named."""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml

from uav_fusion.core.data import load_flight
from uav_fusion.core.errors import ConfigError
from uav_fusion.core.estimators import load_profile, run_flight
from uav_fusion.core.estimators.adaptive import (
    CEP_PER_SIGMA,
    HELD_S,
    AdaptiveRadarR,
    AdaptiveRfR,
    NoiseChannel,
    observe_rf_fix,
)
from uav_fusion.core.estimators.kalman import CvFilter
from uav_fusion.core.estimators.parts import CepRfR, PolarRadarR
from uav_fusion.core.profiles.model import profile_from_dict
from uav_fusion.core.site import load_site
from uav_fusion.resources import data_path

RADAR = (0.0, 0.0, 2.0)


def _polar_reports(
    n: int, s_r: float, s_az: float, s_el: float, seed: int
) -> tuple[np.ndarray, np.ndarray]:
    """A UAV on a slow circle ~600 m from the radar at 80 m, 1 Hz, and its reports with white
    polar errors (range m, azimuth and elevation rad)."""
    rng = np.random.default_rng(seed)
    t = np.arange(n, dtype=float)
    ang = 0.01 * t
    truth = np.stack([600 * np.cos(ang), 600 * np.sin(ang), np.full(n, 80.0)], axis=1)
    d = truth - np.array(RADAR)
    r = np.linalg.norm(d, axis=1)
    az = np.arctan2(d[:, 0], d[:, 1])
    el = np.arcsin(d[:, 2] / r)
    r = r + rng.normal(0, s_r, n)
    az = az + rng.normal(0, s_az, n)
    el = el + rng.normal(0, s_el, n)
    rho = r * np.cos(el)
    z = np.stack([rho * np.sin(az), rho * np.cos(az), r * np.sin(el)], axis=1) + np.array(RADAR)
    return t, z


def _run_radar(adaptive: AdaptiveRadarR, t: np.ndarray, z: np.ndarray) -> None:
    f = CvFilter((0.05, 0.05, 0.05))
    f.set_state([*z[0], 0.0, 0.0, 0.0], np.diag([100.0, 100.0, 100.0, 100.0, 100.0, 100.0]))
    for k in range(1, len(t)):
        f.predict(t[k] - t[k - 1])
        zk = tuple(float(v) for v in z[k])
        adaptive.observe(zk, *f.mean())
        f.update(zk, adaptive.r_at(*zk))


def test_radar_sigmas_converge_to_the_streams_own() -> None:
    """A radar twice as noisy as its specification on every channel (the spec is the prior):
    each estimate ends within 20 % of the stream's own sigma. The stream's errors are white,
    so the allowance for correlated ones is kept at a metre (a 100 m gate): an allowance the
    errors do not have makes the track's covariance larger than its errors, and the samples
    ``d^2 - u^T P u`` then come out low."""
    true = (3.0, math.radians(1.2), math.radians(2.0))
    spec = PolarRadarR(RADAR, 1.5, math.radians(0.6), math.radians(1.0))
    ad = AdaptiveRadarR(spec, window=400, bound=3.0, gate_m=100.0)
    t, z = _polar_reports(3000, *true, seed=4)
    _run_radar(ad, t, z)
    got = (ad.range.sigma, ad.az.sigma, ad.el.sigma)
    for g, s in zip(got, true, strict=True):
        assert g == pytest.approx(s, rel=0.2)
    assert not (ad.range.held or ad.az.held or ad.el.held)
    # the R the track uses now is that of the estimated sigmas
    assert ad.model.sigma_az_rad == ad.az.sigma
    assert ad.status()["radar_noise_samples"] == len(t) - 1


def _adapted(
    spec: tuple[float, float], truth: tuple[float, float], n: int, seed: int
) -> AdaptiveRadarR:
    """The adaptive radar R (window 300, bound 2) after ``n`` reports: specified and true
    (range m, angle deg) sigmas, the angle sigma for azimuth and elevation alike."""
    rad = math.radians
    ad = AdaptiveRadarR(PolarRadarR(RADAR, spec[0], rad(spec[1]), rad(spec[1])), window=300,
                        bound=2.0, gate_m=1000.0)
    t, z = _polar_reports(n, truth[0], rad(truth[1]), rad(truth[1]), seed=seed)
    _run_radar(ad, t, z)
    return ad


def test_radar_sigmas_never_fall_below_the_specification() -> None:
    """A radar four times better than specified: innovations that small are what errors
    correlated over time look like, so each estimate stays at its spec."""
    ad = _adapted((8.0, 2.0), (2.0, 0.5), 2000, seed=5)
    assert ad.range.sigma == 8.0
    assert ad.az.sigma == pytest.approx(math.radians(2.0))
    assert ad.range.held and ad.az.held and ad.el.held


def test_radar_sigma_above_its_bound_is_held_there() -> None:
    ad = _adapted((1.0, 0.2), (5.0, 1.0), 1500, seed=7)
    assert ad.range.sigma == 2.0
    assert ad.az.sigma == pytest.approx(math.radians(0.4))


def test_rf_checks_move_the_allowance_within_its_bounds() -> None:
    """The allowance starts at the spec's cross-range sigma at the gate's edge; RF fixes whose
    NIS averages 2 leave it, larger ones raise it (to f0 x bound at most), smaller ones lower
    it (to f0 / bound at least)."""
    spec = PolarRadarR(RADAR, 2.0, math.radians(2.0), math.radians(2.0))
    ad = AdaptiveRadarR(spec, window=200, bound=2.0, gate_m=1000.0)
    f0 = math.radians(2.0) * 1000.0
    assert ad.floor_m == pytest.approx(f0)
    for nis in (1.0, 3.0) * 50:  # mean NIS / 2 = 1
        ad.check(nis, 2)
    assert ad.floor_m == pytest.approx(f0, rel=0.06)
    for _ in range(5):
        ad.check(8.0, 2)
    assert ad.floor_m > 1.5 * f0
    ad.check(float("nan"), 2)
    assert ad.checks == 105
    for _ in range(200):
        ad.check(1e6, 2)  # one outlier counts as NIS / 2 = 5 at most; bounded above
    assert ad.floor_m == pytest.approx(2.0 * f0)
    for _ in range(200):
        ad.check(0.0, 2)
    assert ad.floor_m == pytest.approx(f0 / 2.0)
    # the R the track uses carries the allowance on each axis
    e, n, u = 0.0, 1000.0, 2.0
    assert ad.r_at(e, n, u)[0] == pytest.approx(ad.model.r_at(e, n, u)[0])
    assert ad.r_at(e, n, u)[0] - replace(ad.model, floor_m=0.0).r_at(e, n, u)[0] == (
        pytest.approx((f0 / 2.0) ** 2)
    )


def test_rf_cep_scale_converges() -> None:
    """Fixes whose real sigma is 1.8x their CEP-derived sigma (spec scale 1): the scale ends
    within 20 %."""
    rng = np.random.default_rng(6)
    spec = CepRfR(scale=1.0, floor_m=0.0, fallback=(100.0, 0.0, 100.0))
    ad = AdaptiveRfR(spec, window=300, bound=3.0)
    f = CvFilter((0.05, 0.05, 0.05))
    f.set_state([0.0, 1000.0, 60.0, 0.0, 0.0, 0.0], np.diag([400.0, 400.0, 100.0, 9.0, 9.0, 1.0]))
    for _ in range(2000):
        f.predict(3.9)
        cep = float(rng.uniform(8.0, 20.0))
        s = 1.8 * cep / CEP_PER_SIGMA
        z = (float(rng.normal(0, s)), float(1000.0 + rng.normal(0, s)))
        ad.observe(z, *f.mean(), cep)
        f.update(z, ad.r_for(cep))
    assert ad.scale.sigma == pytest.approx(1.8, rel=0.2)
    # the R of the next fix follows the estimate
    v = ad.r_for(10.0)[0]
    assert math.sqrt(v) == pytest.approx(ad.scale.sigma * 10.0 / CEP_PER_SIGMA)


def test_channel_ignores_non_finite_samples_and_starts_at_its_spec() -> None:
    ch = NoiseChannel(spec=5.0, bound=2.0, window=10)
    assert ch.sigma == 5.0 and ch.held
    ch.observe(float("nan"))
    ch.observe(float("inf"))
    assert ch.n == 0 and ch.sigma == 5.0
    for _ in range(50):
        ch.observe(49.0)
    assert ch.sigma == pytest.approx(7.0, rel=0.01) and not ch.held
    for _ in range(50):
        ch.observe(-30.0)  # innovations smaller than the prediction's own spread
    assert ch.sigma == 5.0 and ch.held


def _tracker_dict(**measurement: object) -> dict[str, Any]:
    src = load_profile("tracker").source
    assert src is not None
    base: dict[str, Any] = yaml.safe_load(src.read_text())
    for path, value in measurement.items():
        node = base
        keys = path.split("__")
        for k in keys[:-1]:
            node = node.setdefault(k, {})
        node[keys[-1]] = value
    return base


def _number(value: object) -> float:
    """A number of an estimator's status (typed ``object``: some statuses hold text)."""
    assert isinstance(value, int | float)
    return float(value)


def test_adaptive_with_a_floor_stops_naming_the_key(tmp_path: Path) -> None:
    d = _tracker_dict(measurement__adaptive={"window": 100, "bound": 2.0})
    d["measurement"]["radar"]["floor_m"] = 40.0  # a fixed allowance as well: refused
    p = tmp_path / "mine.yaml"
    p.write_text(yaml.safe_dump(d))
    with pytest.raises(ConfigError, match=r"mine\.yaml.*measurement\.radar\.floor_m"):
        load_profile(p)
    d["measurement"]["radar"]["floor_m"] = 0.0
    d["measurement"]["adaptive"]["bound"] = 0.5
    p.write_text(yaml.safe_dump(d))
    with pytest.raises(ConfigError, match=r"mine\.yaml.*measurement\.adaptive\.bound"):
        load_profile(p)
    d["measurement"]["adaptive"]["bound"] = 2.0
    p.write_text(yaml.safe_dump(d))
    assert load_profile(p).adaptive_window == 100


def test_tracker_with_adaptive_noise_runs_a_flight_and_reports_its_sigmas(
    tmp_path: Path,
) -> None:
    """The default flight with the online R: the track holds the UAV, and the estimates have
    moved from the spec and are what the status (/diagnostics) shows."""
    d = _tracker_dict(measurement__adaptive={"window": 200, "bound": 2.0})
    d["measurement"]["radar"]["floor_m"] = 0.0
    prof = profile_from_dict(d, tmp_path / "adaptive.yaml")
    res = run_flight(load_flight(data_path("default_flight")), prof, load_site())
    status = res.status
    assert _number(status["radar_noise_samples"]) > 100
    assert _number(status["radar_allowance_checks"]) > 5
    assert prof.range_gate_m is not None
    f0 = math.radians(prof.radar_sigma_az_deg) * prof.range_gate_m
    allowance = _number(status["radar_allowance_m"])
    # within its bounds (the status rounds to 0.01 m; on this flight it ends at the lower one)
    assert f0 / 2.0 - 0.01 <= allowance <= 2.0 * f0 + 0.01
    assert allowance != pytest.approx(f0, rel=1e-3)  # the RF fixes moved it
    sig_az = _number(status["radar_sigma_az_deg"])
    assert prof.radar_sigma_az_deg <= sig_az <= 2.0 * prof.radar_sigma_az_deg
    assert sum(1 for s in res.steps if s.counted) > 1000


@pytest.mark.parametrize(("age", "to_radar"), [(HELD_S, True), (HELD_S + 0.01, False)])
def test_a_fix_checks_the_radar_only_while_the_radar_holds_the_track(
    age: float, to_radar: bool
) -> None:
    """``HELD_S`` at its edge: an RF fix with a 3D radar update at most that old checks the
    radar's allowance for correlated errors; one later is a sample of the RF noise instead."""
    spec = PolarRadarR(RADAR, 2.0, math.radians(2.0), math.radians(2.0))
    radar = AdaptiveRadarR(spec, window=200, bound=2.0, gate_m=1000.0)
    rf = AdaptiveRfR(CepRfR(scale=1.0, floor_m=0.0, fallback=(100.0, 0.0, 100.0)), 300, 3.0)
    f = CvFilter((0.05, 0.05, 0.05))
    f.set_state([0.0, 1000.0, 60.0, 0.0, 0.0, 0.0], np.diag([400.0, 400.0, 100.0, 9.0, 9.0, 1.0]))
    observe_rf_fix(radar, rf, 0.0, age, f, (5.0, 1003.0), 1.2, 10.0)
    assert (radar.checks, rf.scale.n) == ((1, 0) if to_radar else (0, 1))
