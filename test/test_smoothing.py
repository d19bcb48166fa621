"""RTS smoothing against filterpy, and the fixed-lag smoother against RTS on the same data."""

from __future__ import annotations

import numpy as np
import pytest
from filterpy.kalman import rts_smoother

from uav_fusion.core.estimators.imm import packed_arrays
from uav_fusion.core.estimators.kalman import CvFilter, pack_r
from uav_fusion.core.estimators.models import cv_process_noise, cv_transition
from uav_fusion.core.estimators.smoothing import Filtered, fixed_lag, rts

Q = (1.5, 2.5, 0.7)


def _filtered(seed: int, n: int = 80) -> tuple[list[Filtered], np.ndarray]:
    """A CV filter over a noisy accelerating path (radar 3D and RF 2D); entries and truth."""
    rng = np.random.default_rng(seed)
    f = CvFilter(Q)
    f.set_state(np.array([0.0, 0.0, 40.0, 0.0, 0.0, 0.0]), np.diag([50.0] * 3 + [100.0] * 3))
    entries = [Filtered(0.0, *packed_arrays(*f.mean()), Q)]
    truth = [np.array([0.0, 0.0, 40.0])]
    t = 0.0
    for k in range(n):
        dt = float(rng.uniform(0.2, 1.5))
        t += dt
        p = np.array([0.3 * t * t, 4.0 * t, 40.0 + 5.0 * np.sin(0.1 * t)])
        f.predict(dt)
        if k % 3 == 2:
            f.update((p[:2] + rng.normal(0, 10.0, 2)).tolist(), pack_r(np.eye(2) * 100.0))
        else:
            f.update((p + rng.normal(0, 6.0, 3)).tolist(), pack_r(np.eye(3) * 36.0))
        entries.append(Filtered(t, *packed_arrays(*f.mean()), Q))
        truth.append(p)
    return entries, np.array(truth)


@pytest.mark.parametrize("seed", [1, 2])
def test_rts_matches_filterpy(seed: int) -> None:
    entries, _ = _filtered(seed)
    xs = np.array([e.x for e in entries])
    Ps = np.array([e.P for e in entries])
    Fs = np.zeros((len(entries), 6, 6))
    Qs = np.zeros((len(entries), 6, 6))
    for k in range(len(entries) - 1):  # filterpy: Fs[k], Qs[k] take entry k to k + 1
        T = entries[k + 1].t - entries[k].t
        Fs[k] = cv_transition(T)
        Qs[k] = cv_process_noise(T, Q)
    ref_x, ref_P, _, _ = rts_smoother(xs, Ps, Fs, Qs)
    ours = rts(entries)
    np.testing.assert_allclose(np.array([x for x, _ in ours]), ref_x, rtol=1e-9, atol=1e-8)
    np.testing.assert_allclose(np.array([P for _, P in ours]), ref_P, rtol=1e-8, atol=1e-8)


def test_rts_reduces_the_error() -> None:
    entries, truth = _filtered(3, 200)
    f_err = np.linalg.norm(np.array([e.x[:3] for e in entries]) - truth, axis=1)
    s_err = np.linalg.norm(np.array([x[:3] for x, _ in rts(entries)]) - truth, axis=1)
    assert s_err.mean() < 0.85 * f_err.mean()


@pytest.mark.parametrize("lag", [0.0, 1.0, 3.0, 10.0])
def test_fixed_lag_equals_rts_restricted_to_the_lag_window(lag: float) -> None:
    entries, _ = _filtered(4, 40)
    out = fixed_lag(entries, lag)
    for k, (x, P) in enumerate(out):
        j = max(i for i, e in enumerate(entries) if e.t <= entries[k].t + lag)
        ref_x, ref_P = rts(entries[: j + 1])[k]
        np.testing.assert_array_equal(x, ref_x)
        np.testing.assert_array_equal(P, ref_P)
    if lag == 0.0:  # no lag: the filtered estimates themselves
        for e, (x, _) in zip(entries, out, strict=True):
            np.testing.assert_array_equal(x, e.x)
    big = fixed_lag(entries, 1e9)  # a lag longer than the flight: offline RTS
    for (x, _), (rx, _) in zip(big, rts(entries), strict=True):
        np.testing.assert_array_equal(x, rx)


@pytest.mark.parametrize("lag_s", [0.0, 1.0, 3.0, 10.0])
def test_streaming_fixed_lag_equals_the_batch_one(lag_s: float) -> None:
    from uav_fusion.core.estimators.smoothing import Filtered, FixedLagSmoother, fixed_lag

    rng = np.random.default_rng(4)
    t = np.cumsum(rng.choice([0.0, 0.25, 0.5, 4.0], size=120))  # repeats, gaps
    entries = []
    for k, tk in enumerate(t):
        A = rng.normal(size=(6, 6))
        P = A @ A.T + 6.0 * np.eye(6)
        entries.append(Filtered(float(tk), rng.normal(size=6) * (k + 1), P, (2.0, 2.0, 0.5)))
    batch = fixed_lag(entries, lag_s)
    sm = FixedLagSmoother(lag_s)
    got = []
    for e in entries:
        out = sm.push(e)
        assert all(o[0].t + lag_s < e.t for o in out)  # released only once final
        got.extend(out)
    got.extend(sm.finish())
    assert [g[0] for g in got] == entries
    for (_, xs, Ps), (bx, bP) in zip(got, batch, strict=True):
        assert np.array_equal(xs, bx) and np.array_equal(Ps, bP)
    with pytest.raises(ValueError):
        FixedLagSmoother(float("inf"))
