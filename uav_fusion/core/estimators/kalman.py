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

from collections.abc import Sequence

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
