"""fusion_node: radar + RF fusion with the core estimator, in timestamp order.

Subscribes ``radar/pose`` (PoseWithCovarianceStamped; reports sharing one stamp form one
radar frame of candidates) and ``rf/fix`` (PointStamped; NaN = failed attempt). Incoming
measurements go through a :class:`~uav_fusion.core.reorder.ReorderBuffer` so that the
estimator sees them in the same order as the offline run whatever the arrival order: an
item is released once every input stream has moved past it, or once the watermark (latest
stamp seen, or the simulated clock) is ``reorder_window_s`` beyond it. Items arriving later
than that are dropped and counted (``late_<source>``). At the end of a stream the buffer is
flushed by an idle timer (``idle_flush_s`` of wall time without input), by the
``fusion/flush`` service (std_srvs/Trigger) and on shutdown.

Time faults (duplicates, stamps far ahead, runs of late messages, the simulated clock jumping
back) are handled by :class:`uav_fusion.core.timeline.Timeline` with this node's parameters
``max_future_s``, ``late_run_reset`` and ``clock_jump_back_s``; it counts
``<source>_duplicate``, ``<source>_future``, ``clock_jumps_back`` and ``timeline_resets``.

Accounting: for each input stream, ``received_<s>`` = ``used_<s>`` + the sum of
``rejected_<s>_<reason>`` (refused by the estimator: gates, not selected, failed RF
attempts, ...) + the sum of ``dropped_<s>_<reason>`` and ``dropped_late_<s>`` (never
reached the estimator) +
``buffer_pending`` + ``held_<s>`` (the last two are 0 after a flush).

Publishes, for every filter step, nav_msgs/Odometry on ``fusion/odom`` and the same message
on ``fusion/odom/updated`` or ``fusion/odom/coasted``; for every accepted measurement the
measurement itself on ``fusion/accepted/radar`` or ``fusion/accepted/rf`` (passed every gate,
NIS included; a measurement that only started the track is not "accepted"); and counters on
``/diagnostics``. Malformed messages (NaN, bad covariance, wrong frame, zero stamp) are
dropped and counted by reason — never a traceback.
"""

from __future__ import annotations

import math
import sys
import time
from collections import Counter, deque
from collections.abc import Sequence
from typing import Any

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PointStamped, PoseWithCovarianceStamped
from nav_msgs.msg import Odometry
from rclpy.clock import Clock
from rclpy.clock_type import ClockType
from rclpy.node import Node
from std_srvs.srv import Trigger

from uav_fusion.core.errors import UavFusionError
from uav_fusion.core.estimator import FusionEstimator, Profile, load_profile
from uav_fusion.core.records import RADAR, RF, Measurement
from uav_fusion.core.reorder import Batch, ReorderBuffer
from uav_fusion.core.site import load_site
from uav_fusion.core.timeline import Timeline, TimelineConfig
from uav_fusion.ros import conversions as cv
from uav_fusion.ros.diagnostics import make_status
from uav_fusion.ros.params import Param, declare_all, not_empty
from uav_fusion.ros.qos import stream_qos
from uav_fusion.ros.runtime import run_node

NODE_NAME = "fusion_node"


def fusion_params() -> list[Param]:
    def topic(name: str, default: str, what: str) -> Param:
        return Param(name, default, what, check=not_empty)

    return [
        Param("profile", "paper", "estimator profile: a name under config/profiles or a path"),
        Param("site_file", "", "site YAML ('' = bundled Lake Wheeler site)"),
        Param("world_frame", "", "frame of inputs and outputs ('' = the site's frame_id)"),
        topic("child_frame_id", "uav", "child frame id of the published Odometry"),
        topic("radar_topic", "radar/pose", "radar input (PoseWithCovarianceStamped)"),
        topic("rf_topic", "rf/fix", "RF input (PointStamped; NaN = failed attempt)"),
        topic("odom_topic", "fusion/odom", "every filter step (Odometry)"),
        topic("updated_topic", "fusion/odom/updated", "steps that updated (Odometry)"),
        topic("coasted_topic", "fusion/odom/coasted", "steps that coasted (Odometry)"),
        topic("accepted_radar_topic", "fusion/accepted/radar", "accepted radar measurements"),
        topic("accepted_rf_topic", "fusion/accepted/rf", "accepted RF measurements"),
        topic("flush_service", "fusion/flush", "std_srvs/Trigger: flush the reorder buffer"),
        Param(
            "reorder_window_s", 2.0,
            "sensor seconds a measurement may arrive late and still be processed in order",
            lo=0.001, hi=3600.0,
        ),
        Param(
            "use_message_covariance", True,
            "radar R from the message covariance (true) or from the profile (false)",
        ),
        Param(
            "idle_flush_s", 2.0,
            "wall seconds without input after which the buffer is flushed (0 = never)",
            lo=0.0, hi=3600.0, read_only=False,
        ),
        Param(
            "diagnostics_period_s", 1.0, "wall seconds between /diagnostics messages",
            lo=0.05, hi=3600.0, read_only=False,
        ),
        Param("qos_depth", 1000, "history depth of the reliable streams", lo=1, hi=1000000),
        Param(
            "max_future_s", 30.0,
            "sensor seconds a stamp may lie ahead of the simulated clock (or, without one, of "
            "the latest stamp seen) before it is held or dropped as 'future'",
            lo=0.001, hi=1.0e9,
        ),
        Param(
            "late_run_reset", 50,
            "this many messages in a row that are late for the reorder window or repeats mean "
            "the input timeline went back: reset the filter and the buffer (0 = never)",
            lo=0, hi=1000000,
        ),
        Param(
            "clock_jump_back_s", 1.0,
            "a backwards jump of the simulated clock larger than this resets the filter",
            lo=0.0, hi=1.0e9,
        ),
    ]


class FusionNode(Node):
    """Thin node around :class:`FusionEstimator` (see the module docstring)."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(NODE_NAME, **kwargs)
        self.p = declare_all(self, fusion_params())
        self.site = load_site(self.p["site_file"] or None)
        self.profile: Profile = load_profile(self.p["profile"])
        self.frame = str(self.p["world_frame"] or self.site.frame_id)
        self.child_frame = str(self.p["child_frame_id"])
        self.estimator = FusionEstimator(self.profile, self.site)
        self.received: Counter[str] = Counter()
        self.used: Counter[str] = Counter()
        self.refused: Counter[str] = Counter()  # "<source>_<reason>"
        # message drops (malformed, refused by the estimator); the timeline counts its own
        self._bad: Counter[str] = Counter()
        self.timeline = Timeline(
            TimelineConfig(
                reorder_window_s=float(self.p["reorder_window_s"]),
                max_future_s=float(self.p["max_future_s"]),
                late_run_reset=int(self.p["late_run_reset"]),
                clock_jump_back_s=float(self.p["clock_jump_back_s"]),
            ),
            self,
        )
        self.statuses: Counter[str] = Counter()
        self.reasons: Counter[str] = Counter()
        self.nis: dict[str, list[float]] = {RADAR: [], RF: []}
        self.steps_published = 0
        self.accepted_published = 0
        self._seq = 0
        self._last_input = time.monotonic()
        self._rates: dict[str, deque[float]] = {RADAR: deque(), RF: deque()}

        qos = stream_qos(int(self.p["qos_depth"]))
        self.pub_odom = self.create_publisher(Odometry, self.p["odom_topic"], qos)
        self.pub_updated = self.create_publisher(Odometry, self.p["updated_topic"], qos)
        self.pub_coasted = self.create_publisher(Odometry, self.p["coasted_topic"], qos)
        self.pub_acc_radar = self.create_publisher(
            PoseWithCovarianceStamped, self.p["accepted_radar_topic"], qos
        )
        self.pub_acc_rf = self.create_publisher(PointStamped, self.p["accepted_rf_topic"], qos)
        self.pub_diag = self.create_publisher(DiagnosticArray, "/diagnostics", 10)
        self.create_subscription(
            PoseWithCovarianceStamped, self.p["radar_topic"], self._on_radar, qos
        )
        self.create_subscription(PointStamped, self.p["rf_topic"], self._on_rf, qos)
        self.create_service(Trigger, self.p["flush_service"], self._on_flush)
        steady = Clock(clock_type=ClockType.STEADY_TIME)
        self._idle_timer = self.create_timer(0.1, self._on_idle, clock=steady)
        self._diag_timer = self.create_timer(
            float(self.p["diagnostics_period_s"]), self.publish_diagnostics, clock=steady
        )
        self.add_on_set_parameters_callback(self._on_params)
        self.get_logger().info(
            f"fusing {self.p['radar_topic']} + {self.p['rf_topic']} with profile "
            f"'{self.profile.name}', reorder window {self.buffer.window_s:g} s"
        )

    @property
    def buffer(self) -> ReorderBuffer[Measurement]:
        """The timeline's reorder buffer."""
        return self.timeline.buffer

    @property
    def dropped(self) -> Counter[str]:
        """Every drop by ``<source>_<reason>`` (and ``late_<source>``)."""
        return self._bad + self.timeline.dropped

    @property
    def clock_jumps_back(self) -> int:
        return self.timeline.clock_jumps_back

    @property
    def timeline_resets(self) -> int:
        return self.timeline.timeline_resets

    # --- parameters -----------------------------------------------------------------------
    def _on_params(self, params: list[Any]) -> Any:
        from rcl_interfaces.msg import SetParametersResult

        for par in params:
            if par.name == "diagnostics_period_s" and par.value > 0:
                self._diag_timer.timer_period_ns = int(par.value * 1e9)
        return SetParametersResult(successful=True)

    # --- input ----------------------------------------------------------------------------
    def _next_seq(self) -> int:
        self._seq += 1
        return self._seq

    def _note_input(self, source: str) -> None:
        now = time.monotonic()
        self._last_input = now
        self.received[source] += 1
        self._rates[source].append(now)

    def _on_radar(self, msg: PoseWithCovarianceStamped) -> None:
        self.timeline.check_clock(self._sim_now())
        self._note_input(RADAR)
        try:
            m = cv.msg_to_radar_measurement(msg, self.frame, seq=self._next_seq())
        except cv.MessageError as exc:
            self._drop(RADAR, exc)
            return
        if not self.p["use_message_covariance"]:
            m.R = None
        self.timeline.admit(RADAR, m.t, m, self._sim_now())

    def _on_rf(self, msg: PointStamped) -> None:
        self.timeline.check_clock(self._sim_now())
        self._note_input(RF)
        try:
            m = cv.msg_to_rf_measurement(msg, self.frame, seq=self._next_seq())
        except cv.MessageError as exc:
            self._drop(RF, exc)
            return
        # None = a failed attempt: the RF stream moved on, nothing to fuse
        clock = self._sim_now()
        self.timeline.admit(RF, cv.time_from_stamp(msg.header.stamp), m, clock)
        self.timeline.release(clock)

    def _drop(self, source: str, exc: cv.MessageError) -> None:
        self._count_drop(source, exc.reason, f"dropping bad {source} message(s): {exc}")

    def _count_drop(self, source: str, reason: str, warning: str, n: int = 1) -> None:
        key = f"{source}_{reason}"
        if self._bad[key] == 0:
            self.get_logger().warning(warning)
        self._bad[key] += n

    # --- timeline sink (uav_fusion.core.timeline) -------------------------------------------
    def process(self, batches: Sequence[Batch[Measurement]]) -> None:
        self._process(batches)

    def failed_attempt(self, source: str, t: float) -> None:
        self.refused[f"{source}_failed_attempt"] += 1
        self.statuses["rf_failed_attempt"] += 1

    def restart(self, reason: str) -> None:
        self.estimator.restart_timeline(reason)

    def warn(self, text: str) -> None:
        self.get_logger().warning(text)

    def _sim_now(self) -> float | None:
        if not self.get_parameter("use_sim_time").value:
            return None
        ns = self.get_clock().now().nanoseconds
        return cv.ns_to_time(ns) if ns > 0 else None

    # --- processing -----------------------------------------------------------------------
    def _process(self, batches: Sequence[Batch[Measurement]]) -> None:
        for b in batches:
            try:
                if b.source == RADAR:
                    steps = self.estimator.process_frame(list(b.items))
                else:
                    steps = []
                    for m in b.items:
                        steps.extend(self.estimator.process(m))
            except UavFusionError as exc:  # the estimator refused the input: count, go on
                self._bad[f"{b.source}_refused"] += len(b.items)
                self.get_logger().warning(f"estimator refused {b.source} at {b.t:.3f}: {exc}")
                continue
            by_seq = {m.seq: m for m in b.items}
            for step in steps:
                self._publish_step(step, by_seq)

    def _publish_step(self, step: Any, by_seq: dict[int, Measurement]) -> None:
        status = str(step.status)
        self.statuses[status] += 1
        if step.updated:
            self.used[str(step.source)] += 1
        else:
            self.refused[f"{step.source}_{step.reason or status}"] += 1
        if not step.updated and step.reason:
            self.reasons[str(step.reason)] += 1
        if step.nis is not None and math.isfinite(step.nis):
            self.nis.setdefault(str(step.source), []).append(float(step.nis))
        if not (step.updated or step.coasted):
            return  # e.g. a measurement that only started a track: no estimate to publish
        odom = cv.step_to_odometry(step, self.frame, self.child_frame)
        self.pub_odom.publish(odom)
        (self.pub_updated if step.updated else self.pub_coasted).publish(odom)
        self.steps_published += 1
        # the accepted-measurement topics carry what passed every gate (NIS included):
        # a measurement that only (re)started the track was not validated
        if getattr(step, "validated", step.updated):
            m = by_seq.get(int(step.seq))
            if m is None:
                return
            if m.source == RADAR:
                R = m.R if m.R is not None else self.profile.r_radar
                self.pub_acc_radar.publish(cv.radar_measurement_to_msg(m, self.frame, R))
            else:
                self.pub_acc_rf.publish(cv.rf_measurement_to_msg(m, self.frame))
            self.accepted_published += 1

    def flush(self) -> int:
        """Process everything held in the reorder buffer; returns the number of items.

        Stamps held back as too far ahead (unconfirmed) are dropped as ``future``.
        """
        return self.timeline.flush()

    def _on_flush(self, _req: Trigger.Request, resp: Trigger.Response) -> Trigger.Response:
        n = self.flush()
        resp.success = True
        resp.message = f"flushed {n} measurement(s); {self.steps_published} steps published"
        return resp

    def _on_idle(self) -> None:
        self.timeline.check_clock(self._sim_now())
        idle = float(self.get_parameter("idle_flush_s").value)
        self.timeline.release(self._sim_now())
        pending = self.timeline.pending or self.timeline.holding
        if idle > 0 and pending and time.monotonic() - self._last_input >= idle:
            n = self.flush()
            self.get_logger().info(f"no input for {idle:g} s: flushed {n} measurement(s)")

    # --- diagnostics ----------------------------------------------------------------------
    def diagnostics(self) -> dict[str, str]:
        """The counters published on /diagnostics, as key -> text."""
        vals: dict[str, Any] = {}
        for src in (RADAR, RF):
            vals[f"received_{src}"] = self.received[src]
            vals[f"used_{src}"] = self.used[src]
            vals[f"held_{src}"] = len(self.timeline.held[src])
        for k, v in sorted(self.refused.items()):
            vals[f"rejected_{k}"] = v
        for k, v in sorted(self.statuses.items()):
            vals[f"steps_{k}"] = v
        for k, v in sorted(self.reasons.items()):
            vals[f"rejected_{k}"] = v
        for k, v in sorted(self.dropped.items()):
            vals[f"dropped_{k}"] = v
        counters = getattr(self.estimator, "counters", None)
        if isinstance(counters, dict):
            for k, v in sorted(counters.items()):
                vals[f"estimator_{k}"] = v
        for src, xs in self.nis.items():
            if xs:
                a = np.asarray(xs)
                vals[f"nis_{src}_count"] = a.size
                vals[f"nis_{src}_mean"] = f"{a.mean():.4g}"
                vals[f"nis_{src}_max"] = f"{a.max():.4g}"
        now = time.monotonic()
        for src, q in self._rates.items():
            while q and now - q[0] > 10.0:
                q.popleft()
            vals[f"input_rate_{src}_hz"] = f"{len(q) / 10.0:.3g}"
        vals["steps_published"] = self.steps_published
        vals["buffer_pending"] = self.buffer.pending
        vals["buffer_max_depth"] = self.buffer.max_depth
        vals["clock_jumps_back"] = self.clock_jumps_back
        vals["timeline_resets"] = self.timeline_resets
        return {k: str(v) for k, v in vals.items()}

    def publish_diagnostics(self) -> None:
        vals = self.diagnostics()
        n_drop = sum(self.dropped.values())
        arr = DiagnosticArray()
        arr.header.stamp = self.get_clock().now().to_msg()
        arr.status = [make_status(
            f"{self.get_name()}: fusion",
            f"{self.steps_published} steps, {n_drop} dropped",
            vals.items(),
            warn=bool(n_drop),
        )]
        self.pub_diag.publish(arr)

    def destroy_node(self) -> None:
        try:
            if (self.timeline.pending or self.timeline.holding) and self.context.ok():
                self.flush()
        finally:
            super().destroy_node()


def main(args: Sequence[str] | None = None) -> int:
    return run_node(FusionNode, args, name=NODE_NAME)


if __name__ == "__main__":
    sys.exit(main())
