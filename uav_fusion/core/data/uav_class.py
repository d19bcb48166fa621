"""Which radar reports are the UAV's: the one definition used everywhere.

The radar labels every report with class probabilities; ``catProb[0]`` is the UAV class
(``RadarTrack.uav_prob``). A single report's probability is noisy (a UAV track's first reports
are often unclassified, a bird can look like a UAV for a frame), so the class is decided per
**track**: a radar track is the UAV's when the mean of its reports' UAV probabilities over the
whole flight is at least a threshold. A track none of whose reports carries a finite
probability counts as the UAV's (nothing says otherwise). Every report of a UAV track is a
UAV report; birds and clutter tracks are the others.

Users: the raw radar row of Table II (``uav_fusion evaluate``, ``radar_replay``'s raw topic
and the bag converter, all with the profile's ``evaluation.raw_radar_min_mean_uav_prob``) and
the calibration statistics (``uav_fusion calibrate``). Like the paper's largest-track choice
this looks at the whole flight, so it is an offline rule; the filter's own per-report class
gate is a different setting (``gating.min_uav_prob``).
"""

from __future__ import annotations

import math
from collections.abc import Iterable

from uav_fusion.core.records import RadarFrame, RadarTrack

DEFAULT_MIN_MEAN_UAV_PROB = 0.5  # the paper profile's evaluation.raw_radar_min_mean_uav_prob


def track_mean_uav_prob(frames: Iterable[RadarFrame]) -> dict[int, float | None]:
    """Mean UAV class probability of every radar track id (None: no finite probability)."""
    sums: dict[int, float] = {}
    counts: dict[int, int] = {}
    ids: dict[int, None] = {}
    for frame in frames:
        for trk in frame.tracks:
            ids[trk.track_id] = None
            p = trk.uav_prob
            if p is not None and math.isfinite(p):
                sums[trk.track_id] = sums.get(trk.track_id, 0.0) + p
                counts[trk.track_id] = counts.get(trk.track_id, 0) + 1
    return {i: (sums[i] / counts[i] if i in counts else None) for i in ids}


def uav_track_ids(
    frames: Iterable[RadarFrame], min_mean_uav_prob: float | None
) -> tuple[set[int], set[int]]:
    """(UAV track ids, other track ids); with ``min_mean_uav_prob`` None every track is a UAV
    track."""
    means = track_mean_uav_prob(frames)
    uav = {
        i
        for i, p in means.items()
        if min_mean_uav_prob is None or p is None or p >= min_mean_uav_prob
    }
    return uav, set(means) - uav


def uav_class_tracks(
    frames: Iterable[RadarFrame], min_mean_uav_prob: float | None
) -> list[RadarTrack]:
    """Every report of every UAV track (:func:`uav_track_ids`), in frame order; every report
    when ``min_mean_uav_prob`` is None."""
    frames = list(frames)
    uav, _ = uav_track_ids(frames, min_mean_uav_prob)
    return [trk for frame in frames for trk in frame.tracks if trk.track_id in uav]


class RunningUavClass:
    """The per-track rule as a live stream can apply it: a report is the UAV's when the mean
    UAV probability of its track *so far* (this report included) is at least the threshold
    (a track without a finite probability yet counts as the UAV's). It looks only at the past,
    so early reports of a track can be classed differently than by the offline rule, which
    averages the whole flight (``radar_stream``'s ``radar/raw``)."""

    def __init__(self, min_mean_uav_prob: float | None) -> None:
        self.threshold = min_mean_uav_prob
        self._sums: dict[int, float] = {}
        self._counts: dict[int, int] = {}

    def is_uav(self, trk: RadarTrack) -> bool:
        p = trk.uav_prob
        if p is not None and math.isfinite(p):
            self._sums[trk.track_id] = self._sums.get(trk.track_id, 0.0) + p
            self._counts[trk.track_id] = self._counts.get(trk.track_id, 0) + 1
        if self.threshold is None:
            return True
        n = self._counts.get(trk.track_id, 0)
        return n == 0 or self._sums[trk.track_id] / n >= self.threshold
