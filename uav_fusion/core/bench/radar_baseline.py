"""The radar's own tracks passed through: the baseline a multi-UAV tracker has to beat.

A radar with an onboard tracker already outputs tracks with a class. A user who takes them
as they come, keeping the ones the classifier calls a UAV, has a multi-UAV tracker for free;
fusion earns its keep only where it does better. At each epoch of the benchmark's grid the
baseline publishes every report of the latest radar frame at or before the epoch (if that
frame is at most :data:`~uav_fusion.core.estimators.adaptive.HELD_S` old, the radar's longest
update interval) whose own class probability is at least ``min_uav_prob`` (0.5, the paper's
raw radar row), under the radar's track id, moved to the epoch with its reported velocity.
The site file's mount calibration corrects the positions, as it does for the trackers.

The multi-UAV benchmark scores it as the profile ``radar``, beside the profiles it runs.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

from uav_fusion.core.data.uav_class import DEFAULT_MIN_MEAN_UAV_PROB
from uav_fusion.core.estimators.adaptive import HELD_S
from uav_fusion.core.estimators.parts import alignment_from_site
from uav_fusion.core.records import Flight
from uav_fusion.core.scoring.gospa import EpochTracks, PublishedTrack, pool
from uav_fusion.core.scoring.outcomes import UavSamples
from uav_fusion.core.site import Site

if TYPE_CHECKING:
    from uav_fusion.core.bench.multi import MultiFlightResult

#: the baseline's name where the benchmark lists profiles
NAME = "radar"


def radar_epochs(
    flight: Flight,
    site: Site,
    grid_hz: float,
    t0: float,
    t1: float,
    min_uav_prob: float = DEFAULT_MIN_MEAN_UAV_PROB,
) -> list[EpochTracks]:
    """The baseline's tracks at every epoch ``k / grid_hz`` in ``[t0, t1]`` (see the module
    text)."""
    frames = sorted(flight.radar, key=lambda fr: fr.t)
    align = alignment_from_site(site)
    out: list[EpochTracks] = []
    j = -1
    k = math.ceil(t0 * grid_hz)
    while k / grid_hz < t0:
        k += 1
    while (t := k / grid_hz) <= t1:
        while j + 1 < len(frames) and frames[j + 1].t <= t:
            j += 1
        tracks: list[PublishedTrack] = []
        if j >= 0 and t - frames[j].t <= HELD_S:
            for trk in frames[j].tracks:
                p = trk.uav_prob
                if p is None or not p >= min_uav_prob:
                    continue
                e, n, u = trk.e, trk.n, trk.u
                if align is not None:
                    e, n, u = align.point(e, n, u)
                v = trk.vel_ned
                ve, vn, vu = (v[1], v[0], -v[2]) if v is not None else (0.0, 0.0, 0.0)
                dt = t - trk.t
                x = np.array([e + ve * dt, n + vn * dt, u + vu * dt, ve, vn, vu], dtype=float)
                if np.all(np.isfinite(x)):
                    tracks.append(PublishedTrack(trk.track_id, x))
        out.append(EpochTracks(t, tuple(tracks)))
        k += 1
    return out


def _common_mean(a: UavSamples, b: UavSamples) -> tuple[int, float, float]:
    """The epochs both cover and each one's mean error over them."""
    ca, cb = a.covered(), b.covered()
    if ca.size != cb.size or not np.array_equal(a.times, b.times):
        return 0, math.nan, math.nan
    both = ca & cb
    ea = np.full(ca.size, np.nan)
    eb = np.full(cb.size, np.nan)
    ea[ca] = a.errors
    eb[cb] = b.errors
    n = int(both.sum())
    if n == 0:
        return 0, math.nan, math.nan
    return n, float(ea[both].mean()), float(eb[both].mean())


def against_radar(results: Sequence[MultiFlightResult]) -> str:
    """Each profile against the baseline: per flight its mean GOSPA and the baseline's; per
    UAV the mean error of each over the epochs both cover; and the counts of flights with a
    lower GOSPA and of UAVs with an error at most the baseline's."""
    radar = {r.flight_id: r for r in results if r.profile == NAME}
    rows = [
        "profile | flight | GOSPA m (radar) | UAV: epochs both cover, mean error m (radar)",
    ]
    counts: dict[str, list[int]] = {}
    for r in results:
        base = radar.get(r.flight_id)
        if r.profile == NAME or base is None:
            continue
        c = counts.setdefault(r.profile, [0, 0, 0, 0])
        g, gb = pool([r.samples]).gospa_mean_m, pool([base.samples]).gospa_mean_m
        c[0] += g < gb
        c[1] += 1
        theirs = {u.name: u for u in base.samples.uavs}
        cells = []
        for u in r.samples.uavs:
            n, mine, other = _common_mean(u, theirs[u.name]) if u.name in theirs else (0, 0, 0)
            if n:
                c[2] += mine <= other
                c[3] += 1
                cells.append(f"{u.name} {n}, {mine:.1f} ({other:.1f})")
            else:
                cells.append(f"{u.name} -")
        rows.append(f"{r.profile} | {r.flight_id} | {g:.1f} ({gb:.1f}) | {'; '.join(cells)}")
    for name, (lo, flights, ok, uavs) in counts.items():
        rows.append(
            f"{name}: GOSPA below the radar's on {lo} of {flights} flights; mean error at most "
            f"the radar's on {ok} of {uavs} UAVs (epochs both cover)"
        )
    return "\n".join(rows)
