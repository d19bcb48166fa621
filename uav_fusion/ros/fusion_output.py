"""The fusion node's output: publishers, views and diagnostics.

:meth:`FusionOutput.publish` takes the :class:`~uav_fusion.core.estimators.grid.Outputs` an
estimator gave and publishes them:

- filter steps (the paper's filter, the single-UAV tracker): every step with an estimate on
  ``fusion/odom/updated`` or ``fusion/odom/coasted``; every measurement that passed every
  gate (NIS included; a measurement that only started a track is not "accepted") on
  ``fusion/accepted/radar`` or ``fusion/accepted/rf``; for an estimator without a
  fixed-rate output (the paper's) every step also on ``fusion/odom`` and ``fusion/fix``;
- the fixed-rate output (``fixed_rate`` estimators): every epoch with a published track on
  ``fusion/odom`` and ``fusion/fix``;
- the multi-UAV tracks: every confirmed track at every epoch on ``fusion/tracks``
  (``child_frame_id`` ``track_<id>``);
- fixed-lag smoothed estimates on ``fusion/odom/smoothed``.

A message nobody subscribes to is not built. The views (``fusion/path``, ``fusion/markers``,
:mod:`uav_fusion.ros.visualization`) keep their state cheaply per output and build messages
only when published (:meth:`FusionOutput.publish_views`). :meth:`FusionOutput.diagnostics`
gathers the node's counters: ``received_<s>`` = ``used_<s>`` + the ``rejected_<s>_<reason>``
(refused by the estimator, failed attempts and empty frames) + the ``dropped_<s>_<reason>``
and ``dropped_late_<s>`` (never reached the estimator) + ``buffer_pending`` + ``held_<s>``.
"""

from __future__ import annotations

import math
import time
from collections import Counter, deque
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PointStamped, PoseWithCovarianceStamped
from nav_msgs.msg import Odometry
from nav_msgs.msg import Path as NavPath
from rclpy.event_handler import PublisherEventCallbacks
from rclpy.node import Node
from rclpy.publisher import Publisher
from sensor_msgs.msg import NavSatFix
from visualization_msgs.msg import MarkerArray

from uav_fusion.core.estimators.consider import consider_for
from uav_fusion.core.estimators.grid import GridEpoch, GridState, Outputs
from uav_fusion.core.estimators.steps import Step
from uav_fusion.core.live.pipeline import Pipeline
from uav_fusion.core.records import RADAR, RF
from uav_fusion.core.site import Site
from uav_fusion.ros import conversions as cv
from uav_fusion.ros import odometry as od
from uav_fusion.ros.diagnostics import make_status
from uav_fusion.ros.fusion_input import FusionInput
from uav_fusion.ros.qos import DIAGNOSTICS_QOS
from uav_fusion.ros.visualization import (
    ReportLayer,
    SiteLayer,
    TrackLayer,
    TracksLayer,
    Visualization,
)

_UPPER = tuple((i, j) for i in range(6) for j in range(i, 6))


@dataclass(frozen=True)
class OutputTopics:
    """The output topics (the node's parameters of the same names)."""

    odom: str = "fusion/odom"
    updated: str = "fusion/odom/updated"
    coasted: str = "fusion/odom/coasted"
    accepted_radar: str = "fusion/accepted/radar"
    accepted_rf: str = "fusion/accepted/rf"
    fix: str = "fusion/fix"
    smoothed: str = "fusion/odom/smoothed"
    tracks: str = "fusion/tracks"
    path: str = "fusion/path"
    markers: str = "fusion/markers"


@dataclass(frozen=True)
class ViewSettings:
    """How the views look (the node's parameters of the same names)."""

    path_max_poses: int = 20000
    marker_history: int = 200
    covariance_sigma: float = 2.0
    range_gate_m: float | None = None


class FusionOutput:
    """Publishes what the estimator gives (see the module text)."""

    def __init__(
        self,
        node: Node,
        pipeline: Pipeline,
        site: Site,
        frame_id: str,
        child_frame_id: str,
        topics: OutputTopics,
        qos: Any,
        views: ViewSettings,
    ) -> None:
        self.node = node
        self.pipeline = pipeline
        self.site = site
        self.frame = frame_id
        self.child_frame = child_frame_id
        self.fixed_rate = pipeline.estimator.fixed_rate
        #: the per-step, smoothed and view covariances get the consider term the fixed-rate
        #: and track outputs have from the estimator (uav_fusion.core.estimators.consider)
        self.consider = consider_for(pipeline.estimator.profile, site)
        # publishers need no QoS event handlers (waitables the executor would poll)
        quiet = PublisherEventCallbacks(use_default_callbacks=False)

        def pub(cls: Any, topic: str, q: Any = qos) -> Publisher:
            return node.create_publisher(cls, topic, q, event_callbacks=quiet)

        self.pub_odom = pub(Odometry, topics.odom)
        self.pub_updated = pub(Odometry, topics.updated)
        self.pub_coasted = pub(Odometry, topics.coasted)
        self.pub_acc_radar = pub(PoseWithCovarianceStamped, topics.accepted_radar)
        self.pub_acc_rf = pub(PointStamped, topics.accepted_rf)
        self.pub_fix = pub(NavSatFix, topics.fix)
        self.pub_smoothed = pub(Odometry, topics.smoothed)
        self.pub_tracks = pub(Odometry, topics.tracks)
        self.pub_path = pub(NavPath, topics.path, DIAGNOSTICS_QOS)
        self.pub_markers = pub(MarkerArray, topics.markers, DIAGNOSTICS_QOS)
        self.pub_diag = pub(DiagnosticArray, "/diagnostics", DIAGNOSTICS_QOS)
        # accounting of the estimator's steps
        self.used: Counter[str] = Counter()
        self.refused: Counter[str] = Counter()  # "<source>_<reason>"
        self.statuses: Counter[str] = Counter()
        self.reasons: Counter[str] = Counter()
        self.nis: dict[str, list[float]] = {RADAR: [], RF: []}
        #: steps with an estimate (each goes to fusion/odom/updated or coasted)
        self.steps_published = 0
        #: measurements that passed every gate (fusion/accepted/radar or /rf)
        self.accepted_published = 0
        #: fixed-rate epochs with a published track (fusion/odom of fixed-rate estimators)
        self.grid_published = 0
        #: track messages on fusion/tracks, and the epochs they came from
        self.tracks_published = 0
        self.track_epochs = 0
        #: smoothed estimates on fusion/odom/smoothed
        self.smoothed_published = 0
        # views: the state is kept cheaply per output; messages are built only when published
        self._path: deque[tuple[float, float, float, float]] = deque(maxlen=views.path_max_poses)
        self._sigma = views.covariance_sigma
        self.track_layer = TrackLayer(sigma=views.covariance_sigma)
        self.report_layer = ReportLayer(history=views.marker_history)
        self.tracks_layer: TracksLayer | None = None
        self.visualization = Visualization(
            frame_id,
            [SiteLayer(site, views.range_gate_m), self.report_layer, self.track_layer],
        )
        self._views_dirty = True
        self.last_view = -math.inf
        self._last: Step | None = None  # the latest published step, for the views
        self.paths_published = 0
        self.markers_published = 0

    # --- outputs --------------------------------------------------------------------------
    def publish(self, out: Outputs) -> None:
        """Publish everything in ``out`` (see the module text)."""
        for step in out.steps:
            self._step(step)
        if self.fixed_rate:
            for gs in out.grid:
                self._grid(gs)
        for ep in out.tracks:
            self._tracks(ep)
        cons = self.consider
        for t, x, P in out.smoothed:
            self.smoothed_published += 1
            if self.pub_smoothed.get_subscription_count():
                Pp = cons.cov(x, P) if cons is not None else P
                self.pub_smoothed.publish(
                    od.state_to_odometry(t, x, Pp, self.frame, self.child_frame)
                )

    def _step(self, step: Step) -> None:
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
        meas = self.pipeline.estimator.measurement(step)
        if meas is not None:
            z = meas[0]
            if source == RADAR:
                if z.size == 2:  # horizontal only (beyond the 3D range gate): drawn at the
                    z = np.append(z, step.values[2])  # track's height
                self.report_layer.radar(z, validated)
            else:
                self.report_layer.rf_fix(z, updated)
        if not (updated or step.coasted):
            return  # e.g. a measurement that only started a track: no estimate to publish
        self.steps_published += 1
        v = step.values
        if self.consider is not None:
            v = self.consider.values(v)
        self._path.append((step.t, v[0], v[1], v[2]))
        self._last = step
        self._views_dirty = True
        side = self.pub_updated if updated else self.pub_coasted
        odom = self.pub_odom if not self.fixed_rate else None
        if side.get_subscription_count() or (odom and odom.get_subscription_count()):
            msg = od.odometry_from_values(step.t, v, self.frame, self.child_frame)
            side.publish(msg)
            if odom is not None:
                odom.publish(msg)
        if odom is not None and self.pub_fix.get_subscription_count():
            self.pub_fix.publish(self._fix(step.t, v))
        if validated and meas is not None and (source != RADAR or meas[0].size == 3):
            # (a horizontal-only radar update has no height: not on fusion/accepted/radar)
            self.accepted_published += 1
            z, R = meas
            if source == RADAR:
                if self.pub_acc_radar.get_subscription_count() and R is not None:
                    self.pub_acc_radar.publish(cv.radar_to_msg(step.t, z, R, self.frame))
            elif self.pub_acc_rf.get_subscription_count():
                en = (float(z[0]), float(z[1]))
                self.pub_acc_rf.publish(cv.rf_to_msg(step.t, en, self.frame))

    def _grid(self, gs: GridState) -> None:
        """One epoch of the fixed-rate output (nothing without a published track)."""
        if not gs.published:
            return
        self.grid_published += 1
        if self.pub_odom.get_subscription_count():
            self.pub_odom.publish(
                od.state_to_odometry(gs.t, gs.x, gs.P, self.frame, self.child_frame)
            )
        if self.pub_fix.get_subscription_count():
            v = (*gs.x.tolist(), *(gs.P[i, j] for i, j in _UPPER))
            self.pub_fix.publish(self._fix(gs.t, v))

    def _tracks(self, ep: GridEpoch) -> None:
        """One epoch of the multi-UAV tracker: every confirmed track on fusion/tracks."""
        self.track_epochs += 1
        if self.tracks_layer is None:
            self.tracks_layer = TracksLayer(sigma=self._sigma)
            self.visualization.add(self.tracks_layer)
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
                    od.state_to_odometry(ep.t, o.x, o.P, self.frame, f"track_{o.track_id}")
                )

    def _fix(self, t: float, v: Sequence[float]) -> NavSatFix:
        """The fused position as NavSatFix (WGS84, HAE; covariance = P's position block in
        ENU, which is NavSatFix's convention)."""
        lat, lon, h = self.site.to_geodetic(v[0], v[1], v[2])
        return od.navsatfix_from_enu(t, float(lat), float(lon), float(h), v, self.child_frame)

    # --- views ----------------------------------------------------------------------------
    def path_message(self) -> NavPath:
        """fusion/path: the latest ``path_max_poses`` fused positions."""
        return od.path_from_points(self._path, self.frame)

    def markers_message(self) -> MarkerArray:
        """fusion/markers: every layer of :mod:`uav_fusion.ros.visualization`."""
        if self._last is not None:  # its arrays are built here, not for every step
            x, P = self._last.x, self._last.P
            if self.consider is not None:
                P = self.consider.cov(x, P)
            self.track_layer.update(x[:3].tolist(), P[:3, :3].tolist())
        return self.visualization.array(self.node.get_clock().now().to_msg())

    def publish_views(self, force: bool = False) -> None:
        """Publish fusion/path and fusion/markers if subscribed and something changed."""
        if not (self._views_dirty or force):
            return
        self._views_dirty = False
        self.last_view = time.monotonic()
        if self.pub_path.get_subscription_count():
            self.pub_path.publish(self.path_message())
            self.paths_published += 1
        if self.pub_markers.get_subscription_count():
            self.pub_markers.publish(self.markers_message())
            self.markers_published += 1

    # --- diagnostics ----------------------------------------------------------------------
    def diagnostics(self, inp: FusionInput, pipe: Pipeline) -> dict[str, str]:
        """The counters published on /diagnostics, as key -> text."""
        vals: dict[str, Any] = {}
        for src in (RADAR, RF):
            vals[f"received_{src}"] = inp.received[src]
            vals[f"used_{src}"] = self.used[src]
            vals[f"held_{src}"] = len(pipe.held[src])
        refused = self.refused + pipe.empty
        for k, v in sorted(refused.items()):
            vals[f"rejected_{k}"] = v
        statuses = self.statuses.copy()
        if pipe.empty["rf_failed_attempt"]:
            statuses["rf_failed_attempt"] = pipe.empty["rf_failed_attempt"]
        for k, v in sorted(statuses.items()):
            vals[f"steps_{k}"] = v
        for k, v in sorted(self.reasons.items()):
            vals[f"rejected_{k}"] = v
        for k, v in sorted((inp.dropped + pipe.dropped).items()):
            vals[f"dropped_{k}"] = v
        est = pipe.estimator
        if est.fixed_rate:
            vals["grid_published"] = self.grid_published
        if self.track_epochs:
            vals["tracks_published"] = self.tracks_published
        if inp.frames:
            vals["received_radar_reports"] = inp.received_reports
        vals.update(est.status())
        for k, v in sorted(est.counters.items()):
            vals[f"estimator_{k}"] = v
        for src, xs in self.nis.items():
            if xs:
                a = np.asarray(xs)
                vals[f"nis_{src}_count"] = a.size
                vals[f"nis_{src}_mean"] = f"{a.mean():.4g}"
                vals[f"nis_{src}_max"] = f"{a.max():.4g}"
        vals["steps_published"] = self.steps_published
        vals["buffer_pending"] = pipe.buffer.pending
        vals["buffer_max_depth"] = pipe.buffer.max_depth
        rw = pipe.rewinder
        if rw is not None:
            vals["rewinds"] = rw.rewinds
            vals["refiltered_inputs"] = rw.refiltered
        # matched readers per output: outputs nobody reads are not built
        for key, p in (("odom", self.pub_odom), ("updated", self.pub_updated),
                       ("coasted", self.pub_coasted), ("accepted_radar", self.pub_acc_radar),
                       ("accepted_rf", self.pub_acc_rf), ("fix", self.pub_fix),
                       ("path", self.pub_path), ("markers", self.pub_markers)):
            vals[f"subscribers_{key}"] = p.get_subscription_count()
        vals["clock_jumps_back"] = pipe.clock_jumps_back
        vals["timeline_resets"] = pipe.timeline_resets
        return {k: str(v) for k, v in vals.items()}

    def publish_diagnostics(self, inp: FusionInput, pipe: Pipeline) -> None:
        vals = self.diagnostics(inp, pipe)
        n_drop = sum(inp.dropped.values()) + sum(pipe.dropped.values())
        arr = DiagnosticArray()
        arr.header.stamp = self.node.get_clock().now().to_msg()
        name = self.node.get_name()
        arr.status = [make_status(
            f"{name}: fusion",
            f"{self.steps_published} steps, {n_drop} dropped",
            vals.items(),
            warn=bool(n_drop),
        )] + [mon.status(name) for mon in inp.monitors.values()]
        self.pub_diag.publish(arr)
