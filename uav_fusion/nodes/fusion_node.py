"""fusion_node: radar + RF fusion with the core estimator, in timestamp order.

Subscribes ``radar/pose`` (PoseWithCovarianceStamped; reports sharing one stamp form one
radar frame of candidates) and ``rf/fix`` (PointStamped; NaN = failed attempt). Incoming
measurements go through a :class:`~uav_fusion.core.live.reorder.ReorderBuffer` so that the
estimator sees them in the same order as the offline run whatever the arrival order: an
item is released once every input stream has moved past it, or once the watermark (latest
stamp seen, or the simulated clock) is ``reorder_window_s`` beyond it. Items arriving later
than that are dropped and counted (``late_<source>``). At the end of a stream the buffer is
flushed by an idle timer (``idle_flush_s`` of wall time without input), by the
``fusion/flush`` service (std_srvs/Trigger) and on shutdown.

Time faults (duplicates, stamps far ahead, runs of late messages, the simulated clock jumping
back) are handled by :class:`uav_fusion.core.live.timeline.Timeline` with this node's parameters
``max_future_s``, ``late_run_reset`` and ``clock_jump_back_s``; it counts
``<source>_duplicate``, ``<source>_future``, ``clock_jumps_back`` and ``timeline_resets``.

Accounting: for each input stream, ``received_<s>`` = ``used_<s>`` + the sum of
``rejected_<s>_<reason>`` (refused by the estimator: gates, not selected, failed RF
attempts, ...) + the sum of ``dropped_<s>_<reason>`` and ``dropped_late_<s>`` (never
reached the estimator) +
``buffer_pending`` + ``held_<s>`` (the last two are 0 after a flush).

**Tracker profiles** (``association.mode: track_score``, e.g. ``tracker``) run the
:class:`~uav_fusion.core.estimators.tracker.Tracker` instead, on every report of every radar
frame and every RF attempt with its quality: the node subscribes ``radar/tracks`` and
``rf/fixes`` (sensor_msgs/PointCloud2, :mod:`uav_fusion.core.data.clouds`) instead of
``radar/pose`` and ``rf/fix``. Frames and attempts go through the same timeline, so the
tracker sees them in the offline run's order (:func:`uav_fusion.core.estimators.offline.
tracker_stream`); empty frames and failed attempts only move their stream on (offline they
are skipped too). A malformed point is dropped and counted (``dropped_radar_point_<reason>``)
and the message's good points are kept. ``fusion/odom`` then carries the **fixed-rate
output**: at every ``1 / frequency`` epoch the processed time passes, the confirmed track
predicted to the epoch with its covariance (:class:`uav_fusion.core.estimators.grid.StepGrid`, the
function the benchmark scores, so live equals offline), while its last accepted measurement
is at most ``max_coast_s`` old; when the inputs stall for ``stall_timeout_s`` (and nothing is
buffered) the epochs up to the current time (simulated clock, else wall clock; at most
``max_coast_s`` past the last processed time) are published too. ``fusion/odom/updated`` and
``fusion/odom/coasted`` keep one message per filter step (what Table II reads).

Paper profile: publishes, for every filter step, nav_msgs/Odometry on ``fusion/odom`` and
the same message on ``fusion/odom/updated`` or ``fusion/odom/coasted``; for every accepted
measurement the measurement itself on ``fusion/accepted/radar`` or ``fusion/accepted/rf``
(passed every gate, NIS included; a measurement that only started the track is not
"accepted"); and counters on ``/diagnostics`` (tracker profiles add the time since the last
accepted measurement, the followed radar track, its UAV score and probability and the grid
epochs published). Malformed messages (NaN, bad covariance, wrong frame, zero stamp) are
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
from sensor_msgs.msg import NavSatFix, PointCloud2
from std_srvs.srv import Trigger
from visualization_msgs.msg import MarkerArray

from uav_fusion.core.errors import UavFusionError
from uav_fusion.core.estimators import FusionEstimator, Profile, load_profile
from uav_fusion.core.estimators.grid import GridState, StepGrid
from uav_fusion.core.estimators.multi import GridEpoch, MultiGrid, MultiTracker
from uav_fusion.core.estimators.offline import TrackerItem, feed_tracker, tracker_item
from uav_fusion.core.estimators.smoothing import Filtered, FixedLagSmoother
from uav_fusion.core.estimators.tracker import Tracker, TrackerStep, radar_model_from_profile
from uav_fusion.core.live.reorder import Batch, ReorderBuffer
from uav_fusion.core.live.timeline import Timeline, TimelineConfig
from uav_fusion.core.records import RADAR, RF, Measurement, RadarFrame
from uav_fusion.core.site import load_site
from uav_fusion.ros import conversions as cv
from uav_fusion.ros.app import run_node
from uav_fusion.ros.diagnostics import InputMonitor, make_status
from uav_fusion.ros.params import Param, declare_all, not_empty
from uav_fusion.ros.qos import DIAGNOSTICS_QOS, stream_qos
from uav_fusion.ros.visualization import (
    ReportLayer,
    SiteLayer,
    TrackLayer,
    TracksLayer,
    Visualization,
)

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
        topic("radar_tracks_topic", "radar/tracks", "tracker profiles' radar input (PointCloud2)"),
        topic("rf_fixes_topic", "rf/fixes", "RF input of tracker profiles (PointCloud2)"),
        Param(
            "frequency", 10.0, "tracker profiles: rate of the fixed-rate output on fusion/odom",
            lo=0.01, hi=1000.0,
        ),
        Param(
            "stall_timeout_s", 1.0,
            "tracker profiles: wall seconds without input (and nothing buffered) after which "
            "fusion/odom is predicted up to the current time (0 = never)",
            lo=0.0, hi=3600.0, read_only=False,
        ),
        topic("odom_topic", "fusion/odom",
              "every filter step (paper profile) or the fixed-rate output (tracker profiles)"),
        topic("updated_topic", "fusion/odom/updated", "steps that updated (Odometry)"),
        topic("coasted_topic", "fusion/odom/coasted", "steps that coasted (Odometry)"),
        topic("accepted_radar_topic", "fusion/accepted/radar", "accepted radar measurements"),
        topic("accepted_rf_topic", "fusion/accepted/rf", "accepted RF measurements"),
        topic("path_topic", "fusion/path", "the fused track (nav_msgs/Path)"),
        topic("markers_topic", "fusion/markers", "views (visualization_msgs/MarkerArray)"),
        topic("fix_topic", "fusion/fix", "fused position as sensor_msgs/NavSatFix"),
        Param(
            "multi_target", False,
            "tracker profiles: also run the multi-UAV tracker and publish every confirmed "
            "track on tracks_topic",
        ),
        topic("tracks_topic", "fusion/tracks",
              "multi_target: every confirmed track at every grid epoch (Odometry; "
              "child_frame_id 'track_<id>')"),
        topic("smoothed_topic", "fusion/odom/smoothed",
              "profiles with smoother.lag_s: every step, fixed-lag smoothed (Odometry)"),
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
        #: tracker profiles run the Tracker on radar/tracks + rf/fixes with fixed-rate output
        self.tracker_mode = self.profile.uses_tracker
        self.tracker: Tracker | None = None
        self.grid: StepGrid | None = None
        self.estimator: FusionEstimator | None = None
        if self.tracker_mode:
            self.tracker = Tracker(self.profile, self.site)
            self.grid = StepGrid(self.profile, float(self.p["frequency"]))
            self._radar_r = radar_model_from_profile(self.profile, self.site)
            gate = self.profile.range_gate_m
            range_gate = float(gate if gate is not None else self.site.radar.range_gate_m)
        else:
            self.estimator = FusionEstimator(self.profile, self.site)
            range_gate = self.estimator.range_gate_m
        #: grid epochs published on fusion/odom (tracker profiles)
        self.grid_published = 0
        #: radar reports received on radar/tracks, malformed points included (tracker profiles)
        self.received_reports = 0
        # live fixed-lag smoothing (profiles with a finite smoother.lag_s)
        lag = self.profile.smoother_lag_s
        finite = lag is not None and math.isfinite(lag)
        self._smooth_lag = lag if self.tracker_mode and finite else None
        self._smoother: FixedLagSmoother | None = None
        self._smooth_segment = -1
        #: smoothed steps published on fusion/odom/smoothed
        self.smoothed_published = 0
        # every UAV at once (multi_target): the multi-UAV tracker beside the single-UAV one
        self.multi: MultiTracker | None = None
        self.multi_grid: MultiGrid | None = None
        if self.tracker_mode and bool(self.p["multi_target"]):
            self.multi = MultiTracker(self.profile, self.site)
            self.multi_grid = MultiGrid(self.multi, float(self.p["frequency"]))
        #: track messages published on fusion/tracks, and the grid epochs they came from
        self.tracks_published = 0
        self.track_epochs = 0
        self._processed_t = -math.inf
        self._stall_s = float(self.p["stall_timeout_s"])
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
        self.pub_smoothed = pub(Odometry, self.p["smoothed_topic"])
        self.pub_tracks = pub(Odometry, self.p["tracks_topic"])
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
            [SiteLayer(self.site, range_gate), self.report_layer, self.track_layer],
        )
        self.tracks_layer: TracksLayer | None = None
        if self.multi is not None:
            self.tracks_layer = TracksLayer(sigma=float(self.p["covariance_sigma"]))
            self.visualization.add(self.tracks_layer)
        self._views_dirty = True
        self._last_view = -math.inf
        self._last_step: Any = None
        self.paths_published = 0
        self.markers_published = 0
        self.radar_topic = str(
            self.p["radar_tracks_topic"] if self.tracker_mode else self.p["radar_topic"]
        )
        self.rf_topic = str(self.p["rf_fixes_topic"] if self.tracker_mode else self.p["rf_topic"])
        self.inputs = {
            src: InputMonitor(
                topic,
                min_hz=float(self.p["input_min_hz"]),
                max_hz=float(self.p["input_max_hz"]),
                min_delay_s=float(self.p["stamp_delay_min_s"]),
                max_delay_s=float(self.p["stamp_delay_max_s"]),
            )
            for src, topic in ((RADAR, self.radar_topic), (RF, self.rf_topic))
        }
        radar_type: Any = PointCloud2 if self.tracker_mode else PoseWithCovarianceStamped
        rf_type: Any = PointCloud2 if self.tracker_mode else PointStamped
        self._sub_radar = self.create_subscription(
            radar_type, self.radar_topic, self._on_radar, qos
        )
        self._sub_rf = self.create_subscription(rf_type, self.rf_topic, self._on_rf, qos)
        self.create_service(Trigger, self.p["flush_service"], self._on_flush)
        steady = Clock(clock_type=ClockType.STEADY_TIME)
        self._idle_timer = self.create_timer(0.1, self._on_tick, clock=steady)
        self._diag_timer = self.create_timer(
            float(self.p["diagnostics_period_s"]), self.publish_diagnostics, clock=steady
        )
        mode = (
            f", tracker with fixed-rate output at {float(self.p['frequency']):g} Hz"
            if self.tracker_mode
            else ""
        )
        self.get_logger().info(
            f"fusing {self.radar_topic} + {self.rf_topic} with profile "
            f"'{self.profile.name}'{mode}, reorder window {self.buffer.window_s:g} s"
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
            elif par.name == "stall_timeout_s":
                self._stall_s = float(par.value)
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

    def _one_radar(self, msg: Any) -> None:
        if self.tracker_mode:
            self._one_radar_frame(msg)
            return
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

    def _one_rf(self, msg: Any) -> None:
        if self.tracker_mode:
            self._one_rf_fixes(msg)
            return
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

    def _count_points(self, source: str, bad: Counter[str]) -> None:
        for reason, n in sorted(bad.items()):
            self._count_drop(
                source, f"point_{reason}",
                f"dropping {source} point(s) that cannot be measurements ({reason})", n,
            )  # fmt: skip

    def _one_radar_frame(self, msg: PointCloud2) -> None:
        """Tracker profiles: one radar/tracks cloud (every report of one frame)."""
        now, clock = self._now()
        timeline = self.timeline
        timeline.check_clock(clock)
        self._last_input = time.monotonic()
        self.received[RADAR] += 1
        try:
            frame, bad = cv.msg_to_radar_frame(msg, self.frame)
        except cv.MessageError as exc:
            self._tick_input(RADAR, msg, now)
            self._drop(RADAR, exc)
            return
        self._count_points(RADAR, bad)
        self.received_reports += len(frame.tracks) + sum(bad.values())
        self.inputs[RADAR].tick(now - frame.t)
        if not frame.tracks:  # an empty frame only moves the radar stream on
            timeline.admit(RADAR, frame.t, None, clock)
            timeline.release(clock)
            return
        self._seq += 1
        timeline.admit(RADAR, frame.t, tracker_item(frame, self._seq), clock)

    def _one_rf_fixes(self, msg: PointCloud2) -> None:
        """Tracker profiles: one rf/fixes cloud (normally one attempt)."""
        now, clock = self._now()
        timeline = self.timeline
        timeline.check_clock(clock)
        self._last_input = time.monotonic()
        self.received[RF] += 1
        try:
            attempts, bad = cv.msg_to_rf_attempts(msg, self.frame)
        except cv.MessageError as exc:
            self._tick_input(RF, msg, now)
            self._drop(RF, exc)
            return
        self._count_points(RF, bad)
        self.inputs[RF].tick(now - cv.time_from_stamp(msg.header.stamp))
        for a in attempts:
            self._seq += 1
            timeline.admit(RF, a.t, tracker_item(a, self._seq) if a.ok else None, clock)
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

    # --- timeline sink (uav_fusion.core.live.timeline) -------------------------------------------
    def process(self, batches: Sequence[Batch[Measurement]]) -> None:
        self._process(batches)

    def failed_attempt(self, source: str, t: float) -> None:
        if source == RADAR:  # tracker profiles: a frame without reports
            self.refused[f"{source}_empty_frame"] += 1
            return
        self.refused[f"{source}_failed_attempt"] += 1
        self.statuses["rf_failed_attempt"] += 1

    def restart(self, reason: str) -> None:
        if self.estimator is not None:
            self.estimator.restart_timeline(reason)
            return
        # tracker profiles: a new timeline starts from scratch (a bag loop)
        self.tracker = Tracker(self.profile, self.site)
        self.grid = StepGrid(self.profile, float(self.p["frequency"]))
        self._processed_t = -math.inf
        self._smoother = None
        if self.multi is not None:
            self.multi = MultiTracker(self.profile, self.site)
            self.multi_grid = MultiGrid(self.multi, float(self.p["frequency"]))

    def warn(self, text: str) -> None:
        self.get_logger().warning(text)

    def _sim_now(self) -> float | None:
        return self._now()[1]

    # --- processing -----------------------------------------------------------------------
    def _process(self, batches: Sequence[Batch[Measurement]]) -> None:
        if self.tracker_mode:
            self._process_tracker(batches)
            return
        assert self.estimator is not None
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

    def _process_tracker(self, batches: Sequence[Batch[Measurement]]) -> None:
        tracker, grid = self.tracker, self.grid
        assert tracker is not None and grid is not None
        for b in batches:
            for m in b.items:
                item = m.item if isinstance(m, TrackerItem) else None
                if item is None:
                    continue
                if self.multi is not None and self.multi_grid is not None:
                    for ep in self.multi_grid.before(item.t):
                        self._publish_tracks(ep)
                    if isinstance(item, RadarFrame):
                        self.multi.process_radar_frame(item)
                    else:
                        self.multi.process_rf(item)
                for step in feed_tracker(tracker, item):
                    self._publish_tracker_step(step)
                    for gs in grid.feed_step(step):
                        self._publish_grid(gs)
                self._processed_t = max(self._processed_t, b.t)

    def _publish_tracker_step(self, step: TrackerStep) -> None:
        """Counters, views and the per-step topics (updated, coasted, accepted)."""
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
        validated = step.validated
        z = np.asarray(step.z, dtype=float)
        if source == RADAR:
            if z.size == 2:  # horizontal only (beyond the 3D range gate): drawn at the track's
                z = np.append(z, step.values[2])  # height
            self.report_layer.radar(z, validated)
        else:
            self.report_layer.rf_fix(z, updated)
        if self._smooth_lag is not None and step.counted:
            self._smooth(step)
        if not (updated or step.coasted):
            return
        self.steps_published += 1
        v = step.values
        self._path.append((step.t, v[0], v[1], v[2]))
        self._last_step = step
        self._views_dirty = True
        side = self.pub_updated if updated else self.pub_coasted
        if side.get_subscription_count():
            side.publish(cv.odometry_from_values(step.t, v, self.frame, self.child_frame))
        if validated and (source != RADAR or step.dim == 3):
            # (a horizontal-only radar update has no height: not on fusion/accepted/radar)
            self.accepted_published += 1
            if source == RADAR:
                if self.pub_acc_radar.get_subscription_count():
                    r = self._radar_r.r_at(float(z[0]), float(z[1]), float(z[2]))
                    R = np.array([[r[0], r[1], r[2]], [r[1], r[3], r[4]], [r[2], r[4], r[5]]])
                    self.pub_acc_radar.publish(cv.radar_to_msg(step.t, z, R, self.frame))
            elif self.pub_acc_rf.get_subscription_count():
                en = (float(z[0]), float(z[1]))
                self.pub_acc_rf.publish(cv.rf_to_msg(step.t, en, self.frame))

    def _smooth(self, step: TrackerStep) -> None:
        """Feed one estimate of a confirmed track to the fixed-lag smoother (a new one per
        track segment) and publish what became final."""
        assert self._smooth_lag is not None
        if self._smoother is None or step.segment != self._smooth_segment:
            self.finish_smoothing()
            self._smoother = FixedLagSmoother(self._smooth_lag)
            self._smooth_segment = step.segment
        entry = Filtered(step.t, step.x, step.P, step.q_eff)
        for e, xs, Ps in self._smoother.push(entry):
            self._publish_smoothed(e.t, xs, Ps)

    def finish_smoothing(self) -> None:
        """End the current segment's smoothing window: publish its remaining estimates."""
        if self._smoother is not None:
            for e, xs, Ps in self._smoother.finish():
                self._publish_smoothed(e.t, xs, Ps)

    def _publish_smoothed(self, t: float, x: Any, P: Any) -> None:
        self.smoothed_published += 1
        if self.pub_smoothed.get_subscription_count():
            self.pub_smoothed.publish(cv.state_to_odometry(t, x, P, self.frame, self.child_frame))

    def _publish_tracks(self, ep: GridEpoch) -> None:
        """One grid epoch of the multi-UAV tracker: every confirmed track on fusion/tracks."""
        self.track_epochs += 1
        if self.tracks_layer is not None:
            self.tracks_layer.update(
                (o.track_id, o.x[:3].tolist(), o.P[:3, :3].tolist(), o.uav_prob) for o in ep.tracks
            )
            self._views_dirty = True
        if not ep.tracks:
            return
        self.tracks_published += len(ep.tracks)
        if self.pub_tracks.get_subscription_count():
            for o in ep.tracks:
                self.pub_tracks.publish(
                    cv.state_to_odometry(ep.t, o.x, o.P, self.frame, f"track_{o.track_id}")
                )

    def _publish_grid(self, gs: GridState) -> None:
        """One epoch of the fixed-rate output (nothing without a published track)."""
        if not gs.published:
            return
        self.grid_published += 1
        if self.pub_odom.get_subscription_count():
            self.pub_odom.publish(
                cv.state_to_odometry(gs.t, gs.x, gs.P, self.frame, self.child_frame)
            )
        if self.pub_fix.get_subscription_count():
            v = (*gs.x.tolist(), *(gs.P[i, j] for i in range(6) for j in range(i, 6)))
            self.pub_fix.publish(self._fix(gs.t, v))

    def advance_output(self, t: float) -> int:
        """Tracker profiles: publish the fixed-rate epochs up to ``t`` (inputs stalled);
        returns the number published. Only forward from the last processed time, and at
        most ``max_coast_s`` (60 s without a limit) beyond it."""
        grid = self.grid
        if grid is None or not math.isfinite(self._processed_t):
            return 0
        cap = self.profile.max_coast_s if self.profile.max_coast_s is not None else 60.0
        target = min(t, self._processed_t + cap)
        if target <= self._processed_t:
            return 0
        before = self.grid_published
        for gs in grid.advance(target):
            self._publish_grid(gs)
        if self.multi_grid is not None:
            for ep in self.multi_grid.advance(target):
                self._publish_tracks(ep)
        return self.grid_published - before

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
        if self._smooth_lag is not None:
            self.finish_smoothing()
            self._smoother = None
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
        stall = self._stall_s
        if (
            self.tracker_mode
            and stall > 0
            and not (self.timeline.pending or self.timeline.holding)
            and time.monotonic() - self._last_input >= stall
        ):
            self.advance_output(self._now()[0])
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
        if self.tracker is not None:
            vals.update(self._tracker_diagnostics())
        counters = getattr(self.estimator or self.tracker, "counters", None)
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

    def _tracker_diagnostics(self) -> dict[str, Any]:
        tr = self.tracker
        assert tr is not None
        out: dict[str, Any] = {"grid_published": self.grid_published}
        if self.multi is not None:
            confirmed = [t for t in self.multi.tracks if t.confirmed]
            out["multi_tracks_confirmed"] = len(confirmed)
            out["multi_track_ids"] = " ".join(str(t.id) for t in confirmed) or "-"
            out["tracks_published"] = self.tracks_published
        out["received_radar_reports"] = self.received_reports
        best = tr.best_track()
        ref = self._processed_t
        if best is None:
            out["track"] = "tentative" if tr.active else "none"
            return out
        out["track"] = "confirmed"
        if best.last_update_t is not None and math.isfinite(ref):
            out["since_last_accepted_s"] = f"{ref - best.last_update_t:.3f}"
        last_3d = tr.last_3d_t  # when the height was last measured (radar in 3D)
        if self.multi is None and math.isfinite(ref):
            out["since_last_3d_radar_s"] = "-" if last_3d is None else f"{ref - last_3d:.3f}"
        obj = tr.objects.objects.get(best.radar_object) if best.radar_object is not None else None
        if obj is not None:
            score = obj.score(tr.cfg)
            out["followed_radar_track"] = obj.id
            out["uav_score"] = f"{score:.3f}"
            out["uav_probability"] = f"{1.0 / (1.0 + math.exp(-max(-30.0, min(30.0, score)))):.3f}"
        return out

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
