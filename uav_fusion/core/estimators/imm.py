"""An IMM of CV models with different ``q``: the tracker's alternative motion filter
(``motion.model: imm``; the CV model is :class:`~uav_fusion.core.estimators.kalman.CvFilter`).

Its modes are kept in :class:`~uav_fusion.core.estimators.kalman.CvKalman` (the paper's
hand-unrolled kernels), so a prediction or an update costs a few microseconds; the IMM's
mixing and combination are written on the packed lists (6 state values, 21 covariance
values) in plain Python.

IMM (Blom and Bar-Shalom 1988) cycle:

* ``predict(T)``: with ``cbar = mu Pi`` and ``omega_ij = Pi_ij mu_i / cbar_j``, mode j starts
  from the mixed estimate ``x0_j = sum_i omega_ij x_i``,
  ``P0_j = sum_i omega_ij (P_i + (x_i - x0_j)(x_i - x0_j)^T)`` and is predicted over ``T``;
  ``mu <- cbar``;
* ``update(z, R)``: each mode is updated with ``z``; the likelihood of mode j is
  ``N(y_j; 0, S_j)``; ``mu_j <- L_j mu_j / sum``.

Alternating predict and update this is filterpy's ``IMMEstimator`` cycle (tested).

The published estimate is the moment-matched combination ``x = sum mu_j x_j``,
``P = sum mu_j (P_j + (x_j - x)(x_j - x)^T)``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import numpy.typing as npt

from uav_fusion.core.estimators.kalman import (
    _PAIRS,
    Q3,
    CvKalman,
    PackedR,
    _nis,
    _update,
    expand_upper,
    update_linear,
    update_scalar,
)

FloatArray = npt.NDArray[np.float64]

_LOG2PI = math.log(2.0 * math.pi)


def innovation_logdet(p: Sequence[float], r: PackedR) -> float:
    """``log det S`` of ``S = H P H^T + R`` for a position measurement (packed ``P``/``R``)."""
    if len(r) == 3:
        s00 = p[0] + r[0]
        s01 = p[1] + r[1]
        s11 = p[6] + r[2]
        return math.log(s00 * s11 - s01 * s01)
    s00 = p[0] + r[0]
    s01 = p[1] + r[1]
    s02 = p[2] + r[2]
    s11 = p[6] + r[3]
    s12 = p[7] + r[4]
    s22 = p[11] + r[5]
    det = (
        s00 * (s11 * s22 - s12 * s12)
        + s01 * (s02 * s12 - s01 * s22)
        + s02 * (s01 * s12 - s02 * s11)
    )
    return math.log(det)


def outer_diff(xa: Sequence[float], xb: Sequence[float]) -> list[float]:
    """Packed upper triangle of ``d d^T`` with ``d = xa - xb``."""
    d = [a - b for a, b in zip(xa, xb, strict=True)]
    return [d[i] * d[j] for i, j in _PAIRS]


def mix2(
    w0: float,
    w1: float,
    xa: Sequence[float],
    xb: Sequence[float],
    pa: Sequence[float],
    pb: Sequence[float],
    dd: Sequence[float],
) -> tuple[list[float], list[float]]:
    """Two-component moment match with ``w0 + w1 = 1``: the spread term
    ``sum_i w_i (x_i - x)(x_i - x)^T`` equals ``w0 w1 d d^T`` (``dd``, from :func:`outer_diff`)."""
    c = w0 * w1
    x = [w0 * a + w1 * b for a, b in zip(xa, xb, strict=True)]
    P = [w0 * u + w1 * v + c * e for u, v, e in zip(pa, pb, dd, strict=True)]
    return x, P


def combine(
    weights: Sequence[float], xs: Sequence[Sequence[float]], ps: Sequence[Sequence[float]]
) -> tuple[list[float], list[float]]:
    """Moment-matched mixture of packed Gaussians: ``sum w_j (x_j, P_j + dx dx^T)``."""
    if len(weights) == 2:  # the common case: P = w0 P0 + w1 P1 + w0 w1 d d^T, d = x0 - x1
        w0, w1 = weights
        xa, xb = xs
        return mix2(w0, w1, xa, xb, ps[0], ps[1], outer_diff(xa, xb))
    x = [0.0] * 6
    for w, xj in zip(weights, xs, strict=True):
        for k in range(6):
            x[k] += w * xj[k]
    P = [0.0] * 21
    for w, xj, pj in zip(weights, xs, ps, strict=True):
        d = [xj[k] - x[k] for k in range(6)]
        for idx, (i, j) in enumerate(_PAIRS):
            P[idx] += w * (pj[idx] + d[i] * d[j])
    return x, P


class ImmFilter:
    """Interacting multiple model filter over CV modes with per-mode ``q``.

    ``mu`` holds the mode probabilities of the current estimate: after :meth:`predict` the
    predicted ones (``mu Pi``), after :meth:`update` the posterior ones. Every prediction with
    ``T > 0`` is one Markov step of ``transition`` (``T == 0`` changes nothing).
    """

    __slots__ = ("_mean", "modes", "mu", "transition")

    def __init__(
        self,
        qs: Sequence[Q3],
        transition: Sequence[Sequence[float]],
        initial: Sequence[float],
    ) -> None:
        n = len(qs)
        if n < 1 or len(transition) != n or len(initial) != n:
            raise ValueError("IMM: one q, one transition row and one initial probability per mode")
        self.modes = [CvKalman(q) for q in qs]
        self.transition = tuple(tuple(float(v) for v in row) for row in transition)
        s = float(sum(initial))
        self.mu = [float(v) / s for v in initial]
        self._mean: tuple[list[float], list[float]] | None = None

    def set_state(self, x: FloatArray | Sequence[float], P: FloatArray) -> None:
        for m in self.modes:
            m.set_state(x, P)
        self._mean = None

    def predict(self, T: float) -> None:
        if T == 0.0:
            return
        modes = self.modes
        n = len(modes)
        pi = self.transition
        mu = self.mu
        cbar = [sum(pi[i][j] * mu[i] for i in range(n)) for j in range(n)]
        xs = [m.x for m in modes]
        ps = [m.P for m in modes]
        mixed = []
        dd = outer_diff(xs[0], xs[1]) if n == 2 else None
        for j in range(n):
            omega = [pi[i][j] * mu[i] / cbar[j] if cbar[j] > 0 else 0.0 for i in range(n)]
            if dd is not None:
                mixed.append(mix2(omega[0], omega[1], xs[0], xs[1], ps[0], ps[1], dd))
            else:
                mixed.append(combine(omega, xs, ps))
        for m, (x0, p0) in zip(modes, mixed, strict=True):
            m.x = x0
            m.P = p0
            m.predict(T)
        self.mu = cbar
        self._mean = None

    def nis(self, z: Sequence[float], r: PackedR) -> float:
        x, P = self.mean()
        tmp = CvKalman((0.0, 0.0, 0.0))
        tmp.x = x
        tmp.P = P
        return _nis(tmp, z, r)

    def update(self, z: Sequence[float], r: PackedR) -> float:
        """Update every mode and the mode probabilities; returns the combined prior's NIS."""
        nis0 = self.nis(z, r)
        dim = len(z)
        logl = []
        for m in self.modes:
            ld = innovation_logdet(m.P, r)
            nis = _update(m, z, r)
            logl.append(-0.5 * (nis + ld + dim * _LOG2PI))
        top = max(logl)
        w = [c * math.exp(v - top) for c, v in zip(self.mu, logl, strict=True)]
        s = sum(w)
        if s > 0:
            self.mu = [v / s for v in w]
        self._mean = None
        return nis0

    def mean(self) -> tuple[list[float], list[float]]:
        """The combined estimate (cached until the next predict or update; do not modify)."""
        if self._mean is None:
            self._mean = combine(self.mu, [m.x for m in self.modes], [m.P for m in self.modes])
        return self._mean

    def copy(self) -> ImmFilter:
        c = ImmFilter([m.q for m in self.modes], self.transition, self.mu)
        for src, dst in zip(self.modes, c.modes, strict=True):
            dst.x = list(src.x)
            dst.P = list(src.P)
        return c

    def mode_probabilities(self) -> tuple[float, ...]:
        return tuple(self.mu)

    def update_scalar(self, idx: int, value: float, var: float) -> None:
        """The pseudo-measurement applied to every mode (mode probabilities unchanged)."""
        for m in self.modes:
            update_scalar(m, idx, value, var)
        self._mean = None

    def update_linear(self, h: Sequence[float], value: float, var: float) -> None:
        """The pseudo-measurement applied to every mode (mode probabilities unchanged)."""
        for m in self.modes:
            update_linear(m, h, value, var)
        self._mean = None

    def effective_q(self) -> Q3:
        q = [0.0, 0.0, 0.0]
        for w, m in zip(self.mu, self.modes, strict=True):
            for k in range(3):
                q[k] += w * m.q[k]
        return (q[0], q[1], q[2])


def packed_arrays(x: Sequence[float], p: Sequence[float]) -> tuple[FloatArray, FloatArray]:
    """(x (6,), P (6, 6)) arrays from packed lists."""
    return np.array(x, dtype=float), expand_upper(p)
