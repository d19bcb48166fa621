"""rf_stream: the RF geolocation server's rows (Keysight CSV, AADM columns) live, as rf_replay
publishes a recorded flight.

Reads from ``url``: the server's CSV file as it grows (followed across rotation and
truncation) or the same rows over TCP or UDP (:mod:`uav_fusion.ros.stream`). A header line
(a field named ``Meas ID``) sets the columns; without one the AADM header is assumed. Every
attempt is published with its sensor time as stamp on ``rf/fix`` (PointStamped; a failed
attempt as NaN) and ``rf/fixes`` (PointCloud2 with CEP, sensor counts, measurement id,
centre frequency and RHO). Bad rows are dropped and counted by reason on ``/diagnostics``.

The clock-offset warning starts at 10 s here: a TDOA server writes a fix after computing it,
seconds after the signal it locates.
"""

from __future__ import annotations

import sys
from collections.abc import Sequence
from typing import Any

from geometry_msgs.msg import PointStamped
from rclpy.publisher import Publisher
from sensor_msgs.msg import PointCloud2

from uav_fusion.core.ingest.decode import Record
from uav_fusion.core.records import RfAttempt
from uav_fusion.ros.conversions import rf_attempt_to_msg, rf_attempts_to_cloud_msg
from uav_fusion.ros.params import rf_output_params
from uav_fusion.ros.stream import StreamNode, run_stream

NODE_NAME = "rf_stream"


class RfStream(StreamNode):
    """Publishes live RF attempts (see the module text)."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(
            NODE_NAME,
            "rf",
            clock_offset_warn_s=10.0,
            stale_s=30.0,
            extra=rf_output_params(),
            **kwargs,
        )
        self.pub = self.create_publisher(PointStamped, self.p["rf_topic"], self.qos)
        self.pub_fixes = (
            self.create_publisher(PointCloud2, self.p["rf_fixes_topic"], self.qos)
            if self.p["publish_fixes"] else None
        )

    def stream_groups(self) -> list[tuple[Publisher, ...]]:
        return [tuple(p for p in (self.pub, self.pub_fixes) if p is not None)]

    def publish_records(self, records: Sequence[Record]) -> int:
        n = 0
        for a in records:
            assert isinstance(a, RfAttempt)
            if self.pub_fixes is not None:
                n += self.send(self.pub_fixes, rf_attempts_to_cloud_msg([a], self.frame_id))
            n += self.send(self.pub, rf_attempt_to_msg(a, self.frame_id))
        return n


def main(args: Sequence[str] | None = None) -> int:
    return run_stream(RfStream, args, NODE_NAME)


if __name__ == "__main__":
    sys.exit(main())
