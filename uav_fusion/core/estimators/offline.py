"""Offline run of the estimator over a flight, and the run's outputs (counts, CSV)."""

from __future__ import annotations

import csv
import math
import struct
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import numpy.typing as npt

from uav_fusion.core.estimators.paper import FusionEstimator, Step
from uav_fusion.core.estimators.profile import Profile
from uav_fusion.core.estimators.selection import StreamInfo, StreamItem, build_stream
from uav_fusion.core.estimators.smoothing import Filtered, fixed_lag
from uav_fusion.core.estimators.tracker import Tracker, TrackerStep
from uav_fusion.core.records import RADAR, RF, Flight, Measurement, RadarFrame, RfAttempt
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
    """Feed a stream (single measurements and candidate lists) through an estimator."""
    steps: list[Step] = []
    for item in stream:
        if isinstance(item, list):
            steps.extend(est.process_frame(item))
        else:
            steps.extend(est.process(item))
    return steps


def tracker_stream(flight: Flight, profile: Profile) -> Iterator[RadarFrame | RfAttempt]:
    """A flight's raw radar frames and successful RF attempts in (time, radar before RF, file
    position) order: what the :class:`Tracker` consumes."""
    keyed: list[tuple[float, int, int]] = []
    if profile.use_radar:
        keyed.extend((fr.t, 0, i) for i, fr in enumerate(flight.radar) if fr.tracks)
    if profile.use_rf:
        keyed.extend((a.t, 1, i) for i, a in enumerate(flight.rf) if a.ok)
    keyed.sort()
    for _, rank, i in keyed:
        yield flight.radar[i] if rank == 0 else flight.rf[i]


@dataclass(eq=False, slots=True)
class TrackerItem(Measurement):
    """A radar frame or an RF attempt travelling through a live timeline
    (:class:`~uav_fusion.core.live.timeline.Timeline`) as a :class:`Measurement`: ``t`` and
    ``source`` order it, ``z`` (every report's position, or the fix's) recognises repeats,
    ``item`` is what the :class:`Tracker` consumes."""

    item: RadarFrame | RfAttempt | None = None


def tracker_item(item: RadarFrame | RfAttempt, seq: int = 0) -> TrackerItem:
    """Wrap a radar frame or an RF attempt for a live timeline."""
    if isinstance(item, RadarFrame):
        z = np.array([v for trk in item.tracks for v in (trk.e, trk.n, trk.u)], dtype=float)
        return TrackerItem(t=item.t, source=RADAR, z=z, seq=seq, item=item)
    return TrackerItem(t=item.t, source=RF, z=np.array((item.e, item.n)), seq=seq, item=item)


def feed_tracker(tracker: Tracker, item: RadarFrame | RfAttempt) -> list[TrackerStep]:
    """One radar frame or RF attempt through ``tracker`` (what :func:`run_tracker` does per
    item)."""
    if isinstance(item, RadarFrame):
        return tracker.process_radar_frame(item)
    return tracker.process_rf(item)


def run_tracker(tracker: Tracker, stream: Iterable[RadarFrame | RfAttempt]) -> list[TrackerStep]:
    """Feed radar frames and RF attempts through a :class:`Tracker`."""
    steps: list[TrackerStep] = []
    for item in stream:
        steps.extend(feed_tracker(tracker, item))
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


def _run_tracker_flight(flight: Flight, profile: Profile, site: Site) -> RunResult:
    tracker = Tracker(profile, site)
    steps = run_tracker(tracker, tracker_stream(flight, profile))
    if profile.smoother_lag_s is not None:
        steps = smooth_steps(steps, profile.smoother_lag_s)
    reports = sum(len(fr.tracks) for fr in flight.radar) if profile.use_radar else 0
    info = StreamInfo(
        radar_frames=len(flight.radar) if profile.use_radar else 0,
        radar_reports=reports,
        radar_selected=reports,
        not_selected=0,
        selected_track_id=None,
        rf_attempts=len(flight.rf) if profile.use_rf else 0,
        rf_fixes=sum(
            1 for a in flight.rf if a.ok and math.isfinite(a.e) and math.isfinite(a.n)
        )
        if profile.use_rf
        else 0,
    )
    counters = dict(tracker.counters)
    counters["radar_reports"] = reports
    counters["radar_objects"] = len(tracker.objects.objects)
    return RunResult(
        steps=list[Step](steps), counters=counters, info=info, profile_name=profile.name
    )


def run_flight(flight: Flight, profile: Profile, site: Site) -> RunResult:
    """``flight_measurements`` fed through a fresh :class:`FusionEstimator`; a profile with
    ``association.mode: track_score`` runs the :class:`Tracker` over every radar report
    instead (then fixed-lag smoothing when ``smoother.lag_s`` is set)."""
    if profile.uses_tracker:
        return _run_tracker_flight(flight, profile, site)
    stream, info = build_stream(flight, profile, site)
    est = FusionEstimator(profile, site)
    steps = run_stream(est, stream)
    counters = dict(est.counters)
    counters["radar_reports"] = info.radar_reports
    counters["rejected_not_selected_offline"] = info.not_selected
    return RunResult(steps=steps, counters=counters, info=info, profile_name=profile.name)
