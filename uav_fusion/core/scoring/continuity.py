"""Track continuity of each UAV over a flight's epochs (:mod:`uav_fusion.core.scoring.gospa`).

Per UAV, the track id assigned at each of its airborne epochs (None: no track): the ID
switches counted on GOSPA's per-epoch assignment (:func:`id_switches`), the fragmentations
(:func:`fragmentations`), and the ID switches counted on the CLEAR MOT correspondence
(Bernardin and Stiefelhagen, 2008; :class:`KeptCorrespondence`), which keeps a UAV's track
through a crossing as long as that track stays published and closer than the cut-off.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import numpy.typing as npt
from scipy.optimize import linear_sum_assignment
from scipy.spatial.distance import cdist

FloatArray = npt.NDArray[np.float64]


def id_switches(track_ids: Sequence[int | None]) -> int:
    """Changes of the assigned track id from one assigned epoch to the next (None: none)."""
    return len(id_switch_indices(track_ids))


def id_switch_indices(track_ids: Sequence[int | None]) -> list[int]:
    """The indices at which :func:`id_switches` counts a switch."""
    out: list[int] = []
    prev = None
    for k, tid in enumerate(track_ids):
        if tid is None:
            continue
        if prev is not None and tid != prev:
            out.append(k)
        prev = tid
    return out


def fragmentations(track_ids: Sequence[int | None]) -> int:
    """Resumptions of assignment after unassigned epochs that followed an assigned one."""
    n, seen, gap = 0, False, False
    for tid in track_ids:
        if tid is None:
            gap = seen
        else:
            if gap:
                n += 1
            seen, gap = True, False
    return n


class KeptCorrespondence:
    """The CLEAR MOT correspondence, epoch by epoch, and the ID switches counted on it: a
    UAV keeps its previous track while that track is published and closer than ``c_m``
    (closest kept pairs first, one UAV per track); the remaining UAVs and tracks are assigned
    by minimum total squared distance, pairs at ``c_m`` or more left unassigned."""

    def __init__(self, c_m: float) -> None:
        self.c_m = c_m
        self.previous: dict[str, int] = {}
        self.switches: dict[str, list[float]] = {}  # per UAV: the times of its switches

    def step(
        self, t: float, names: list[str], X: FloatArray, track_ids: list[int], Y: FloatArray
    ) -> None:
        if not names or not track_ids:
            return
        D = cdist(X, Y)
        col = {tid: j for j, tid in enumerate(track_ids)}
        match: dict[int, int] = {}
        taken: set[int] = set()
        held = sorted(
            (float(D[i, col[self.previous[n]]]), i, col[self.previous[n]])
            for i, n in enumerate(names)
            if self.previous.get(n) in col
        )
        for d, i, j in held:
            if d < self.c_m and j not in taken:
                match[i] = j
                taken.add(j)
        rows = [i for i in range(len(names)) if i not in match]
        cols = [j for j in range(len(track_ids)) if j not in taken]
        if rows and cols:
            sub = D[np.ix_(rows, cols)]
            r, c = linear_sum_assignment(np.minimum(sub, self.c_m) ** 2)
            for a, b in zip(r.tolist(), c.tolist(), strict=True):
                if sub[a, b] < self.c_m:
                    match[rows[a]] = cols[b]
        for i, j in match.items():
            n, tid = names[i], track_ids[j]
            before = self.previous.get(n)
            if before is not None and before != tid:
                self.switches.setdefault(n, []).append(t)
            self.previous[n] = tid
