"""The tracker profiles' stiff vertical (docs/estimator.md, "A stiff vertical").

A radar's track reports come out of its onboard tracker, so their angle errors are correlated
over seconds. The profiles hold the climb rate nearly fixed (``q`` up 0.002 m^2/s^3) and start
the elevation sigma at the radar's specification (2 deg), so a UAV holding its height gets a
better height than any one report gives, while a steady climb is still followed. These
scenes feed the multi-UAV tracker (the same filter as the single-UAV one) reports whose
azimuth and elevation errors are AR(1) processes with a 6 s time constant, and compare the
shipped profile with the vertical it replaced (``q`` up 4, 1.6 deg).
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
import pytest

from uav_fusion.core.estimators.multi import MultiTracker, run_multi
from uav_fusion.core.profiles.model import Profile, load_profile
from uav_fusion.core.records import RadarFrame, RadarTrack
from uav_fusion.core.site import Site, load_site

Path3 = Callable[[float], np.ndarray]
START = 1000.0


@pytest.fixture(scope="module")
def site() -> Site:
    return load_site()


def _profiles() -> tuple[Profile, Profile]:
    shipped = load_profile("tracker")
    before = shipped.with_changes(q=(20.0, 20.0, 4.0), radar_sigma_el_deg=1.6)
    return shipped, before


def _stream(
    site: Site, path: Path3, duration_s: float, seed: int, sigma_deg: float = 1.5
) -> tuple[list[RadarFrame], np.ndarray]:
    """4 Hz reports of one UAV (radar track 7, UAV class 0.8) whose azimuth and elevation
    errors are AR(1) with a 6 s time constant and ``sigma_deg``; also each report's height
    error (report minus truth)."""
    rng = np.random.default_rng(seed)
    r0 = np.array(site.radar.enu, dtype=float)
    dt, tau = 0.25, 6.0
    a = math.exp(-dt / tau)
    w = math.radians(sigma_deg) * math.sqrt(1.0 - a * a)
    err = rng.normal(0.0, math.radians(sigma_deg), 2)
    frames: list[RadarFrame] = []
    height_err: list[float] = []
    for k in range(int(duration_s / dt)):
        t = START + k * dt
        tau_s = t - START
        p = r0 + path(tau_s)
        d = p - r0
        rho = math.hypot(d[0], d[1])
        rng_m = math.hypot(rho, d[2]) + rng.normal(0.0, 1.0)
        az = math.atan2(d[0], d[1]) + err[0]
        el = math.atan2(d[2], rho) + err[1]
        err = a * err + rng.normal(0.0, w, 2)
        q = r0 + rng_m * np.array(
            [math.cos(el) * math.sin(az), math.cos(el) * math.cos(az), math.sin(el)]
        )
        height_err.append(float(q[2] - p[2]))
        v = path(tau_s + 0.5) - path(tau_s - 0.5)
        rcs = round(-10.0 + float(rng.normal(0.0, 2.0)), 3)
        rep = RadarTrack(
            t, 7, 0.0, 0.0, 0.0, float(q[0]), float(q[1]), float(q[2]),
            (float(v[1]), float(v[0]), float(-v[2])), 0.8, None, rcs,
        )  # fmt: skip
        frames.append(RadarFrame(t, (rep,)))
    return frames, np.array(height_err)


def _height_rms(
    site: Site, profile: Profile, frames: list[RadarFrame], path: Path3, after_s: float
) -> float:
    epochs = run_multi(MultiTracker(profile, site), list(frames), 1.0, START, frames[-1].t)
    r0 = np.array(site.radar.enu, dtype=float)
    errs = []
    for ep in epochs:
        if ep.t - START < after_s:
            continue
        assert len(ep.tracks) == 1, f"one track on the UAV at {ep.t - START:.0f} s"
        truth = r0 + path(ep.t - START)
        assert np.linalg.norm(ep.tracks[0].x[:2] - truth[:2]) < 60.0
        errs.append(float(ep.tracks[0].x[2] - truth[2]))
    assert len(errs) > 60
    return float(np.sqrt(np.mean(np.square(errs))))


def _level(tau: float) -> np.ndarray:
    """About the radar: 800 m north-west of it, 60 m up, 8 m/s on a square circuit of 400 m legs."""
    s = (8.0 * tau) % 1600.0
    leg, x = divmod(s, 400.0)
    corners = [(-700.0, 300.0), (-700.0, 700.0), (-300.0, 700.0), (-300.0, 300.0)]
    (e0, n0), (e1, n1) = corners[int(leg)], corners[(int(leg) + 1) % 4]
    f = x / 400.0
    return np.array([e0 + f * (e1 - e0), n0 + f * (n1 - n0), 60.0])


def _climbing(tau: float) -> np.ndarray:
    """The same circuit, climbing steadily at 1 m/s from 40 m."""
    return _level(tau) + np.array([0.0, 0.0, tau - 20.0], dtype=np.float64)


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_a_uav_holding_its_height_gets_a_better_height_than_its_reports(
    site: Site, seed: int
) -> None:
    shipped, before = _profiles()
    frames, rep_err = _stream(site, _level, 200.0, seed)
    stiff = _height_rms(site, shipped, frames, _level, 40.0)
    loose = _height_rms(site, before, frames, _level, 40.0)
    reports = float(np.sqrt(np.mean(np.square(rep_err[160:]))))
    # measured: 10.9-15.0 m against 17.6-20.7 m (before) and 17.9-20.0 m (the reports)
    assert stiff < 0.85 * loose, (stiff, loose)
    assert stiff < 0.85 * reports, (stiff, reports)


@pytest.mark.parametrize("seed", [1, 2])
def test_a_steady_climb_is_still_followed(site: Site, seed: int) -> None:
    shipped, before = _profiles()
    frames, rep_err = _stream(site, _climbing, 200.0, seed)
    stiff = _height_rms(site, shipped, frames, _climbing, 40.0)
    loose = _height_rms(site, before, frames, _climbing, 40.0)
    reports = float(np.sqrt(np.mean(np.square(rep_err[160:]))))
    # measured: 14.4-15.2 m against 17.6-20.7 m (before) and 18.1-19.9 m (the reports)
    assert stiff < 0.85 * loose and stiff < 0.85 * reports, (stiff, loose, reports)
