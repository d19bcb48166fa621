"""Fault cases, area "processes": nodes killed and restarted as real OS processes (their
console scripts), and a replay restarted in-process. The test process observes over DDS."""

from __future__ import annotations

import json
import re
import signal
import subprocess
import sys
import time
import uuid
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticArray
from faultkit import RF, T0, FusionHarness, accounting, radar_msg, straight
from geometry_msgs.msg import PointStamped, PoseWithCovarianceStamped
from nav_msgs.msg import Odometry
from rclpy.context import Context
from rclpy.duration import Duration
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import HistoryPolicy, QoSProfile
from rclpy.serialization import deserialize_message

from uav_fusion.ros import conversions as cv
from uav_fusion.ros import odometry as od
from uav_fusion.ros.qos import stream_qos

pytestmark = pytest.mark.processes

BIN = Path(sys.executable).parent


class Procs:
    """Child processes running console scripts; logs in ``logdir``."""

    def __init__(self, logdir: Path) -> None:
        self.logdir = logdir
        self.procs: dict[str, subprocess.Popen[bytes]] = {}

    def start(self, key: str, script: str, *params: str) -> subprocess.Popen[bytes]:
        exe = BIN / script
        if not exe.exists():
            pytest.skip(f"console script {script} is not installed (pip install -e .)")
        args = [str(exe), "--ros-args"]
        for p in params:
            args += ["-p", p]
        out = (self.logdir / f"{key}.log").open("wb")
        self.procs[key] = subprocess.Popen(args, stdout=out, stderr=subprocess.STDOUT)
        return self.procs[key]

    def log(self, key: str) -> str:
        return (self.logdir / f"{key}.log").read_text(errors="replace")

    def stop(self, key: str, sig: int = signal.SIGINT) -> int:
        p = self.procs[key]
        if p.poll() is None:
            p.send_signal(sig)
        try:
            return p.wait(timeout=30)
        except subprocess.TimeoutExpired:
            p.kill()
            return p.wait()

    def stop_all(self) -> None:
        for key in self.procs:
            self.stop(key)


class Observer:
    """An in-process node with an executor; collects what it subscribes to."""

    def __init__(self, ctx: Context) -> None:
        self.node = Node(f"fault_observer_{uuid.uuid4().hex[:6]}", context=ctx)
        self.ex = SingleThreadedExecutor(context=ctx)
        self.ex.add_node(self.node)
        self.odom: list[Odometry] = []
        self.diag: dict[str, dict[str, str]] = {}
        qos = stream_qos(5000)
        self.sub_odom = self.node.create_subscription(
            Odometry, "fusion/odom", self.odom.append, qos
        )
        self.node.create_subscription(DiagnosticArray, "/diagnostics", self._on_diag, 10)
        self.pub_radar = self.node.create_publisher(PoseWithCovarianceStamped, "radar/pose", qos)

    def _on_diag(self, msg: DiagnosticArray) -> None:
        for st in msg.status:
            self.diag[st.name] = {kv.key: kv.value for kv in st.values}

    def spin_until(self, cond: Callable[[], bool], limit_s: float, what: str) -> None:
        end = time.monotonic() + limit_s
        while not cond():
            assert time.monotonic() < end, f"timed out waiting for {what}"
            self.ex.spin_once(timeout_sec=0.05)

    def readers(self, topic: str) -> set[bytes]:
        return {bytes(i.endpoint_gid) for i in self.node.get_subscriptions_info_by_topic(topic)}

    def wait_new_reader(self, topic: str, old: set[bytes], limit_s: float = 60.0) -> None:
        """Wait until a reader not in ``old`` exists and our radar writer matches all readers."""
        self.spin_until(lambda: bool(self.readers(topic) - old), limit_s, f"a new {topic} reader")
        self.spin_until(
            lambda: self.pub_radar.get_subscription_count() >= len(self.readers(topic)),
            limit_s,
            "our writer to match the new reader",
        )

    def destroy(self) -> None:
        self.node.destroy_node()


def eval_inputs(obs: Observer) -> dict[str, str]:
    for name, vals in obs.diag.items():
        if name.endswith(": inputs"):
            return vals
    return {}


@pytest.mark.fault("PROC-01")
def test_fusion_node_sigkill_and_restart_reinitialises_and_the_gap_is_reported(
    ctx: Context, tmp_path: Path
) -> None:
    procs = Procs(tmp_path)
    obs = Observer(ctx)
    rep = tmp_path / "report"
    try:
        procs.start(
            "evaluator", "evaluator_node", f"output_dir:={rep}", "figures:=false",
            "log_period_s:=0.2", "step_gap_s:=5.0",
        )
        procs.start("fusion1", "fusion_node", "idle_flush_s:=0.3")
        obs.spin_until(
            lambda: obs.pub_radar.get_subscription_count() >= 1
            and obs.node.count_subscribers("fusion/odom/updated") >= 1
            and obs.node.count_publishers("fusion/odom/updated") >= 1,
            60.0, "fusion_node and evaluator_node",
        )
        obs.spin_until(lambda: bool(eval_inputs(obs)), 30.0, "evaluator diagnostics")
        # the fusion node's own view: its updated writer is matched with the evaluator
        obs.spin_until(
            lambda: int(obs.diag.get("fusion_node: fusion", {}).get("subscribers_updated", 0))
            >= 1, 60.0, "the evaluator matched with fusion_node")
        before = obs.readers("radar/pose")

        def segment(t_from: float, t_to: float) -> int:
            ts = np.arange(t_from, t_to, 0.25)
            for t in ts:
                obs.pub_radar.publish(radar_msg(float(t), *straight(float(t))))
            return len(ts)

        def evaluator_steps() -> int:
            return int(eval_inputs(obs).get("used fusion/odom/updated", "0"))

        n1 = segment(T0, T0 + 10.0)
        obs.spin_until(lambda: len(obs.odom) >= n1, 60.0, "steps of the first fusion_node")
        # the gap is measured from the last step the evaluator received: let it have them all
        obs.spin_until(lambda: evaluator_steps() >= n1, 60.0, "the evaluator's first steps")
        procs.procs["fusion1"].send_signal(signal.SIGKILL)
        assert procs.procs["fusion1"].wait(timeout=10) == -signal.SIGKILL
        segment(T0 + 10.0, T0 + 20.0)  # nobody fuses these
        procs.start("fusion2", "fusion_node", "idle_flush_s:=0.3")
        obs.wait_new_reader("radar/pose", before)
        # our odometry reader must match the new node before it publishes anything
        obs.spin_until(lambda: obs.sub_odom.get_publisher_count() >= 1, 60.0, "new odom writer")

        # The evaluator matches the new node on its own time (discovery takes up to seconds
        # on a loaded machine) and volatile QoS loses what was published before that, so
        # feed the new node at a steady pace until the evaluator has seen one of its steps.
        n3, t = 0, T0 + 20.0
        deadline = time.monotonic() + 60.0
        while evaluator_steps() <= n1:
            assert time.monotonic() < deadline, "timed out waiting for steps of the new node"
            n3 += segment(t, t + 1.0)
            t += 1.0
            def fused(n: int = n1 + n3) -> bool:
                return len(obs.odom) >= n

            obs.spin_until(fused, 60.0, "steps of the new node")
            pause = time.monotonic() + 0.3
            while time.monotonic() < pause:
                obs.ex.spin_once(timeout_sec=0.05)
        seen, since = evaluator_steps(), time.monotonic()
        while time.monotonic() - since < 1.0:  # until the evaluator's count settles
            obs.ex.spin_once(timeout_sec=0.05)
            if evaluator_steps() != seen:
                seen, since = evaluator_steps(), time.monotonic()
        assert procs.stop("evaluator") == 0
    finally:
        procs.stop_all()
        obs.destroy()
    times = [cv.time_from_stamp(o.header.stamp) for o in obs.odom]
    assert times[n1 - 1] == T0 + 9.75 and times[n1] == T0 + 20.0  # restarted at the new data
    second = [od.odometry_to_state(o) for o in obs.odom[n1:]]
    assert abs(second[0].x[0] - straight(T0 + 20.0)[0]) < 1e-6  # a fresh track at the report
    assert "Traceback" not in procs.log("fusion2")
    text = (rep / "report.md").read_text()
    # the gap starts at the last step of the killed node and ends at the first step of the
    # new one the evaluator received (T0 + 20 s unless it matched the new node late)
    gap = re.search(r"1 longer than 5 s: ([\d.]+) s from 2025-10-07T19:42:29\.750Z to ", text)
    assert gap, text
    assert float(gap.group(1)) >= 10.2
    metrics = json.loads((rep / "metrics.json").read_text())
    assert n1 < metrics["steps"] <= n1 + n3


@pytest.mark.fault("PROC-02")
def test_evaluator_restarted_writes_a_report_for_what_each_run_saw(
    ctx: Context, tmp_path: Path
) -> None:
    procs = Procs(tmp_path)
    obs = Observer(ctx)
    pub = obs.node.create_publisher(PoseWithCovarianceStamped, "radar/raw", stream_qos(1000))
    try:
        counts = []
        for run, (n, sig) in enumerate(((10, signal.SIGTERM), (5, signal.SIGINT)), 1):
            obs.diag.clear()
            old = obs.readers("radar/raw")
            procs.start(
                f"eval{run}", "evaluator_node", f"output_dir:={tmp_path / f'rep{run}'}",
                "figures:=false", "log_period_s:=0.2",
            )
            def new_reader(old: set[bytes] = old) -> bool:
                return bool(obs.readers("radar/raw") - old)

            obs.spin_until(new_reader, 60.0, "reader")
            obs.spin_until(
                lambda: pub.get_subscription_count() >= len(obs.readers("radar/raw")),
                60.0, "matching",
            )
            for k in range(n):
                t = T0 + 100.0 * run + k
                pub.publish(radar_msg(t, *straight(t)))
            def used(n: int = n) -> bool:
                return eval_inputs(obs).get("used radar/raw") == str(n)

            obs.spin_until(used, 30.0, "evaluator")
            counts.append(procs.stop(f"eval{run}", sig))
    finally:
        procs.stop_all()
        obs.destroy()
    assert counts == [0, 0]
    for run, n in ((1, 10), (2, 5)):
        log = procs.log(f"eval{run}")
        assert "report written to" in log and "Traceback" not in log, log
        m = json.loads((tmp_path / f"rep{run}" / "metrics.json").read_text())
        assert m["radar_reports"] == n


@pytest.mark.fault("PROC-03")
def test_restarted_replay_resends_its_file_and_repeats_are_not_fused_twice(
    ctx: Context, short_flight: Path
) -> None:
    """rf_replay stops after a few attempts and a new one replays the whole file again: the
    attempts already fused are dropped (``late_rf`` or ``rf_duplicate``), the rest is fused,
    and the RF stream still balances."""
    from uav_fusion.core.data import load_flight
    from uav_fusion.core.site import load_site
    from uav_fusion.nodes.rf_replay import RfReplay

    flight = load_flight(short_flight, load_site())
    n_rf = len(flight.rf)
    h = FusionHarness(ctx, reorder_window_s=60.0)
    radar = [radar_msg(float(t), *straight(float(t))) for t in np.arange(T0, T0 + 30.0, 0.25)]
    h.send(*radar)
    params = [Parameter("flight_dir", value=str(short_flight)), Parameter("rate", value=0.0)]
    r1 = RfReplay(context=h.fusion.context, parameter_overrides=params)
    h.ex.add_node(r1)
    r1.start_standalone()
    h.spin_until(lambda: h.fusion.received[RF] >= 4, 60.0)
    h.ex.remove_node(r1)
    r1.destroy_node()
    first = h.fusion.received[RF]
    assert 4 <= first < n_rf
    r2 = RfReplay(context=h.fusion.context, parameter_overrides=params)
    h.ex.add_node(r2)
    r2.start_standalone()
    h.spin_until(lambda: h.fusion.received[RF] >= first + n_rf, 60.0)
    h.ex.remove_node(r2)
    r2.destroy_node()
    h.settle()
    d = h.diagnostics()
    repeats = h.fusion.dropped["late_rf"] + h.fusion.dropped["rf_duplicate"]
    assert repeats == first
    assert set(h.fusion.dropped) <= {"late_rf", "rf_duplicate"}
    rec, used, rej, drop = accounting(d, RF)
    assert rec == used + rej + drop == first + n_rf
    assert used + rej == n_rf  # every attempt of the file fused or refused exactly once
    h.destroy()


@pytest.mark.fault("PROC-04")
@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT], ids=["SIGTERM", "SIGINT"])
def test_recorder_signalled_during_a_burst_keeps_a_valid_contiguous_bag(
    ctx: Context, tmp_path: Path, sig: signal.Signals
) -> None:
    """The recorder is stopped while messages are still being published: the bag opens
    cleanly and holds exactly the count the recorder reports, as an unbroken prefix of what
    was sent, including everything acknowledged before the signal."""
    from uav_fusion.bag.reader import BagReader

    out = tmp_path / "rec"
    topic = f"/f{uuid.uuid4().hex[:8]}/rf/fix"
    proc = subprocess.Popen(
        [sys.executable, "-m", "uav_fusion.nodes.bag_recorder", str(out),
         "--ros-args", "-p", f'topics:=["{topic}"]'],
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
    )
    node = Node("fault_burst", context=ctx)
    try:
        pub = node.create_publisher(
            PointStamped, topic, QoSProfile(history=HistoryPolicy.KEEP_ALL, depth=1)
        )
        deadline = time.monotonic() + 30
        while pub.get_subscription_count() == 0:
            assert time.monotonic() < deadline, "recorder never subscribed"
            assert proc.poll() is None, proc.communicate()[0]
            time.sleep(0.02)

        def msg(i: int) -> PointStamped:
            m = PointStamped()
            m.header.frame_id = "enu_lw1"
            m.header.stamp = cv.stamp_from_time(T0 + 0.01 * i)
            m.point.x = float(i)
            return m

        for i in range(500):
            pub.publish(msg(i))
        assert pub.wait_for_all_acked(Duration(seconds=20))
        acked = 500
        proc.send_signal(sig)
        i = 500
        while proc.poll() is None and i < 2500:  # keep publishing into the shutdown
            pub.publish(msg(i))
            i += 1
        log = proc.communicate(timeout=30)[0]
    finally:
        if proc.poll() is None:
            proc.kill()
        node.destroy_node()
    assert proc.returncode == 0, log
    assert "Traceback" not in log
    r = BagReader(out)
    assert r.warnings == []
    n = r.topics[topic].count
    assert f"recorded {n} messages" in log
    assert n >= acked
    xs = [deserialize_message(m.data, PointStamped).point.x for m in r.messages([topic])]
    assert xs == [float(k) for k in range(n)]
