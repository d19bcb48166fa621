"""fusion_node: radar + RF fusion with the profile's estimator, in timestamp order.

The node only wires three parts together:

- :mod:`uav_fusion.ros.fusion_input`: each message to core records, with its checks and
  drop accounting (the inputs depend on what the estimator reads: ``radar/pose`` + ``rf/fix``
  for the paper's filter, ``radar/tracks`` + ``rf/fixes`` for the trackers);
- :mod:`uav_fusion.core.live.pipeline`: time order (zero wait with late data re-filtered, or
  a reorder window; duplicates, future stamps, clock jumps), then the estimator
  (:mod:`uav_fusion.core.estimators.base`: the profile's ``estimator``, or the ``estimator``
  parameter);
- :mod:`uav_fusion.ros.fusion_output`: publishers, views and diagnostics.

Timers: a 0.1 s tick follows the simulated clock, flushes the buffer after ``idle_flush_s`` of
wall time without input, predicts the fixed-rate output up to the current time when the
inputs stall for ``stall_timeout_s`` (at most ``max_coast_s`` past the last processed time)
and publishes the views every ``view_period_s``; diagnostics every ``diagnostics_period_s``.
With ``output_delay_s`` >= 0 a 10 ms timer publishes every fixed-rate epoch once the sensor
time is that far past it. The sensor time, for both, comes from the node's clock and the
stamps of the recent inputs (:mod:`~uav_fusion.core.live.sensor_clock`). Each such move of
the output is a ``clock`` row of the arrival schedule. The ``fusion/flush`` service
(std_srvs/Trigger) flushes the buffer, as does shutdown.
"""

from __future__ import annotations

import math
import sys
import time
from collections import Counter, deque
from collections.abc import Sequence
from typing import Any

from rclpy.clock import Clock
from rclpy.clock_type import ClockType
from rclpy.node import Node
from rclpy.parameter import Parameter
from std_srvs.srv import Trigger

from uav_fusion.core.estimators import ESTIMATORS, Estimator, load_profile, make_estimator
from uav_fusion.core.estimators.grid import Outputs
from uav_fusion.core.live.pipeline import Pipeline, PipelineConfig
from uav_fusion.core.live.schedule import CLOCK
from uav_fusion.core.live.sensor_clock import SensorClock
from uav_fusion.core.records import RADAR, RF
from uav_fusion.core.site import load_site
from uav_fusion.ros.app import run_node
from uav_fusion.ros.conversions import ns_to_time
from uav_fusion.ros.fusion_input import ArrivalLog, FusionInput, InputTopics
from uav_fusion.ros.fusion_output import FusionOutput, OutputTopics, ViewSettings
from uav_fusion.ros.params import Param, declare_all, positive, topic_param
from uav_fusion.ros.qos import stream_qos

NODE_NAME = "fusion_node"
#: most messages taken from one input in one go (bounds the time other callbacks wait)
DRAIN_MAX = 500


def _stamp_key(msg: Any) -> tuple[int, int]:
    st = msg.header.stamp
    return st.sec, st.nanosec


def fusion_params() -> list[Param]:
    topic = topic_param  # a topic name: must not be empty
    return [
        Param("profile", "paper", "estimator profile: a name under config/profiles or a path"),
        Param("site_file", "", "site YAML ('' = bundled Lake Wheeler site)"),
        Param("world_frame", "", "frame of inputs and outputs ('' = the site's frame_id)"),
        topic("child_frame_id", "uav", "child frame id of the published Odometry"),
        topic("radar_topic", "radar/pose",
              "the paper estimator's radar input (PoseWithCovarianceStamped)"),
        topic("rf_topic", "rf/fix", "the paper estimator's RF input (PointStamped; NaN = failed)"),
        topic("radar_tracks_topic", "radar/tracks", "the trackers' radar input (PointCloud2)"),
        topic("rf_fixes_topic", "rf/fixes", "the trackers' RF input (PointCloud2)"),
        Param(
            "frequency", 10.0, "the trackers: rate of the fixed-rate output on fusion/odom",
            lo=0.01, hi=1000.0,
        ),
        Param(
            "stall_timeout_s", 1.0,
            "the trackers: wall seconds without input (and nothing buffered) after which "
            "fusion/odom is predicted up to the current time (0 = never)",
            lo=0.0, hi=3600.0, read_only=False,
        ),
        Param(
            "output_delay_s", -1.0,
            "the trackers: publish each fusion/odom epoch once the sensor time, as the node's "
            "clock and the inputs' stamps put it now, is this many seconds past it, without "
            "waiting for the next input (< 0 = off: an epoch is published when an input moves "
            "time past it)",
            lo=-1.0, hi=60.0,
        ),
        topic("odom_topic", "fusion/odom",
              "every filter step (paper) or the fixed-rate output (the trackers)"),
        topic("updated_topic", "fusion/odom/updated", "steps that updated (Odometry)"),
        topic("coasted_topic", "fusion/odom/coasted", "steps that coasted (Odometry)"),
        topic("accepted_radar_topic", "fusion/accepted/radar", "accepted radar measurements"),
        topic("accepted_rf_topic", "fusion/accepted/rf", "accepted RF measurements"),
        topic("path_topic", "fusion/path", "the fused track (nav_msgs/Path)"),
        topic("markers_topic", "fusion/markers", "views (visualization_msgs/MarkerArray)"),
        topic("fix_topic", "fusion/fix", "fused position as sensor_msgs/NavSatFix"),
        Param(
            "estimator", "",
            "the estimator: '' = the profile's own ('estimator' key), or paper, tracker or "
            "multi (every confirmed track on tracks_topic)",
            choices=("", *ESTIMATORS),
        ),
        topic("tracks_topic", "fusion/tracks",
              "estimator multi: every confirmed track at every grid epoch (Odometry; "
              "child_frame_id 'track_<id>')"),
        topic("smoothed_topic", "fusion/odom/smoothed",
              "profiles with a finite smoother.lag_s: every step, fixed-lag smoothed"),
        topic("flush_service", "fusion/flush", "std_srvs/Trigger: flush the reorder buffer"),
        Param(
            "reorder_window_s", 0.0,
            "0: fuse every measurement the moment it arrives, a late one by rewinding and "
            "re-filtering (max_lag_s); > 0: hold measurements this many sensor seconds to "
            "process them in order without rewinding",
            lo=0.0, hi=3600.0,
        ),
        Param(
            "max_lag_s", 10.0,
            "reorder_window_s 0: sensor seconds a measurement may arrive late and still be "
            "fused exactly (older: dropped as late); > 0",
            lo=0.0, hi=3600.0, check=positive,
        ),
        Param(
            "arrivals_file", "",
            "write the arrival schedule here (CSV source,stamp,arrival; '' = none): "
            "uav_fusion run --arrivals reproduces the node's outputs from it",
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
            "this many messages in a row that are late (max_lag_s or the reorder window) or "
            "repeats mean the input timeline went back: reset the filter and the buffer "
            "(0 = never)",
            lo=0, hi=1000000,
        ),
        Param(
            "clock_jump_back_s", 1.0,
            "a backwards jump of the simulated clock larger than this resets the filter",
            lo=0.0, hi=1.0e9,
        ),
    ]


class FusionNode(Node):
    """Wires :class:`FusionInput`, :class:`Pipeline` and :class:`FusionOutput` (see the
    module text)."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(NODE_NAME, **kwargs)
        p = self.p = declare_all(self, fusion_params())
        self.site = load_site(p["site_file"] or None)
        self.profile = load_profile(p["profile"])
        estimator = make_estimator(
            self.profile, self.site, float(p["frequency"]), kind=p["estimator"] or None, live=True
        )
        frame = str(p["world_frame"] or self.site.frame_id)
        warn = self.get_logger().warning
        self.input = FusionInput(
            estimator.reads, frame,
            InputTopics(p["radar_topic"], p["rf_topic"], p["radar_tracks_topic"],
                        p["rf_fixes_topic"]),
            warn,
            use_message_covariance=bool(p["use_message_covariance"]),
            arrivals=ArrivalLog(p["arrivals_file"]) if p["arrivals_file"] else None,
            monitor={"min_hz": float(p["input_min_hz"]), "max_hz": float(p["input_max_hz"]),
                     "min_delay_s": float(p["stamp_delay_min_s"]),
                     "max_delay_s": float(p["stamp_delay_max_s"])},
        )  # fmt: skip
        self.pipeline = Pipeline(
            estimator,
            PipelineConfig(
                reorder_window_s=float(p["reorder_window_s"]),
                max_lag_s=float(p["max_lag_s"]),
                max_future_s=float(p["max_future_s"]),
                late_run_reset=int(p["late_run_reset"]),
                clock_jump_back_s=float(p["clock_jump_back_s"]),
            ),
            warn,
        )
        gate = self.profile.range_gate_m
        qos = stream_qos(int(p["qos_depth"]))
        self.output = FusionOutput(
            self, self.pipeline, self.site, frame, str(p["child_frame_id"]),
            OutputTopics(p["odom_topic"], p["updated_topic"], p["coasted_topic"],
                         p["accepted_radar_topic"], p["accepted_rf_topic"], p["fix_topic"],
                         p["smoothed_topic"], p["tracks_topic"], p["path_topic"],
                         p["markers_topic"]),
            qos,
            ViewSettings(int(p["path_max_poses"]), int(p["marker_history"]),
                         float(p["covariance_sigma"]),
                         float(gate if gate is not None else self.site.radar.range_gate_m)),
        )  # fmt: skip
        # parameters read per message are cached and kept current by a post-set callback
        self._sim = bool(self.get_parameter("use_sim_time").value)
        self._idle_s = float(p["idle_flush_s"])
        self._stall_s = float(p["stall_timeout_s"])
        self._out_delay = float(p["output_delay_s"])
        self._sensor_clock = SensorClock()
        self._view_period = float(p["view_period_s"])
        self.add_post_set_parameters_callback(self._after_params)
        self._ros_clock = self.get_clock()
        self._last_input = time.monotonic()
        inp = self.input
        self._sub_radar = self.create_subscription(
            inp.radar_type, inp.radar_topic, self._on_radar, qos
        )
        self._sub_rf = self.create_subscription(inp.rf_type, inp.rf_topic, self._on_rf, qos)
        self.create_service(Trigger, p["flush_service"], self._on_flush)
        steady = Clock(clock_type=ClockType.STEADY_TIME)
        self._tick_timer = self.create_timer(0.1, self._on_tick, clock=steady)
        if self._out_delay >= 0.0 and estimator.fixed_rate:
            self._clock_timer = self.create_timer(0.01, self._on_clock, clock=steady)
        self._diag_timer = self.create_timer(
            float(p["diagnostics_period_s"]), self.publish_diagnostics, clock=steady
        )
        hz = float(p["frequency"])
        mode = f", fixed-rate output at {hz:g} Hz" if estimator.fixed_rate else ""
        order = (
            f"zero wait (late data re-filtered up to {float(p['max_lag_s']):g} s)"
            if self.pipeline.rewinder is not None
            else f"reorder window {self.pipeline.buffer.window_s:g} s"
        )
        self.get_logger().info(
            f"fusing {inp.radar_topic} + {inp.rf_topic} with profile '{self.profile.name}' "
            f"(estimator {estimator.kind}{mode}), {order}"
        )

    # --- what tests and tools read --------------------------------------------------------
    @property
    def input_topics(self) -> tuple[str, str]:
        """The radar and RF topics the node subscribes to, resolved (``/radar/pose``, ...)."""
        return self._sub_radar.topic_name, self._sub_rf.topic_name

    @property
    def received(self) -> Counter[str]:
        """Messages received per source."""
        return self.input.received

    @property
    def dropped(self) -> Counter[str]:
        """Every drop by ``<source>_<reason>`` (and ``late_<source>``)."""
        return self.input.dropped + self.pipeline.dropped

    @property
    def estimator(self) -> Estimator:
        """The estimator (zero wait: the one the latest rewind went back to)."""
        return self.pipeline.estimator

    @property
    def steps_published(self) -> int:
        return self.output.steps_published

    def diagnostics(self) -> dict[str, str]:
        """The counters published on /diagnostics, as key -> text."""
        return self.output.diagnostics(self.input, self.pipeline)

    def publish_diagnostics(self) -> None:
        self.output.publish_diagnostics(self.input, self.pipeline)

    # --- input ----------------------------------------------------------------------------
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

    def _now(self) -> tuple[float, float | None]:
        """(node clock now in seconds, the simulated clock or None)."""
        ns = self._ros_clock.now().nanoseconds
        now = ns_to_time(ns)
        return now, (now if self._sim and ns > 0 else None)

    def _on_radar(self, msg: Any) -> None:
        self._take_all(RADAR, msg)

    def _on_rf(self, msg: Any) -> None:
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
        self._last_input = time.monotonic()
        out = Outputs()
        while radar or rf:
            if rf and (not radar or _stamp_key(rf[0]) < _stamp_key(radar[0])):
                out.add(self._one(RF, rf.popleft()))
            else:
                out.add(self._one(RADAR, radar.popleft()))
        self.output.publish(out)

    def _one(self, source: str, msg: Any) -> Outputs:
        """One message: decoded (or dropped), then through the pipeline."""
        now, clock = self._now()
        pipe = self.pipeline
        if source == RADAR:
            frame = self.input.radar(msg, now)
            if frame is None:
                return Outputs()
            out, t = pipe.radar(frame, clock), frame.t
        else:
            attempts = self.input.rf(msg, now)
            if attempts is None:
                return Outputs()
            out = pipe.rf(attempts, clock)
            t = max((a.t for a in attempts), default=math.inf)
        if t <= pipe.processed_t:  # fused (not held, not dropped as ahead of time)
            self._sensor_clock.observe(t, now)
        return out

    # --- time passing ---------------------------------------------------------------------
    def flush(self) -> int:
        """Process everything held in the reorder buffer and finish the smoothing windows;
        returns the number of measurements processed. Stamps held back as too far ahead
        (unconfirmed) are dropped as ``future``."""
        n = self.pipeline.pending
        self.output.publish(self.pipeline.flush())
        self.output.publish_views()
        return n

    def _on_flush(self, _req: Trigger.Request, resp: Trigger.Response) -> Trigger.Response:
        n = self.flush()
        resp.success = True
        resp.message = (
            f"flushed {n} measurement(s); {self.output.steps_published} steps published"
        )
        return resp

    def _on_tick(self) -> None:
        now, clock = self._now()
        pipe = self.pipeline
        self.output.publish(pipe.tick(clock))
        quiet_s = time.monotonic() - self._last_input
        if self._idle_s > 0 and (pipe.pending or pipe.holding) and quiet_s >= self._idle_s:
            n = self.flush()
            self.get_logger().info(f"no input for {self._idle_s:g} s: flushed {n} measurement(s)")
        if self._stall_s > 0 and quiet_s >= self._stall_s:
            self._move_output(self._sensor_clock.at(now))
        if time.monotonic() - self.output.last_view >= self._view_period:
            self.output.publish_views()

    def _on_clock(self) -> None:
        """output_delay_s: the fixed-rate output up to the sensor time now, less the delay."""
        if self._sensor_clock.known:
            now, _ = self._now()
            self._move_output(self._sensor_clock.at(now) - self._out_delay)

    def _move_output(self, t: float) -> None:
        """The fixed-rate output moved on to ``t`` without input; the arrival schedule
        records it, so that an offline run publishes the same epochs at the same point."""
        out, moved = self.pipeline.stall(t)
        if moved is None:
            return
        arrivals = self.input.arrivals
        if arrivals is not None and (out.grid or out.tracks):
            arrivals.add(CLOCK, moved)
        self.output.publish(out)

    def destroy_node(self) -> None:
        try:
            if (self.pipeline.pending or self.pipeline.holding) and self.context.ok():
                self.flush()
        finally:
            if self.input.arrivals is not None:
                self.input.arrivals.close()
            super().destroy_node()


def main(args: Sequence[str] | None = None) -> int:
    return run_node(FusionNode, args, name=NODE_NAME)


if __name__ == "__main__":
    sys.exit(main())
