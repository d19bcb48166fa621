"""The filter's arithmetic: CV prediction and position updates written out element-wise.

The matrices are tiny (6x6 state, 2x2/3x3 innovation), so a generic matrix library spends
most of its time in call overhead. This module exploits the structure instead:

* prediction with ``F(T) = [[I, T I], [0, I]]`` and the continuous white-noise acceleration
  ``Q(T)`` (diagonal per axis) touches each upper-triangle element of ``P`` once;
* ``H = [I_m 0]`` means ``HPH^T`` is the top-left block of ``P`` and ``PH^T`` its first
  ``m`` columns;
* the 2x2 / 3x3 innovation covariance is inverted in closed form;
* the Joseph form ``(I-KH) P (I-KH)^T + K R K^T`` with ``K = P H^T S^-1`` is evaluated as
  ``P - (HP)^T J (HP)`` with ``J = 2 S^-1 - S^-1 S S^-1``, which is the same expression
  multiplied out (exact for whatever ``S^-1`` was computed, so it keeps the Joseph form's
  tolerance of gain errors); only the upper triangle is stored, so ``P`` is exactly
  symmetric by construction.

State is held in Python lists: ``x`` 6 floats, ``P`` the 21 floats of the upper triangle,
row by row (``UPPER_INDEX[i][j]`` gives the position of element (i, j)); :func:`expand_upper`
turns it into the full symmetric 6x6 array. The kernels read both lists into local variables
in one unpacking and install new lists rather than writing element by element (the same
floating-point operations in the same order, so the same results, with less interpreter work).
:mod:`uav_fusion.core.estimators.models` has the plain matrix version the tests compare with.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Protocol

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]

_INF = float("inf")

# position of element (i, j) of the symmetric 6x6 P in the 21-float upper-triangle list
UPPER_INDEX: tuple[tuple[int, ...], ...] = tuple(
    tuple((6 * min(i, j) - min(i, j) * (min(i, j) - 1) // 2) + abs(j - i) for j in range(6))
    for i in range(6)
)
_FULL = np.array(UPPER_INDEX, dtype=np.intp).reshape(36)
_UPPER_PAIRS = tuple((i, j) for i in range(6) for j in range(i, 6))


def expand_upper(p: Sequence[float] | FloatArray) -> FloatArray:
    """Full symmetric 6x6 array from the 21-float upper triangle."""
    return np.asarray(p, dtype=float)[_FULL].reshape(6, 6)


# R packed as the upper triangle: 3D (r00, r01, r02, r11, r12, r22), 2D (r00, r01, r11)
PackedR = tuple[float, ...]


def pack_r(R: FloatArray) -> PackedR:
    """Upper triangle of a symmetric 2x2 or 3x3 ``R`` as a tuple (after symmetrising)."""
    a = np.asarray(R, dtype=float)
    a = 0.5 * (a + a.T)
    v: tuple[float, ...]
    if a.shape == (3, 3):
        v = (a[0, 0], a[0, 1], a[0, 2], a[1, 1], a[1, 2], a[2, 2])
    elif a.shape == (2, 2):
        v = (a[0, 0], a[0, 1], a[1, 1])
    else:
        raise ValueError(f"R must be 2x2 or 3x3, got shape {a.shape}")
    # plain floats: numpy scalars would make every operation of the filter several times slower
    return tuple(float(e) for e in v)


def expand_cov3(c: Sequence[float]) -> FloatArray:
    """Full symmetric 3x3 array from its upper triangle (xx, xy, xz, yy, yz, zz)."""
    return np.array(((c[0], c[1], c[2]), (c[1], c[3], c[4]), (c[2], c[4], c[5])), dtype=float)


class CvKalman:
    """Six-state constant-velocity Kalman filter for 2D/3D position measurements."""

    __slots__ = ("P", "q", "x")

    def __init__(self, q: tuple[float, float, float]) -> None:
        self.q = (float(q[0]), float(q[1]), float(q[2]))
        self.x: list[float] = [0.0] * 6
        self.P: list[float] = [0.0] * 21

    # --- state access -------------------------------------------------------------------
    def set_state(self, x: FloatArray | Sequence[float], P: FloatArray) -> None:
        """Set the state; ``P`` (6x6) is symmetrised and its upper triangle kept."""
        xa = np.asarray(x, dtype=float).reshape(6)
        Pa = np.asarray(P, dtype=float).reshape(6, 6)
        Pa = 0.5 * (Pa + Pa.T)
        self.x = [float(v) for v in xa]
        self.P = [float(Pa[i, j]) for i, j in _UPPER_PAIRS]

    def x_array(self) -> FloatArray:
        return np.array(self.x)

    def P_array(self) -> FloatArray:
        return expand_upper(self.P)

    # --- prediction ---------------------------------------------------------------------
    def predict(self, T: float) -> None:
        """Propagate state and covariance over ``T`` seconds (``T`` may be 0)."""
        if T == 0.0:
            return
        x0, x1, x2, x3, x4, x5 = self.x
        self.x = [x0 + T * x3, x1 + T * x4, x2 + T * x5, x3, x4, x5]
        qx, qy, qz = self.q
        T2 = T * T
        q3 = T2 * T / 3.0
        q2 = 0.5 * T2
        # A = pos-pos block (a_ij), B = pos-vel block (b_ij = P[i, 3 + j]), C = vel-vel block
        (
            a00, a01, a02, b00, b01, b02,
            a11, a12, b10, b11, b12,
            a22, b20, b21, b22,
            c00, c01, c02,
            c11, c12,
            c22,
        ) = self.P
        self.P = [
            # A' = A + T (B + B^T) + T^2 C + Q_pp
            a00 + (T * (b00 + b00) + T2 * c00 + qx * q3),
            a01 + (T * (b01 + b10) + T2 * c01),
            a02 + (T * (b02 + b20) + T2 * c02),
            # B' = B + T C + Q_pv
            b00 + T * c00 + qx * q2,
            b01 + T * c01,
            b02 + T * c02,
            a11 + (T * (b11 + b11) + T2 * c11 + qy * q3),
            a12 + (T * (b12 + b21) + T2 * c12),
            b10 + T * c01,
            b11 + T * c11 + qy * q2,
            b12 + T * c12,
            a22 + (T * (b22 + b22) + T2 * c22 + qz * q3),
            b20 + T * c02,
            b21 + T * c12,
            b22 + T * c22 + qz * q2,
            # C' = C + Q_vv
            c00 + qx * T,
            c01,
            c02,
            c11 + qy * T,
            c12,
            c22 + qz * T,
        ]

    # --- 3D position measurement (radar) ------------------------------------------------
    def nis3(self, z0: float, z1: float, z2: float, r: PackedR) -> float:
        """Normalised innovation squared of a 3D position against the current prediction."""
        p = self.P
        x = self.x
        s00 = p[0] + r[0]
        s01 = p[1] + r[1]
        s02 = p[2] + r[2]
        s11 = p[6] + r[3]
        s12 = p[7] + r[4]
        s22 = p[11] + r[5]
        i00 = s11 * s22 - s12 * s12
        i01 = s02 * s12 - s01 * s22
        i02 = s01 * s12 - s02 * s11
        det = s00 * i00 + s01 * i01 + s02 * i02
        i11 = s00 * s22 - s02 * s02
        i12 = s01 * s02 - s00 * s12
        i22 = s00 * s11 - s01 * s01
        y0 = z0 - x[0]
        y1 = z1 - x[1]
        y2 = z2 - x[2]
        return (
            y0 * (i00 * y0 + i01 * y1 + i02 * y2)
            + y1 * (i01 * y0 + i11 * y1 + i12 * y2)
            + y2 * (i02 * y0 + i12 * y1 + i22 * y2)
        ) / det

    def update3(self, z0: float, z1: float, z2: float, r: PackedR, gate: float = _INF) -> float:
        """Joseph-form update with a 3D position; returns the NIS of the innovation.

        With ``gate`` given, a measurement whose NIS exceeds it (or is NaN) leaves the
        state untouched; the caller compares the returned NIS with the gate.
        """
        # the rows of HP are the first three rows of P: h_ij = P[i, j] (h10 = h01, ...)
        (
            h00, h01, h02, h03, h04, h05,
            h11, h12, h13, h14, h15,
            h22, h23, h24, h25,
            p33, p34, p35,
            p44, p45,
            p55,
        ) = self.P
        x0, x1, x2, x3, x4, x5 = self.x
        r00, r01, r02, r11, r12, r22 = r
        s00 = h00 + r00
        s01 = h01 + r01
        s02 = h02 + r02
        s11 = h11 + r11
        s12 = h12 + r12
        s22 = h22 + r22
        i00 = s11 * s22 - s12 * s12
        i01 = s02 * s12 - s01 * s22
        i02 = s01 * s12 - s02 * s11
        d = 1.0 / (s00 * i00 + s01 * i01 + s02 * i02)
        i00 *= d
        i01 *= d
        i02 *= d
        i11 = (s00 * s22 - s02 * s02) * d
        i12 = (s01 * s02 - s00 * s12) * d
        i22 = (s00 * s11 - s01 * s01) * d
        y0 = z0 - x0
        y1 = z1 - x1
        y2 = z2 - x2
        u0 = i00 * y0 + i01 * y1 + i02 * y2
        u1 = i01 * y0 + i11 * y1 + i12 * y2
        u2 = i02 * y0 + i12 * y1 + i22 * y2
        nis = y0 * u0 + y1 * u1 + y2 * u2
        if not nis <= gate:  # also NaN
            return nis
        # x += (HP)^T S^-1 y
        self.x = [
            x0 + (h00 * u0 + h01 * u1 + h02 * u2),
            x1 + (h01 * u0 + h11 * u1 + h12 * u2),
            x2 + (h02 * u0 + h12 * u1 + h22 * u2),
            x3 + (h03 * u0 + h13 * u1 + h23 * u2),
            x4 + (h04 * u0 + h14 * u1 + h24 * u2),
            x5 + (h05 * u0 + h15 * u1 + h25 * u2),
        ]
        # M = S^-1 S, J = 2 S^-1 - M S^-1: the Joseph form's middle factor
        m00 = i00 * s00 + i01 * s01 + i02 * s02
        m01 = i00 * s01 + i01 * s11 + i02 * s12
        m02 = i00 * s02 + i01 * s12 + i02 * s22
        m10 = i01 * s00 + i11 * s01 + i12 * s02
        m11 = i01 * s01 + i11 * s11 + i12 * s12
        m12 = i01 * s02 + i11 * s12 + i12 * s22
        m20 = i02 * s00 + i12 * s01 + i22 * s02
        m21 = i02 * s01 + i12 * s11 + i22 * s12
        m22 = i02 * s02 + i12 * s12 + i22 * s22
        j00 = 2.0 * i00 - (m00 * i00 + m01 * i01 + m02 * i02)
        j01 = 2.0 * i01 - (m00 * i01 + m01 * i11 + m02 * i12)
        j02 = 2.0 * i02 - (m00 * i02 + m01 * i12 + m02 * i22)
        j11 = 2.0 * i11 - (m10 * i01 + m11 * i11 + m12 * i12)
        j12 = 2.0 * i12 - (m10 * i02 + m11 * i12 + m12 * i22)
        j22 = 2.0 * i22 - (m20 * i02 + m21 * i12 + m22 * i22)
        # V = J (HP)
        v00 = j00 * h00 + j01 * h01 + j02 * h02
        v01 = j00 * h01 + j01 * h11 + j02 * h12
        v02 = j00 * h02 + j01 * h12 + j02 * h22
        v03 = j00 * h03 + j01 * h13 + j02 * h23
        v04 = j00 * h04 + j01 * h14 + j02 * h24
        v05 = j00 * h05 + j01 * h15 + j02 * h25
        v10 = j01 * h00 + j11 * h01 + j12 * h02
        v11 = j01 * h01 + j11 * h11 + j12 * h12
        v12 = j01 * h02 + j11 * h12 + j12 * h22
        v13 = j01 * h03 + j11 * h13 + j12 * h23
        v14 = j01 * h04 + j11 * h14 + j12 * h24
        v15 = j01 * h05 + j11 * h15 + j12 * h25
        v20 = j02 * h00 + j12 * h01 + j22 * h02
        v21 = j02 * h01 + j12 * h11 + j22 * h12
        v22 = j02 * h02 + j12 * h12 + j22 * h22
        v23 = j02 * h03 + j12 * h13 + j22 * h23
        v24 = j02 * h04 + j12 * h14 + j22 * h24
        v25 = j02 * h05 + j12 * h15 + j22 * h25
        # P - (HP)^T V (upper triangle)
        self.P = [
            h00 - (h00 * v00 + h01 * v10 + h02 * v20),
            h01 - (h00 * v01 + h01 * v11 + h02 * v21),
            h02 - (h00 * v02 + h01 * v12 + h02 * v22),
            h03 - (h00 * v03 + h01 * v13 + h02 * v23),
            h04 - (h00 * v04 + h01 * v14 + h02 * v24),
            h05 - (h00 * v05 + h01 * v15 + h02 * v25),
            h11 - (h01 * v01 + h11 * v11 + h12 * v21),
            h12 - (h01 * v02 + h11 * v12 + h12 * v22),
            h13 - (h01 * v03 + h11 * v13 + h12 * v23),
            h14 - (h01 * v04 + h11 * v14 + h12 * v24),
            h15 - (h01 * v05 + h11 * v15 + h12 * v25),
            h22 - (h02 * v02 + h12 * v12 + h22 * v22),
            h23 - (h02 * v03 + h12 * v13 + h22 * v23),
            h24 - (h02 * v04 + h12 * v14 + h22 * v24),
            h25 - (h02 * v05 + h12 * v15 + h22 * v25),
            p33 - (h03 * v03 + h13 * v13 + h23 * v23),
            p34 - (h03 * v04 + h13 * v14 + h23 * v24),
            p35 - (h03 * v05 + h13 * v15 + h23 * v25),
            p44 - (h04 * v04 + h14 * v14 + h24 * v24),
            p45 - (h04 * v05 + h14 * v15 + h24 * v25),
            p55 - (h05 * v05 + h15 * v15 + h25 * v25),
        ]
        return nis

    # --- 2D position measurement (RF) ---------------------------------------------------
    def nis2(self, z0: float, z1: float, r: PackedR) -> float:
        """Normalised innovation squared of a 2D (east, north) position."""
        p = self.P
        x = self.x
        s00 = p[0] + r[0]
        s01 = p[1] + r[1]
        s11 = p[6] + r[2]
        y0 = z0 - x[0]
        y1 = z1 - x[1]
        return (s11 * y0 * y0 - 2.0 * s01 * y0 * y1 + s00 * y1 * y1) / (s00 * s11 - s01 * s01)

    def update2(self, z0: float, z1: float, r: PackedR, gate: float = _INF) -> float:
        """Joseph-form update with a 2D position; returns the NIS of the innovation.

        With ``gate`` given, a measurement whose NIS exceeds it (or is NaN) leaves the
        state untouched; the caller compares the returned NIS with the gate.
        """
        # the rows of HP are the first two rows of P: h_ij = P[i, j] (h10 = h01)
        (
            h00, h01, h02, h03, h04, h05,
            h11, h12, h13, h14, h15,
            p22, p23, p24, p25,
            p33, p34, p35,
            p44, p45,
            p55,
        ) = self.P
        x0, x1, x2, x3, x4, x5 = self.x
        r00, r01, r11 = r
        s00 = h00 + r00
        s01 = h01 + r01
        s11 = h11 + r11
        d = 1.0 / (s00 * s11 - s01 * s01)
        i00 = s11 * d
        i01 = -s01 * d
        i11 = s00 * d
        y0 = z0 - x0
        y1 = z1 - x1
        u0 = i00 * y0 + i01 * y1
        u1 = i01 * y0 + i11 * y1
        nis = y0 * u0 + y1 * u1
        if not nis <= gate:  # also NaN
            return nis
        # x += (HP)^T S^-1 y
        self.x = [
            x0 + (h00 * u0 + h01 * u1),
            x1 + (h01 * u0 + h11 * u1),
            x2 + (h02 * u0 + h12 * u1),
            x3 + (h03 * u0 + h13 * u1),
            x4 + (h04 * u0 + h14 * u1),
            x5 + (h05 * u0 + h15 * u1),
        ]
        # M = S^-1 S, J = 2 S^-1 - M S^-1: the Joseph form's middle factor
        m00 = i00 * s00 + i01 * s01
        m01 = i00 * s01 + i01 * s11
        m10 = i01 * s00 + i11 * s01
        m11 = i01 * s01 + i11 * s11
        j00 = 2.0 * i00 - (m00 * i00 + m01 * i01)
        j01 = 2.0 * i01 - (m00 * i01 + m01 * i11)
        j11 = 2.0 * i11 - (m10 * i01 + m11 * i11)
        # V = J (HP)
        v00 = j00 * h00 + j01 * h01
        v01 = j00 * h01 + j01 * h11
        v02 = j00 * h02 + j01 * h12
        v03 = j00 * h03 + j01 * h13
        v04 = j00 * h04 + j01 * h14
        v05 = j00 * h05 + j01 * h15
        v10 = j01 * h00 + j11 * h01
        v11 = j01 * h01 + j11 * h11
        v12 = j01 * h02 + j11 * h12
        v13 = j01 * h03 + j11 * h13
        v14 = j01 * h04 + j11 * h14
        v15 = j01 * h05 + j11 * h15
        # P - (HP)^T V (upper triangle)
        self.P = [
            h00 - (h00 * v00 + h01 * v10),
            h01 - (h00 * v01 + h01 * v11),
            h02 - (h00 * v02 + h01 * v12),
            h03 - (h00 * v03 + h01 * v13),
            h04 - (h00 * v04 + h01 * v14),
            h05 - (h00 * v05 + h01 * v15),
            h11 - (h01 * v01 + h11 * v11),
            h12 - (h01 * v02 + h11 * v12),
            h13 - (h01 * v03 + h11 * v13),
            h14 - (h01 * v04 + h11 * v14),
            h15 - (h01 * v05 + h11 * v15),
            p22 - (h02 * v02 + h12 * v12),
            p23 - (h02 * v03 + h12 * v13),
            p24 - (h02 * v04 + h12 * v14),
            p25 - (h02 * v05 + h12 * v15),
            p33 - (h03 * v03 + h13 * v13),
            p34 - (h03 * v04 + h13 * v14),
            p35 - (h03 * v05 + h13 * v15),
            p44 - (h04 * v04 + h14 * v14),
            p45 - (h04 * v05 + h14 * v15),
            p55 - (h05 * v05 + h15 * v15),
        ]
        return nis


# --- the motion filter a track runs: the CV model (an IMM of CV models: imm.py) -------------
Q3 = tuple[float, float, float]
_PAIRS = tuple((i, j) for i in range(6) for j in range(i, 6))
_PI = tuple(i for i, _ in _PAIRS)
_PJ = tuple(j for _, j in _PAIRS)
_UNIT = tuple(tuple(1.0 if i == k else 0.0 for i in range(6)) for k in range(6))


class MotionFilter(Protocol):
    """What the tracker needs from a motion filter (CV or IMM)."""

    def set_state(self, x: FloatArray | Sequence[float], P: FloatArray) -> None: ...
    def predict(self, T: float) -> None: ...
    def nis(self, z: Sequence[float], r: PackedR) -> float: ...
    def update(self, z: Sequence[float], r: PackedR) -> float: ...
    def mean(self) -> tuple[list[float], list[float]]: ...
    def copy(self) -> MotionFilter: ...
    def mode_probabilities(self) -> tuple[float, ...]: ...
    def effective_q(self) -> Q3: ...
    def update_scalar(self, idx: int, value: float, var: float) -> None: ...
    def update_linear(self, h: Sequence[float], value: float, var: float) -> None: ...


def _nis(kf: CvKalman, z: Sequence[float], r: PackedR) -> float:
    if len(z) == 3:
        return kf.nis3(z[0], z[1], z[2], r)
    return kf.nis2(z[0], z[1], r)


def _update(kf: CvKalman, z: Sequence[float], r: PackedR) -> float:
    if len(z) == 3:
        return kf.update3(z[0], z[1], z[2], r)
    return kf.update2(z[0], z[1], r)


def update_scalar(kf: CvKalman, idx: int, value: float, var: float) -> None:
    """Update with a scalar pseudo-measurement of state element ``idx`` (variance ``var``):
    :func:`update_linear` with ``h = e_idx`` (``K = P e_i / (P_ii + var)``)."""
    update_linear(kf, _UNIT[idx], value, var)


def update_linear(kf: CvKalman, h: Sequence[float], value: float, var: float) -> None:
    """Update with a scalar pseudo-measurement ``h . x`` (``h`` over the 6 state elements,
    variance ``var``): ``K = P h / (h^T P h + var)``, ``x += K (value - h . x)``,
    ``P -= K K^T (h^T P h + var)``."""
    p = kf.P
    col = [sum(p[UPPER_INDEX[a][b]] * h[b] for b in range(6) if h[b]) for a in range(6)]
    s = sum(h[a] * col[a] for a in range(6)) + var
    y = value - sum(h[a] * kf.x[a] for a in range(6))
    kf.x = [xa + ca * y / s for xa, ca in zip(kf.x, col, strict=True)]
    kf.P = [pv - col[i] * col[j] / s for pv, i, j in zip(p, _PI, _PJ, strict=True)]


class CvFilter:
    """One constant-velocity model (the paper's filter as a :class:`MotionFilter`)."""

    __slots__ = ("kf",)

    def __init__(self, q: Q3) -> None:
        self.kf = CvKalman(q)

    def set_state(self, x: FloatArray | Sequence[float], P: FloatArray) -> None:
        self.kf.set_state(x, P)

    def predict(self, T: float) -> None:
        self.kf.predict(T)

    def nis(self, z: Sequence[float], r: PackedR) -> float:
        return _nis(self.kf, z, r)

    def update(self, z: Sequence[float], r: PackedR) -> float:
        return _update(self.kf, z, r)

    def mean(self) -> tuple[list[float], list[float]]:
        return self.kf.x, self.kf.P

    def copy(self) -> CvFilter:
        c = CvFilter(self.kf.q)
        c.kf.x = list(self.kf.x)
        c.kf.P = list(self.kf.P)
        return c

    def mode_probabilities(self) -> tuple[float, ...]:
        return (1.0,)

    def update_scalar(self, idx: int, value: float, var: float) -> None:
        update_scalar(self.kf, idx, value, var)

    def update_linear(self, h: Sequence[float], value: float, var: float) -> None:
        update_linear(self.kf, h, value, var)

    def effective_q(self) -> Q3:
        return self.kf.q


# --- quadratic forms on packed covariances (the multi-UAV tracker's costs) -------------------
def velocity_nis(
    x: list[float], p: list[float], vel_ned: tuple[float, float, float] | None, s2: float
) -> float:
    """NIS (3 dof) of a reported NED velocity against the velocity of the state ``x`` whose
    6x6 covariance is packed in ``p`` (upper triangle by rows), plus ``s2`` on each axis; 0
    for a report without a velocity or a singular sum."""
    if vel_ned is None:
        return 0.0
    q = quad3(
        vel_ned[1] - x[3], vel_ned[0] - x[4], -vel_ned[2] - x[5],
        p[15] + s2, p[16], p[17], p[18] + s2, p[19], p[20] + s2,
    )  # fmt: skip
    return 0.0 if q is None else q


def merge_nis(
    xa: list[float], pa: list[float], xb: list[float], pb: list[float], k: int
) -> float | None:
    """Squared Mahalanobis distance of two states' positions (the first ``k`` = 2 or 3 axes)
    on the sum of their covariances (packed upper triangles); None when the sum is
    singular."""
    d0 = xa[0] - xb[0]
    d1 = xa[1] - xb[1]
    s00 = pa[0] + pb[0]
    s01 = pa[1] + pb[1]
    s11 = pa[6] + pb[6]
    if k == 2:
        det = s00 * s11 - s01 * s01
        if det == 0.0:
            return None
        q = (d0 * (s11 * d0 - s01 * d1) + d1 * (s00 * d1 - s01 * d0)) / det
        return q if math.isfinite(q) else None
    return quad3(
        d0, d1, xa[2] - xb[2], s00, s01, pa[2] + pb[2], s11, pa[7] + pb[7], pa[11] + pb[11]
    )


def quad3(
    d0: float, d1: float, d2: float,
    s00: float, s01: float, s02: float, s11: float, s12: float, s22: float,
) -> float | None:  # fmt: skip
    """``d^T S^-1 d`` for a symmetric 3x3 ``S`` (upper triangle), by its adjugate; None when
    ``S`` is singular or the result is not finite."""
    i00 = s11 * s22 - s12 * s12
    i01 = s02 * s12 - s01 * s22
    i02 = s01 * s12 - s02 * s11
    det = s00 * i00 + s01 * i01 + s02 * i02
    if det == 0.0:
        return None
    i11 = s00 * s22 - s02 * s02
    i12 = s01 * s02 - s00 * s12
    i22 = s00 * s11 - s01 * s01
    q = (
        d0 * (i00 * d0 + i01 * d1 + i02 * d2)
        + d1 * (i01 * d0 + i11 * d1 + i12 * d2)
        + d2 * (i02 * d0 + i12 * d1 + i22 * d2)
    ) / det
    return q if math.isfinite(q) else None
