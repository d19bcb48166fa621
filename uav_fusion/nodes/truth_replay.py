"""truth_replay: publishes a flight's RTK truth as sensor_msgs/NavSatFix on ``truth/fix``.

By default this replay drives the shared timeline: it publishes ``/clock`` (sensor UTC time)
so that ``radar_replay`` and ``rf_replay`` started with ``use_sim_time:=true`` follow it.
Parameters: see :func:`uav_fusion.ros.replay.replay_params` and ``docs/graph.md``.
"""

from __future__ import annotations

import sys
from collections.abc import Sequence
from typing import Any

from rclpy.publisher import Publisher
from sensor_msgs.msg import NavSatFix

from uav_fusion.ros.conversions import truth_to_navsatfix
from uav_fusion.ros.replay import ReplayNode, run_replay, topic_param

NODE_NAME = "truth_replay"


class TruthReplay(ReplayNode):
    """Replays the truth log of a flight folder."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(
            NODE_NAME,
            publish_clock=True,
            extra=[
                topic_param("truth_topic", "truth/fix", "NavSatFix topic of the truth"),
                topic_param("truth_frame", "gps", "frame id of the truth receiver"),
            ],
            **kwargs,
        )
        self.pub = self.create_publisher(NavSatFix, self.p["truth_topic"], self.qos)

    def streams(self) -> list[tuple[Publisher, list[tuple[float, Any]]]]:
        frame = str(self.p["truth_frame"])
        return [(self.pub, [(f.t, truth_to_navsatfix(f, frame)) for f in self.flight.truth])]


def main(args: Sequence[str] | None = None) -> int:
    return run_replay(TruthReplay, args, NODE_NAME)


if __name__ == "__main__":
    sys.exit(main())
