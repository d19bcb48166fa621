"""Oracle tests: our filter against filterpy and Stone Soup on the same mixed, gated stream.

Both references run the textbook matrix equations (filterpy's KalmanFilter with the Joseph
update; Stone Soup's KalmanPredictor / KalmanUpdater with ``use_joseph_cov``). They are fed
the same measurements in the same order, gate with the same chi-square thresholds computed
from their own innovation covariances, and must agree with our element-wise filter to 1e-9
(relative to the size of each quantity) after every measurement, with identical decisions.
"""

from __future__ import annotations

import datetime as dt
from dataclasses import dataclass

import numpy as np
import pytest

from uav_fusion.core.estimators import FusionEstimator, Profile, Step, load_profile
from uav_fusion.core.estimators.models import cv_process_noise, cv_transition, position_h
from uav_fusion.core.estimators.synthetic import simulate_stream
from uav_fusion.core.records import RADAR, Measurement
from uav_fusion.core.site import load_site

R_RADAR = np.array([[30.0, 4.0, -2.0], [4.0, 45.0, 3.0], [-2.0, 3.0, 80.0]])
R_RF = np.array([[600.0, 120.0], [120.0, 900.0]])
Q_AXES = (1.5, 2.5, 0.7)
RTOL = 1e-9


@dataclass
class Ref:
    x: np.ndarray
    P: np.ndarray
    accepted: bool
    nis: float | None


def _profile(q: tuple[float, float, float]) -> Profile:
    # radar range gate out of the way: the oracles know nothing of it
    return load_profile("paper").with_changes(
        q=q, r_radar=R_RADAR, r_rf=R_RF, range_gate_m=1e7, init_sources=(RADAR,)
    )


def _stream(seed: int, q: tuple[float, float, float]) -> list[Measurement]:
    s = simulate_stream(
        seed,
        120.0,
        q,
        R_RADAR,
        R_RF,
        outlier_rate={"radar": 0.03, "rf": 0.3},
        outlier_scale_m=300.0,
        t0=0.0,
    )
    # the stream starts with a radar report (our init source); times on a 1 us grid, the
    # resolution of Stone Soup's datetime stamps
    first = next(i for i, m in enumerate(s.measurements) if m.source == RADAR)
    for m in s.measurements:
        m.t = round(m.t, 6)
    return s.measurements[first:]


def _ours(ms: list[Measurement], q: tuple[float, float, float]) -> list[Step]:
    est = FusionEstimator(_profile(q), load_site())
    out: list[Step] = []
    for m in ms:
        out.extend(est.process(m))
    return out


def _initial(m: Measurement, profile: Profile) -> tuple[np.ndarray, np.ndarray]:
    x = np.zeros(6)
    x[:3] = m.z
    P = np.zeros((6, 6))
    P[:3, :3] = R_RADAR
    P[3:, 3:] = np.eye(3) * profile.init_velocity_std_mps**2
    return x, P


def _filterpy(ms: list[Measurement], q: tuple[float, float, float], builtin_q: bool) -> list[Ref]:
    from filterpy.common import Q_continuous_white_noise
    from filterpy.kalman import KalmanFilter

    profile = _profile(q)
    est = FusionEstimator(profile, load_site())
    kf = KalmanFilter(dim_x=6, dim_z=3)
    kf.x, kf.P = _initial(ms[0], profile)
    out = [Ref(kf.x.copy(), kf.P.copy(), True, None)]
    t = ms[0].t
    for m in ms[1:]:
        T = m.t - t
        t = m.t
        if builtin_q:  # filterpy's own CWNA builder, state ordered [x y z vx vy vz]
            Q = Q_continuous_white_noise(
                2, dt=T, spectral_density=q[0], block_size=3, order_by_dim=False
            )
        else:
            Q = cv_process_noise(T, q)
        kf.predict(F=cv_transition(T), Q=Q)
        H = position_h(m.dim)
        R = R_RADAR if m.dim == 3 else R_RF
        y = m.z - H @ kf.x
        S = H @ kf.P @ H.T + R
        nis = float(y @ np.linalg.solve(S, y))
        ok = nis <= est.gate_threshold[m.dim]
        if ok:
            kf.update(m.z, R=R, H=H)  # with H given, filterpy takes z shaped like H @ x
        out.append(Ref(kf.x.copy(), kf.P.copy(), ok, nis))
    return out


def _stonesoup(ms: list[Measurement], q: tuple[float, float, float]) -> list[Ref]:
    from stonesoup.models.measurement.linear import LinearGaussian
    from stonesoup.models.transition.linear import (
        CombinedLinearGaussianTransitionModel,
        ConstantVelocity,
    )
    from stonesoup.predictor.kalman import KalmanPredictor
    from stonesoup.types.detection import Detection
    from stonesoup.types.hypothesis import SingleHypothesis
    from stonesoup.types.state import GaussianState
    from stonesoup.updater.kalman import KalmanUpdater

    profile = _profile(q)
    est = FusionEstimator(profile, load_site())
    # Stone Soup orders the state per axis: [x vx y vy z vz]
    perm = np.array([0, 3, 1, 4, 2, 5])  # ss index i holds our state element perm[i]
    inv = np.argsort(perm)
    tm = CombinedLinearGaussianTransitionModel([ConstantVelocity(qa) for qa in q])
    predictor = KalmanPredictor(tm)
    updater = KalmanUpdater(measurement_model=None, use_joseph_cov=True)
    mm = {
        3: LinearGaussian(ndim_state=6, mapping=(0, 2, 4), noise_covar=R_RADAR),
        2: LinearGaussian(ndim_state=6, mapping=(0, 2), noise_covar=R_RF),
    }
    epoch = dt.datetime(2025, 10, 7, tzinfo=dt.UTC)

    def stamp(t: float) -> dt.datetime:
        return epoch + dt.timedelta(seconds=t)

    x0, P0 = _initial(ms[0], profile)
    state = GaussianState(x0[perm].reshape(6, 1), P0[np.ix_(perm, perm)], timestamp=stamp(ms[0].t))
    out = [Ref(x0, P0, True, None)]
    for m in ms[1:]:
        pred = predictor.predict(state, timestamp=stamp(m.t))
        det = Detection(m.z.reshape(-1, 1), timestamp=stamp(m.t), measurement_model=mm[m.dim])
        hyp = SingleHypothesis(pred, det)
        mp = updater.predict_measurement(pred, measurement_model=mm[m.dim])
        y = (det.state_vector - mp.state_vector).ravel().astype(float)
        S = np.asarray(mp.covar, float)
        nis = float(y @ np.linalg.solve(S, y))
        ok = nis <= est.gate_threshold[m.dim]
        state = updater.update(hyp) if ok else pred
        xs = np.asarray(state.state_vector, float).ravel()
        Ps = np.asarray(state.covar, float)
        out.append(Ref(xs[inv], Ps[np.ix_(inv, inv)], ok, nis))
    return out


def _close(a: np.ndarray, b: np.ndarray, rtol: float) -> bool:
    scale = max(float(np.max(np.abs(b))), 1e-300)
    return bool(np.all(np.abs(a - b) <= rtol * np.maximum(np.abs(b), 1e-6 * scale)))


def _compare(ours: list[Step], ref: list[Ref], rtol: float) -> None:
    assert len(ours) == len(ref)
    n_acc = n_rej = 0
    for k, (s, r) in enumerate(zip(ours, ref, strict=True)):
        assert s.updated == r.accepted, f"step {k}: decision differs (nis {s.nis} vs {r.nis})"
        n_acc += r.accepted
        n_rej += not r.accepted
        if r.nis is not None:
            assert s.nis is not None and abs(s.nis - r.nis) <= rtol * max(r.nis, 1.0)
        assert _close(s.x, r.x, rtol), f"step {k}: state differs\n{s.x}\n{r.x}"
        assert _close(s.P, r.P, rtol), f"step {k}: covariance differs\n{s.P}\n{r.P}"
    # the stream exercises both branches and both dimensions
    assert n_rej >= 10 and n_acc >= 100
    assert {s.dim for s in ours if s.coasted} == {2, 3}


@pytest.mark.parametrize("seed", [3, 17])
def test_matches_filterpy_per_axis_q(seed: int) -> None:
    ms = _stream(seed, Q_AXES)
    _compare(_ours(ms, Q_AXES), _filterpy(ms, Q_AXES, builtin_q=False), RTOL)


def test_matches_filterpy_with_its_own_q_builder() -> None:
    q = (2.0, 2.0, 2.0)
    ms = _stream(5, q)
    _compare(_ours(ms, q), _filterpy(ms, q, builtin_q=True), RTOL)


@pytest.mark.parametrize("seed", [3, 29])
def test_matches_stonesoup(seed: int) -> None:
    ms = _stream(seed, Q_AXES)
    _compare(_ours(ms, Q_AXES), _stonesoup(ms, Q_AXES), RTOL)


def test_reference_q_equals_filterpy_builder() -> None:
    from filterpy.common import Q_continuous_white_noise

    for T in (0.01, 0.25, 3.88, 17.0):
        ref = Q_continuous_white_noise(
            2, dt=T, spectral_density=1.7, block_size=3, order_by_dim=False
        )
        np.testing.assert_allclose(cv_process_noise(T, (1.7, 1.7, 1.7)), ref, rtol=1e-15)


def test_comparison_detects_a_wrong_filter() -> None:
    """The oracle comparison is sharp: a 1e-6 change of q is visible."""
    ms = _stream(3, Q_AXES)
    ours = _ours(ms, Q_AXES)
    other = _filterpy(ms, (Q_AXES[0] * (1 + 1e-6), Q_AXES[1], Q_AXES[2]), builtin_q=False)
    with pytest.raises(AssertionError):
        _compare(ours, other, RTOL)
