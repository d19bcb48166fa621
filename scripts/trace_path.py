"""Trace one radar report's way through the code, from ``radar/tracks`` to ``fusion/odom``.

Runs a fusion node (``tracker`` profile by default) in this process on the bundled flight,
feeding its radar frames (``radar/tracks``) and RF fixes (``rf/fixes``) one message at a time
in time order. For one chosen radar frame it records, with :func:`sys.setprofile`, every
function of the package that runs while the frame's message is taken, and while the message
that leads to the first ``fusion/odom`` publication at or after the frame's time is handled
(with a reorder window the frame is fused later than it arrives). It prints the modules of
the package those functions live in, in order of first entry, and how often control entered
the node's module from elsewhere.

    python scripts/trace_path.py [--frame 400] [--profile tracker] [--window 2.0]
"""

from __future__ import annotations

import argparse
import os
import random
import sys
import time
from collections.abc import Callable
from pathlib import Path
from types import FrameType
from typing import Any

os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
os.environ.setdefault("ROS_DOMAIN_ID", str(random.randint(101, 199)))

import rclpy
from nav_msgs.msg import Odometry
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from sensor_msgs.msg import PointCloud2

import uav_fusion
from uav_fusion.nodes.fusion_node import FusionNode
from uav_fusion.resources import DEFAULT_FLIGHT, data_path

try:  # the layout of the package at the time
    from uav_fusion.core.data import load_flight
except ImportError:  # pragma: no cover - older layout
    from uav_fusion.core.dataset import load_flight  # type: ignore[no-redef]
from uav_fusion.core.site import load_site
from uav_fusion.ros import conversions as cv

PKG = Path(uav_fusion.__file__).resolve().parent
NODE_FILE = str(Path(sys.modules[FusionNode.__module__].__file__ or "").resolve())


def module_of(filename: str) -> str | None:
    try:
        rel = Path(filename).resolve().relative_to(PKG)
    except ValueError:
        return None
    return "uav_fusion/" + rel.as_posix()


class Recorder:
    def __init__(self) -> None:
        self.order: list[str] = []
        self.node_entries = 0

    def __call__(self, frame: FrameType, event: str, arg: Any) -> None:
        if event != "call":
            return
        mod = module_of(frame.f_code.co_filename)
        if mod is None:
            return
        if mod not in self.order:
            self.order.append(mod)
        if frame.f_code.co_filename == NODE_FILE:
            back = frame.f_back
            if back is None or back.f_code.co_filename != NODE_FILE:
                self.node_entries += 1


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frame", type=int, default=1200, help="index of the traced radar frame")
    ap.add_argument("--profile", default="tracker")
    ap.add_argument("--window", type=float, default=0.0,
                    help="reorder_window_s (default 0: zero wait)")
    args = ap.parse_args(argv)
    site = load_site(None)
    flight = load_flight(data_path(DEFAULT_FLIGHT), site)
    frame_id = site.frame_id
    items: list[tuple[float, int, Any]] = [
        (fr.t, 0, cv.radar_frame_to_cloud_msg(fr, frame_id)) for fr in flight.radar if fr.tracks
    ]
    items += [(a.t, 1, cv.rf_attempts_to_cloud_msg([a], frame_id)) for a in flight.rf]
    items.sort(key=lambda e: (e[0], e[1]))
    radar_idx = [i for i, e in enumerate(items) if e[1] == 0]
    target = radar_idx[args.frame]
    t_frame = items[target][0]

    rclpy.init()
    try:
        fusion = FusionNode(parameter_overrides=[
            Parameter("profile", value=args.profile),
            Parameter("reorder_window_s", value=args.window),
            Parameter("idle_flush_s", value=0.0),
            Parameter("stall_timeout_s", value=0.0),
        ])
        io = Node("trace_io")
        qos = 10000
        pub_radar = io.create_publisher(PointCloud2, "radar/tracks", qos)
        pub_rf = io.create_publisher(PointCloud2, "rf/fixes", qos)
        odom: list[float] = []
        io.create_subscription(
            Odometry, "fusion/odom", lambda m: odom.append(cv.time_from_stamp(m.header.stamp)), qos
        )
        ex = SingleThreadedExecutor()
        ex.add_node(fusion)
        ex.add_node(io)
        taken = [0]
        current: list[Recorder | None] = [None]  # the recorder of the traced callback
        for sub in list(fusion.subscriptions):
            inner: Callable[[Any], None] = sub.callback

            def counted(msg: Any, inner: Callable[[Any], None] = inner) -> None:
                taken[0] += 1
                rec = current[0]
                if rec is not None:  # trace this subscription callback only
                    sys.setprofile(rec)
                try:
                    inner(msg)
                finally:
                    sys.setprofile(None)

            sub.callback = counted

        def spin_until(cond: Callable[[], bool], limit: float = 30.0) -> None:
            end = time.monotonic() + limit
            while not cond():
                if time.monotonic() > end:
                    raise SystemExit("timed out waiting for the fusion node")
                ex.spin_once(timeout_sec=0.01)

        spin_until(lambda: pub_radar.get_subscription_count() > 0
                   and pub_rf.get_subscription_count() > 0
                   and fusion.count_subscribers("fusion/odom") > 0)
        spins: list[tuple[int, Recorder]] = []
        for i, (_t, kind, msg) in enumerate(items):
            before = taken[0]
            n_odom = len(odom)

            def took(before: int = before) -> bool:
                return taken[0] > before

            (pub_radar if kind == 0 else pub_rf).publish(msg)
            rec = Recorder()
            current[0] = rec if i >= target else None
            spin_until(took)
            current[0] = None
            # the fusion node's outputs reach the subscriber in the next spins
            end = time.monotonic() + 0.05
            while time.monotonic() < end:
                ex.spin_once(timeout_sec=0.005)
            if i == target:
                spins.append((i, rec))
            elif i > target and any(t >= t_frame for t in odom[n_odom:]):
                spins.append((i, rec))
                break
        merged = Recorder()
        for _i, r in spins:
            merged.order += [m for m in r.order if m not in merged.order]
            merged.node_entries += r.node_entries
        traced = [i for i, _ in spins]
        fusion.destroy_node()
        io.destroy_node()
    finally:
        rclpy.try_shutdown()
    print(f"profile {args.profile}, radar frame {args.frame} at t={t_frame:.3f}; "
          f"traced messages {traced}")
    print(f"modules entered ({len(merged.order)}):")
    for m in merged.order:
        print(f"  {m}")
    print(f"entries into {module_of(NODE_FILE)}: "
          + " + ".join(str(r.node_entries) for _, r in spins)
          + f" = {merged.node_entries}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
