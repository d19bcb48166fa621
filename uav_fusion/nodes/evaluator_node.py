"""evaluator_node: keeps the paper's Table II live and writes the evaluation report.

Subscribes (topic names are parameters; defaults from docs/graph.md):

- ``truth/fix`` (sensor_msgs/NavSatFix): RTK truth, converted to ENU with the site file;
- ``radar/raw`` (geometry_msgs/PoseWithCovarianceStamped): every UAV-class radar report;
- ``rf/fix`` (geometry_msgs/PointStamped): every RF attempt, failed ones as x = y = z = NaN;
- ``fusion/accepted/radar``, ``fusion/accepted/rf``: the measurements the filter accepted;
- ``fusion/odom/updated``, ``fusion/odom/coasted`` (nav_msgs/Odometry): the filter's steps;
- with ``grid_topic`` set (e.g. ``fusion/odom`` of a tracker profile): the fixed-rate output,
  scored on its grid (``grid_hz``) like the accuracy benchmark
  (:mod:`uav_fusion.core.scoring.fixed_rate`: coverage of the airborne epochs, error mean /
  p95 / max, gross share, ANEES);
  the figures go into the report's header and metrics.json. A message off the grid is
  counted (``off_grid``) and not scored;
- with ``tracks_topic`` set (``fusion/tracks`` of a fusion node running the multi-UAV
  estimator): every confirmed track at every epoch of its grid (``tracks_hz``; Odometry,
  ``child_frame_id`` ``track_<id>``), scored as a set against every UAV's truth on
  ``truth/<vehicle>/fix`` (the vehicles listed in ``vehicles``, or, with ``vehicles`` empty,
  every such topic the node discovers) like the multi-UAV benchmark
  (:mod:`uav_fusion.core.scoring.gospa`: GOSPA with p 2, c 100 m, alpha 2; per-UAV coverage,
  errors, ID switches; false-track seconds). The epochs from the first truth sample to the
  last one (the report), or to the last track message (the periodic log and /diagnostics),
  are scored; an epoch without a message has no track.

Every message goes into a :class:`uav_fusion.core.scoring.evaluation.Evaluator` (the
fixed-rate output and the tracks are kept as received and scored by
:mod:`uav_fusion.core.scoring.published`); nothing is scored on arrival, so estimates that
arrive before the truth bracketing them are scored exactly once the report is made.
Malformed messages (NaN, wrong frame, zero stamp, bad covariance) are counted by topic and
reason and dropped. Every ``log_period_s`` the node logs a summary line and publishes the
rows on ``/diagnostics``. The report (report.md, metrics.csv,
metrics.json, figures) is written to ``output_dir`` when the ``~/write_report`` service
(std_srvs/Trigger) is called and, if ``write_on_shutdown`` is true, when the node stops.

Faults: per topic, ``received`` = ``used`` + ``refused`` (the Evaluator's own drops) +
``dropped`` (malformed messages, by reason); all three are on ``/diagnostics`` and in the
report. Gaps between fused steps longer than ``step_gap_s`` (a fusion node that stopped or
restarted) are listed in the report and on ``/diagnostics``. A backwards jump of the
simulated clock by more than ``clock_jump_back_s`` (a bag loop) writes the report of the
finished timeline to ``<output_dir>/before_clock_jump_<k>``, restarts the evaluation and
logs a warning.
"""

from __future__ import annotations

import math
import re
import sys
import threading
from collections import Counter
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, TypeVar

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PointStamped, PoseWithCovarianceStamped
from nav_msgs.msg import Odometry
from rclpy.clock import Clock
from rclpy.clock_type import ClockType
from rclpy.node import Node
from rclpy.qos import QoSProfile
from sensor_msgs.msg import NavSatFix
from std_srvs.srv import Trigger

from uav_fusion.core.errors import UavFusionError
from uav_fusion.core.scoring.evaluation import COASTED, UPDATED, Evaluation, Evaluator, rows_summary
from uav_fusion.core.scoring.fixed_rate import GridScore, on_grid
from uav_fusion.core.scoring.outcomes import MultiScore, multi_summary
from uav_fusion.core.scoring.published import (
    gap_text,
    rcs_key,
    rcs_lookup,
    score_published_grid,
    score_published_tracks,
    step_gaps,
)
from uav_fusion.core.scoring.report import ReportFiles, write_report
from uav_fusion.core.site import Site, load_site
from uav_fusion.ros.app import run_node
from uav_fusion.ros.conversions import (
    MessageError,
    is_failed_rf,
    msg_to_radar_measurement,
    msg_to_rf_measurement,
    navsatfix_to_truth,
    time_from_stamp,
)
from uav_fusion.ros.diagnostics import evaluation_statuses, make_status, tracks_status
from uav_fusion.ros.odometry import odometry_to_state
from uav_fusion.ros.params import Param, declare_all, not_empty
from uav_fusion.ros.qos import stream_qos

M = TypeVar("M")

NODE_NAME = "evaluator_node"
#: a vehicle's truth topic, and a track's child frame on tracks_topic
VEHICLE_TOPIC = re.compile(r"^/?truth/(?P<vehicle>[A-Za-z0-9][A-Za-z0-9-]*)/fix$")
TRACK_FRAME = re.compile(r"^track_(?P<id>\d+)$")
#: wall seconds the stop (writing the report with its figures) and teardown may take
REPORT_GRACE_S = 120.0

PARAMS: tuple[Param, ...] = (
    Param("site_file", "", "site YAML ('' = the shipped site)"),
    Param("truth_topic", "truth/fix", "RTK truth (NavSatFix)", check=not_empty),
    Param("radar_raw_topic", "radar/raw", "every UAV-class radar report", check=not_empty),
    Param("rf_topic", "rf/fix", "every RF attempt (failed = NaN point)", check=not_empty),
    Param("accepted_radar_topic", "fusion/accepted/radar", "accepted radar measurements",
          check=not_empty),
    Param("accepted_rf_topic", "fusion/accepted/rf", "accepted RF measurements",
          check=not_empty),
    Param("odom_updated_topic", "fusion/odom/updated", "updated steps (Odometry)",
          check=not_empty),
    Param("odom_coasted_topic", "fusion/odom/coasted", "coasted steps (Odometry)",
          check=not_empty),
    Param("frame_id", "", "expected ENU frame of the estimates ('' = the site's frame_id)"),
    Param("output_dir", "out/report", "report folder", check=not_empty, read_only=False),
    Param("coverage_tolerance_s", 1.0, "age limit of a sample for the time coverage (s)",
          lo=0.0, hi=3600.0),
    Param("max_truth_gap_s", 2.0, "longest truth gap interpolated across (s)", lo=1e-3,
          hi=3600.0),
    Param("log_period_s", 5.0, "wall-clock period of the summary log and /diagnostics (s; 0 = off)",
          lo=0.0, hi=3600.0),
    Param("write_on_shutdown", True, "write the report when the node stops", read_only=False),
    Param("figures", True, "draw the PNG figures", read_only=False),
    Param("qos_depth", 1000, "subscription queue depth", lo=1, hi=1_000_000),
    Param("flight_name", "", "flight name written into the report", read_only=False),
    Param("step_gap_s", 10.0, "gaps between fused steps longer than this are reported (s)",
          lo=1e-3, hi=1e9),
    Param("rcs_flight_dir", "",
          "flight folder whose radar file supplies each raw report's RCS for the RCS "
          "histogram (standard pose messages carry no RCS); '' = no RCS"),
    Param("grid_topic", "",
          "fixed-rate output to score on its grid ('' = none; fusion/odom of tracker profiles)"),
    Param("grid_hz", 10.0, "rate of grid_topic (the fusion node's frequency)", lo=0.01,
          hi=1000.0),
    Param("tracks_topic", "",
          "every confirmed track of the multi-UAV tracker to score as a set ('' = none; "
          "fusion/tracks)"),
    Param("tracks_hz", 10.0, "rate of tracks_topic (the fusion node's frequency)", lo=0.01,
          hi=1000.0),
    Param("vehicles", "",
          "comma-separated UAV names whose truth/<vehicle>/fix topics score tracks_topic "
          "('' = every such topic discovered)"),
    Param("clock_jump_back_s", 1.0,
          "a backwards jump of the simulated clock larger than this restarts the evaluation",
          lo=0.0, hi=1e9),
)


class EvaluatorNode(Node):
    """Feeds an :class:`Evaluator` from the live graph and writes the report on request."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(NODE_NAME, **kwargs)
        v = declare_all(self, PARAMS)
        site_file = str(v["site_file"])
        self.truth_topic = str(v["truth_topic"])
        self.radar_raw_topic = str(v["radar_raw_topic"])
        self.rf_topic = str(v["rf_topic"])
        self.accepted_radar_topic = str(v["accepted_radar_topic"])
        self.accepted_rf_topic = str(v["accepted_rf_topic"])
        self.updated_topic = str(v["odom_updated_topic"])
        self.coasted_topic = str(v["odom_coasted_topic"])
        self.grid_topic = str(v["grid_topic"])
        self.grid_hz = float(v["grid_hz"])
        self.tracks_topic = str(v["tracks_topic"])
        self.tracks_hz = float(v["tracks_hz"])
        listed = [x.strip() for x in str(v["vehicles"]).split(",") if x.strip()]
        bad = [x for x in listed if VEHICLE_TOPIC.match(f"truth/{x}/fix") is None]
        if bad:
            raise UavFusionError(
                f"{NODE_NAME}: bad parameters: vehicles: {', '.join(map(repr, bad))} are not "
                "vehicle names (letters, digits and '-')"
            )
        self.vehicles_listed = listed
        # multi-target scoring: (t, track id, state) per track message, truth per vehicle
        self._tracks: list[tuple[float, int, Any]] = []
        self._vehicle_truth: dict[str, list[tuple[float, float, float, float]]] = {}
        # the fixed-rate output received (t, x, P) and the truth's height (t, h) for scoring it
        self._grid: list[tuple[float, Any, Any]] = []
        self._truth_h: list[tuple[float, float, float, float, float]] = []
        frame = str(v["frame_id"])
        self.output_dir = Path(str(v["output_dir"]))
        tolerance = float(v["coverage_tolerance_s"])
        max_gap = float(v["max_truth_gap_s"])
        self.log_period_s = float(v["log_period_s"])
        self.write_on_shutdown = bool(v["write_on_shutdown"])
        self.figures = bool(v["figures"])
        depth = int(v["qos_depth"])
        self.flight_name = str(v["flight_name"])

        self._tolerance, self._max_gap = tolerance, max_gap
        self.step_gap_s = float(v["step_gap_s"])
        self.clock_jump_back_s = float(v["clock_jump_back_s"])
        try:
            self.site: Site = load_site(site_file or None)
            self.evaluator = self._new_evaluator()
            self._rcs = rcs_lookup(str(v["rcs_flight_dir"]), self.site)
        except (UavFusionError, ValueError) as exc:
            raise UavFusionError(f"{NODE_NAME}: bad parameters: {exc}") from None
        self.frame_id = frame or self.site.frame_id
        self.dropped: Counter[str] = Counter()
        self.received: Counter[str] = Counter()
        self.used: Counter[str] = Counter()
        self.refused: Counter[str] = Counter()
        self.clock_jumps_back = 0
        self._last_clock: float | None = None
        self._lock = threading.Lock()
        self.last_report: ReportFiles | None = None

        self._qos = stream_qos(depth)
        self._subscribe_inputs(self._qos)
        self.diag_pub = self.create_publisher(DiagnosticArray, "/diagnostics", 10)
        self.create_service(Trigger, "~/write_report", self._on_write_report)
        self._logged_at = -1
        if self.log_period_s > 0 and math.isfinite(self.log_period_s):
            # wall-clock period: at 40x replay a sim-time period would flood the console
            self.create_timer(
                self.log_period_s, self._on_timer, clock=Clock(clock_type=ClockType.STEADY_TIME)
            )
        self.create_timer(0.2, self._check_clock, clock=Clock(clock_type=ClockType.STEADY_TIME))
        self.get_logger().info(
            f"scoring against truth on '{self.truth_topic}' in frame '{self.frame_id}'; "
            f"report -> {self.output_dir} (service ~/write_report)"
        )

    def _subscribe_inputs(self, qos: QoSProfile) -> None:
        """Every input topic (module text); with ``tracks_topic``, the listed vehicles' truth,
        or a timer that subscribes each vehicle's truth topic as it appears."""
        self.create_subscription(NavSatFix, self.truth_topic, self._on_truth, qos)
        self.create_subscription(
            PoseWithCovarianceStamped, self.radar_raw_topic, self._on_radar_raw, qos
        )
        self.create_subscription(PointStamped, self.rf_topic, self._on_rf, qos)
        self.create_subscription(
            PoseWithCovarianceStamped, self.accepted_radar_topic, self._on_accepted_radar, qos
        )
        self.create_subscription(PointStamped, self.accepted_rf_topic, self._on_accepted_rf, qos)
        self.create_subscription(Odometry, self.updated_topic, self._on_updated, qos)
        self.create_subscription(Odometry, self.coasted_topic, self._on_coasted, qos)
        if self.grid_topic:
            self.create_subscription(Odometry, self.grid_topic, self._on_grid, qos)
        if self.tracks_topic:
            self.create_subscription(Odometry, self.tracks_topic, self._on_tracks, qos)
            for name in self.vehicles_listed:
                self._subscribe_vehicle(name)
            if not self.vehicles_listed:
                self.create_timer(
                    0.5, self._discover_vehicles, clock=Clock(clock_type=ClockType.STEADY_TIME)
                )

    def _new_evaluator(self) -> Evaluator:
        return Evaluator(
            radar_enu=self.site.radar.enu,
            tolerance_s=self._tolerance,
            max_truth_gap_s=self._max_gap,
        )

    def _check_clock(self) -> None:
        """A backwards jump of the simulated clock (bag loop): report and start over."""
        if not self.get_parameter("use_sim_time").value:
            return
        ns = self.get_clock().now().nanoseconds
        if ns <= 0:
            return
        now = ns / 1e9
        last, self._last_clock = self._last_clock, now
        if last is None or last - now <= self.clock_jump_back_s:
            return
        self.clock_jumps_back += 1
        k = self.clock_jumps_back
        where = "not written"
        try:
            files = self.write_report(self.output_dir / f"before_clock_jump_{k}")
            where = str(files.folder)
        except (UavFusionError, OSError) as exc:
            where = f"not written ({exc})"
        with self._lock:
            self.evaluator = self._new_evaluator()
            self._grid.clear()
            self._truth_h.clear()
            self._tracks.clear()
            for rows in self._vehicle_truth.values():
                rows.clear()
        self.get_logger().warning(
            f"simulated clock jumped back {last - now:.3f} s (from {last:.3f} to {now:.3f}; a "
            f"bag loop?): evaluation restarted; report of the finished timeline: {where}"
        )

    # --- input -----------------------------------------------------------------------------
    def _guard(self, topic: str, fn: Callable[[M], bool], msg: M) -> None:
        """Run one message's conversion + feed; count and drop anything malformed."""
        self._check_clock()
        self.received[topic] += 1
        try:
            with self._lock:
                kept = fn(msg)  # a refusal is counted, by reason, in the Evaluator's drops
            (self.used if kept else self.refused)[topic] += 1
        except MessageError as exc:
            self.dropped[f"{topic}: {exc.reason}"] += 1
        except (ValueError, TypeError, OverflowError, IndexError) as exc:
            self.dropped[f"{topic}: {type(exc).__name__}"] += 1

    def _check_frame(self, frame_id: str) -> None:
        if frame_id != self.frame_id:
            raise MessageError("wrong_frame", f"frame '{frame_id}', expected '{self.frame_id}'")

    def _truth(self, msg: NavSatFix) -> bool:
        fix = navsatfix_to_truth(msg, self.site)
        kept = self.evaluator.add_truth(fix.t, fix.e, fix.n, fix.u)
        if kept and self.grid_topic:
            self._truth_h.append((fix.t, fix.e, fix.n, fix.u, fix.h))
        return kept

    def _grid_state(self, msg: Odometry) -> bool:
        self._check_frame(msg.header.frame_id)
        s = odometry_to_state(msg)
        if s.t == 0.0:
            raise MessageError("zero_stamp", "message has no stamp (0)")
        if not on_grid(s.t, self.grid_hz):
            raise MessageError("off_grid", f"stamp {s.t:.6f} is not a {self.grid_hz:g} Hz epoch")
        self._grid.append((s.t, s.x, s.P))
        return True

    def grid_score(self) -> GridScore | None:
        """The fixed-rate output received so far, scored on its grid against the truth
        (None without ``grid_topic`` or without truth)."""
        with self._lock:
            truth = list(self._truth_h)
            grid_msgs = list(self._grid)
        if not self.grid_topic:
            return None
        return score_published_grid(truth, grid_msgs, self.grid_hz, self.site.takeoff_h)

    # --- multi-target scoring ------------------------------------------------------------
    @property
    def vehicle_topics(self) -> list[str]:
        """The vehicles whose truth topic this node reads (multi-target scoring)."""
        return list(self._vehicle_truth)

    def _subscribe_vehicle(self, name: str) -> None:
        if name in self._vehicle_truth:
            return
        self._vehicle_truth[name] = []
        topic = f"truth/{name}/fix"

        def feed(msg: NavSatFix) -> bool:
            return self._vehicle_fix(name, msg)

        def on_fix(msg: NavSatFix) -> None:
            self._guard(topic, feed, msg)

        self.create_subscription(NavSatFix, topic, on_fix, self._qos)
        self.get_logger().info(f"scoring {self.tracks_topic} against {topic}")

    def _discover_vehicles(self) -> None:
        """Subscribe every truth/<vehicle>/fix topic that has appeared in the graph."""
        for name, types in self.get_topic_names_and_types():
            m = VEHICLE_TOPIC.match(name)
            if m is not None and "sensor_msgs/msg/NavSatFix" in types:
                self._subscribe_vehicle(m["vehicle"])

    def _vehicle_fix(self, vehicle: str, msg: NavSatFix) -> bool:
        fix = navsatfix_to_truth(msg, self.site)
        self._vehicle_truth[vehicle].append((fix.t, fix.e, fix.n, fix.u))
        return True

    def _track(self, msg: Odometry) -> bool:
        self._check_frame(msg.header.frame_id)
        s = odometry_to_state(msg)
        m = TRACK_FRAME.match(msg.child_frame_id)
        if m is None:
            raise MessageError(
                "bad_track_id", f"child_frame_id {msg.child_frame_id!r} is not track_<id>"
            )
        if not on_grid(s.t, self.tracks_hz):
            raise MessageError("off_grid", f"stamp {s.t:.6f} is not a {self.tracks_hz:g} Hz epoch")
        self._tracks.append((s.t, int(m["id"]), s.x))
        return True

    def _on_tracks(self, msg: Odometry) -> None:
        self._guard(self.tracks_topic, self._track, msg)

    def multi_score(self, final: bool = True) -> MultiScore | None:
        """The tracks received so far scored as a set against every vehicle's truth (None
        without ``tracks_topic`` or without a vehicle with two truth samples). ``final``:
        up to the last truth sample; otherwise up to the last track message."""
        with self._lock:
            truth = {k: list(v) for k, v in self._vehicle_truth.items()}
            tracks = list(self._tracks)
        if not self.tracks_topic:
            return None
        return score_published_tracks(truth, tracks, self.tracks_hz, final)

    def _radar_raw(self, msg: PoseWithCovarianceStamped) -> bool:
        m = msg_to_radar_measurement(msg, self.frame_id)
        rcs = self._rcs.get(rcs_key(m.t, m.z[0], m.z[1])) if self._rcs else None
        e, n, u = (float(v) for v in m.z)
        return self.evaluator.add_radar_report(m.t, e, n, u, rcs_dbsm=rcs)

    def _rf(self, msg: PointStamped) -> bool:
        self._check_frame(msg.header.frame_id)
        if is_failed_rf(msg):
            t = time_from_stamp(msg.header.stamp)
            if t == 0.0:
                raise MessageError("zero_stamp", "message has no stamp (0)")
            return self.evaluator.add_rf_attempt(t, False)
        m = msg_to_rf_measurement(msg, self.frame_id)
        assert m is not None  # failed attempts handled above
        return self.evaluator.add_rf_attempt(m.t, True, float(m.z[0]), float(m.z[1]))

    def _accepted_radar(self, msg: PoseWithCovarianceStamped) -> bool:
        m = msg_to_radar_measurement(msg, self.frame_id)
        return self.evaluator.add_validated(m.t, "radar", m.z)

    def _accepted_rf(self, msg: PointStamped) -> bool:
        m = msg_to_rf_measurement(msg, self.frame_id)
        if m is None:
            raise MessageError("nan", "an accepted RF measurement cannot be a failed attempt")
        return self.evaluator.add_validated(m.t, "rf", m.z)

    def _step(self, msg: Odometry, status: str) -> bool:
        self._check_frame(msg.header.frame_id)
        s = odometry_to_state(msg)
        if s.t == 0.0:
            raise MessageError("zero_stamp", "message has no stamp (0)")
        return self.evaluator.add_step(s.t, status, s.x)

    def _on_truth(self, msg: NavSatFix) -> None:
        self._guard(self.truth_topic, self._truth, msg)

    def _on_radar_raw(self, msg: PoseWithCovarianceStamped) -> None:
        self._guard(self.radar_raw_topic, self._radar_raw, msg)

    def _on_rf(self, msg: PointStamped) -> None:
        self._guard(self.rf_topic, self._rf, msg)

    def _on_accepted_radar(self, msg: PoseWithCovarianceStamped) -> None:
        self._guard(self.accepted_radar_topic, self._accepted_radar, msg)

    def _on_accepted_rf(self, msg: PointStamped) -> None:
        self._guard(self.accepted_rf_topic, self._accepted_rf, msg)

    def _on_updated(self, msg: Odometry) -> None:
        self._guard(self.updated_topic, lambda m: self._step(m, UPDATED), msg)

    def _on_coasted(self, msg: Odometry) -> None:
        self._guard(self.coasted_topic, lambda m: self._step(m, COASTED), msg)

    def _on_grid(self, msg: Odometry) -> None:
        self._guard(self.grid_topic, self._grid_state, msg)

    # --- output ----------------------------------------------------------------------------
    def evaluate(self) -> Evaluation:
        """Score everything received so far (message drops merged into the drop counts)."""
        with self._lock:
            ev = self.evaluator.evaluate()
        dropped = dict(ev.dropped)
        for k, v in self.dropped.items():
            dropped[k] = dropped.get(k, 0) + v
        return _with_dropped(ev, dropped)

    def _on_timer(self) -> None:
        ev = self.evaluate()
        seen = sum(self.received.values())
        if seen != self._logged_at:  # log only when something new arrived; diagnostics always
            self._logged_at = seen
            self.get_logger().info(rows_summary(ev))
        self.diag_pub.publish(self.diagnostics(ev))

    def diagnostics(self, ev: Evaluation) -> DiagnosticArray:
        arr = DiagnosticArray()
        arr.header.stamp = self.get_clock().now().to_msg()
        arr.status.extend(evaluation_statuses(self.get_name(), ev))
        n_drop = sum(ev.dropped.values())
        counts = [("received", self.received), ("used", self.used),
                  ("refused", self.refused), ("dropped", ev.dropped)]
        values = [(f"{what} {k}", str(v)) for what, c in counts for k, v in sorted(c.items())]
        values.append(("fused step gaps", self.gap_text(ev)))
        ms = self.multi_score(final=False)
        if ms is not None:
            arr.status.append(tracks_status(self.get_name(), ms))
        values.append(("clock jumps back", str(self.clock_jumps_back)))
        arr.status.append(make_status(
            f"{self.get_name()}: inputs",
            f"{sum(self.received.values())} messages, {n_drop} dropped",
            values,
            warn=bool(n_drop),
        ))
        return arr

    def _refresh_runtime_params(self) -> None:
        """Re-read the parameters that may change while running (set_parameters)."""
        self.output_dir = Path(str(self.get_parameter("output_dir").value))
        self.figures = bool(self.get_parameter("figures").value)
        self.write_on_shutdown = bool(self.get_parameter("write_on_shutdown").value)
        self.flight_name = str(self.get_parameter("flight_name").value)

    def step_gaps(self, ev: Evaluation) -> list[tuple[float, float]]:
        """(start, end) of every gap between fused steps longer than ``step_gap_s``."""
        return step_gaps(ev.samples["kf_all"].t, self.step_gap_s)

    def gap_text(self, ev: Evaluation) -> str:
        return gap_text(self.step_gaps(ev), self.step_gap_s)

    def write_report(self, folder: Path | None = None) -> ReportFiles:
        """Score everything received so far and write the report to ``output_dir``."""
        self._refresh_runtime_params()
        ev = self.evaluate()

        def counts(c: Counter[str]) -> str:
            return ", ".join(f"{k} {v}" for k, v in sorted(c.items())) or "none"

        info = {
            "mode": f"live ({NODE_NAME})",
            "flight": self.flight_name or "(not given)",
            "site": str(self.site.source or self.site.name),
            "messages received": counts(self.received),
            "messages used": counts(self.used),
            "messages refused": counts(self.refused),
            "messages dropped": counts(self.dropped),
            "fused step gaps": self.gap_text(ev),
            "clock jumps back": str(self.clock_jumps_back),
        }
        gs = self.grid_score()
        if gs is not None:
            info[f"fixed-rate output ({self.grid_topic}, {self.grid_hz:g} Hz)"] = (
                f"coverage {gs.coverage_pct:.1f} % of {gs.epochs} airborne epochs; error mean "
                f"{gs.err_mean_m:.1f} m, p95 {gs.err_p95_m:.1f} m, max {gs.err_max_m:.1f} m; "
                f"> 100 m {gs.gross_pct:.1f} %; ANEES {gs.anees:.2f} (3 when honest)"
            )
        ms = self.multi_score()
        if ms is not None:
            info[f"tracks ({self.tracks_topic}, {self.tracks_hz:g} Hz)"] = multi_summary(ms)
        out = self.output_dir if folder is None else folder
        files = write_report(ev, out, self.site, info, figures=self.figures)
        self.last_report = files
        return files

    def _on_write_report(
        self, request: Trigger.Request, response: Trigger.Response
    ) -> Trigger.Response:
        try:
            files = self.write_report()
        except (UavFusionError, OSError) as exc:
            response.success = False
            response.message = str(exc)
            self.get_logger().error(f"report not written: {exc}")
            return response
        response.success = True
        response.message = str(files.markdown)
        self.get_logger().info(f"report written to {files.folder}")
        return response


def _with_dropped(ev: Evaluation, dropped: dict[str, int]) -> Evaluation:
    from dataclasses import replace

    return replace(ev, dropped=dropped)


def main(args: Sequence[str] | None = None) -> int:
    def on_stop(node: Node, _executor: Any) -> None:
        assert isinstance(node, EvaluatorNode)
        node._refresh_runtime_params()
        if node.write_on_shutdown:
            try:
                files = node.write_report()
                print(f"{NODE_NAME}: report written to {files.folder}", file=sys.stderr)
            except (UavFusionError, OSError) as exc:
                print(f"{NODE_NAME}: report not written: {exc}", file=sys.stderr)

    return run_node(EvaluatorNode, args, on_stop=on_stop, name=NODE_NAME,
                    stop_grace_s=REPORT_GRACE_S)


if __name__ == "__main__":
    sys.exit(main())
