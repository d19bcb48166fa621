"""The twin radar's onboard multi-target tracker, one for every object the radar detects.

Constant-velocity Kalman filters; global nearest neighbour association (every track-detection
pair inside its gate, confirmed tracks first, then by distance, each track and detection used
once); a detection outside every gate starts a tentative track, confirmed by M of N hits;
tracks coast on their prediction and are deleted after a coasting time that grows with range.
Nothing tells the tracker which object a detection came from (:attr:`Detection.obj` only
labels what the track follows, for the twin's diagnostics).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from uav_fusion.core.twin.config import RadarModel
from uav_fusion.core.twin.scene import SceneObject

FloatArray = npt.NDArray[np.float64]


@dataclass
class Detection:
    pos: FloatArray
    R: FloatArray
    rcs_dbsm: float
    obj: SceneObject


@dataclass
class TrackMeta:
    track_id: int
    born: float
    last_update: float
    hits: list[bool]
    confirmed: bool
    rcs_dbsm: float
    obj: SceneObject
    logit: float = 0.0
    noise: float = 0.0


class OnboardTracker:
    """The onboard multi-target tracker (CV Kalman filters, GNN association, M-of-N)."""

    def __init__(
        self, cfg: RadarModel, rpos: FloatArray, initial_logit: float, first_id: int
    ) -> None:
        self.cfg, self.rpos = cfg, rpos
        self.initial_logit = initial_logit
        self.next_id = first_id  # the id of the next track started
        self.X = np.zeros((0, 6))
        self.P = np.zeros((0, 6, 6))
        self.meta: list[TrackMeta] = []
        self.t = math.nan

    def scan(self, t: float, dets: list[Detection]) -> None:
        """One scan: predict, associate, update the tracks that took a detection, start a
        track on every other detection, then confirm and delete."""
        self.predict(t)
        assign = self.associate(dets)
        updated: set[int] = set()
        for det, i in zip(dets, assign, strict=True):
            if i >= 0:
                self.update(i, det, t)
                updated.add(i)
        for det, i in zip(dets, assign, strict=True):
            if i < 0:
                self.start(det, t, self.next_id)
                self.next_id += 1
        self.prune(t, updated)

    def predict(self, t: float) -> None:
        if self.meta and math.isfinite(self.t) and t > self.t:
            dt = t - self.t
            F = np.eye(6)
            F[0:3, 3:6] = dt * np.eye(3)
            q = self.cfg.tracker_q_mps2
            Q = np.zeros((6, 6))
            for k in range(3):
                Q[k, k] = q * dt**3 / 3.0
                Q[k, k + 3] = Q[k + 3, k] = q * dt**2 / 2.0
                Q[k + 3, k + 3] = q * dt
            self.X = self.X @ F.T
            self.P = np.einsum("ij,njk,lk->nil", F, self.P, F) + Q
        self.t = t

    def associate(self, dets: list[Detection]) -> list[int]:
        """Track index for every detection (-1: none), global nearest neighbour."""
        cfg = self.cfg
        out = [-1] * len(dets)
        n_tr = len(self.meta)
        if not dets or n_tr == 0:
            return out
        D = np.array([d.pos for d in dets])
        trR = np.array([float(np.trace(d.R)) for d in dets])
        trP = np.trace(self.P[:, 0:3, 0:3], axis1=1, axis2=2)
        dist = np.linalg.norm(self.X[:, None, 0:3] - D[None, :, :], axis=2)
        gate = cfg.tracker_gate_sigma * np.sqrt((trP[:, None] + trR[None, :]) / 3.0)
        gate += cfg.tracker_gate_min_m
        ti, di = np.nonzero(dist <= gate)
        if ti.size == 0:
            return out
        conf = np.array([0 if self.meta[i].confirmed else 1 for i in ti])
        order = np.lexsort((dist[ti, di], conf))
        used_t: set[int] = set()
        for k in order:
            a, b = int(ti[k]), int(di[k])
            if a in used_t or out[b] >= 0:
                continue
            used_t.add(a)
            out[b] = a
        return out

    def update(self, i: int, det: Detection, t: float) -> None:
        P = self.P[i]
        S = P[0:3, 0:3] + det.R
        K = np.linalg.solve(S, P[0:3, :]).T
        x = self.X[i] + K @ (det.pos - self.X[i, 0:3])
        speed = float(np.linalg.norm(x[3:6]))
        if speed > self.cfg.tracker_max_speed_mps:
            x[3:6] *= self.cfg.tracker_max_speed_mps / speed
        self.X[i] = x
        P = P - K @ P[0:3, :]
        self.P[i] = 0.5 * (P + P.T)
        m = self.meta[i]
        m.last_update = t
        m.hits.append(True)
        m.rcs_dbsm = det.rcs_dbsm
        m.obj = det.obj

    def start(self, det: Detection, t: float, track_id: int) -> None:
        P0 = np.zeros((6, 6))
        P0[0:3, 0:3] = det.R
        P0[3:6, 3:6] = np.eye(3) * 15.0**2
        x0 = np.concatenate([det.pos, np.zeros(3)])
        self.X = np.vstack([self.X, x0[None, :]])
        self.P = np.concatenate([self.P, P0[None, :, :]])
        self.meta.append(
            TrackMeta(track_id, t, t, [True], False, det.rcs_dbsm, det.obj, self.initial_logit)
        )

    def prune(self, t: float, updated: set[int]) -> None:
        cfg = self.cfg
        keep: list[int] = []
        for i, m in enumerate(self.meta):
            if i not in updated and m.born != t:
                m.hits.append(False)
            if not m.confirmed:
                recent = m.hits[-cfg.confirm_window :]
                if sum(recent) >= cfg.confirm_hits:
                    m.confirmed = True
                elif len(m.hits) >= cfg.confirm_window:
                    continue  # tentative track that failed confirmation
            rng_tr = float(np.linalg.norm(self.X[i, 0:3] - self.rpos))
            frac = min(1.0, rng_tr / cfg.max_coast_ref_range_m)
            max_coast = cfg.max_coast_s + frac * (cfg.max_coast_far_s - cfg.max_coast_s)
            if t - m.last_update > max_coast:
                continue
            if len(m.hits) > 32:
                del m.hits[:-16]
            keep.append(i)
        if len(keep) != len(self.meta):
            self.X = self.X[keep]
            self.P = self.P[keep]
            self.meta = [self.meta[i] for i in keep]
