"""The fusion node's input: each message to core records, with its checks and accounting.

What the node subscribes depends on what its estimator reads
(:data:`~uav_fusion.core.estimators.base.READS`):

- ``selected`` (the paper's filter): ``radar/pose`` (PoseWithCovarianceStamped; reports
  sharing one stamp form one radar frame of candidates; the covariance is the report's R
  unless ``use_message_covariance`` is false) and ``rf/fix`` (PointStamped; NaN = a failed
  attempt);
- ``frames`` (the trackers): ``radar/tracks`` (PointCloud2: every report of one radar frame)
  and ``rf/fixes`` (PointCloud2: RF attempts with their quality;
  :mod:`uav_fusion.core.data.clouds`).

With an arrival log (:class:`ArrivalLog`, the node's ``arrivals_file``), every input with
something to fuse is written down as it arrives (``source,stamp,arrival``, the format of
:mod:`uav_fusion.core.live.schedule`), so that ``uav_fusion run --arrivals`` can fuse the same
flight in the same order offline and reproduce what the node published.

A message that cannot be decoded (NaN, bad covariance, wrong frame, zero stamp, unusable
layout) is dropped and counted as ``<source>_<reason>``; a point of a cloud that cannot be a
measurement is dropped and counted as ``<source>_point_<reason>`` while the message's good
points are kept. The first drop of each reason is logged. Every message ticks its input's
rate and stamp-delay monitor (:class:`~uav_fusion.ros.diagnostics.InputMonitor`).
"""

from __future__ import annotations

import csv
import time
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from geometry_msgs.msg import PointStamped, PoseWithCovarianceStamped
from sensor_msgs.msg import PointCloud2

from uav_fusion.core.live.schedule import HEADER
from uav_fusion.core.records import RADAR, RF, RadarFrame, RfAttempt
from uav_fusion.ros import conversions as cv
from uav_fusion.ros.diagnostics import InputMonitor


@dataclass(frozen=True)
class InputTopics:
    """The topics of each kind of input (the node's parameters)."""

    radar_pose: str = "radar/pose"
    rf_fix: str = "rf/fix"
    radar_tracks: str = "radar/tracks"
    rf_fixes: str = "rf/fixes"


class ArrivalLog:
    """The arrival schedule of a live node, written as inputs arrive (see the module text)."""

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._fh = self.path.open("w", newline="", encoding="utf-8")
        self._w = csv.writer(self._fh)
        self._w.writerow(HEADER)
        self.rows = 0
        self._last_radar: float | None = None

    def add(self, source: str, stamp: float) -> None:
        """One input as it arrives; one row per radar frame (the paper's ``radar/pose``
        brings a frame's candidates one message each, back to back: the first one's arrival
        is the frame's)."""
        if source == "radar":
            if stamp == self._last_radar:
                return
            self._last_radar = stamp
        self._w.writerow((source, repr(stamp), repr(time.time())))
        self.rows += 1

    def close(self) -> None:
        self._fh.close()


class FusionInput:
    """Decodes the fusion node's two inputs (see the module text)."""

    def __init__(
        self,
        reads: str,
        frame_id: str,
        topics: InputTopics,
        warn: Callable[[str], None],
        *,
        use_message_covariance: bool = True,
        monitor: dict[str, float] | None = None,
        arrivals: ArrivalLog | None = None,
    ) -> None:
        self.frame_id = frame_id
        self.frames = reads == "frames"
        self.warn = warn
        self.use_message_covariance = use_message_covariance
        self.arrivals = arrivals
        self.radar_topic = topics.radar_tracks if self.frames else topics.radar_pose
        self.rf_topic = topics.rf_fixes if self.frames else topics.rf_fix
        self.radar_type: Any = PointCloud2 if self.frames else PoseWithCovarianceStamped
        self.rf_type: Any = PointCloud2 if self.frames else PointStamped
        #: messages received per source (malformed ones included)
        self.received: Counter[str] = Counter()
        #: messages and points dropped, ``<source>_<reason>``
        self.dropped: Counter[str] = Counter()
        #: radar reports received on ``radar/tracks``, malformed points included
        self.received_reports = 0
        m = monitor or {}
        self.monitors = {
            src: InputMonitor(topic, **m)  # type: ignore[arg-type]
            for src, topic in ((RADAR, self.radar_topic), (RF, self.rf_topic))
        }

    def radar(self, msg: Any, now: float) -> RadarFrame | None:
        """One radar message received at node time ``now``: its frame, or None (dropped)."""
        self.received[RADAR] += 1
        try:
            if self.frames:
                frame, bad = cv.msg_to_radar_frame(msg, self.frame_id)
                self._count_points(RADAR, bad)
                self.received_reports += len(frame.tracks) + sum(bad.values())
            else:
                frame = cv.msg_to_radar_report(msg, self.frame_id)
                if not self.use_message_covariance:
                    frame = RadarFrame(frame.t, (replace(frame.tracks[0], cov=None),))
        except cv.MessageError as exc:
            self._dropped_message(RADAR, msg, now, exc)
            return None
        self.monitors[RADAR].tick(now - frame.t)
        if self.arrivals is not None and frame.tracks:
            self.arrivals.add(RADAR, frame.t)
        return frame

    def rf(self, msg: Any, now: float) -> list[RfAttempt] | None:
        """One RF message received at node time ``now``: its attempts, or None (dropped)."""
        self.received[RF] += 1
        try:
            if self.frames:
                attempts, bad = cv.msg_to_rf_attempts(msg, self.frame_id)
                self._count_points(RF, bad)
            else:
                attempts = [cv.msg_to_rf_attempt(msg, self.frame_id)]
        except cv.MessageError as exc:
            self._dropped_message(RF, msg, now, exc)
            return None
        self.monitors[RF].tick(now - cv.time_from_stamp(msg.header.stamp))
        if self.arrivals is not None:
            for a in attempts:
                if a.ok:
                    self.arrivals.add(RF, a.t)
        return attempts

    def _dropped_message(self, source: str, msg: Any, now: float, exc: cv.MessageError) -> None:
        st = msg.header.stamp
        zero = st.sec == 0 and st.nanosec == 0
        self.monitors[source].tick(None if zero else now - cv.time_from_stamp(st))
        self._count(source, exc.reason, f"dropping bad {source} message(s): {exc}")

    def _count_points(self, source: str, bad: Counter[str]) -> None:
        for reason, n in sorted(bad.items()):
            self._count(
                source, f"point_{reason}",
                f"dropping {source} point(s) that cannot be measurements ({reason})", n,
            )  # fmt: skip

    def _count(self, source: str, reason: str, warning: str, n: int = 1) -> None:
        key = f"{source}_{reason}"
        if self.dropped[key] == 0:
            self.warn(warning)
        self.dropped[key] += n

