#!/usr/bin/env python3
"""Node benchmark: fusion_node against a bare rclpy relay, same feed, same QoS, same loop.

Each node under test runs in its own process (one after the other, never together) and is
fed the bundled flight's fusion inputs (``radar/pose`` as the radar replay publishes it, then
``rf/fix``; 2 228 messages in time order) by this process at a fixed offered rate. Measured
per run:

- **CPU µs per input**: user + system time of the node's process (``/proc/<pid>/stat``) from
  just before the first input until its last output arrived, divided by the inputs;
- **latency** p50 / p99: wall time from publishing an input to receiving the output stamped
  with that input's stamp (for a radar frame, from its last candidate), measured by a third
  process (``--receiver``) on the same monotonic clock. The fusion node's outputs wait in its
  reorder window until every input stream has moved past them (or the stamps ran
  ``reorder_window_s`` ahead), so its latency includes that wait. The window is in sensor
  seconds; at an offered rate of R msg/s the feed advances R / 2.68 sensor seconds per wall
  second, so the bench sets ``reorder_window_s`` = max(2, skew x R / 2.68): the window then
  tolerates ``--skew-ms`` (250) of wall-clock skew between the two topics (scheduling on a
  loaded machine) at every rate, and adds at most that much latency;
- **lossless**: every expected output arrived (relay: one Odometry per input; fusion: one per
  filter step that has an estimate, as the offline run of the same profile gives).

The relay (``--relay``, run by this script) is the least a node can do with these inputs: it
subscribes both topics with the same QoS, runs under the same node runtime
(:mod:`uav_fusion.ros.app`, one SingleThreadedExecutor), and publishes one
``nav_msgs/Odometry`` per input, stamped like it. The fusion node runs with the profile given
(``paper``, pinned by default so the figure tracks the node, not the estimator).

After the fixed rates the script searches each node's highest lossless rate (doubling, then
bisecting) and prints the ratios relay/fusion (CPU per message) and fusion/relay (rate).

Usage::

    python scripts/bench_node.py                      # rates 200 500, search, paper profile
    python scripts/bench_node.py --rates 200 500 1000 --no-search --repeat 3

Sets ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST and a random ROS_DOMAIN_ID in 101-232 unless
given (test runs pick 1-100), and refuses to run when another process publishes the inputs.
"""

from __future__ import annotations

import argparse
import os
import random
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
# a domain above the 1-100 that test runs pick, so that no other run on this machine talks
# into the benchmark (checked before every run: only this feeder may publish the inputs)
os.environ.setdefault("ROS_DOMAIN_ID", str(random.SystemRandom().randint(101, 232)))
os.environ.setdefault("ROS_LOG_DIR", tempfile.mkdtemp(prefix="uav_fusion_bench_"))

BIN = Path(sys.executable).parent
CLK_TCK = os.sysconf("SC_CLK_TCK")


# --- the relay (child process) -------------------------------------------------------------
def relay_main() -> int:
    from geometry_msgs.msg import PointStamped, PoseWithCovarianceStamped
    from nav_msgs.msg import Odometry
    from rclpy.node import Node

    from uav_fusion.ros.app import run_node
    from uav_fusion.ros.qos import stream_qos

    class Relay(Node):
        def __init__(self) -> None:
            super().__init__("relay")
            qos = stream_qos(1000)
            self.pub = self.create_publisher(Odometry, "fusion/odom", qos)
            self.create_subscription(PoseWithCovarianceStamped, "radar/pose", self.on_msg, qos)
            self.create_subscription(PointStamped, "rf/fix", self.on_msg, qos)

        def on_msg(self, msg: Any) -> None:
            out = Odometry()
            out.header.stamp = msg.header.stamp
            out.header.frame_id = msg.header.frame_id
            self.pub.publish(out)

    return run_node(Relay, ["relay"], name="relay")


# --- the receiver (child process) ----------------------------------------------------------
def receiver_main(out: str) -> int:
    """Subscribe fusion/odom; on stop write one line per message: stamp ns, receive time."""
    from nav_msgs.msg import Odometry
    from rclpy.node import Node

    from uav_fusion.ros.app import run_node
    from uav_fusion.ros.qos import stream_qos

    got: list[tuple[int, float]] = []

    ready = Path(out + ".ready")

    class Receiver(Node):
        def __init__(self) -> None:
            super().__init__("bench_receiver")
            self.sub = self.create_subscription(Odometry, "fusion/odom", self.on_msg,
                                                stream_qos(1000))
            self.create_timer(0.05, self.check)

        def check(self) -> None:
            # matched with the node's writer: from now on nothing it publishes is missed
            if not ready.exists() and self.sub.get_publisher_count() >= 1:
                ready.write_text("matched\n")

        def on_msg(self, m: Any) -> None:
            got.append((m.header.stamp.sec * 1_000_000_000 + m.header.stamp.nanosec,
                        time.monotonic()))

    def write(_node: Node, _ex: Any) -> None:
        Path(out).write_text("".join(f"{s} {t!r}\n" for s, t in got))

    return run_node(Receiver, ["bench_receiver"], on_stop=write, name="bench_receiver")


# --- the feeder (this process) -------------------------------------------------------------
@dataclass
class Feed:
    msgs: list[tuple[str, Any, int]]  # (topic, message, stamp ns) in publishing order
    expected_fusion: int

    @property
    def sensor_rate(self) -> float:
        """Inputs per sensor second (the flight's own rate)."""
        span = (self.msgs[-1][2] - self.msgs[0][2]) / 1e9
        return len(self.msgs) / span


def build_feed(profile: str) -> Feed:
    from uav_fusion.core.data import load_flight
    from uav_fusion.core.estimators import load_profile, run_flight
    from uav_fusion.core.estimators.selection import (
        pose_covariance,
        radar_profile,
        selected_radar,
    )
    from uav_fusion.core.site import load_site
    from uav_fusion.resources import DEFAULT_FLIGHT, data_path
    from uav_fusion.ros import conversions as cv

    site = load_site()
    flight = load_flight(data_path(DEFAULT_FLIGHT), site)
    prof = radar_profile(profile)
    cov = pose_covariance(prof, site)
    items: list[tuple[float, int, str, Any]] = []
    for frame in selected_radar(flight, prof, site):
        for m in frame:
            items.append((m.t, len(items), "radar/pose",
                          cv.radar_measurement_to_msg(m, site.frame_id, cov(*m.z))))
    for a in flight.rf:
        items.append((a.t, len(items), "rf/fix", cv.rf_attempt_to_msg(a, site.frame_id)))
    items.sort(key=lambda it: (it[0], it[1]))
    msgs = [(topic, msg, cv.time_to_ns(t)) for t, _, topic, msg in items]
    steps = run_flight(flight, load_profile(profile), site).steps
    expected = sum(1 for s in steps if s.updated or s.coasted)
    return Feed(msgs, expected)


@dataclass
class Run:
    kind: str
    rate: float
    inputs: int
    outputs: int
    expected: int
    cpu_s: float
    lat_ms: list[float] = field(default_factory=list)

    @property
    def lossless(self) -> bool:
        return self.outputs >= self.expected

    @property
    def us_per_input(self) -> float:
        return 1e6 * self.cpu_s / self.inputs

    def pct(self, q: float) -> float:
        if not self.lat_ms:
            return float("nan")
        xs = sorted(self.lat_ms)
        return xs[min(len(xs) - 1, int(q * len(xs)))]


def cpu_seconds(pid: int) -> float:
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / CLK_TCK  # utime, stime


class Bench:
    def __init__(self, feed: Feed, profile: str, skew_ms: float, pythonpath: str) -> None:
        import rclpy
        from geometry_msgs.msg import PointStamped, PoseWithCovarianceStamped
        from rclpy.context import Context
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.node import Node

        from uav_fusion.ros.qos import stream_qos

        self.feed = feed
        self.profile = profile
        self.skew_ms = skew_ms
        self.pythonpath = pythonpath
        self.ctx = Context()
        rclpy.init(context=self.ctx)
        self.node = Node("bench_feeder", context=self.ctx)
        qos = stream_qos(1000)
        self.pubs = {
            "radar/pose": self.node.create_publisher(PoseWithCovarianceStamped, "radar/pose",
                                                     qos),
            "rf/fix": self.node.create_publisher(PointStamped, "rf/fix", qos),
        }
        self.tmp = Path(tempfile.mkdtemp(prefix="uav_fusion_bench_"))
        self.ex = SingleThreadedExecutor(context=self.ctx)
        self.ex.add_node(self.node)

    def close(self) -> None:
        from rclpy.utilities import try_shutdown

        self.node.destroy_node()
        try_shutdown(context=self.ctx)

    def _spin_until(self, cond: Any, limit_s: float) -> bool:
        end = time.monotonic() + limit_s
        while not cond():
            if time.monotonic() > end:
                return False
            self.ex.spin_once(timeout_sec=0.01)
        return True

    def window_s(self, rate: float) -> float:
        """The reorder window (sensor s) that tolerates ``skew_ms`` of wall-clock skew between
        the two input topics at ``rate`` (never below the default 2 s)."""
        return max(2.0, round(self.skew_ms / 1000.0 * rate / self.feed.sensor_rate, 3))

    def _start(self, kind: str, rate: float) -> subprocess.Popen[bytes]:
        env = dict(os.environ)
        if kind == "relay":
            args = [sys.executable, __file__, "--relay"]
        else:
            args = [sys.executable, "-m", "uav_fusion.nodes.fusion_node", "--ros-args",
                    "-p", f"profile:={self.profile}", "-p", "idle_flush_s:=0.3",
                    "-p", f"reorder_window_s:={self.window_s(rate)}"]
            if self.pythonpath:  # another version of the package (a before/after comparison)
                env["PYTHONPATH"] = self.pythonpath
        log = (self.tmp / f"{kind}.log").open("wb")
        # with another copy of the package, start there so that its modules come first
        cwd = self.pythonpath if kind != "relay" and self.pythonpath else None
        return subprocess.Popen(args, stdout=log, stderr=subprocess.STDOUT, env=env, cwd=cwd)

    def run(self, kind: str, rate: float) -> Run:
        out = self.tmp / "received.txt"
        out.unlink(missing_ok=True)
        Path(str(out) + ".ready").unlink(missing_ok=True)
        recv = subprocess.Popen([sys.executable, __file__, "--receiver", str(out)],
                                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        proc = self._start(kind, rate)
        try:
            ready = self._spin_until(
                lambda: all(p.get_subscription_count() > 0 for p in self.pubs.values())
                and self.node.count_publishers("fusion/odom") > 0
                and self.node.count_subscribers("fusion/odom") > 0
                and Path(str(out) + ".ready").exists(),
                60.0,
            )
            if not ready:
                raise RuntimeError(f"{kind} did not come up")
            self._spin_until(lambda: False, 0.5)  # let discovery settle
            strangers = [t for t in self.pubs if self.node.count_publishers(t) != 1] + (
                ["fusion/odom"] if self.node.count_publishers("fusion/odom") != 1 else [])
            if strangers:
                raise RuntimeError(
                    f"another process publishes on {', '.join(strangers)} in ROS_DOMAIN_ID "
                    f"{os.environ['ROS_DOMAIN_ID']}: the figures would be void; run again"
                )
            msgs = self.feed.msgs
            expected = len(msgs) if kind == "relay" else self.feed.expected_fusion
            sent: dict[int, float] = {}
            cpu0 = cpu_seconds(proc.pid)
            t0 = time.monotonic()
            for k, (topic, msg, stamp) in enumerate(msgs):
                due = t0 + k / rate
                while True:
                    now = time.monotonic()
                    if now >= due:
                        break
                    if due - now > 0.002:
                        self.ex.spin_once(timeout_sec=min(due - now - 0.001, 0.01))
                sent[stamp] = time.monotonic()
                self.pubs[topic].publish(msg)
            # outputs still in flight: the node's CPU stops rising once it has sent them all
            # (the fusion node flushes its reorder buffer after idle_flush_s = 0.3 s)
            # (node and receiver both idle for 1.5 s: on a loaded machine either may lag)
            def cpus() -> tuple[float, float]:
                return cpu_seconds(proc.pid), cpu_seconds(recv.pid)

            last, since = cpus(), time.monotonic()
            while time.monotonic() - since < 1.5:
                self._spin_until(lambda: False, 0.2)
                c = cpus()
                if c[0] - last[0] > 0.02 or c[1] - last[1] > 0.02:
                    last, since = c, time.monotonic()
            cpu1 = cpu_seconds(proc.pid)
        finally:
            for p in (proc, recv):
                p.send_signal(2)
                try:
                    p.wait(timeout=30)
                except subprocess.TimeoutExpired:
                    p.kill()
                    p.wait()
        got = [line.split() for line in out.read_text().splitlines()] if out.exists() else []
        if len(got) < expected:  # say why: the node's warnings (drops are logged by reason)
            for line in (self.tmp / f"{kind}.log").read_text(errors="replace").splitlines():
                if "WARN" in line or "ERROR" in line:
                    print(f"    {kind} {rate:.0f} msg/s: {line.strip()[:200]}", flush=True)
        lat = [1e3 * (float(t) - sent[int(st)]) for st, t in got if int(st) in sent]
        return Run(kind, rate, len(msgs), len(got), expected, cpu1 - cpu0, lat)


def median_run(runs: list[Run]) -> tuple[Run, bool]:
    """The run with the median CPU per input, and whether every run was lossless."""
    runs = sorted(runs, key=lambda r: r.us_per_input)
    return runs[len(runs) // 2], all(r.lossless for r in runs)


def search(bench: Bench, kind: str, start: float, limit: float, steps: int) -> float:
    """Highest offered rate (msg/s) at which ``kind`` loses nothing."""
    good, bad = 0.0, None
    rate = start
    while rate <= limit:
        r = bench.run(kind, rate)
        print(f"  search {kind:6s} {rate:8.0f} msg/s: "
              f"{'lossless' if r.lossless else f'LOST {r.expected - r.outputs}'}", flush=True)
        if not r.lossless:
            bad = rate
            break
        good = rate
        rate *= 2
    if bad is None:
        return good
    for _ in range(steps):
        mid = 0.5 * (good + bad)
        r = bench.run(kind, mid)
        print(f"  search {kind:6s} {mid:8.0f} msg/s: "
              f"{'lossless' if r.lossless else f'LOST {r.expected - r.outputs}'}", flush=True)
        if r.lossless:
            good = mid
        else:
            bad = mid
    return good


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--relay", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--receiver", default="", help=argparse.SUPPRESS)
    ap.add_argument("--rates", type=float, nargs="+", default=[200.0, 500.0])
    ap.add_argument("--profile", default="paper")
    ap.add_argument("--repeat", type=int, default=3, help="runs per rate and node (median)")
    ap.add_argument("--no-search", action="store_true", help="skip the lossless-rate search")
    ap.add_argument("--search-start", type=float, default=500.0)
    ap.add_argument("--search-limit", type=float, default=64000.0)
    ap.add_argument("--search-steps", type=int, default=3)
    ap.add_argument("--skew-ms", type=float, default=250.0,
                    help="wall-clock skew between the input topics the fusion node's reorder "
                    "window tolerates: reorder_window_s = max(2, skew x rate / flight rate)")
    ap.add_argument("--fusion-pythonpath", default="",
                    help="run fusion_node from another copy of the package (before/after)")
    args = ap.parse_args()
    if args.relay:
        return relay_main()
    if args.receiver:
        return receiver_main(args.receiver)
    feed = build_feed(args.profile)
    print(f"feed: {len(feed.msgs)} inputs of the bundled flight; fusion expects "
          f"{feed.expected_fusion} outputs (profile {args.profile}); "
          f"{args.repeat} run(s) per point, median by CPU; the flight's own rate "
          f"{feed.sensor_rate:.2f} inputs per sensor second; reorder window tolerates "
          f"{args.skew_ms:g} ms of skew", flush=True)
    bench = Bench(feed, args.profile, args.skew_ms, args.fusion_pythonpath)
    try:
        rows: list[tuple[float, Run, Run, bool, bool]] = []
        for rate in args.rates:
            runs: dict[str, Run] = {}
            clean: dict[str, bool] = {}
            for kind in ("relay", "fusion"):
                rs = [bench.run(kind, rate) for _ in range(args.repeat)]
                runs[kind], clean[kind] = median_run(rs)
                print(f"  {kind:6s} {rate:6.0f} msg/s: "
                      + ", ".join(f"{r.us_per_input:.0f}" for r in rs) + " µs/input; outputs "
                      + ", ".join(f"{r.outputs}/{r.expected}" for r in rs), flush=True)
            rows.append((rate, runs["relay"], runs["fusion"], clean["relay"], clean["fusion"]))
        print()
        print("| offered msg/s | fusion reorder window s | relay µs/input | fusion µs/input | "
              "relay/fusion | relay p50/p99 ms | fusion p50/p99 ms | "
              "every run lossless (relay, fusion) |")
        print("|---:|---:|---:|---:|---:|---:|---:|---|")
        for rate, rl, fu, rl_ok, fu_ok in rows:
            print(f"| {rate:.0f} | {bench.window_s(rate):g} | {rl.us_per_input:.0f} | "
                  f"{fu.us_per_input:.0f} | {rl.us_per_input / fu.us_per_input:.2f} | "
                  f"{rl.pct(0.5):.1f} / {rl.pct(0.99):.1f} | {fu.pct(0.5):.1f} / "
                  f"{fu.pct(0.99):.1f} | {'yes' if rl_ok else 'NO'}, "
                  f"{'yes' if fu_ok else 'NO'} |", flush=True)
        if not args.no_search:
            print()
            hi = {}
            for kind in ("relay", "fusion"):
                hi[kind] = search(bench, kind, args.search_start, args.search_limit,
                                  args.search_steps)
            print(f"\nhighest lossless rate: relay {hi['relay']:.0f} msg/s, fusion "
                  f"{hi['fusion']:.0f} msg/s, fusion/relay "
                  f"{hi['fusion'] / hi['relay'] if hi['relay'] else float('nan'):.2f}")
    finally:
        bench.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
