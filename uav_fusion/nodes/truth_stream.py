"""truth_stream: an RTK vehicle log (``*_vehicleOut.txt`` rows) live, for live scoring, as
truth_replay publishes a recorded one.

Reads from ``url``: the log file as it grows (followed across rotation and truncation) or
the same rows over TCP or UDP (:mod:`uav_fusion.ros.stream`). Every fix is published on
``truth/fix`` (sensor_msgs/NavSatFix) stamped with its UTC time (the site's truth clock
offset applied, as the file reader does); rows without a fix are counted, not published.
One node follows one vehicle: for several UAVs run one per log with ``truth_topic`` set to
``truth/<vehicle>/fix``.
"""

from __future__ import annotations

import sys
from collections.abc import Sequence
from typing import Any

from rclpy.publisher import Publisher
from sensor_msgs.msg import NavSatFix

from uav_fusion.core.ingest.decode import Record
from uav_fusion.core.records import TruthFix
from uav_fusion.ros.conversions import truth_to_navsatfix
from uav_fusion.ros.params import topic_param
from uav_fusion.ros.stream import StreamNode, run_stream

NODE_NAME = "truth_stream"


class TruthStream(StreamNode):
    """Publishes live truth fixes (see the module text)."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(
            NODE_NAME,
            "truth",
            clock_offset_warn_s=2.0,
            stale_s=5.0,
            extra=[
                topic_param("truth_topic", "truth/fix", "NavSatFix topic of the truth"),
                topic_param("truth_frame", "gps", "frame id of the truth receiver"),
            ],
            **kwargs,
        )
        self.pub = self.create_publisher(NavSatFix, self.p["truth_topic"], self.qos)

    def stream_groups(self) -> list[tuple[Publisher, ...]]:
        return [(self.pub,)]

    def publish_records(self, records: Sequence[Record]) -> int:
        frame = str(self.p["truth_frame"])
        n = 0
        for fix in records:
            assert isinstance(fix, TruthFix)
            n += self.send(self.pub, truth_to_navsatfix(fix, frame))
        return n


def main(args: Sequence[str] | None = None) -> int:
    return run_stream(TruthStream, args, NODE_NAME)


if __name__ == "__main__":
    sys.exit(main())
