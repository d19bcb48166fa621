"""Rauch-Tung-Striebel smoothing of a CV track: offline over a whole flight, and fixed-lag.

A track segment is a list of :class:`Filtered` entries (time, filtered ``x``, ``P``, and the
white-acceleration ``q`` of the prediction that led to the entry). Between entries ``k`` and
``k+1`` the CV model gives ``F = F(T)``, ``Q = Q(T, q_{k+1})`` with ``T = t_{k+1} - t_k``, and
the RTS backward pass (Rauch, Tung and Striebel 1965) is

    P_pred = F P_k F^T + Q,  G = P_k F^T P_pred^-1,
    xs_k = x_k + G (xs_{k+1} - F x_k),  Ps_k = P_k + G (Ps_{k+1} - P_pred) G^T.

For a CV filter ``P_pred`` is exactly the filter's own prediction; for an IMM the entries hold
the combined estimate and ``q`` its mode-probability-weighted ``q`` (an approximation).

Fixed lag ``L``: the estimate of entry ``k`` uses the data up to ``t_k + L``: it is the RTS
backward pass over entries ``k .. j`` with ``j`` the last entry with ``t_j <= t_k + L``,
evaluated at ``k``; which is exactly the full RTS over the entries ``0 .. j`` at ``k`` (the
backward pass at ``k`` depends only on the entries after it; tested).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from uav_fusion.core.estimator.models import cv_process_noise, cv_transition

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True)
class Filtered:
    """One filtered estimate of a track segment."""

    t: float
    x: FloatArray
    P: FloatArray
    q: tuple[float, float, float]


def _backward(
    entries: Sequence[Filtered], xs: FloatArray, Ps: FloatArray, k: int
) -> tuple[FloatArray, FloatArray]:
    e, nxt = entries[k], entries[k + 1]
    T = nxt.t - e.t
    F = cv_transition(T)
    Pp = F @ e.P @ F.T + cv_process_noise(T, nxt.q)
    G = np.linalg.solve(Pp.T, (e.P @ F.T).T).T  # P F^T Pp^-1 (Pp symmetric)
    x = e.x + G @ (xs - F @ e.x)
    P = e.P + G @ (Ps - Pp) @ G.T
    return x, 0.5 * (P + P.T)


def rts(entries: Sequence[Filtered]) -> list[tuple[FloatArray, FloatArray]]:
    """Smoothed ``(x, P)`` of every entry of one segment (the last one is its filtered)."""
    n = len(entries)
    if n == 0:
        return []
    out: list[tuple[FloatArray, FloatArray]] = [(entries[-1].x, entries[-1].P)] * n
    xs, Ps = entries[-1].x, entries[-1].P
    for k in range(n - 2, -1, -1):
        xs, Ps = _backward(entries, xs, Ps, k)
        out[k] = (xs, Ps)
    return out


def fixed_lag(entries: Sequence[Filtered], lag_s: float) -> list[tuple[FloatArray, FloatArray]]:
    """Fixed-lag smoothed ``(x, P)`` of every entry: entry ``k`` smoothed with the data up
    to ``t_k + lag_s`` (see the module text)."""
    n = len(entries)
    out: list[tuple[FloatArray, FloatArray]] = []
    j = 0
    for k in range(n):
        j = max(j, k)
        while j + 1 < n and entries[j + 1].t <= entries[k].t + lag_s:
            j += 1
        xs, Ps = entries[j].x, entries[j].P
        for i in range(j - 1, k - 1, -1):
            xs, Ps = _backward(entries, xs, Ps, i)
        out.append((xs, Ps))
    return out
