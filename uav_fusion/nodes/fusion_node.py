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
from nav_msgs.msg import Path as NavPath
from rclpy.clock import Clock
from rclpy.clock_type import ClockType
from rclpy.event_handler import PublisherEventCallbacks
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.publisher import Publisher
from sensor_msgs.msg import NavSatFix
from std_srvs.srv import Trigger
from visualization_msgs.msg import MarkerArray

from uav_fusion.core.errors import UavFusionError
from uav_fusion.core.estimator import FusionEstimator, Profile, load_profile
from uav_fusion.core.records import RADAR, RF, Measurement
from uav_fusion.core.reorder import Batch, ReorderBuffer
from uav_fusion.core.site import load_site
from uav_fusion.core.timeline import Timeline, TimelineConfig
from uav_fusion.ros import conversions as cv
from uav_fusion.ros.diagnostics import InputMonitor, make_status
from uav_fusion.ros.params import Param, declare_all, not_empty
from uav_fusion.ros.qos import DIAGNOSTICS_QOS, stream_qos
from uav_fusion.ros.runtime import run_node
from uav_fusion.ros.visualization import ReportLayer, SiteLayer, TrackLayer, Visualization

NODE_NAME = "fusion_node"
#: most messages taken from one input in one go (bounds the time other callbacks wait)
DRAIN_MAX = 500


def _stamp_key(msg: Any) -> tuple[int, int]:
    st = msg.header.stamp
    return st.sec, st.nanosec


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
        topic("path_topic", "fusion/path", "the fused track (nav_msgs/Path)"),
        topic("markers_topic", "fusion/markers", "views (visualization_msgs/MarkerArray)"),
        topic("fix_topic", "fusion/fix", "fused position as sensor_msgs/NavSatFix"),
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
            "view_period_s", 0.5,
            "wall seconds between fusion/path and fusion/markers messages (only while "
            "subscribed, and only after new steps)",
            lo=0.02, hi=3600.0, read_only=False,
        ),
        Param("path_max_poses", 20000, "most poses kept in fusion/path (the latest)",
              lo=1, hi=10000000),
        Param("marker_history", 200, "radar reports and RF fixes kept in fusion/markers",
              lo=1, hi=100000),
        Param("covariance_sigma", 2.0, "the covariance ellipsoid marker spans this many sigma",
              lo=0.1, hi=10.0),
        Param("input_min_hz", 0.0,
              "diagnostics: below this input rate (Hz, per input) is 'Frequency too low' "
              "(0 = no lower bound)", lo=0.0, hi=1.0e6),
        Param("input_max_hz", 1.0e6,
              "diagnostics: above this input rate (Hz, per input) is 'Frequency too high'",
              lo=0.0, hi=1.0e9),
        Param("stamp_delay_min_s", -1.0,
              "diagnostics: a receive time minus stamp below this is 'too far in future'",
              lo=-1.0e9, hi=1.0e9),
        Param("stamp_delay_max_s", 5.0,
              "diagnostics: a receive time minus stamp above this is 'too far in past'",
              lo=-1.0e9, hi=1.0e9),
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
        #: steps with an estimate (each goes to fusion/odom and to updated or coasted)
        self.steps_published = 0
        #: measurements that passed every gate (fusion/accepted/radar or /rf)
        self.accepted_published = 0
        self._seq = 0
        self._last_input = time.monotonic()
        self._use_message_cov = bool(self.p["use_message_covariance"])
        self._r_radar = self.profile.r_radar
        # parameters read per message are cached and kept current by a post-set callback
        self._sim = bool(self.get_parameter("use_sim_time").value)
        self._idle_s = float(self.p["idle_flush_s"])
        self._view_period = float(self.p["view_period_s"])
        self.add_post_set_parameters_callback(self._after_params)
        self._ros_clock = self.get_clock()

        qos = stream_qos(int(self.p["qos_depth"]))
        # publishers need no QoS event handlers (waitables the executor would poll)
        quiet = PublisherEventCallbacks(use_default_callbacks=False)

        def pub(cls: Any, topic: str, q: Any = qos) -> Publisher:
            return self.create_publisher(cls, topic, q, event_callbacks=quiet)

        self.pub_odom = pub(Odometry, self.p["odom_topic"])
        self.pub_updated = pub(Odometry, self.p["updated_topic"])
        self.pub_coasted = pub(Odometry, self.p["coasted_topic"])
        self.pub_acc_radar = pub(PoseWithCovarianceStamped, self.p["accepted_radar_topic"])
        self.pub_acc_rf = pub(PointStamped, self.p["accepted_rf_topic"])
        self.pub_fix = pub(NavSatFix, self.p["fix_topic"])
        self.pub_path = pub(NavPath, self.p["path_topic"], DIAGNOSTICS_QOS)
        self.pub_markers = pub(MarkerArray, self.p["markers_topic"], DIAGNOSTICS_QOS)
        self.pub_diag = pub(DiagnosticArray, "/diagnostics", DIAGNOSTICS_QOS)
        # views: the state is kept cheaply per step; messages are built only when published
        self._path: deque[tuple[float, float, float, float]] = deque(
            maxlen=int(self.p["path_max_poses"])
        )
        self.track_layer = TrackLayer(sigma=float(self.p["covariance_sigma"]))
        self.report_layer = ReportLayer(history=int(self.p["marker_history"]))
        self.visualization = Visualization(
            self.frame,
            [SiteLayer(self.site, self.estimator.range_gate_m), self.report_layer,
             self.track_layer],
        )
        self._views_dirty = True
        self._last_view = -math.inf
        self._last_step: Any = None
        self.paths_published = 0
        self.markers_published = 0
        self.inputs = {
            src: InputMonitor(
                topic,
                min_hz=float(self.p["input_min_hz"]),
                max_hz=float(self.p["input_max_hz"]),
                min_delay_s=float(self.p["stamp_delay_min_s"]),
                max_delay_s=float(self.p["stamp_delay_max_s"]),
            )
            for src, topic in ((RADAR, self.p["radar_topic"]), (RF, self.p["rf_topic"]))
        }
        self._sub_radar = self.create_subscription(
            PoseWithCovarianceStamped, self.p["radar_topic"], self._on_radar, qos
        )
        self._sub_rf = self.create_subscription(PointStamped, self.p["rf_topic"], self._on_rf, qos)
        self.create_service(Trigger, self.p["flush_service"], self._on_flush)
        steady = Clock(clock_type=ClockType.STEADY_TIME)
        self._idle_timer = self.create_timer(0.1, self._on_tick, clock=steady)
        self._diag_timer = self.create_timer(
            float(self.p["diagnostics_period_s"]), self.publish_diagnostics, clock=steady
        )
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
    def _after_params(self, params: list[Parameter]) -> None:
        for par in params:
            if par.name == "use_sim_time":
                self._sim = bool(par.value)
            elif par.name == "idle_flush_s":
                self._idle_s = float(par.value)
            elif par.name == "view_period_s":
                self._view_period = float(par.value)
            elif par.name == "diagnostics_period_s" and par.value > 0:
                self._diag_timer.timer_period_ns = int(par.value * 1e9)

    # --- input ----------------------------------------------------------------------------
    def _now(self) -> tuple[float, float | None]:
        """(node clock now in seconds, the simulated clock or None)."""
        ns = self._ros_clock.now().nanoseconds
        now = cv.ns_to_time(ns)
        return now, (now if self._sim and ns > 0 else None)

    def _on_radar(self, msg: PoseWithCovarianceStamped) -> None:
        self._take_all(RADAR, msg)

    def _on_rf(self, msg: PointStamped) -> None:
        self._take_all(RF, msg)

    def _take_all(self, source: str, msg: Any) -> None:
        """Take every message already delivered on both inputs and handle them in stamp
        order (each stream's own order kept: a two-way merge).

        The executor takes one message per ready subscription in turn, so under a backlog
        the sparse RF stream would overtake the radar stream by the whole backlog and push
        the reorder watermark past radar messages still queued (dropped as late). Draining
        both queues here and merging by stamp keeps the arrival order the publishers had.
        """
        radar: deque[Any] = deque()
        rf: deque[Any] = deque()
        (radar if source == RADAR else rf).append(msg)
        for q, sub in ((radar, self._sub_radar), (rf, self._sub_rf)):
            handle = sub.handle
            while len(q) < DRAIN_MAX:
                with handle:
                    got = handle.take_message(sub.msg_type, sub.raw)
                if got is None:
                    break
                q.append(got[0])
        while radar or rf:
            if rf and (not radar or _stamp_key(rf[0]) < _stamp_key(radar[0])):
                self._one_rf(rf.popleft())
            else:
                self._one_radar(radar.popleft())

    def _one_radar(self, msg: PoseWithCovarianceStamped) -> None:
        now, clock = self._now()
        timeline = self.timeline
        timeline.check_clock(clock)
        self._last_input = time.monotonic()
        self.received[RADAR] += 1
        self._seq += 1
        try:
            m = cv.msg_to_radar_measurement(msg, self.frame, seq=self._seq)
        except cv.MessageError as exc:
            self._tick_input(RADAR, msg, now)
            self._drop(RADAR, exc)
            return
        self.inputs[RADAR].tick(now - m.t)
        if not self._use_message_cov:
            m.R = None
        timeline.admit(RADAR, m.t, m, clock)

    def _one_rf(self, msg: PointStamped) -> None:
        now, clock = self._now()
        timeline = self.timeline
        timeline.check_clock(clock)
        self._last_input = time.monotonic()
        self.received[RF] += 1
        self._seq += 1
        try:
            m = cv.msg_to_rf_measurement(msg, self.frame, seq=self._seq)
        except cv.MessageError as exc:
            self._tick_input(RF, msg, now)
            self._drop(RF, exc)
            return
        t = cv.time_from_stamp(msg.header.stamp)
        self.inputs[RF].tick(now - t)
        # None = a failed attempt: the RF stream moved on, nothing to fuse
        timeline.admit(RF, t, m, clock)
        timeline.release(clock)

    def _tick_input(self, source: str, msg: Any, now: float) -> None:
        st = msg.header.stamp
        zero = st.sec == 0 and st.nanosec == 0
        self.inputs[source].tick(None if zero else now - cv.time_from_stamp(st))

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
        return self._now()[1]

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
        status = step.status
        self.statuses[status] += 1
        source = step.source
        updated = step.updated
        if updated:
            self.used[source] += 1
        else:
            self.refused[f"{source}_{step.reason or status}"] += 1
            if step.reason:
                self.reasons[step.reason] += 1
        nis = step.nis
        if nis is not None and math.isfinite(nis):
            self.nis[source].append(float(nis))
        m = by_seq.get(step.seq)
        validated = step.validated
        if m is not None:  # the views' report layer: accepted or refused measurements
            if source == RADAR:
                self.report_layer.radar(m.z, validated)
            else:
                self.report_layer.rf_fix(m.z, updated)
        if not (updated or step.coasted):
            return  # e.g. a measurement that only started a track: no estimate to publish
        self.steps_published += 1
        v = step.values
        self._path.append((step.t, v[0], v[1], v[2]))
        self._last_step = step
        self._views_dirty = True
        side = self.pub_updated if updated else self.pub_coasted
        if self.pub_odom.get_subscription_count() or side.get_subscription_count():
            odom = cv.odometry_from_values(step.t, v, self.frame, self.child_frame)
            self.pub_odom.publish(odom)
            side.publish(odom)
        if self.pub_fix.get_subscription_count():
            self.pub_fix.publish(self._fix(step.t, v))
        # the accepted-measurement topics carry what passed every gate (NIS included):
        # a measurement that only (re)started the track was not validated
        if validated and m is not None:
            self.accepted_published += 1
            if source == RADAR:
                if self.pub_acc_radar.get_subscription_count():
                    R = m.R if m.R is not None else self._r_radar
                    self.pub_acc_radar.publish(cv.radar_measurement_to_msg(m, self.frame, R))
            elif self.pub_acc_rf.get_subscription_count():
                self.pub_acc_rf.publish(cv.rf_measurement_to_msg(m, self.frame))

    # --- views ----------------------------------------------------------------------------
    def _fix(self, t: float, v: Sequence[float]) -> NavSatFix:
        """The fused position as NavSatFix (WGS84, HAE; covariance = P's position block in
        ENU, which is NavSatFix's convention)."""
        lat, lon, h = self.site.to_geodetic(v[0], v[1], v[2])
        return cv.navsatfix_from_enu(t, float(lat), float(lon), float(h), v, self.child_frame)

    def path_message(self) -> NavPath:
        """fusion/path: the latest ``path_max_poses`` fused positions."""
        return cv.path_from_points(self._path, self.frame)

    def markers_message(self) -> MarkerArray:
        """fusion/markers: every layer of :mod:`uav_fusion.ros.visualization`."""
        step = self._last_step
        if step is not None:
            self.track_layer.update(step.x[:3], step.P[:3, :3].tolist())
        now = self._ros_clock.now().to_msg()
        return self.visualization.array(now)

    def publish_views(self, force: bool = False) -> None:
        """Publish fusion/path and fusion/markers if subscribed and something changed."""
        if not (self._views_dirty or force):
            return
        self._views_dirty = False
        self._last_view = time.monotonic()
        if self.pub_path.get_subscription_count():
            self.pub_path.publish(self.path_message())
            self.paths_published += 1
        if self.pub_markers.get_subscription_count():
            self.pub_markers.publish(self.markers_message())
            self.markers_published += 1

    def flush(self) -> int:
        """Process everything held in the reorder buffer; returns the number of items.

        Stamps held back as too far ahead (unconfirmed) are dropped as ``future``.
        """
        n = self.timeline.flush()
        self.publish_views()
        return n

    def _on_flush(self, _req: Trigger.Request, resp: Trigger.Response) -> Trigger.Response:
        n = self.flush()
        resp.success = True
        resp.message = f"flushed {n} measurement(s); {self.steps_published} steps published"
        return resp

    def _on_tick(self) -> None:
        clock = self._sim_now()
        self.timeline.check_clock(clock)
        self.timeline.release(clock)
        idle = self._idle_s
        pending = self.timeline.pending or self.timeline.holding
        if idle > 0 and pending and time.monotonic() - self._last_input >= idle:
            n = self.flush()
            self.get_logger().info(f"no input for {idle:g} s: flushed {n} measurement(s)")
        if time.monotonic() - self._last_view >= self._view_period:
            self.publish_views()

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
        vals["steps_published"] = self.steps_published
        vals["buffer_pending"] = self.buffer.pending
        vals["buffer_max_depth"] = self.buffer.max_depth
        # matched readers per output: outputs nobody reads are not built
        for key, p in (("odom", self.pub_odom), ("updated", self.pub_updated),
                       ("coasted", self.pub_coasted), ("accepted_radar", self.pub_acc_radar),
                       ("accepted_rf", self.pub_acc_rf), ("fix", self.pub_fix),
                       ("path", self.pub_path), ("markers", self.pub_markers)):
            vals[f"subscribers_{key}"] = p.get_subscription_count()
        vals["clock_jumps_back"] = self.clock_jumps_back
        vals["timeline_resets"] = self.timeline_resets
        return {k: str(v) for k, v in vals.items()}

    def publish_diagnostics(self) -> None:
        vals = self.diagnostics()
        n_drop = sum(self.dropped.values())
        arr = DiagnosticArray()
        arr.header.stamp = self.get_clock().now().to_msg()
        name = self.get_name()
        arr.status = [make_status(
            f"{name}: fusion",
            f"{self.steps_published} steps, {n_drop} dropped",
            vals.items(),
            warn=bool(n_drop),
        )] + [mon.status(name) for mon in self.inputs.values()]
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
