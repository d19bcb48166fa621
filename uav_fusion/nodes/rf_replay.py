"""rf_replay: publishes every RF localisation attempt as geometry_msgs/PointStamped.

Topic ``rf/fix``: x = east, y = north (ENU metres, site frame), z = 0.0; a failed attempt
is published as x = y = z = NaN so subscribers can count attempts. Topic ``rf/fixes``
(sensor_msgs/PointCloud2, one point per attempt; layout :mod:`uav_fusion.core.data.clouds`): the
same attempts with their CEP, valid and total sensor counts, measurement id, centre frequency
and RHO, what the tracker profiles consume. Stamps are the sensor's UTC times. Parameters:
see :func:`uav_fusion.ros.replay.replay_params` and ``docs/graph.md``.
"""

from __future__ import annotations

import sys
from collections.abc import Sequence
from typing import Any

from geometry_msgs.msg import PointStamped
from rclpy.publisher import Publisher
from sensor_msgs.msg import PointCloud2

from uav_fusion.ros.conversions import rf_attempt_to_msg, rf_attempts_to_cloud_msg
from uav_fusion.ros.params import rf_output_params
from uav_fusion.ros.replay import ReplayNode, run_replay

NODE_NAME = "rf_replay"


class RfReplay(ReplayNode):
    """Replays the RF CSV of a flight folder."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(
            NODE_NAME,
            publish_clock=False,
            extra=rf_output_params(),
            **kwargs,
        )
        self.pub = self.create_publisher(PointStamped, self.p["rf_topic"], self.qos)
        self.pub_fixes = (
            self.create_publisher(PointCloud2, self.p["rf_fixes_topic"], self.qos)
            if self.p["publish_fixes"]
            else None
        )

    def alternatives(self) -> list[tuple[Publisher, ...]]:
        # the fusion node reads rf/fix (paper) or rf/fixes (tracker profiles)
        return [(self.pub, self.pub_fixes)] if self.pub_fixes is not None else []

    def streams(self) -> list[tuple[Publisher, list[tuple[float, Any]]]]:
        fid = self.frame_id
        out: list[tuple[Publisher, list[tuple[float, Any]]]] = [
            (self.pub, [(a.t, rf_attempt_to_msg(a, fid)) for a in self.flight.rf])
        ]
        if self.pub_fixes is not None:
            fixes = [(a.t, rf_attempts_to_cloud_msg([a], fid)) for a in self.flight.rf]
            out.append((self.pub_fixes, fixes))
        return out


def main(args: Sequence[str] | None = None) -> int:
    return run_replay(RfReplay, args, NODE_NAME)


if __name__ == "__main__":
    sys.exit(main())
