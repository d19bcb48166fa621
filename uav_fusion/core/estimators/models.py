"""Constant-velocity motion model and position measurement models (plain numpy reference).

State ``s = [x y z vx vy vz]`` in the site's ENU frame (metres, metres per second).

* Transition over an interval ``T``: ``F(T) = [[I3, T*I3], [0, I3]]``.
* Process noise: the continuous white-noise acceleration model (Bar-Shalom, Li and
  Kirubarajan 2001, eq. 6.2.2-12), per axis ``q~ * [[T^3/3, T^2/2], [T^2/2, T]]`` with a
  spectral density ``q~`` (m^2/s^3) per axis.
* Radar: ``H = [I3 0]`` (3D position); RF/TDOA: ``H = [I2 0]`` (east, north).

These functions build full matrices and are what the tests compare against; the filter itself
(:mod:`uav_fusion.core.estimators.kalman`) uses the same equations written out element-wise.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]

STATE_DIM = 6


def cv_transition(T: float) -> FloatArray:
    """``F(T)`` of the 3D constant-velocity model."""
    F = np.eye(STATE_DIM)
    F[0, 3] = F[1, 4] = F[2, 5] = T
    return F


def cv_process_noise(T: float, q: tuple[float, float, float] | FloatArray) -> FloatArray:
    """Continuous white-noise acceleration ``Q(T)`` with spectral density ``q[i]`` per axis."""
    qa = np.asarray(q, dtype=float)
    Q = np.zeros((STATE_DIM, STATE_DIM))
    i = np.arange(3)
    Q[i, i] = qa * T**3 / 3.0
    Q[i, i + 3] = Q[i + 3, i] = qa * T**2 / 2.0
    Q[i + 3, i + 3] = qa * T
    return Q


def position_h(dim: int) -> FloatArray:
    """``H = [I_dim 0]``: the first ``dim`` position axes (3 radar, 2 RF)."""
    if dim not in (2, 3):
        raise ValueError(f"measurement dimension must be 2 or 3, got {dim}")
    H = np.zeros((dim, STATE_DIM))
    H[np.arange(dim), np.arange(dim)] = 1.0
    return H


def kf_predict(
    x: FloatArray, P: FloatArray, T: float, q: tuple[float, float, float] | FloatArray
) -> tuple[FloatArray, FloatArray]:
    """Textbook matrix prediction (reference implementation)."""
    F = cv_transition(T)
    return F @ x, F @ P @ F.T + cv_process_noise(T, q)


def kf_update_joseph(
    x: FloatArray, P: FloatArray, z: FloatArray, R: FloatArray
) -> tuple[FloatArray, FloatArray, float]:
    """Textbook matrix update in Joseph form (reference implementation); returns (x, P, NIS)."""
    H = position_h(z.shape[0])
    y = z - H @ x
    S = H @ P @ H.T + R
    Si = np.linalg.inv(S)
    K = P @ H.T @ Si
    L = np.eye(STATE_DIM) - K @ H
    Pn = L @ P @ L.T + K @ R @ K.T
    return x + K @ y, 0.5 * (Pn + Pn.T), float(y @ Si @ y)
