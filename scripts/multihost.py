#!/usr/bin/env python3
"""The node graph across three "hosts": network namespaces joined by a bridge, unprivileged.

Topology (addresses exist only inside the namespaces; nothing is routed anywhere else)::

      radar host 10.201.0.11          RF host 10.201.0.12          fusion host 10.201.0.13
      radar_replay                    rf_replay                    truth_replay (/clock),
           |                               |                       fusion_node, evaluator_node
          eth0 ---- veth ---+--- br0 ---+--- veth ---- eth0            eth0
                            |   (switch |                                |
                            |  namespace)+------------ veth -------------+

One user + network namespace (``unshare --user --map-root-user --net``, no root needed) is
the switch: it holds the bridge ``br0``. Each host is a further network namespace inside it
with its own ``lo`` and ``eth0`` (one end of a veth pair; the other end is a bridge port).

DDS inside the hosts: ``ROS_AUTOMATIC_DISCOVERY_RANGE=SUBNET`` (multicast discovery, with a
``224.0.0.0/4`` route on ``eth0``), and ``FASTDDS_BUILTIN_TRANSPORTS=UDPv4`` so that Fast DDS
does not use its shared-memory transport: every sample crosses the veth links (the link
counters printed at the end show it). The process that starts all this keeps the LOCALHOST
rule; it speaks no DDS itself.

Time: each replay runs its own paced timeline (``rate`` > 0, ``use_sim_time`` false), as a
sensor with a synchronised clock would; the hosts share one kernel clock, so their clocks
agree exactly. The fusion host's ``truth_replay`` publishes ``/clock`` for ``fusion_node``
and ``evaluator_node`` (``use_sim_time`` true): the clock source sits with its consumers, so
a sensor host's link going down cannot stop the fusion host's time. The three timelines
start together: the fusion host creates its subscriptions only once it sees the publishers
of both sensor hosts, and a replay starts when its subscribers are matched.

Run on the fusion host, ``fusion-host`` mode puts truth_replay, fusion_node and
evaluator_node into one process (one executor) and, when told to finish, writes a JSON
result: the evaluator's fused track, every counter, and the arrival time of each RF and
radar message.

Usage::

    python scripts/multihost.py                        # bundled flight at 25x, no fault
    python scripts/multihost.py --rate 25 --rf-outage 10 --outage-after 5
    python scripts/multihost.py --flight DIR --rate 10 --out DIR

The test ``test/test_multihost.py`` uses this module.
"""

from __future__ import annotations

import argparse
import ctypes
import json
import math
import os
import random
import re
import select
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any

SUBNET = "10.201.0"
HOSTS = ("radar", "rf", "fusion")
HOST_ADDR = {"radar": f"{SUBNET}.11", "rf": f"{SUBNET}.12", "fusion": f"{SUBNET}.13"}
BIN = Path(sys.executable).parent
SCRIPT = Path(__file__).resolve()
_PR_SET_PDEATHSIG = 1


class LabError(RuntimeError):
    """The namespaces could not be built or a step inside them failed."""


def _die_with_parent() -> None:
    """preexec_fn: the child gets SIGKILL when the process that started it dies."""
    libc = ctypes.CDLL(None, use_errno=True)
    libc.prctl(_PR_SET_PDEATHSIG, signal.SIGKILL)


def probe() -> str | None:
    """None if unprivileged user + network namespaces work here, else the reason."""
    for tool in ("unshare", "nsenter", "ip"):
        if shutil.which(tool) is None:
            return f"'{tool}' is not installed"
    try:
        res = subprocess.run(
            ["unshare", "--user", "--map-root-user", "--net", "--",
             "sh", "-c", "ip link add b0 type bridge && unshare --net true"],
            capture_output=True, text=True, timeout=30,
        )
    except (OSError, subprocess.TimeoutExpired) as exc:
        return f"unshare failed: {exc}"
    if res.returncode != 0:
        return f"user + network namespaces are not available: {res.stderr.strip()}"
    return None


def host_env(domain_id: int, log_dir: Path, host: str = "",
             discovery: str = "subnet") -> dict[str, str]:
    """Environment of every ROS process inside ``host``.

    ``discovery``: ``subnet`` = multicast discovery on the hosts' subnet; ``static`` =
    ``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`` plus ``ROS_STATIC_PEERS`` = the other two
    hosts' addresses (unicast discovery, no multicast needed).
    """
    env = {k: v for k, v in os.environ.items() if not k.startswith(("ROS_", "FASTDDS_",
                                                                     "FASTRTPS_", "RMW_"))}
    env.update(
        ROS_DOMAIN_ID=str(domain_id),
        ROS_AUTOMATIC_DISCOVERY_RANGE="SUBNET" if discovery == "subnet" else "LOCALHOST",
        RMW_IMPLEMENTATION="rmw_fastrtps_cpp",
        FASTDDS_BUILTIN_TRANSPORTS="UDPv4",
        ROS_LOG_DIR=str(log_dir),
        PYTHONUNBUFFERED="1",
    )
    if discovery == "static":
        env["ROS_STATIC_PEERS"] = ";".join(a for h, a in HOST_ADDR.items() if h != host)
    elif discovery != "subnet":
        raise ValueError(f"discovery must be 'subnet' or 'static', not '{discovery}'")
    return env


class Lab:
    """The switch namespace, three host namespaces and every process started in them.

    Everything is started with a parent-death signal and stopped by pid in :meth:`close`
    (also on errors), so no namespace outlives it: a network namespace disappears with its
    last process.
    """

    def __init__(self, workdir: Path, domain_id: int | None = None,
                 discovery: str = "subnet") -> None:
        self.workdir = workdir
        self.domain_id = domain_id or random.SystemRandom().randint(1, 100)
        self.discovery = discovery
        self.env = {h: host_env(self.domain_id, workdir / "roslog", h, discovery)
                    for h in HOSTS}
        self.switch: subprocess.Popen[bytes] | None = None
        self.hosts: dict[str, subprocess.Popen[bytes]] = {}
        self.procs: dict[str, subprocess.Popen[bytes]] = {}
        self._logs: list[IO[bytes]] = []

    # --- namespaces ---------------------------------------------------------------------
    def _holder(self, cmd: Sequence[str]) -> subprocess.Popen[bytes]:
        # ``cat`` keeps a namespace alive until its stdin closes (also when we die)
        return subprocess.Popen(
            [*cmd, "cat"], stdin=subprocess.PIPE, stdout=subprocess.DEVNULL,
            preexec_fn=_die_with_parent,
        )

    def _enter(self, pid: int) -> list[str]:
        return ["nsenter", "-t", str(pid), "-U", "-n", "--preserve-credentials", "--"]

    def _wait_ns(self, p: subprocess.Popen[bytes], other: int) -> None:
        """Wait until the holder ``p`` runs in a network namespace other than ``other``'s."""
        mine = os.readlink(f"/proc/{other}/ns/net")
        end = time.monotonic() + 30.0
        while True:
            if p.poll() is not None:
                raise LabError(f"namespace holder exited with status {p.returncode}")
            try:
                if os.readlink(f"/proc/{p.pid}/ns/net") != mine and \
                        Path(f"/proc/{p.pid}/cmdline").read_bytes().startswith(b"cat"):
                    return
            except OSError:
                pass
            if time.monotonic() > end:
                raise LabError("namespace holder did not start within 30 s")
            time.sleep(0.02)

    def sh(self, where: str, *cmd: str) -> str:
        """Run a command in the switch (``where='switch'``) or a host namespace."""
        pid = self.switch.pid if where == "switch" else self.hosts[where].pid  # type: ignore[union-attr]
        res = subprocess.run([*self._enter(pid), *cmd], capture_output=True, text=True,
                             timeout=30)
        if res.returncode != 0:
            raise LabError(f"{where}: {' '.join(cmd)}: {res.stderr.strip()}")
        return res.stdout

    def open(self) -> Lab:
        self.workdir.mkdir(parents=True, exist_ok=True)
        self.switch = self._holder(["unshare", "--user", "--map-root-user", "--net", "--"])
        self._wait_ns(self.switch, os.getpid())
        self.sh("switch", "ip", "link", "add", "br0", "type", "bridge")
        self.sh("switch", "ip", "link", "set", "br0", "up")
        for name in HOSTS:
            h = self._holder([*self._enter(self.switch.pid), "unshare", "--net", "--"])
            self.hosts[name] = h
            self._wait_ns(h, self.switch.pid)
            port = f"sw-{name}"
            self.sh("switch", "ip", "link", "add", port, "type", "veth", "peer", "name",
                    "eth0", "netns", str(h.pid))
            self.sh("switch", "ip", "link", "set", port, "master", "br0")
            self.sh("switch", "ip", "link", "set", port, "up")
            self.sh(name, "ip", "link", "set", "lo", "up")
            self.sh(name, "ip", "addr", "add", f"{HOST_ADDR[name]}/24", "dev", "eth0")
            self.link(name, up=True)
        return self

    def link(self, host: str, up: bool) -> None:
        """Bring a host's ``eth0`` down or up (inside its namespace); up restores its routes."""
        self.sh(host, "ip", "link", "set", "eth0", "up" if up else "down")
        if up and self.discovery == "subnet":
            # taking a link down drops its routes; the subnet route comes back by itself
            self.sh(host, "ip", "route", "replace", "224.0.0.0/4", "dev", "eth0")

    def counters(self, host: str) -> tuple[int, int]:
        """(rx bytes, tx bytes) of a host's ``eth0``."""
        stats = Path("/proc", str(self.hosts[host].pid), "net", "dev").read_text()
        for line in stats.splitlines():
            if line.strip().startswith("eth0:"):
                f = line.split(":", 1)[1].split()
                return int(f[0]), int(f[8])
        raise LabError(f"{host}: no eth0")

    # --- processes ----------------------------------------------------------------------
    def start(self, host: str, key: str, cmd: Sequence[str],
              stdin: int | None = None) -> subprocess.Popen[bytes]:
        """Start ``cmd`` inside ``host``; its output goes to ``<workdir>/<key>.log``."""
        log = (self.workdir / f"{key}.log").open("wb")
        self._logs.append(log)
        p = subprocess.Popen(
            [*self._enter(self.hosts[host].pid), *cmd], stdout=log, stderr=subprocess.STDOUT,
            stdin=stdin, env=self.env[host], preexec_fn=_die_with_parent,
        )
        self.procs[key] = p
        return p

    def log(self, key: str) -> str:
        path = self.workdir / f"{key}.log"
        return path.read_text(errors="replace") if path.exists() else ""

    def stop(self, key: str, timeout_s: float = 30.0) -> int:
        p = self.procs[key]
        if p.poll() is None:
            p.send_signal(signal.SIGINT)
        try:
            return p.wait(timeout=timeout_s)
        except subprocess.TimeoutExpired:
            p.kill()
            return p.wait()

    def close(self) -> None:
        for key in list(self.procs):
            self.stop(key)
        for h in [*self.hosts.values(), *([self.switch] if self.switch else [])]:
            if h.poll() is None and h.stdin is not None:
                h.stdin.close()
            try:
                h.wait(timeout=10)
            except subprocess.TimeoutExpired:
                h.kill()
                h.wait()
        for f in self._logs:
            f.close()

    def pids(self) -> list[int]:
        """Every pid this lab started (holders and nodes)."""
        ps = [*self.procs.values(), *self.hosts.values(), *([self.switch] if self.switch else [])]
        return [p.pid for p in ps]


@contextmanager
def lab(workdir: Path, domain_id: int | None = None, discovery: str = "subnet") -> Iterator[Lab]:
    the_lab = Lab(workdir, domain_id, discovery)
    try:
        yield the_lab.open()
    finally:
        the_lab.close()


# --- one run of the graph across the hosts ------------------------------------------------
@dataclass
class Outage:
    """Take ``host``'s link down ``after_s`` wall seconds into its replay, for ``down_s``."""

    host: str = "rf"
    after_s: float = 5.0
    down_s: float = 10.0
    down_at: float = math.nan  # time.monotonic() when it went down / came back
    up_at: float = math.nan


@dataclass
class RunResult:
    result: dict[str, Any]
    sent: dict[str, int]
    codes: dict[str, int]
    logs: dict[str, str]
    wall_s: float
    bytes_rx_tx: dict[str, tuple[int, int]] = field(default_factory=dict)
    outage: Outage | None = None


_SENT = re.compile(r"replay finished: \d+ messages sent \(([^)]*)\)")


def sent_counts(log: str) -> dict[str, int]:
    """Per-topic sent counts from a replay's final log line."""
    m = _SENT.search(log)
    if m is None:
        return {}
    out = {}
    for part in m.group(1).split(", "):
        topic, n = part.rsplit(" ", 1)
        out[topic.lstrip("/")] = int(n)
    return out


def _wait(cond: Callable[[], bool], limit_s: float, what: str,
          procs: dict[str, subprocess.Popen[bytes]]) -> None:
    end = time.monotonic() + limit_s
    while not cond():
        dead = {k: p.returncode for k, p in procs.items() if p.poll() not in (None, 0)}
        if dead:
            raise LabError(f"while waiting for {what}: process(es) failed: {dead}")
        if time.monotonic() > end:
            raise LabError(f"timed out after {limit_s:g} s waiting for {what}")
        time.sleep(0.05)


def run_graph(
    the_lab: Lab,
    flight: Path,
    rate: float,
    reorder_window_s: float,
    tag: str,
    outage: Outage | None = None,
    limit_s: float = 600.0,
    progress: Callable[[str], None] | None = None,
) -> RunResult:
    """Run radar_replay, rf_replay and the fusion host once over ``flight``.

    A failure raises :class:`LabError` with the end of every process's log."""
    keys = [f"{tag}_fusion", f"{tag}_radar", f"{tag}_rf"]
    try:
        return _run_graph(the_lab, flight, rate, reorder_window_s, tag, outage, limit_s,
                          progress)
    except LabError as exc:
        tails = "\n".join(f"--- {k}.log (end):\n{the_lab.log(k)[-3000:]}" for k in keys)
        raise LabError(f"{exc}\n{tails}") from None


def _run_graph(
    the_lab: Lab,
    flight: Path,
    rate: float,
    reorder_window_s: float,
    tag: str,
    outage: Outage | None,
    limit_s: float,
    progress: Callable[[str], None] | None,
) -> RunResult:
    say = progress or (lambda _m: None)
    out_json = the_lab.workdir / f"{tag}_result.json"
    t0 = time.monotonic()
    replay = [f"flight_dir:={flight}", f"rate:={float(rate)!r}", "exit_when_done:=true",
              "wait_for_subscribers_s:=300.0"]
    procs = the_lab.procs
    keys = [f"{tag}_fusion", f"{tag}_radar", f"{tag}_rf"]
    fusion = the_lab.start("fusion", keys[0], [
        sys.executable, str(SCRIPT), "fusion-host", "--flight", str(flight),
        "--rate", f"{rate:.6g}", "--window", f"{reorder_window_s:.6g}",
        "--out", str(out_json), "--report", str(the_lab.workdir / f"{tag}_report"),
    ], stdin=subprocess.PIPE)
    the_lab.start("radar", keys[1], [str(BIN / "radar_replay"), "--ros-args",
                                     *_params(replay)])
    # rf/fix is read by fusion_node and evaluator_node: start once both are matched
    the_lab.start("rf", keys[2], [str(BIN / "rf_replay"), "--ros-args",
                                  *_params([*replay, "min_subscribers:=2"])])
    mine = {k: procs[k] for k in keys}
    say(f"{tag}: 3 hosts started, waiting for discovery across the bridge")
    _wait(lambda: "replaying" in the_lab.log(keys[2]) and "replaying" in the_lab.log(keys[1]),
          limit_s, "both sensor replays to start", mine)
    say(f"{tag}: replays running at {rate:g}x")
    if outage is not None:
        started = time.monotonic()
        _wait(lambda: time.monotonic() - started >= outage.after_s, limit_s, "the outage", mine)
        outage.down_at = time.monotonic()
        the_lab.link(outage.host, up=False)
        say(f"{tag}: {outage.host} host link down")
        _wait(lambda: time.monotonic() - outage.down_at >= outage.down_s, limit_s,
              "the end of the outage", mine)
        the_lab.link(outage.host, up=True)
        outage.up_at = time.monotonic()
        say(f"{tag}: {outage.host} host link up after {outage.up_at - outage.down_at:.1f} s")
    replays = {k: procs[k] for k in keys[1:]}
    _wait(lambda: all(p.poll() is not None for p in replays.values()), limit_s,
          "the sensor replays to finish", mine)
    say(f"{tag}: sensor replays done, finishing the fusion host")
    assert fusion.stdin is not None
    fusion.stdin.write(b"finish\n")
    fusion.stdin.flush()
    _wait(lambda: fusion.poll() is not None, limit_s, "the fusion host to finish", mine)
    codes = {k: int(procs[k].returncode) for k in keys}
    logs = {k: the_lab.log(k) for k in keys}
    if codes[keys[0]] != 0 or not out_json.exists():
        raise LabError(f"fusion host failed ({codes}):\n{logs[keys[0]]}")
    sent: dict[str, int] = {}
    for k in keys[1:]:
        sent.update(sent_counts(logs[k]))
    return RunResult(
        result=json.loads(out_json.read_text()), sent=sent, codes=codes, logs=logs,
        wall_s=time.monotonic() - t0,
        bytes_rx_tx={h: the_lab.counters(h) for h in HOSTS}, outage=outage,
    )


def _params(items: Sequence[str]) -> list[str]:
    out: list[str] = []
    for it in items:
        out += ["-p", it]
    return out


# --- accounting -----------------------------------------------------------------------------
def sensor_time(run: RunResult, mono: float) -> float:
    """The fusion host's replay time at wall instant ``mono`` (time.monotonic())."""
    tl = run.result["timeline"]
    return float(tl["t_start"] + (mono - tl["wall0"]) * tl["rate"])


def accounting(run: RunResult, window_s: float, source: str = "rf") -> dict[str, Any]:
    """A sensor stream's accounting across the links (definitions in docs/deploy.md).

    - sent: the replay's own count (its final log line);
    - arrived: what reached fusion_node (recorded per message on the fusion host; equal to
      evaluator_node's ``received`` count, which is checked);
    - lateness of an arrival: fusion_node's watermark just before it arrived (the latest
      stamp of any input stream or the simulated clock, whichever is later) minus its stamp;
    - on time: lateness <= ``window_s`` (the reorder window): fused in time order;
    - late: lateness > ``window_s``: a fix is dropped by fusion_node as late (it still
      counts in the evaluator's raw RF row); a failed attempt carries nothing to fuse;
    - lost: sent - arrived (never arrived).
    """
    topic = {"rf": "rf/fix", "radar": "radar/pose"}[source]
    arr = run.result["arrivals"][source]
    sent = run.sent.get(topic, -1)
    late = [a for a in arr if a[1] - a[0] > window_s]
    on_time = [a for a in arr if a[1] - a[0] <= window_s]
    out: dict[str, Any] = {
        "sent": sent,
        "arrived": len(arr),
        "on_time": len(on_time),
        "late": len(late),
        "lost": sent - len(arr),
        "late_fixes": sum(1 for a in late if not a[4]),
        "fusion_dropped_late": int(run.result["fusion"].get(f"dropped_late_{source}", 0)),
        "fusion_received": int(run.result["fusion"][f"received_{source}"]),
        "dropped_late_on_time": sum(1 for a in on_time if a[3]),
        "max_lateness_s": max((a[1] - a[0] for a in arr), default=0.0),
    }
    if source == "rf":
        out["evaluator_received"] = int(run.result["evaluator"]["received"].get(topic, 0))
    o = run.outage
    if o is not None and late:
        after = [a[2] for a in arr if a[2] >= o.up_at]
        out["first_arrival_after_link_up_s"] = (min(after) - o.up_at) if after else math.nan
        out["late_arrivals_within_s_of_link_up"] = max(a[2] for a in late) - o.up_at
    return out


# --- the fusion host process ---------------------------------------------------------------
def _recording_fusion_node() -> type[Any]:
    """fusion_node, recording for every arriving measurement message: its stream, stamp,
    the node's watermark just before it arrived (the latest stamp of any stream or the
    simulated clock, whichever is later), the wall time, and whether the node dropped it as
    late for its reorder window."""
    from uav_fusion.nodes.fusion_node import FusionNode
    from uav_fusion.ros import conversions as cv

    class RecordingFusionNode(FusionNode):  # type: ignore[misc]
        def __init__(self, **kwargs: Any) -> None:
            self.arrivals: dict[str, list[tuple[float, float, float, bool, bool]]] = {
                "rf": [], "radar": []}
            self.step_log: list[tuple[float, str, bool]] = []  # (time, source, updated)
            super().__init__(**kwargs)

            publish = self.output.publish

            def logged(out: Any) -> None:
                self.step_log.extend(
                    (float(s.t), str(s.source), bool(s.updated)) for s in out.steps
                )
                publish(out)

            self.output.publish = logged  # type: ignore[method-assign]

        # the node drains both input queues per callback and handles each message in _one:
        # record there, so every message is seen once, in order
        def _one(self, source: str, msg: Any) -> Any:
            clock = self._now()[1]
            wm = self.pipeline.buffer.watermark
            mark = wm if clock is None else max(clock, wm)
            late = self.dropped[f"late_{source}"]
            out = super()._one(source, msg)
            failed = source == "rf" and cv.is_failed_rf(msg)
            self.arrivals[source].append((cv.time_from_stamp(msg.header.stamp), mark,
                                          time.monotonic(),
                                          self.dropped[f"late_{source}"] > late, failed))
            return out

    return RecordingFusionNode


def fusion_host(flight: str, rate: float, window: float, out: Path, report: Path) -> int:
    """truth_replay + fusion_node + evaluator_node in one process on the fusion host."""
    import rclpy
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node
    from rclpy.parameter import Parameter

    from uav_fusion.nodes.evaluator_node import EvaluatorNode
    from uav_fusion.nodes.truth_replay import TruthReplay

    def log(msg: str) -> None:
        print(f"fusion-host: {msg}", flush=True)

    ctx = Context()
    rclpy.init(context=ctx)
    ex = SingleThreadedExecutor(context=ctx)
    gate = Node("fusion_host_gate", context=ctx)
    ex.add_node(gate)
    finish = False

    def spin_until(cond: Callable[[], bool], limit_s: float, what: str) -> None:
        nonlocal finish
        end = time.monotonic() + limit_s
        while not cond():
            if time.monotonic() > end:
                raise LabError(f"timed out after {limit_s:g} s waiting for {what}")
            ex.spin_once(timeout_sec=0.05)
            if not finish and select.select([sys.stdin], [], [], 0)[0]:
                finish = sys.stdin.readline().strip() == "finish" or finish

    topics = ("radar/pose", "radar/raw", "rf/fix")
    spin_until(lambda: all(gate.count_publishers(t) >= 1 for t in topics), 300.0,
               "the sensor hosts' publishers")
    log("saw the radar and RF hosts' publishers; creating subscriptions")
    sim = Parameter("use_sim_time", value=True)
    # the truth replay (its /clock drives evaluator_node) loads its flight before any
    # subscription exists, so that its timeline starts with the sensor hosts' (each replay
    # starts once its subscribers match); 1 /clock subscriber: evaluator_node
    truth = TruthReplay(context=ctx, parameter_overrides=[
        Parameter("flight_dir", value=flight), Parameter("rate", value=rate),
        Parameter("wait_for_clock_subscribers", value=1)])
    # fusion_node's watermark comes from the sensor stamps alone (no use_sim_time): a
    # clock published on this host would run ahead of messages still queued here on a
    # loaded machine and make them look late
    fusion = _recording_fusion_node()(context=ctx, parameter_overrides=[
        Parameter("reorder_window_s", value=window), Parameter("idle_flush_s", value=0.0)])
    evaluator = EvaluatorNode(context=ctx, parameter_overrides=[
        sim, Parameter("output_dir", value=str(report)), Parameter("figures", value=False),
        Parameter("log_period_s", value=0.0), Parameter("write_on_shutdown", value=False)])
    for node in (fusion, evaluator, truth):
        ex.add_node(node)
    drv = truth.start_standalone()
    try:
        spin_until(lambda: finish and drv.done, 3600.0, "the end of the flight")
        drv.wait_acked(30.0)
        n_truth = drv.published_to(truth.pub)
        spin_until(lambda: evaluator.received[truth.p["truth_topic"]] >= n_truth, 60.0,
                   "the evaluator to receive the truth")
        n_flushed = fusion.flush()
        log(f"sensor hosts finished; flushed {n_flushed} buffered measurement(s)")

        def evaluator_has_all() -> bool:
            r = evaluator.received
            return (r["fusion/odom/updated"] + r["fusion/odom/coasted"] >= fusion.steps_published
                    and r["fusion/accepted/radar"] + r["fusion/accepted/rf"]
                    >= fusion.output.accepted_published)

        spin_until(evaluator_has_all, 60.0, "the evaluator to receive every fused step")
        files = evaluator.write_report()
        ev = evaluator.evaluate()
        steps = []
        for kind in ("updated", "coasted"):  # the positions the evaluator scores
            ts, xyz, _ = evaluator.evaluator._steps[kind].arrays()
            steps += [(float(t), kind, [float(v) for v in x])
                      for t, x in zip(ts, xyz, strict=True)]
        steps.sort()
        result = {
            "fusion": fusion.diagnostics(),
            "evaluator": {
                "received": dict(evaluator.received), "used": dict(evaluator.used),
                "refused": dict(evaluator.refused), "dropped": dict(ev.dropped),
                "gaps": evaluator.gap_text(ev),
            },
            "steps": steps,
            "truth_sent": drv.published_to(truth.pub),
            "timeline": {"t_start": drv.t_start, "wall0": drv._wall0, "rate": rate},
            "arrivals": fusion.arrivals,
            "fusion_steps": fusion.step_log,
            "report": str(files.folder),
        }
        out.write_text(json.dumps(result))
        log(f"result written to {out}")
    finally:
        for node in (truth, evaluator, fusion, gate):
            ex.remove_node(node)
            node.destroy_node()
        rclpy.shutdown(context=ctx)
    return 0


# --- command line -------------------------------------------------------------------------
def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    sub = ap.add_subparsers(dest="mode")
    fh = sub.add_parser("fusion-host", help="(inside the fusion host) truth + fusion + evaluator")
    fh.add_argument("--flight", required=True)
    fh.add_argument("--rate", type=float, required=True)
    fh.add_argument("--window", type=float, required=True)
    fh.add_argument("--out", type=Path, required=True)
    fh.add_argument("--report", type=Path, required=True)
    ap.add_argument("--flight", type=Path, default=None, help="flight folder (default: bundled)")
    ap.add_argument("--rate", type=float, default=25.0, help="replay rate (default 25)")
    ap.add_argument("--window", type=float, default=20.0,
                    help="fusion_node reorder_window_s (sensor seconds; default 20)")
    ap.add_argument("--rf-outage", type=float, default=0.0,
                    help="take the RF host's link down for this many wall seconds (0 = no)")
    ap.add_argument("--outage-after", type=float, default=5.0,
                    help="wall seconds after the replays start (default 5)")
    ap.add_argument("--discovery", choices=("subnet", "static"), default="subnet",
                    help="subnet: multicast on the hosts' subnet; static: LOCALHOST range + "
                    "ROS_STATIC_PEERS (default subnet)")
    ap.add_argument("--out", type=Path, default=None, help="work folder (default: a temp dir)")
    opts = ap.parse_args(argv)
    if opts.mode == "fusion-host":
        return fusion_host(opts.flight, opts.rate, opts.window, opts.out, opts.report)

    why = probe()
    if why:
        print(f"multihost: cannot build the hosts: {why}", file=sys.stderr)
        return 2
    from uav_fusion.resources import DEFAULT_FLIGHT, data_path

    flight = (opts.flight or data_path(DEFAULT_FLIGHT)).resolve()
    work = opts.out or Path(tempfile.mkdtemp(prefix="uav_fusion_multihost_"))
    outage = Outage(after_s=opts.outage_after, down_s=opts.rf_outage) if opts.rf_outage else None
    t0 = time.monotonic()
    try:
        with lab(work, discovery=opts.discovery) as the_lab:
            return _report(the_lab, flight, opts, outage, work, t0)
    except LabError as exc:
        print(f"multihost: failed: {exc}", file=sys.stderr)
        return 1


def _report(the_lab: Lab, flight: Path, opts: argparse.Namespace, outage: Outage | None,
            work: Path, t0: float) -> int:
    """Run the graph once in ``the_lab`` and print the figures."""
    print(f"multihost: switch + 3 hosts up in {time.monotonic() - t0:.2f} s "
          f"(domain {the_lab.domain_id}, {opts.discovery} discovery, logs in {work})",
          flush=True)
    run = run_graph(the_lab, flight, opts.rate, opts.window, "run", outage=outage,
                    progress=lambda m: print(f"multihost: {m}", flush=True))
    print(f"multihost: graph run {run.wall_s:.1f} s wall, exit codes {run.codes}")
    for h, (rx, tx) in run.bytes_rx_tx.items():
        print(f"  {h:6s} host eth0: received {rx} B, sent {tx} B")
    for source in ("rf", "radar"):
        acc = accounting(run, opts.window, source)
        print(f"  {source} stream: " + ", ".join(
            f"{k} {v:.2f}" if isinstance(v, float) else f"{k} {v}" for k, v in acc.items()))
    if outage is not None:
        t_down, t_up = sensor_time(run, outage.down_at), sensor_time(run, outage.up_at)
        t0_flight = run.result["timeline"]["t_start"]
        steps = run.result["fusion_steps"]
        print(f"  outage: {outage.up_at - outage.down_at:.1f} s wall = flight time "
              f"{t_down - t0_flight:.0f}-{t_up - t0_flight:.0f} s; fused steps in it: "
              f"{sum(1 for t, _s, _u in steps if t_down < t < t_up)}; RF updates after it: "
              f"{sum(1 for t, src, up in steps if t > t_up and src == 'rf' and up)}")
    diff = compare_offline(flight, run.result["steps"])
    print(f"  fused track vs offline run_flight: {diff}")
    print(f"  evaluator step gaps: {run.result['evaluator']['gaps']}")
    return 0


def compare_offline(flight: Path, steps: list[Any]) -> str:
    """Compare the evaluator's fused track with ``run_flight`` (paper profile), bit for bit."""
    from uav_fusion.core.data import load_flight
    from uav_fusion.core.estimators import load_profile, run_flight
    from uav_fusion.core.site import load_site

    site = load_site()
    off = [s for s in run_flight(load_flight(flight, site), load_profile("paper"), site).steps
           if s.counted and (s.updated or s.coasted)]
    ref = sorted((float(s.t), "updated" if s.updated else "coasted",
                  [float(v) for v in s.x[:3]]) for s in off)
    got = [(float(t), str(k), [float(v) for v in x]) for t, k, x in steps]
    if got == ref:
        return f"identical ({len(ref)} steps: times, kinds and positions equal bit for bit)"
    n = sum(1 for a, b in zip(got, ref, strict=False) if a == b)
    return f"DIFFERENT: {len(got)} live steps vs {len(ref)} offline, {n} equal"


if __name__ == "__main__":
    sys.exit(main())
