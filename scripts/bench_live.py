#!/usr/bin/env python3
"""Live latency benchmark: from a radar line written by the sensor emulator to the fusion
node's message for it.

Every run is the live graph as separate processes: ``uav_fusion emulate`` (radar and RF
lines of the bundled flight, or ``--flight``), ``radar_stream`` and ``rf_stream`` reading
them over TCP or by following the files the emulator writes, and ``fusion_node``; this
process listens. Per radar line that gives a filter step, the latency is

    time the step arrives here  -  time the emulator wrote the line

both on CLOCK_MONOTONIC (one clock for every process of a Linux host; the emulator's write
times come from its arrival schedule, ``--schedule``). Two figures per run:

- **step**: the message on ``fusion/odom/updated`` or ``fusion/odom/coasted`` stamped with the
  line's frame time (every filter step is on one of them);
- **odom**: the first message on ``fusion/odom`` stamped at or after the frame time (the paper
  profile: the step itself; tracker profiles: the fixed-rate output passing the frame; while
  the tracker has no confirmed track it publishes no epoch, and a frame of such a stretch
  counts until the first epoch after it, which makes this figure's tail long);
- **stream**: ``radar_stream``'s own line-to-publish latency from its ``/diagnostics``.

Each run takes ``--wall-s`` wall seconds of flight (``rate`` x that many sensor seconds from
``--start-s`` into the flight; the whole flight at most), at each ``--rates`` over each
``--via``, leaving out the radar lines of the last ``--trim-s`` sensor seconds (at the end of
the input, a pipeline that waits for the RF stream releases them only at its idle flush: an
effect of the input ending, not of the stream). ``--variant NAME:param=value,param=value``
runs the fusion node with those parameters (repeatable; default: ``zero-wait``,
``reorder_window_s`` 0, every measurement fused as it arrives; ``on-clock``, the same with
``output_delay_s`` 0, the fixed-rate epochs published as the sensor time passes them; and
``reorder``, the 2 s reorder window zero wait replaced as the default), so the pipelines are
measured side by side. The fusion node runs with ``stall_timeout_s`` 0 (no stall predictions
between inputs) unless a variant sets it.

Usage::

    python scripts/bench_live.py                               # tcp + file, 1x and 10x
    python scripts/bench_live.py --rates 1 --via tcp --wall-s 30
    python scripts/bench_live.py --variant lag5:max_lag_s=5.0 --variant w02:reorder_window_s=0.2

Sets ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST and a random ROS_DOMAIN_ID in 101-232 unless
given (test runs pick 1-100). Writes ``--out`` (default out/bench_live/results.json).
"""

from __future__ import annotations

import argparse
import json
import os
import random
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
os.environ.setdefault("ROS_DOMAIN_ID", str(random.SystemRandom().randint(101, 232)))
os.environ.setdefault("ROS_LOG_DIR", tempfile.mkdtemp(prefix="uav_fusion_bench_live_"))

BIN = Path(sys.executable).parent
LIMIT_S = 120.0
#: zero wait (late data re-filtered), the same with the fixed-rate epochs published on the
#: clock, and the reorder window zero wait replaced, side by side
DEFAULT_VARIANTS = (
    "zero-wait:reorder_window_s=0.0",
    "on-clock:reorder_window_s=0.0,output_delay_s=0.0",
    "reorder:reorder_window_s=2.0",
)


@dataclass
class RunResult:
    via: str
    rate: float
    variant: str
    sensor_s: float
    radar_lines: int
    steps_matched: int
    step_p50_ms: float
    step_p99_ms: float
    step_max_ms: float
    odom_matched: int
    odom_p50_ms: float
    odom_p99_ms: float
    #: radar_stream's own line-to-publish latency (its /diagnostics at the end of the run)
    stream_p50_ms: float
    stream_p99_ms: float
    emulator_late_max_ms: float


def quantile(xs: list[float], q: float) -> float:
    if not xs:
        return float("nan")
    xs = sorted(xs)
    pos = q * (len(xs) - 1)
    i = int(pos)
    j = min(i + 1, len(xs) - 1)
    return xs[i] + (xs[j] - xs[i]) * (pos - i)


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


class Listener:
    """The fusion node's outputs, received in this process: (stamp ns, monotonic s)."""

    def __init__(self) -> None:
        import rclpy
        from diagnostic_msgs.msg import DiagnosticArray
        from nav_msgs.msg import Odometry
        from rclpy.context import Context
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.node import Node

        from uav_fusion.ros.qos import stream_qos

        self.ctx = Context()
        rclpy.init(context=self.ctx)
        self.node = Node("bench_live_listener", context=self.ctx)
        self.steps: list[tuple[int, float]] = []
        self.odom: list[tuple[int, float]] = []
        self.status: dict[str, dict[str, str]] = {}
        qos = stream_qos(10000)

        def keep(into: list[tuple[int, float]]) -> Any:
            def cb(m: Any) -> None:
                into.append((m.header.stamp.sec * 1_000_000_000 + m.header.stamp.nanosec,
                             time.monotonic()))
            return cb

        sub = self.node.create_subscription
        self.sub_updated = sub(Odometry, "fusion/odom/updated", keep(self.steps), qos)
        sub(Odometry, "fusion/odom/coasted", keep(self.steps), qos)
        sub(Odometry, "fusion/odom", keep(self.odom), qos)

        def on_diag(arr: Any) -> None:
            for st in arr.status:
                self.status[st.name] = {kv.key: kv.value for kv in st.values}

        sub(DiagnosticArray, "/diagnostics", on_diag, 100)
        self.ex = SingleThreadedExecutor(context=self.ctx)
        self.ex.add_node(self.node)
        self._stop = threading.Event()
        self.thread = threading.Thread(target=self._spin, daemon=True)
        self.thread.start()

    def _spin(self) -> None:
        while not self._stop.is_set():
            self.ex.spin_once(timeout_sec=0.05)

    def reset(self) -> None:
        self.steps.clear()
        self.odom.clear()
        self.status.clear()

    def wait(self, cond: Any, what: str, limit_s: float = LIMIT_S) -> None:
        end = time.monotonic() + limit_s
        while not cond():
            if time.monotonic() > end:
                raise RuntimeError(f"timed out waiting for {what}")
            time.sleep(0.02)

    def close(self) -> None:
        import rclpy

        self._stop.set()
        self.thread.join(2.0)
        self.node.destroy_node()
        rclpy.shutdown(context=self.ctx)


def start(cmd: list[str], log: Path) -> subprocess.Popen[bytes]:
    return subprocess.Popen(cmd, stdout=log.open("wb"), stderr=subprocess.STDOUT)


def stop(procs: list[subprocess.Popen[bytes]]) -> None:
    for p in procs:
        if p.poll() is None:
            p.send_signal(signal.SIGINT)
    for p in procs:
        try:
            p.wait(timeout=20)
        except subprocess.TimeoutExpired:
            p.kill()
            p.wait()


def one_run(listener: Listener, args: argparse.Namespace, via: str, rate: float,
            variant: str, params: dict[str, str], work: Path) -> RunResult:
    from uav_fusion.core.data.encoding import stamp_parts
    from uav_fusion.core.ingest.emulator import read_schedule

    run_dir = work / f"{via}_{rate:g}x_{variant}"
    run_dir.mkdir(parents=True)
    listener.reset()
    sensor_s = args.wall_s * rate
    fusion_params = {"profile": args.profile, "stall_timeout_s": "0.0", **params}
    ros = ["--ros-args"]
    for k, v in fusion_params.items():
        ros += ["-p", f"{k}:={v}"]
    procs: list[subprocess.Popen[bytes]] = []
    try:
        procs.append(start([str(BIN / "fusion_node"), *ros], run_dir / "fusion_node.log"))
        listener.wait(lambda: listener.sub_updated.get_publisher_count() > 0,
                      "fusion_node's outputs")
        if via == "tcp":
            urls = {s: f"tcp://127.0.0.1:{free_port()}" for s in ("radar", "rf")}
            emu_out = [f"--{s}={u}" for s, u in urls.items()]
        else:
            feed = run_dir / "sensors"
            feed.mkdir()
            urls = {"radar": f"file://{feed / 'radar.json'}", "rf": f"file://{feed / 'AADM.csv'}"}
            emu_out = [f"--radar=file:{feed / 'radar.json'}", f"--rf=file:{feed / 'AADM.csv'}"]
        common = ["-p", "wait_for_subscribers_s:=60.0", "-p", "clock_offset_warn_s:=0.0",
                  "-p", "diagnostics_period_s:=0.2"]
        # only what the fusion node reads (it waits for subscribers of each topic it sends)
        fusion_reads = ["-p", "publish_raw:=false", "-p",
                        f"publish_pose:={'false' if args.profile != 'paper' else 'true'}",
                        "-p", f"publish_tracks:={'true' if args.profile != 'paper' else 'false'}"]
        procs.append(start([str(BIN / "radar_stream"), "--ros-args", "-p",
                            f"url:={urls['radar']}", "-p", f"profile:={args.profile}", *common,
                            *fusion_reads], run_dir / "radar_stream.log"))
        procs.append(start([str(BIN / "rf_stream"), "--ros-args", "-p", f"url:={urls['rf']}",
                            *common], run_dir / "rf_stream.log"))
        # both stream nodes read (matched with fusion_node) before the first line is written
        listener.wait(lambda: all(listener.status.get(f"{n}: {k} input", {}).get("reading")
                                  == "true" for n, k in (("radar_stream", "radar"),
                                                         ("rf_stream", "rf"))),
                      "the stream nodes to read")
        sched = run_dir / "arrivals.csv"
        emu = start([str(BIN / "uav_fusion"), "emulate", str(args.flight), "--rate", f"{rate:g}",
                     "--sources", "radar,rf", "--start", f"{args.start_s:g}", "--duration",
                     f"{sensor_s:g}", "--schedule", str(sched), "--wait", "60", *emu_out],
                    run_dir / "emulate.log")
        procs.append(emu)
        if emu.wait(timeout=args.wall_s * 3 + LIMIT_S) != 0:
            raise RuntimeError(f"the emulator failed: {(run_dir / 'emulate.log').read_text()}")
        # the last steps: released by the pipeline (at the latest its idle flush), then quiet
        last = (-1, time.monotonic())
        while time.monotonic() - last[1] < args.quiet_s:
            n = len(listener.steps) + len(listener.odom)
            if n != last[0]:
                last = (n, time.monotonic())
            time.sleep(0.05)
        radar_status = dict(listener.status.get("radar_stream: radar input", {}))
    finally:
        stop(procs)
    rows = read_schedule(sched)
    sent = {}
    late = []
    timed = [r[2] for r in rows if r[2] is not None]
    t_end = max(timed) - args.trim_s if timed else 0.0
    for source, _line, t, _due, _unix, mono in rows:
        # the last trim_s sensor seconds are left out: the end of the input, not the stream
        if source == "radar" and t is not None and t <= t_end:
            sec, ns = stamp_parts(t)
            sent[sec * 1_000_000_000 + ns] = mono
    first_step: dict[int, float] = {}
    for stamp, t in listener.steps:
        if stamp in sent and stamp not in first_step:
            first_step[stamp] = t
    step_lat = [(first_step[s] - sent[s]) * 1e3 for s in first_step]
    odom = sorted(listener.odom)
    odom_lat = []
    j = 0
    for stamp in sorted(sent):
        while j < len(odom) and odom[j][0] < stamp:
            j += 1
        if j < len(odom):
            # the first fusion/odom message received with a stamp at or after the frame
            recv = min(t for s, t in odom[j:j + 50] if s >= stamp)
            odom_lat.append((recv - sent[stamp]) * 1e3)
    emu_text = (run_dir / "emulate.log").read_text()
    for word in emu_text.split("max ")[1:2]:
        late.append(float(word.split(" ms")[0]))
    return RunResult(
        via=via, rate=rate, variant=variant, sensor_s=sensor_s, radar_lines=len(sent),
        steps_matched=len(step_lat), step_p50_ms=quantile(step_lat, 0.5),
        step_p99_ms=quantile(step_lat, 0.99), step_max_ms=max(step_lat, default=float("nan")),
        odom_matched=len(odom_lat), odom_p50_ms=quantile(odom_lat, 0.5),
        odom_p99_ms=quantile(odom_lat, 0.99),
        stream_p50_ms=_num(radar_status.get("latency_p50_ms")),
        stream_p99_ms=_num(radar_status.get("latency_p99_ms")),
        emulator_late_max_ms=late[0] if late else float("nan"),
    )


def _num(text: str | None) -> float:
    try:
        return float(text) if text is not None else float("nan")
    except ValueError:
        return float("nan")


def parse_variant(text: str) -> tuple[str, dict[str, str]]:
    name, _, rest = text.partition(":")
    params = {}
    for item in filter(None, rest.split(",")):
        k, eq, v = item.partition("=")
        if not eq:
            raise SystemExit(f"--variant {text!r}: write NAME:param=value,param=value")
        params[k.strip()] = v.strip()
    return name or "variant", params


def table(results: list[RunResult]) -> str:
    head = (f"{'via':<5} {'rate':>5} {'variant':<12} {'lines':>6} {'steps':>6} "
            f"{'step p50 ms':>11} {'step p99 ms':>11} {'odom p50 ms':>11} {'odom p99 ms':>11} "
            f"{'stream p50/p99 ms':>17}")
    lines = [head, "-" * len(head)]
    for r in results:
        lines.append(f"{r.via:<5} {r.rate:>4g}x {r.variant:<12} {r.radar_lines:>6} "
                     f"{r.steps_matched:>6} {r.step_p50_ms:>11.1f} {r.step_p99_ms:>11.1f} "
                     f"{r.odom_p50_ms:>11.1f} {r.odom_p99_ms:>11.1f} "
                     f"{r.stream_p50_ms:>8.2f}/{r.stream_p99_ms:<8.2f}")
    return "\n".join(lines)


def main() -> int:
    from uav_fusion.resources import DEFAULT_FLIGHT, data_path

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--flight", type=Path, default=data_path(DEFAULT_FLIGHT))
    ap.add_argument("--profile", default="tracker")
    ap.add_argument("--via", nargs="+", default=["tcp", "file"], choices=("tcp", "file"))
    ap.add_argument("--rates", nargs="+", type=float, default=[1.0, 10.0])
    ap.add_argument("--wall-s", type=float, default=60.0,
                    help="wall seconds of emulation per run (default 60)")
    ap.add_argument("--start-s", type=float, default=60.0,
                    help="sensor seconds into the flight where each run starts (default 60)")
    ap.add_argument("--trim-s", type=float, default=5.0,
                    help="leave out the radar lines of the last S sensor seconds of each run: "
                    "at the end of the input a pipeline that waits for the other stream "
                    "releases them only at its idle flush (default 5)")
    ap.add_argument("--quiet-s", type=float, default=4.0,
                    help="after the emulator: wait until no output for this long (default 4)")
    ap.add_argument("--variant", action="append", metavar="NAME:param=value,...",
                    help="fusion_node parameters of one variant (default: "
                    + " and ".join(DEFAULT_VARIANTS) + ")")
    ap.add_argument("--out", type=Path, default=Path("out/bench_live/results.json"))
    args = ap.parse_args()
    variants = [parse_variant(v) for v in (args.variant or list(DEFAULT_VARIANTS))]
    work = Path(tempfile.mkdtemp(prefix="bench_live_"))
    listener = Listener()
    results: list[RunResult] = []
    try:
        for via in args.via:
            for rate in args.rates:
                for name, params in variants:
                    print(f"bench_live: {via} at {rate:g}x, {name} {params or ''} ...",
                          flush=True)
                    r = one_run(listener, args, via, rate, name, params, work)
                    results.append(r)
                    print(table([r]).splitlines()[-1], flush=True)
    finally:
        listener.close()
    print()
    print(table(results))
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps({
        "profile": args.profile, "flight": str(args.flight), "wall_s": args.wall_s,
        "start_s": args.start_s, "runs": [asdict(r) for r in results],
        "machine": {"cpus": os.cpu_count()}}, indent=1) + "\n")
    print(f"\nbench_live: written to {args.out}; logs in {work}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
