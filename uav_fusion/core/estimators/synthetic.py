"""Seeded synthetic streams that follow the filter's own models exactly.

Used by the statistical tests and the benchmark: the truth is a constant-velocity target
driven by continuous white-noise acceleration (sampled exactly from ``Q(T)``), radar reports
are truth + N(0, R_radar) at ~0.25 s, RF fixes are truth (east, north) + N(0, R_rf) at
~3.88 s. Outliers can be injected. Not a model of the real sensors: the digital twin is.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from uav_fusion.core.estimators.models import cv_process_noise, cv_transition
from uav_fusion.core.records import (
    RADAR,
    RF,
    Flight,
    Measurement,
    RadarFrame,
    RadarTrack,
    RfAttempt,
    TruthFix,
)
from uav_fusion.core.site import Site

FloatArray = npt.NDArray[np.float64]


@dataclass
class SyntheticStream:
    """Measurements in (t, seq) order plus the true state at each measurement time."""

    measurements: list[Measurement]
    truth: FloatArray  # (N, 6): true state at each measurement's time
    outlier: npt.NDArray[np.bool_]  # (N,) measurement was an injected outlier
    x0: FloatArray = field(default_factory=lambda: np.zeros(6))


def simulate_stream(
    seed: int,
    duration_s: float,
    q: tuple[float, float, float],
    r_radar: FloatArray,
    r_rf: FloatArray,
    *,
    radar_period_s: float = 0.25,
    rf_period_s: float = 3.88,
    jitter: float = 0.2,
    x0: FloatArray | None = None,
    velocity_std: float = 15.0,
    outlier_rate: dict[str, float] | None = None,
    outlier_scale_m: float = 2000.0,
    t0: float = 1.0e9,
) -> SyntheticStream:
    """A mixed radar/RF stream with variable intervals (periods scaled by 1 +- ``jitter``).

    The initial velocity is drawn from N(0, velocity_std^2) per axis, matching the filter's
    initialisation, so the filter is statistically consistent from the first step.
    """
    rng = np.random.default_rng(seed)
    rates = outlier_rate or {}
    times: list[tuple[float, int]] = []
    for src_rank, period in ((0, radar_period_s), (1, rf_period_s)):
        t = 0.0 if src_rank == 0 else period * rng.uniform(0.1, 0.9)
        while t < duration_s:
            times.append((t, src_rank))
            t += period * (1.0 + jitter * rng.uniform(-1.0, 1.0))
    times.sort()
    if x0 is None:
        x = np.array([300.0, -200.0, 60.0, *rng.normal(0.0, velocity_std, 3)])
    else:
        x = np.asarray(x0, dtype=float).copy()
    first = x.copy()
    La = np.linalg.cholesky(np.asarray(r_radar, float))
    Lf = np.linalg.cholesky(np.asarray(r_rf, float))
    ms: list[Measurement] = []
    truth = np.zeros((len(times), 6))
    outl = np.zeros(len(times), dtype=bool)
    t_prev = 0.0
    for k, (t, rank) in enumerate(times):
        T = t - t_prev
        if T > 0:
            Q = cv_process_noise(T, q)
            x = cv_transition(T) @ x + np.linalg.cholesky(Q + 1e-15 * np.eye(6)) @ rng.normal(
                size=6
            )
        t_prev = t
        truth[k] = x
        src = RADAR if rank == 0 else RF
        d = 3 if rank == 0 else 2
        L = La if rank == 0 else Lf
        z = x[:d] + L @ rng.normal(size=d)
        if rng.uniform() < rates.get(src, 0.0):
            ang = rng.uniform(0, 2 * np.pi)
            z = z.copy()
            z[0] += outlier_scale_m * np.cos(ang)
            z[1] += outlier_scale_m * np.sin(ang)
            outl[k] = True
        ms.append(Measurement(t=t0 + t, source=src, z=z, seq=k))
    return SyntheticStream(ms, truth, outl, first)


def stream_to_flight(
    stream: SyntheticStream,
    site: Site,
    *,
    truth_period_s: float = 0.2,
    extra_tracks: list[RadarTrack] | None = None,
    failed_rf_every: int = 0,
) -> Flight:
    """Wrap a synthetic stream as a :class:`Flight` (truth sampled from the stream's states).

    Radar measurements become one-track frames with track id 1; ``extra_tracks`` are merged
    into frames at their times (or get their own frames). RF fixes become ``ok`` attempts;
    every ``failed_rf_every``-th attempt is replaced by a failed one.
    """
    ms = stream.measurements
    ts = np.array([m.t for m in ms])
    grid = np.arange(ts[0], ts[-1], truth_period_s)
    tr = np.column_stack([np.interp(grid, ts, stream.truth[:, i]) for i in range(6)])
    lat, lon, h = site.to_geodetic(tr[:, 0], tr[:, 1], tr[:, 2])
    truth: list[TruthFix] = []
    for t, a, o, hh, r in zip(grid, lat, lon, h, tr, strict=True):
        vel_ned = (float(r[4]), float(r[3]), -float(r[5]))
        e, n, u = float(r[0]), float(r[1]), float(r[2])
        fix = TruthFix(float(t), float(a), float(o), float(hh), e, n, u, vel_ned, 4, 20)
        truth.append(fix)
    frames: dict[float, list[RadarTrack]] = {}
    rf: list[RfAttempt] = []
    # geodetic coordinates of every measurement in one vectorised call
    zs = np.array([(*m.z[:2], m.z[2] if m.dim == 3 else 0.0) for m in ms], dtype=float)
    glat, glon, gh = site.to_geodetic(zs[:, 0], zs[:, 1], zs[:, 2])
    for k, m in enumerate(ms):
        la, lo, hh = float(glat[k]), float(glon[k]), float(gh[k])
        e, n, u = (float(v) for v in zs[k])
        if m.source == RADAR:
            frames.setdefault(m.t, []).append(
                RadarTrack(m.t, 1, la, lo, hh, e, n, u, None, 0.9, None, None)
            )
        else:
            i = len(rf)
            if failed_rf_every and i % failed_rf_every == failed_rf_every - 1:
                rf.append(RfAttempt(m.t, i, False, 0.0, 0.0, np.nan, np.nan, None, None, None))
            else:
                rf.append(RfAttempt(m.t, i, True, la, lo, e, n, None, 4, 4))
    for trk in extra_tracks or []:
        frames.setdefault(trk.t, []).append(trk)
    radar = [RadarFrame(t, tuple(frames[t])) for t in sorted(frames)]
    return Flight("synthetic", truth, radar, rf)
