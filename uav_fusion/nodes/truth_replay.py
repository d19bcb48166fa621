"""truth_replay: publishes a flight's RTK truth as sensor_msgs/NavSatFix on ``truth/fix``.

A flight with several UAVs (one truth file each, ``uav_fusion.core.data.flight``) also
gets one topic per vehicle, ``truth/<vehicle>/fix`` (parameter ``vehicle_topic``, with
``{vehicle}`` in it); ``truth/fix`` stays the first UAV's. ``per_vehicle``: ``auto`` (only
when there are several UAVs), ``always`` or ``never``.

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
from uav_fusion.ros.params import Param, topic_param
from uav_fusion.ros.replay import ReplayNode, run_replay

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
                Param(
                    "per_vehicle",
                    "auto",
                    "one topic per UAV: auto (several UAVs only), always, never",
                    choices=("auto", "always", "never"),
                ),
                Param(
                    "vehicle_topic",
                    "truth/{vehicle}/fix",
                    "per-UAV truth topic ({vehicle}: the vehicle name)",
                    check=_vehicle_topic,
                ),
            ],
            **kwargs,
        )
        self.pub = self.create_publisher(NavSatFix, self.p["truth_topic"], self.qos)
        mode = str(self.p["per_vehicle"])
        several = len(self.flight.vehicles) > 1
        self.vehicle_pubs: dict[str, Publisher] = {}
        if mode == "always" or (mode == "auto" and several):
            fmt = str(self.p["vehicle_topic"])
            for vehicle in self.flight.vehicles:
                topic = fmt.format(vehicle=vehicle)
                self.vehicle_pubs[vehicle] = self.create_publisher(NavSatFix, topic, self.qos)

    def streams(self) -> list[tuple[Publisher, list[tuple[float, Any]]]]:
        frame = str(self.p["truth_frame"])
        out: list[tuple[Publisher, list[tuple[float, Any]]]] = [
            (self.pub, [(f.t, truth_to_navsatfix(f, frame)) for f in self.flight.truth])
        ]
        for vehicle, pub in self.vehicle_pubs.items():
            fixes = self.flight.vehicles[vehicle]
            out.append((pub, [(f.t, truth_to_navsatfix(f, frame)) for f in fixes]))
        return out


def _vehicle_topic(value: Any) -> str | None:
    """A per-vehicle topic pattern must name the vehicle."""
    text = str(value)
    if "{vehicle}" not in text:
        return "must contain {vehicle}"
    try:
        text.format(vehicle="uav1")
    except (KeyError, IndexError, ValueError) as exc:
        return f"is not a valid pattern ({exc})"
    return None


def main(args: Sequence[str] | None = None) -> int:
    return run_replay(TruthReplay, args, NODE_NAME)


if __name__ == "__main__":
    sys.exit(main())
