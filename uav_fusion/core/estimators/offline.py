"""Offline runs: a profile's estimator over a whole flight, and the run's outputs (counts, CSV)."""

from __future__ import annotations

import csv
import struct
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import numpy.typing as npt

from uav_fusion.core.errors import ConfigError
from uav_fusion.core.estimators.base import drive, make_estimator
from uav_fusion.core.estimators.paper import FusionEstimator
from uav_fusion.core.estimators.selection import StreamInfo, StreamItem, input_info
from uav_fusion.core.estimators.smoothing import Filtered, fixed_lag
from uav_fusion.core.estimators.steps import Step, TrackerStep
from uav_fusion.core.estimators.tracker import Tracker
from uav_fusion.core.profiles.model import Profile
from uav_fusion.core.records import RADAR, RF, Flight, RadarFrame, RfAttempt
from uav_fusion.core.site import Site

FloatArray = npt.NDArray[np.float64]


CSV_HEADER = (
    *("t", "seq", "source", "status", "reason", "nis", "dim", "track_id"),
    *("x", "y", "z", "vx", "vy", "vz"),
    *("var_x", "var_y", "var_z", "var_vx", "var_vy", "var_vz"),
)


@dataclass
class RunResult:
    """Every step of a run, the estimator's counters and the stream summary."""

    steps: list[Step]
    counters: dict[str, int]
    info: StreamInfo | None = None
    profile_name: str = ""
    extra: dict[str, int] = field(default_factory=dict)
    #: the estimator's status at the end of the run (its /diagnostics keys)
    status: dict[str, object] = field(default_factory=dict)

    def paper_counts(self) -> dict[str, int]:
        """The counts behind the paper's Table II rows.

        ``all_steps = updated_estimates + coasted_estimates`` (the paper: 2528 + 127 = 2655);
        discarded reports (range gate, class probability, not selected, ...) are not steps,
        and neither are ``tentative`` ones (measurements that started or were tested against
        a track not yet confirmed; their estimates are not published).
        ``radar_accepted`` / ``rf_accepted`` are the "after validation" rows' counts
        (measurements that passed the NIS gate of a confirmed track, the confirming one
        included); ``track_starts`` are the updated estimates that started a confirmed track
        from a measurement without a gate test.
        """
        upd = sum(1 for s in self.steps if s.updated)
        coast = sum(1 for s in self.steps if s.coasted)
        radar_acc = sum(1 for s in self.steps if s.validated and s.source == RADAR)
        rf_acc = sum(1 for s in self.steps if s.validated and s.source == RF)
        out = {
            "all_steps": upd + coast,
            "updated_estimates": upd,
            "coasted_estimates": coast,
            "track_starts": upd - radar_acc - rf_acc,
            "radar_accepted": radar_acc,
            "rf_accepted": rf_acc,
            "tentative": sum(1 for s in self.steps if s.status == "tentative"),
            "discarded": sum(1 for s in self.steps if s.status == "discarded"),
        }
        if self.info is not None:
            out.update(
                radar_reports=self.info.radar_reports,
                radar_not_selected=self.info.not_selected,
                rf_attempts=self.info.rf_attempts,
                rf_fixes=self.info.rf_fixes,
            )
        return out

    def times(self) -> FloatArray:
        return np.array([s.t for s in self.steps], dtype=float)

    def states(self) -> FloatArray:
        """(N, 6) states of all steps (NaN rows where no track existed)."""
        if not self.steps:
            return np.zeros((0, 6))
        return np.array([s.x for s in self.steps], dtype=float)

    def write_csv(self, path: str | Path) -> Path:
        """One row per step: time, source, status, reason, NIS, dim, ids, state, P diagonal."""
        p = Path(path)
        if p.parent and not p.parent.exists():
            p.parent.mkdir(parents=True, exist_ok=True)
        with p.open("w", newline="", encoding="utf-8") as fh:
            w = csv.writer(fh)
            w.writerow(CSV_HEADER)
            for s in self.steps:
                x = s.x
                d = np.diag(s.P)
                w.writerow(
                    [
                        f"{s.t:.6f}",
                        s.seq,
                        s.source,
                        s.status,
                        s.reason or "",
                        "" if s.nis is None else f"{s.nis:.6g}",
                        s.dim,
                        "" if s.track_id is None else s.track_id,
                    ]
                    + [f"{v:.6f}" for v in x]
                    + [f"{v:.6g}" for v in d]
                )
        return p


def run_stream(est: FusionEstimator, stream: Iterable[StreamItem]) -> list[Step]:
    """Feed a measurement stream (single measurements and candidate lists) through the paper's
    filter directly (its own API, as the oracle tests use it)."""
    steps: list[Step] = []
    for item in stream:
        if isinstance(item, list):
            steps.extend(est.process_frame(item))
        else:
            steps.extend(est.process(item))
    return steps


def run_tracker(tracker: Tracker, stream: Iterable[RadarFrame | RfAttempt]) -> list[TrackerStep]:
    """The steps of a :class:`Tracker` fed ``stream`` (time order)."""
    steps: list[TrackerStep] = []
    for item in stream:
        steps.extend(
            tracker.process_radar_frame(item)
            if isinstance(item, RadarFrame)
            else tracker.process_rf(item)
        )
    return steps


_STATE = struct.Struct("27d")
_UPPER = tuple((i, j) for i in range(6) for j in range(i, 6))


def smooth_steps(steps: list[TrackerStep], lag_s: float) -> list[TrackerStep]:
    """The steps with the state of every counted step (an estimate of a confirmed track)
    replaced by its fixed-lag smoothed state (``lag_s``; ``math.inf``: offline RTS over
    each track segment)."""
    by_segment: dict[int, list[int]] = {}
    for k, s in enumerate(steps):
        if s.counted:
            by_segment.setdefault(s.segment, []).append(k)
    out = list(steps)
    for idx in by_segment.values():
        entries = []
        for k in idx:
            s = steps[k]
            q = s.q_eff
            entries.append(Filtered(s.t, s.x, s.P, q))
        smoothed = fixed_lag(entries, lag_s)
        for k, (x, P) in zip(idx, smoothed, strict=True):
            s = steps[k]
            out[k] = s.with_state(_STATE.pack(*x, *(P[i, j] for i, j in _UPPER)))
    return out


def run_flight(flight: Flight, profile: Profile, site: Site) -> RunResult:
    """The profile's single-track estimator (the paper's filter or the tracker,
    :func:`~uav_fusion.core.estimators.base.make_estimator`) over everything it reads of
    ``flight``, then, with ``smoother.lag_s``, each track segment smoothed over the whole run.
    The fixed-rate output of the steps: :func:`~uav_fusion.core.estimators.grid.grid_from_steps`."""
    if profile.estimator == "multi":
        raise ConfigError(
            f"{profile.source or profile.name}: a multi-UAV profile has no single track to run "
            "(its tracks: uav_fusion run --targets, or uav_fusion bench --definition multi)"
        )
    est = make_estimator(profile, site, grid_hz=None)
    steps = drive(est, est.flight_input(flight)).steps
    lag = profile.smoother_lag_s
    if lag is not None:
        steps = list[Step](smooth_steps(list[TrackerStep](steps), lag))  # type: ignore[arg-type]
    info = input_info(flight, profile, est.reads)
    counters = dict(est.counters)
    counters["radar_reports"] = info.radar_reports
    if info.not_selected:
        counters["rejected_not_selected_offline"] = info.not_selected
    return RunResult(
        steps=steps, counters=counters, info=info, profile_name=profile.name, status=est.status()
    )
