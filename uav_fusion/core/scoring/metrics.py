"""Error statistics against truth: interpolation and the paper's Table II row arithmetic."""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]


def interpolate_truth(
    truth_t: FloatArray, truth_enu: FloatArray, t: FloatArray | float, max_gap_s: float = 2.0
) -> FloatArray:
    """Truth ENU linearly interpolated at times ``t`` (the paper's time alignment).

    Rows whose time lies outside the truth span, or inside a truth gap longer than
    ``max_gap_s``, are NaN, so they can never be scored against a stale position.
    """
    tq = np.atleast_1d(np.asarray(t, dtype=float))
    out = np.full((tq.size, 3), np.nan)
    if truth_t.size < 2:
        return out
    idx = np.searchsorted(truth_t, tq, side="right")
    ok = (idx > 0) & (idx < truth_t.size)
    exact_end = tq == truth_t[-1]
    idx = np.where(exact_end, truth_t.size - 1, idx)
    ok |= exact_end
    i1 = np.clip(idx, 1, truth_t.size - 1)
    i0 = i1 - 1
    dt = truth_t[i1] - truth_t[i0]
    ok &= (dt <= max_gap_s) | (tq == truth_t[i0]) | (tq == truth_t[i1])
    w = np.where(dt > 0, (tq - truth_t[i0]) / np.where(dt > 0, dt, 1.0), 0.0)
    interp = truth_enu[i0] + (truth_enu[i1] - truth_enu[i0]) * w[:, None]
    out[ok] = interp[ok]
    return out


def position_errors(est: FloatArray, ref: FloatArray, dims: int = 3) -> FloatArray:
    """Euclidean error over the first ``dims`` axes (2 = horizontal, 3 = full 3D)."""
    d = np.asarray(est, float)[:, :dims] - np.asarray(ref, float)[:, :dims]
    return np.asarray(np.sqrt(np.sum(d * d, axis=1)), dtype=float)


@dataclass(frozen=True)
class ErrorStats:
    """One Table II row: count, min, max, mean, std (sample, ddof=1) and count coverage %."""

    count: int
    min: float
    max: float
    mean: float
    std: float
    coverage_pct: float

    def as_dict(self) -> dict[str, float | int]:
        return asdict(self)


def error_stats(errors: FloatArray, denominator: int | None = None) -> ErrorStats:
    """Statistics of finite errors; coverage = count / denominator (the paper's arithmetic).

    ``denominator`` is the number of opportunities (e.g. 216 RF attempts, 3106 radar reports,
    2655 filter steps); ``None`` means the number of errors given (coverage 100 %).
    """
    e = np.asarray(errors, dtype=float)
    e = e[np.isfinite(e)]
    n = int(e.size)
    denom = int(np.asarray(errors).size) if denominator is None else int(denominator)
    cov = 100.0 * n / denom if denom > 0 else float("nan")
    if n == 0:
        nan = float("nan")
        return ErrorStats(0, nan, nan, nan, nan, cov)
    std = float(np.std(e, ddof=1)) if n > 1 else 0.0
    return ErrorStats(n, float(e.min()), float(e.max()), float(e.mean()), std, cov)
