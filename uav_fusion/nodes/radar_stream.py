"""radar_stream: the radar's JSON lines (Dataset-28 schema) live, as radar_replay publishes a
recorded flight.

Reads from ``url``: a TCP server (reconnecting with backoff), UDP datagrams or a growing
file (followed across rotation and truncation); see :mod:`uav_fusion.ros.stream`. Every
frame is decoded by the file reader's own line decoder and published with its sensor time as
stamp:

- ``radar/tracks`` (PointCloud2): every report of the frame (empty frames too), each with
  the covariance of the profile's radar model;
- ``radar/pose``: every report of the frame as PoseWithCovarianceStamped with the profile's
  radar R (the ``online`` track selection: the candidates of one frame share one stamp; the
  paper's largest-track choice needs the whole flight and cannot be made live);
- ``radar/raw``: the reports of tracks whose mean UAV probability so far reaches the
  profile's ``evaluation.raw_radar_min_mean_uav_prob`` (the offline rule averages the whole
  track; :class:`~uav_fusion.core.data.uav_class.RunningUavClass`).

Bad lines are dropped and counted by reason on ``/diagnostics`` (docs/graph.md, "Live
ingest").
"""

from __future__ import annotations

import sys
from collections.abc import Sequence
from typing import Any

from geometry_msgs.msg import PoseWithCovarianceStamped
from rclpy.publisher import Publisher
from sensor_msgs.msg import PointCloud2

from uav_fusion.core.data.uav_class import RunningUavClass
from uav_fusion.core.estimators.selection import (
    pose_covariance,
    radar_profile,
    report_covariance,
)
from uav_fusion.core.ingest.decode import Record
from uav_fusion.core.records import RadarFrame
from uav_fusion.ros import conversions as cv
from uav_fusion.ros.params import Param, topic_param
from uav_fusion.ros.stream import StreamNode, run_stream

NODE_NAME = "radar_stream"


class RadarStream(StreamNode):
    """Publishes live radar frames (see the module text)."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(
            NODE_NAME,
            "radar",
            clock_offset_warn_s=2.0,
            stale_s=5.0,
            extra=[
                Param("profile", "paper", "estimator profile (its radar R and UAV class rule)"),
                topic_param("radar_topic", "radar/pose", "every report (PoseWithCovariance)"),
                topic_param("radar_raw_topic", "radar/raw", "UAV-class reports"),
                topic_param("radar_tracks_topic", "radar/tracks", "every report (PointCloud2)"),
                Param("publish_pose", True, "publish radar/pose"),
                Param("publish_raw", True, "publish radar/raw"),
                Param("publish_tracks", True, "publish radar/tracks"),
            ],
            **kwargs,
        )
        prof = radar_profile(str(self.p["profile"]))
        self.R = pose_covariance(prof, self.site)
        self.cov = report_covariance(prof, self.site)
        self.uav_class = RunningUavClass(prof.raw_radar_min_mean_uav_prob)
        pub = self.create_publisher
        self.pub_pose = (
            pub(PoseWithCovarianceStamped, self.p["radar_topic"], self.qos)
            if self.p["publish_pose"] else None
        )
        self.pub_raw = (
            pub(PoseWithCovarianceStamped, self.p["radar_raw_topic"], self.qos)
            if self.p["publish_raw"] else None
        )
        self.pub_tracks = (
            pub(PointCloud2, self.p["radar_tracks_topic"], self.qos)
            if self.p["publish_tracks"] else None
        )

    def stream_groups(self) -> list[tuple[Publisher, ...]]:
        main = tuple(p for p in (self.pub_pose, self.pub_tracks) if p is not None)
        groups = [main] if main else []
        if self.pub_raw is not None:
            groups.append((self.pub_raw,))
        return groups

    def publish_records(self, records: Sequence[Record]) -> int:
        n = 0
        fid = self.frame_id
        for frame in records:
            assert isinstance(frame, RadarFrame)
            if self.pub_tracks is not None:
                n += self.send(self.pub_tracks, cv.radar_frame_to_cloud_msg(frame, fid, self.cov))
            for trk in frame.tracks:
                raw = self.pub_raw if self.uav_class.is_uav(trk) else None
                if self.pub_pose is None and raw is None:
                    continue
                R = self.R(trk.e, trk.n, trk.u)  # the same R on both topics
                if self.pub_pose is not None:
                    n += self.send(self.pub_pose, cv.radar_track_to_msg(trk, R, fid))
                if raw is not None:
                    n += self.send(raw, cv.radar_track_to_msg(trk, R, fid))
        return n


def main(args: Sequence[str] | None = None) -> int:
    return run_stream(RadarStream, args, NODE_NAME)


if __name__ == "__main__":
    sys.exit(main())
