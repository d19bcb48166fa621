"""The nodes as separate OS processes (their console scripts), talking DDS between processes.

truth_replay drives ``/clock``; rf_replay and radar_replay follow it with ``use_sim_time``;
fusion_node fuses. The fused track received here must equal the offline core run. The
environment (localhost-only discovery, a random domain) is inherited from conftest.
"""

from __future__ import annotations

import signal
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from nav_msgs.msg import Odometry
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from sensor_msgs.msg import NavSatFix
from test_graph_flight import write_flight

from uav_fusion.core.data import load_flight
from uav_fusion.core.estimators import load_profile, run_flight
from uav_fusion.core.site import load_site
from uav_fusion.ros import odometry as od
from uav_fusion.ros.qos import stream_qos

pytestmark = pytest.mark.processes

BIN = Path(sys.executable).parent


def _script(name: str) -> str:
    p = BIN / name
    if not p.exists():
        pytest.skip(f"console script {name} is not installed (pip install -e .)")
    return str(p)


class Procs:
    def __init__(self, logdir: Path) -> None:
        self.logdir = logdir
        self.procs: dict[str, subprocess.Popen[bytes]] = {}

    def start(self, name: str, *params: str) -> None:
        args = [_script(name), "--ros-args"]
        for p in params:
            args += ["-p", p]
        out = (self.logdir / f"{name}.log").open("wb")
        self.procs[name] = subprocess.Popen(args, stdout=out, stderr=subprocess.STDOUT)

    def log(self, name: str) -> str:
        return (self.logdir / f"{name}.log").read_text(errors="replace")

    def stop(self) -> dict[str, int]:
        codes: dict[str, int] = {}
        for p in self.procs.values():
            if p.poll() is None:
                p.send_signal(signal.SIGINT)
        for name, p in self.procs.items():
            try:
                codes[name] = p.wait(timeout=20)
            except subprocess.TimeoutExpired:
                p.kill()
                codes[name] = p.wait()
        return codes


def _spin_until(ex: SingleThreadedExecutor, cond: Callable[[], bool], limit_s: float) -> bool:
    end = time.monotonic() + limit_s
    while not cond():
        if time.monotonic() > end:
            return False
        ex.spin_once(timeout_sec=0.05)
    return True


def test_separate_processes_equal_the_offline_run(ctx: Context, tmp_path: Path) -> None:
    flight_dir = write_flight(tmp_path / "flight", seconds=20.0)
    site = load_site()
    flight = load_flight(flight_dir, site)
    offline = [s for s in run_flight(flight, load_profile("paper"), site).steps if s.counted]

    node = Node("observer", context=ctx)
    qos = stream_qos(5000)
    odom: list[Odometry] = []
    node.create_subscription(Odometry, "fusion/odom", odom.append, qos)
    truth: list[NavSatFix] = []
    node.create_subscription(NavSatFix, "truth/fix", truth.append, qos)
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(node)

    procs = Procs(tmp_path)
    fd = f"flight_dir:={flight_dir}"
    try:
        # a window of 15 s of flight (3 s of wall time at rate 5): a follower process the machine
        # holds up for a moment must not lose a message to it
        procs.start("fusion_node", "use_sim_time:=true", "reorder_window_s:=15.0")
        procs.start("radar_replay", fd, "use_sim_time:=true", "publish_raw:=false")
        procs.start("rf_replay", fd, "use_sim_time:=true")
        # start the clock only once the followers are matched with the fusion node
        assert _spin_until(
            ex,
            lambda: (
                node.count_publishers("radar/pose") >= 1
                and node.count_publishers("rf/fix") >= 1
                and node.count_subscribers("radar/pose") >= 1
                and node.count_subscribers("rf/fix") >= 1
                and node.count_publishers("fusion/odom") >= 1
            ),
            60.0,
        ), "processes did not come up:\n" + "\n".join(procs.log(n) for n in procs.procs)
        procs.start("truth_replay", fd, "rate:=5.0", "wait_for_clock_subscribers:=3")
        ok = _spin_until(ex, lambda: len(odom) >= len(offline), 120.0)
        assert ok, f"got {len(odom)} of {len(offline)} steps; fusion log:\n" + procs.log(
            "fusion_node"
        )
        _spin_until(ex, lambda: False, 0.5)  # nothing more may come
    finally:
        codes = procs.stop()
        node.destroy_node()
    got = [od.odometry_to_state(m) for m in odom]
    assert [g.t for g in got] == [s.t for s in offline]
    err = np.abs(np.array([g.x for g in got]) - np.array([s.x for s in offline]))
    assert float(err.max()) < 1e-9
    assert len(truth) == len(flight.truth)
    for name in procs.procs:
        assert "Traceback" not in procs.log(name), procs.log(name)
    assert codes == dict.fromkeys(procs.procs, 0), codes


def test_bad_parameter_exits_non_zero_with_a_message(tmp_path: Path) -> None:
    res = subprocess.run(
        [_script("fusion_node"), "--ros-args", "-p", "reorder_window_s:=-1.0"],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert res.returncode == 2
    assert "reorder_window_s" in res.stderr and "Traceback" not in res.stderr
