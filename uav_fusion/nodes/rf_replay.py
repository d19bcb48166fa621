"""rf_replay: publishes every RF localisation attempt as geometry_msgs/PointStamped.

Topic ``rf/fix``: x = east, y = north (ENU metres, site frame), z = 0.0; a failed attempt
is published as x = y = z = NaN so subscribers can count attempts. Stamps are the sensor's
UTC times. Parameters: see :func:`uav_fusion.ros.replay.replay_params` and ``docs/graph.md``.
"""

from __future__ import annotations

import sys
from collections.abc import Sequence
from typing import Any

from geometry_msgs.msg import PointStamped
from rclpy.publisher import Publisher

from uav_fusion.ros.conversions import rf_attempt_to_msg
from uav_fusion.ros.replay import ReplayNode, run_replay, topic_param

NODE_NAME = "rf_replay"


class RfReplay(ReplayNode):
    """Replays the RF CSV of a flight folder."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(
            NODE_NAME,
            publish_clock=False,
            extra=[topic_param("rf_topic", "rf/fix", "PointStamped topic of the RF attempts")],
            **kwargs,
        )
        self.pub = self.create_publisher(PointStamped, self.p["rf_topic"], self.qos)

    def streams(self) -> list[tuple[Publisher, list[tuple[float, Any]]]]:
        return [(self.pub, [(a.t, rf_attempt_to_msg(a, self.frame_id)) for a in self.flight.rf])]


def main(args: Sequence[str] | None = None) -> int:
    return run_replay(RfReplay, args, NODE_NAME)


if __name__ == "__main__":
    sys.exit(main())
