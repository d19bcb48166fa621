"""radar_replay: publishes a flight's radar reports as PoseWithCovarianceStamped.

Two streams (see ``docs/graph.md``):

- ``radar/pose``: the reports the track-selection policy keeps, exactly the radar
  measurements the offline runner feeds the estimator
  (:func:`uav_fusion.core.estimators.selection.selected_radar`); with the paper's policy
  (``largest_track``) that is the largest continuous track. Candidates of one radar frame
  share one stamp.
- ``radar/raw``: every UAV report of every frame, before selection (the evaluator's
  "radar raw" row, :func:`uav_fusion.core.estimators.selection.raw_radar_reports`).
- ``radar/tracks`` (sensor_msgs/PointCloud2): every report of every frame, one cloud per
  frame, with velocity, radar track id, UAV class probability, RCS, range, Doppler and the
  report's covariance from the profile's radar model (layout: :mod:`uav_fusion.core.data.clouds`):
  what the tracker profiles consume.

Covariance: the measurement's own R, else the profile's radar R. Stamps: the radar frame's
UTC time. Parameters: :func:`uav_fusion.ros.replay.replay_params` plus ``profile``,
``track_selection``, ``radar_topic``, ``radar_raw_topic``, ``publish_raw``,
``radar_tracks_topic``, ``publish_tracks``.
"""

from __future__ import annotations

import sys
from collections.abc import Sequence
from typing import Any

from geometry_msgs.msg import PoseWithCovarianceStamped
from rclpy.publisher import Publisher
from sensor_msgs.msg import PointCloud2

from uav_fusion.core.estimators.selection import (
    pose_covariance,
    radar_profile,
    raw_radar_reports,
    report_covariance,
    selected_radar,
)
from uav_fusion.core.profiles.model import SELECTIONS
from uav_fusion.ros import conversions as cv
from uav_fusion.ros.params import Param, topic_param
from uav_fusion.ros.replay import ReplayNode, run_replay

NODE_NAME = "radar_replay"


class RadarReplay(ReplayNode):
    """Replays the radar JSON Lines of a flight folder."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(
            NODE_NAME,
            publish_clock=False,
            extra=[
                Param("profile", "paper", "estimator profile (its R, selection and UAV class)"),
                Param(
                    "track_selection",
                    "profile",
                    "radar track selection: 'profile' (the profile's own) or a policy name",
                    choices=("profile", *SELECTIONS),
                ),
                topic_param("radar_topic", "radar/pose", "selected reports"),
                topic_param("radar_raw_topic", "radar/raw", "every UAV-class report"),
                Param("publish_raw", True, "publish the raw topic too"),
                topic_param("radar_tracks_topic", "radar/tracks", "every report (PointCloud2)"),
                Param("publish_tracks", True, "publish every report as PointCloud2 too"),
            ],
            **kwargs,
        )
        self.profile = radar_profile(str(self.p["profile"]), str(self.p["track_selection"]))
        self.pub = self.create_publisher(PoseWithCovarianceStamped, self.p["radar_topic"], self.qos)
        self.pub_raw = (
            self.create_publisher(PoseWithCovarianceStamped, self.p["radar_raw_topic"], self.qos)
            if self.p["publish_raw"]
            else None
        )
        #: radar/pose is replayed (a graph whose fusion node runs a tracker profile drops it)
        self.pose_stream = True
        self.pub_tracks = (
            self.create_publisher(PointCloud2, self.p["radar_tracks_topic"], self.qos)
            if self.p["publish_tracks"]
            else None
        )

    def alternatives(self) -> list[tuple[Publisher, ...]]:
        # the fusion node reads radar/pose (paper) or radar/tracks (tracker profiles)
        return [(self.pub, self.pub_tracks)] if self.pub_tracks is not None else []

    def streams(self) -> list[tuple[Publisher, list[tuple[float, Any]]]]:
        R = pose_covariance(self.profile, self.site)
        sel = [
            (m.t, cv.radar_measurement_to_msg(m, self.frame_id, R(*m.z)))
            for frame in selected_radar(self.flight, self.profile, self.site)
            for m in frame
        ]
        out: list[tuple[Publisher, list[tuple[float, Any]]]] = []
        if self.pose_stream:
            out.append((self.pub, sel))
        if self.pub_raw is not None:
            raw = [
                (trk.t, cv.radar_track_to_msg(trk, R(trk.e, trk.n, trk.u), self.frame_id))
                for trk in raw_radar_reports(self.flight, self.profile)
            ]
            out.append((self.pub_raw, raw))
        if self.pub_tracks is not None:
            cov = report_covariance(self.profile, self.site)
            clouds = [
                (fr.t, cv.radar_frame_to_cloud_msg(fr, self.frame_id, cov))
                for fr in self.flight.radar
            ]
            out.append((self.pub_tracks, clouds))
        return out


def main(args: Sequence[str] | None = None) -> int:
    return run_replay(RadarReplay, args, NODE_NAME)


if __name__ == "__main__":
    sys.exit(main())
