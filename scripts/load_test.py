#!/usr/bin/env python3
"""Load measurement: push a flight through the node graph at increasing replay rates.

Two measurements (figures go to docs/faults.md):

1. **In-process graph, lossless** (``rate 0``): the ``graph`` runner publishes each batch only
   once every consumer has taken the previous one. Its wall time gives the highest rate the
   graph accepts without loss (flight seconds / wall seconds) and the message throughput.
2. **Separate processes at fixed rates**: ``truth_replay`` drives ``/clock`` at ``rate``;
   ``radar_replay`` and ``rf_replay`` follow it; ``fusion_node`` and ``evaluator_node`` run in
   their own processes. After the replay ends, the received counts (from the nodes'
   ``/diagnostics``) are compared with the counts the lossless run delivered. The first rate
   with a shortfall is where loss starts; the script also says whether any node reported it.

Usage::

    python scripts/load_test.py                       # bundled default flight
    python scripts/load_test.py --flight DIR --rates 25 50 100 200 400

Sets ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST and a random ROS_DOMAIN_ID unless given.
"""

from __future__ import annotations

import argparse
import os
import random
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
os.environ.setdefault("ROS_DOMAIN_ID", str(random.SystemRandom().randint(1, 100)))
os.environ.setdefault("ROS_LOG_DIR", tempfile.mkdtemp(prefix="uav_fusion_load_"))

import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rosgraph_msgs.msg import Clock

from uav_fusion.nodes.graph import Graph
from uav_fusion.resources import DEFAULT_FLIGHT, data_path
from uav_fusion.ros.conversions import stamp_from_time
from uav_fusion.ros.replay import flight_span

BIN = Path(sys.executable).parent
TOPICS = ("truth/fix", "rf/fix", "radar/raw")


def lossless_run(flight: Path, out: Path) -> dict[str, float]:
    """The in-process graph at rate 0: the reference counts and the lossless speed."""
    ctx = Context()
    rclpy.init(context=ctx)
    replay = {"flight_dir": str(flight), "wait_for_subscribers_s": 10.0}
    ov = {
        "truth_replay": {**replay, "rate": 0.0},
        "rf_replay": dict(replay),
        "radar_replay": dict(replay),
        "fusion_node": {"use_sim_time": True, "idle_flush_s": 0.0},
        "evaluator_node": {"output_dir": str(out), "figures": False, "log_period_s": 0.0,
                           "write_on_shutdown": False, "use_sim_time": True},
    }
    g = Graph(ctx, ov)
    try:
        t0 = time.monotonic()
        res = g.run(timeout_s=1800.0, write_report=False)
        wall = time.monotonic() - t0
        if not res.ok:
            raise SystemExit(f"lossless run failed: {res.message}")
        t_a, t_b = flight_span(g.truth.flight)
        ev = g.evaluator
        n_msgs = g.fusion_inputs_published() + g.evaluator_expected()
        return {
            "t_end": t_b,
            "flight_s": t_b - t_a,
            "wall_s": wall,
            "fusion_radar": g.fusion.received["radar"],
            "fusion_rf": g.fusion.received["rf"],
            **{f"eval {t}": ev.received[t] for t in TOPICS},
            "messages": float(n_msgs),
        }
    finally:
        g.destroy()
        rclpy.shutdown(context=ctx)


class Watch:
    def __init__(self, ctx: Context) -> None:
        self.node = Node(f"load_watch_{os.getpid()}", context=ctx)
        self.ex = SingleThreadedExecutor(context=ctx)
        self.ex.add_node(self.node)
        self.values: dict[str, dict[str, str]] = {}
        self.node.create_subscription(DiagnosticArray, "/diagnostics", self._on, 100)
        self.clock_pub = self.node.create_publisher(Clock, "/clock", 10)

    def tick(self, t: float) -> None:
        """Advance the simulated clock (the evaluator's periodic report runs on it)."""
        msg = Clock()
        msg.clock = stamp_from_time(t)
        self.clock_pub.publish(msg)

    def _on(self, msg: DiagnosticArray) -> None:
        for st in msg.status:
            self.values[st.name] = {kv.key: kv.value for kv in st.values}

    def get(self, suffix: str) -> dict[str, str]:
        for k, v in self.values.items():
            if k.endswith(suffix):
                return v
        return {}

    def counts(self) -> dict[str, int]:
        f, e = self.get(": fusion"), self.get(": inputs")
        out = {"fusion_radar": int(f.get("received_radar", 0)),
               "fusion_rf": int(f.get("received_rf", 0))}
        for t in TOPICS:
            out[f"eval {t}"] = int(e.get(f"received {t}", 0))
        return out

    def spin(self, seconds: float) -> None:
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            self.ex.spin_once(timeout_sec=0.05)


def process_run(
    flight: Path, rate: float, ref: dict[str, float], logdir: Path, eval_period: float
) -> dict[str, object]:
    ctx = Context()
    rclpy.init(context=ctx)
    w = Watch(ctx)
    procs: list[subprocess.Popen[bytes]] = []

    def start(name: str, *params: str) -> None:
        args = [str(BIN / name), "--ros-args"]
        for p in params:
            args += ["-p", p]
        log = (logdir / f"{name}_{rate:g}.log").open("wb")
        procs.append(subprocess.Popen(args, stdout=log, stderr=subprocess.STDOUT))

    fd = f"flight_dir:={flight}"
    try:
        start("fusion_node", "use_sim_time:=true", "diagnostics_period_s:=0.5")
        start("evaluator_node", "use_sim_time:=true", f"log_period_s:={eval_period:.3f}",
              "figures:=false", "write_on_shutdown:=false")
        start("radar_replay", fd, "use_sim_time:=true")
        start("rf_replay", fd, "use_sim_time:=true")
        end = time.monotonic() + 60.0
        while time.monotonic() < end and not (
            w.node.count_subscribers("radar/pose") >= 1
            and w.node.count_subscribers("truth/fix") >= 1
            and w.node.count_publishers("radar/pose") >= 1
            and w.node.count_publishers("rf/fix") >= 1
        ):
            w.spin(0.1)
        w.spin(1.0)
        dead = [p.args[0] for p in procs if p.poll() is not None]
        if dead or time.monotonic() >= end:
            raise SystemExit(f"the graph did not come up at rate {rate:g} ({dead}): see {logdir}")
        t0 = time.monotonic()
        start("truth_replay", fd, f"rate:={rate:.3f}", "exit_when_done:=true",
              "wait_for_clock_subscribers:=4")
        truth = procs[-1]
        while truth.poll() is None and time.monotonic() - t0 < 3600.0:
            w.spin(0.2)
        wall = time.monotonic() - t0
        if truth.returncode != 0:
            raise SystemExit(f"truth_replay failed at rate {rate:g}: see {logdir}")
        # wait until the counts stop moving; keep simulated time going after the replay's
        # end, since evaluator_node's periodic /diagnostics run on the simulated clock
        last: dict[str, int] = {}
        stable_since = time.monotonic()
        t_sim = float(ref["t_end"])
        while time.monotonic() - stable_since < 3.0:
            t_sim += eval_period
            w.tick(t_sim)
            w.spin(0.5)
            c = w.counts()
            if c != last:
                last, stable_since = c, time.monotonic()
        got = w.counts()
        fusion_diag = w.get(": fusion")
    finally:
        for p in procs:
            if p.poll() is None:
                p.send_signal(signal.SIGINT)
        for p in procs:
            try:
                p.wait(timeout=20)
            except subprocess.TimeoutExpired:
                p.kill()
        w.node.destroy_node()
        rclpy.shutdown(context=ctx)
    lost = {k: int(ref[k]) - v for k, v in got.items() if int(ref[k]) > v}
    reported = {k: v for k, v in fusion_diag.items() if k.startswith("dropped_")}
    return {"rate": rate, "wall_s": wall, "got": got, "lost": lost, "fusion_dropped": reported}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--flight", type=Path, default=None, help="flight folder (default: bundled)")
    ap.add_argument("--rates", type=float, nargs="+", default=[25.0, 50.0, 100.0, 200.0, 400.0])
    ap.add_argument("--stop-after-loss", action="store_true", help="stop at the first loss")
    ap.add_argument("--eval-log-period", type=float, default=5.0,
                    help="evaluator_node log_period_s (its periodic full scoring; default 5)")
    opts = ap.parse_args()
    flight = opts.flight or data_path(DEFAULT_FLIGHT)
    tmp = Path(tempfile.mkdtemp(prefix="uav_fusion_load_"))
    ref = lossless_run(flight, tmp / "report")
    msgs = ref["messages"]
    print(f"flight {flight}: {ref['flight_s']:.1f} s of sensor time, {msgs:.0f} messages "
          "through the graph (fusion inputs + evaluator inputs)")
    print(f"in-process graph, rate 0 (lossless): {ref['wall_s']:.2f} s wall = "
          f"{ref['flight_s'] / ref['wall_s']:.1f}x real time, {msgs / ref['wall_s']:.0f} msg/s")
    print("separate processes (fusion_node, evaluator_node, 3 replays):")
    print(f"{'rate':>6} {'wall s':>7} {'msg/s':>7}  lost (stream: count)  reported by fusion_node")
    first_loss = None
    for rate in opts.rates:
        r = process_run(flight, rate, ref, tmp, opts.eval_log_period)
        lost = r["lost"]
        assert isinstance(lost, dict)
        wall = float(r["wall_s"])  # type: ignore[arg-type]
        text = ", ".join(f"{k}: {v}" for k, v in lost.items()) or "none"
        print(f"{rate:>6g} {wall:>7.1f} {msgs / wall:>7.0f}  {text}  {r['fusion_dropped'] or '-'}")
        if lost and first_loss is None:
            first_loss = rate
            if opts.stop_after_loss:
                break
    if first_loss is None:
        print(f"no loss up to rate {max(opts.rates):g}")
    else:
        print(f"loss starts at rate {first_loss:g}")
    print(f"logs: {tmp}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
