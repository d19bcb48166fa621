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
from typing import Protocol

import numpy as np
import numpy.typing as npt

from uav_fusion.core.estimators.models import cv_process_noise, cv_transition

FloatArray = npt.NDArray[np.float64]


class SmoothableStep(Protocol):
    """A filter step :class:`SegmentSmoother` can take: a tracker's step."""

    t: float
    segment: int
    q_eff: tuple[float, float, float]

    @property
    def x(self) -> FloatArray: ...

    @property
    def P(self) -> FloatArray: ...


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


class FixedLagSmoother:
    """:func:`fixed_lag` as a stream, for a live node: push the filtered entries of one track
    segment as they come; an entry is returned smoothed as soon as an entry later than
    ``t_k + lag_s`` arrives (or at :meth:`finish`, the end of the segment), computed exactly
    as :func:`fixed_lag` computes it over the whole segment."""

    def __init__(self, lag_s: float) -> None:
        if not lag_s >= 0.0 or lag_s == float("inf"):
            raise ValueError(f"a streaming fixed lag must be finite and >= 0, got {lag_s}")
        self.lag_s = float(lag_s)
        self._entries: list[Filtered] = []  # the entries from the first unfinished one on

    @property
    def pending(self) -> int:
        """Entries pushed and not returned yet."""
        return len(self._entries)

    def push(self, entry: Filtered) -> list[tuple[Filtered, FloatArray, FloatArray]]:
        """Add the segment's next entry; returns the entries now final, smoothed, in order."""
        if self._entries and entry.t < self._entries[-1].t:
            raise ValueError(f"entry at {entry.t} is older than the last ({self._entries[-1].t})")
        self._entries.append(entry)
        return self._release(final=False)

    def finish(self) -> list[tuple[Filtered, FloatArray, FloatArray]]:
        """The segment ended: every remaining entry, smoothed with what there is."""
        out = self._release(final=True)
        self._entries.clear()
        return out

    def _release(self, final: bool) -> list[tuple[Filtered, FloatArray, FloatArray]]:
        es = self._entries
        n = len(es)
        out: list[tuple[Filtered, FloatArray, FloatArray]] = []
        k = 0
        j = 0
        while k < n:
            horizon = es[k].t + self.lag_s
            if not final and es[-1].t <= horizon:
                break  # entries within the lag may still come
            j = max(j, k)
            while j + 1 < n and es[j + 1].t <= horizon:
                j += 1
            xs, Ps = es[j].x, es[j].P
            for i in range(j - 1, k - 1, -1):
                xs, Ps = _backward(es, xs, Ps, i)
            out.append((es[k], xs, Ps))
            k += 1
        del es[:k]
        return out


class SegmentSmoother:
    """Fixed-lag smoothing of a tracker's steps as they come (a live node): the counted steps
    of each track segment go through their own :class:`FixedLagSmoother`; a new segment
    finishes the previous one's window. Returns (t, smoothed x, smoothed P) per estimate
    that became final."""

    def __init__(self, lag_s: float) -> None:
        self.lag_s = lag_s
        self._smoother: FixedLagSmoother | None = None
        self._segment = -1

    def push(self, step: SmoothableStep) -> list[tuple[float, FloatArray, FloatArray]]:
        """One counted step (an estimate of a confirmed track)."""
        out: list[tuple[float, FloatArray, FloatArray]] = []
        sm = self._smoother
        if sm is None or step.segment != self._segment:
            out = self.finish()
            sm = self._smoother = FixedLagSmoother(self.lag_s)
            self._segment = step.segment
        entry = Filtered(step.t, step.x, step.P, step.q_eff)
        out += [(e.t, xs, Ps) for e, xs, Ps in sm.push(entry)]
        return out

    def finish(self) -> list[tuple[float, FloatArray, FloatArray]]:
        """End the current segment's window: its remaining estimates, smoothed."""
        sm = self._smoother
        self._smoother = None
        if sm is None:
            return []
        return [(e.t, xs, Ps) for e, xs, Ps in sm.finish()]
