"""fusion_node with a tracker profile, in-process: every report of every frame (radar/tracks)
and every attempt (rf/fixes) in, the offline tracker's steps out, the fixed-rate output equal
to the core grid, malformed points dropped and counted, output predicted on when inputs stall."""

from __future__ import annotations

import random
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticArray
from nav_msgs.msg import Odometry
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from sensor_msgs.msg import PointCloud2

from uav_fusion.core.data import load_flight
from uav_fusion.core.estimators import load_profile
from uav_fusion.core.estimators.base import feed, make_estimator
from uav_fusion.core.estimators.consider import consider_for
from uav_fusion.core.estimators.grid import Outputs, StepGrid
from uav_fusion.core.estimators.offline import run_tracker, smooth_steps
from uav_fusion.core.estimators.selection import frames_input
from uav_fusion.core.estimators.tracker import Tracker
from uav_fusion.core.live.rewind import simulate
from uav_fusion.core.live.schedule import Arrival, ClockTick, read_schedule
from uav_fusion.core.records import RadarFrame, RadarTrack, RfAttempt
from uav_fusion.core.site import load_site
from uav_fusion.nodes.fusion_node import FusionNode
from uav_fusion.resources import DEFAULT_FLIGHT, data_path
from uav_fusion.ros import conversions as cv
from uav_fusion.ros import odometry as od
from uav_fusion.ros.qos import stream_qos

FRAME = "enu_lw1"
SPAN_S = 240.0  # the first four minutes of the bundled flight: take-off, first track, legs
# radar frames, RF attempts, and the offline tracker's stream of them
FlightData = tuple[list[RadarFrame], list[RfAttempt], list[RadarFrame | RfAttempt]]


class Harness:
    def __init__(self, ctx: Context, **params: Any) -> None:
        params.setdefault("profile", "tracker")
        self.fusion = FusionNode(
            context=ctx, parameter_overrides=[Parameter(k, value=v) for k, v in params.items()]
        )
        self.io = Node("io", context=ctx)
        qos = stream_qos(10000)
        self.pub_radar = self.io.create_publisher(PointCloud2, "radar/tracks", qos)
        self.pub_rf = self.io.create_publisher(PointCloud2, "rf/fixes", qos)
        self.odom: list[Odometry] = []
        self.updated: list[Odometry] = []
        self.coasted: list[Odometry] = []
        self.diag: list[DiagnosticArray] = []
        sub = self.io.create_subscription
        sub(Odometry, "fusion/odom", self.odom.append, qos)
        sub(Odometry, "fusion/odom/updated", self.updated.append, qos)
        sub(Odometry, "fusion/odom/coasted", self.coasted.append, qos)
        sub(DiagnosticArray, "/diagnostics", self.diag.append, 10)
        self.ex = SingleThreadedExecutor(context=ctx)
        self.ex.add_node(self.fusion)
        self.ex.add_node(self.io)
        self.spin_until(
            lambda: self.pub_radar.get_subscription_count() > 0
            and self.pub_rf.get_subscription_count() > 0
            and self.fusion.output.pub_odom.get_subscription_count() > 0
        )

    def spin_until(self, cond: Callable[[], bool], limit_s: float = 120.0) -> None:
        end = time.monotonic() + limit_s
        while not cond():
            assert time.monotonic() < end, "condition not reached"
            self.ex.spin_once(timeout_sec=0.02)

    def feed(self, order: list[tuple[str, Any]]) -> None:
        for i, (kind, msg) in enumerate(order):
            (self.pub_radar if kind == "radar" else self.pub_rf).publish(msg)
            if i % 5 == 4:
                def taken(i: int = i) -> bool:
                    return self.got() >= i + 1

                self.spin_until(taken)

    def got(self) -> int:
        return int(self.fusion.received["radar"] + self.fusion.received["rf"])

    def destroy(self) -> None:
        self.fusion.destroy_node()
        self.io.destroy_node()


@pytest.fixture(scope="module")
def flight_data() -> FlightData:
    """(radar frames, RF attempts) of the first SPAN_S of the bundled flight, and the
    offline tracker's stream over the same data."""
    site = load_site()
    flight = load_flight(data_path(DEFAULT_FLIGHT), site)
    t_end = flight.truth[0].t + SPAN_S
    frames = [fr for fr in flight.radar if fr.t < t_end]
    attempts = [a for a in flight.rf if a.t < t_end]
    stream = [x for x in frames_input(flight, load_profile("tracker")) if x.t < t_end]
    return frames, attempts, stream


def _order(
    frames: list[RadarFrame],
    attempts: list[RfAttempt],
    delay_s: float,
    seed: int,
    min_delay_s: float = 0.0,
) -> list[tuple[str, PointCloud2]]:
    """Both streams as messages, interleaved; RF ``min_delay_s`` to ``delay_s`` late (its own
    order kept)."""
    rng = random.Random(seed)
    keyed = [(fr.t, 0, k, "radar", cv.radar_frame_to_cloud_msg(fr, FRAME))
             for k, fr in enumerate(frames)]  # fmt: skip
    last = -1.0
    for k, a in enumerate(attempts):
        last = max(last, a.t + rng.uniform(min_delay_s, delay_s))
        keyed.append((last, 1, k, "rf", cv.rf_attempts_to_cloud_msg([a], FRAME)))
    keyed.sort(key=lambda e: (e[0], e[1], e[2]))
    return [(kind, msg) for _, _, _, kind, msg in keyed]


@pytest.mark.parametrize(("delay_s", "seed"), [(0.0, 0), (1.5, 1)])
def test_live_tracker_equals_the_offline_run_and_its_grid(
    ctx: Context, flight_data: FlightData, delay_s: float, seed: int
) -> None:
    frames, attempts, stream = flight_data
    site = load_site()
    profile = load_profile("tracker")
    steps = run_tracker(Tracker(profile, site), stream)
    est = [s for s in steps if s.updated or s.coasted]
    # published covariances carry the radar elevation error's consider term
    cons = consider_for(profile, site)
    assert cons is not None
    grid = StepGrid(profile, 10.0, consider=cons.cov)
    expected_grid = [g for s in steps for g in grid.feed_step(s) if g.published]
    assert len(est) > 300 and len(expected_grid) > 1000

    h = Harness(ctx, reorder_window_s=2.0, idle_flush_s=0.0, stall_timeout_s=0.0)
    h.feed(_order(frames, attempts, delay_s, seed))
    h.spin_until(lambda: h.got() == len(frames) + len(attempts))
    h.fusion.flush()
    n_upd = sum(1 for s in est if s.updated)
    h.spin_until(lambda: len(h.updated) == n_upd and len(h.coasted) == len(est) - n_upd)
    got = sorted(
        [od.odometry_to_state(o) for o in h.updated + h.coasted], key=lambda g: g.t
    )
    assert [g.t for g in got] == [s.t for s in est]
    assert np.max(np.abs(np.array([g.x for g in got]) - np.array([s.x for s in est]))) < 1e-9
    want_p = np.array([cons.cov(s.x, s.P)[:3, :3] for s in est])
    assert np.max(np.abs(np.array([g.P[:3, :3] for g in got]) - want_p)) < 1e-6
    # the fixed-rate output is the core grid of the same steps, epoch for epoch
    h.spin_until(lambda: len(h.odom) == len(expected_grid))
    odom = [od.odometry_to_state(o) for o in h.odom]
    assert [o.t for o in odom] == [g.t for g in expected_grid]
    dx = np.array([o.x for o in odom]) - np.array([g.x for g in expected_grid])
    assert np.max(np.abs(dx)) < 1e-9
    dp = np.array([o.P[:3, :3] for o in odom]) - np.array([g.P[:3, :3] for g in expected_grid])
    assert np.max(np.abs(dp)) < 1e-6
    assert not h.fusion.dropped
    # horizontal-only radar updates (beyond the 3D range gate) are counted on /diagnostics
    n_flat = sum(1 for s in steps if s.status == "updated" and s.source == "radar" and s.dim == 2)
    diag = h.fusion.diagnostics()
    assert n_flat > 100 and int(diag["estimator_updated_radar_horizontal"]) == n_flat
    assert float(diag["since_last_3d_radar_s"]) >= 0.0
    h.destroy()


def _key(s: Any) -> tuple[Any, ...]:
    return (s.t, s.source, s.status, s.reason, repr(s.values))  # repr: NaN equals NaN


def test_zero_wait_rf_seconds_late_final_track_equals_in_order_and_live_equals_offline(
    ctx: Context,
    flight_data: FlightData,
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """RF 3 s +- 1 s late, zero wait: every input is fused on arrival; after the last one
    the re-filtered track is the in-order run's, and what the node published equals the
    offline run of the same arrival order."""
    frames, attempts, stream = flight_data
    site = load_site()
    profile = load_profile("tracker")
    in_order = run_tracker(Tracker(profile, site), stream)
    h = Harness(ctx, idle_flush_s=0.0, stall_timeout_s=0.0)
    pipe = h.fusion.pipeline
    assert pipe.rewinder is not None  # zero wait is the default
    arrivals: list[Arrival] = []
    radar_in, rf_in, publish = pipe.radar, pipe.rf, h.fusion.output.publish
    published: list[Outputs] = []

    def radar(frame: RadarFrame, clock: float | None = None) -> Outputs:
        if frame.tracks:
            arrivals.append(("radar", frame))
        return radar_in(frame, clock)

    def rf(atts: Sequence[RfAttempt], clock: float | None = None) -> Outputs:
        arrivals.extend(("rf", a) for a in atts if a.ok)
        return rf_in(atts, clock)

    def record(out: Outputs) -> None:
        published.append(out)
        publish(out)

    monkeypatch.setattr(pipe, "radar", radar)
    monkeypatch.setattr(pipe, "rf", rf)
    monkeypatch.setattr(h.fusion.output, "publish", record)
    h.feed(_order(frames, attempts, 4.0, 5, min_delay_s=2.0))
    h.spin_until(lambda: h.got() == len(frames) + len(attempts))
    h.fusion.flush()
    assert [_key(s) for s in pipe.rewinder.steps] == [_key(s) for s in in_order]
    assert pipe.rewinder.rewinds > 10 and not h.fusion.dropped
    outs, rw, _ = simulate(lambda: make_estimator(profile, site, 10.0, live=True), arrivals)
    final = rw.steps
    assert [_key(s) for s in final] == [_key(s) for s in in_order]
    live_steps = [_key(s) for o in published for s in o.steps]
    assert live_steps == [_key(s) for o in outs for s in o.steps]
    live_grid = [(g.k, repr(g.x.tolist())) for o in published for g in o.grid]
    assert live_grid == [(g.k, repr(g.x.tolist())) for o in outs for g in o.grid]
    assert len(live_steps) == len(in_order) and len(live_grid) > 1000
    h.destroy()


def test_malformed_points_are_dropped_and_counted_the_rest_fused(
    ctx: Context, flight_data: FlightData
) -> None:
    frames, _attempts, _ = flight_data
    h = Harness(ctx, idle_flush_s=0.0, stall_timeout_s=0.0)
    good = next(fr for fr in frames if len(fr.tracks) >= 1)
    bad = RadarTrack(good.t, 999, 0.0, 0.0, 0.0, float("nan"), 1.0, 2.0, None, 0.9, None, None)
    far = RadarTrack(good.t, 998, 0.0, 0.0, 0.0, 3.0e7, 1.0, 2.0, None, 0.9, None, None)
    msg = cv.radar_frame_to_cloud_msg(RadarFrame(good.t, (*good.tracks, bad, far)), FRAME)
    h.pub_radar.publish(msg)
    h.spin_until(lambda: h.fusion.received["radar"] == 1)
    h.fusion.flush()
    assert h.fusion.dropped["radar_point_nan"] == 1
    assert h.fusion.dropped["radar_point_out_of_range"] == 1
    assert h.fusion.input.received_reports == len(good.tracks) + 2
    n = sum(h.fusion.output.statuses.values())
    assert n == len(good.tracks)  # one step per good report, none for the bad points
    broken = cv.radar_frame_to_cloud_msg(good, FRAME)
    broken.data = bytes(broken.data)[:-3]
    h.pub_radar.publish(broken)
    h.spin_until(lambda: h.fusion.received["radar"] == 2)
    assert h.fusion.dropped["radar_bad_layout"] == 1
    h.destroy()


def test_output_is_predicted_on_when_the_inputs_stall(
    ctx: Context, flight_data: FlightData
) -> None:
    frames, attempts, _ = flight_data
    h = Harness(ctx, idle_flush_s=0.2, stall_timeout_s=0.3)
    h.feed(_order(frames, attempts, 0.0, 0))
    h.spin_until(lambda: h.got() == len(frames) + len(attempts))
    fusion = h.fusion
    h.spin_until(lambda: not fusion.pipeline.pending)
    last_t = fusion.pipeline.processed_t
    tracker = fusion.estimator
    assert isinstance(tracker, Tracker) and tracker.best_track() is not None
    # with the inputs silent the epochs beyond the last measurement are published as the
    # sensor time runs on (the node's clock plus the inputs' stamp lead; these stamps are from
    # 2025), never past the track's maximum coast
    max_coast = load_profile("tracker").max_coast_s
    assert max_coast is not None
    best = tracker.best_track()
    assert best is not None and best.last_update_t is not None
    h.spin_until(lambda: bool(h.odom) and cv.time_from_stamp(h.odom[-1].header.stamp) > last_t)
    h.spin_until(lambda: any(d.status and "grid_published" in {v.key for v in d.status[0].values}
                             for d in h.diag))  # fmt: skip
    ts = [cv.time_from_stamp(o.header.stamp) for o in h.odom]
    assert ts == sorted(ts)
    assert ts[-1] <= best.last_update_t + max_coast + 1e-6
    vals = {v.key: v.value for v in h.diag[-1].status[0].values}
    assert vals["track"] == "confirmed" and float(vals["uav_probability"]) > 0.0
    assert float(vals["since_last_accepted_s"]) >= 0.0
    h.destroy()


def test_live_fixed_lag_smoothing_equals_the_offline_one(
    ctx: Context, flight_data: FlightData
) -> None:
    frames, attempts, stream = flight_data
    site = load_site()
    profile = load_profile("tracker_smoothed")
    assert profile.smoother_lag_s == 3.0
    steps = run_tracker(Tracker(profile, site), stream)
    smoothed = [s for s in smooth_steps(steps, 3.0) if s.counted]
    assert len(smoothed) > 300
    # a reorder window: late RF is waited for, so the smoothing windows never see a rewind
    h = Harness(
        ctx, profile="tracker_smoothed", reorder_window_s=2.0, idle_flush_s=0.0,
        stall_timeout_s=0.0,
    )
    got: list[Odometry] = []
    h.io.create_subscription(Odometry, "fusion/odom/smoothed", got.append, stream_qos(10000))
    h.spin_until(lambda: h.fusion.output.pub_smoothed.get_subscription_count() > 0)
    h.feed(_order(frames, attempts, 1.0, 3))
    h.spin_until(lambda: h.got() == len(frames) + len(attempts))
    h.fusion.flush()  # the end of the stream ends the last smoothing window
    h.spin_until(lambda: len(got) == len(smoothed))
    live = [od.odometry_to_state(o) for o in got]
    assert [g.t for g in live] == [s.t for s in smoothed]
    dx = np.array([g.x for g in live]) - np.array([s.x for s in smoothed])
    assert np.max(np.abs(dx)) < 1e-9
    # and it is not the filtered track: smoothing moved the estimates
    filt = [s for s in steps if s.counted]
    assert np.max(np.abs(np.array([s.x for s in filt]) - np.array([s.x for s in smoothed]))) > 1.0
    h.destroy()


def test_every_track_of_the_multi_uav_tracker_on_fusion_tracks(
    ctx: Context, flight_data: FlightData
) -> None:
    frames, attempts, stream = flight_data
    site = load_site()
    profile = load_profile("tracker")
    est = make_estimator(profile, site, 10.0, kind="multi")
    expected = []
    for item in stream:
        expected.extend(feed(est, item).tracks)
    rows = [(ep.t, f"track_{o.track_id}", o.x) for ep in expected for o in ep.tracks]
    assert len(rows) > 1000
    h = Harness(ctx, estimator="multi", idle_flush_s=0.0, stall_timeout_s=0.0)
    got: list[Odometry] = []
    h.io.create_subscription(Odometry, "fusion/tracks", got.append, stream_qos(20000))
    h.spin_until(lambda: h.fusion.output.pub_tracks.get_subscription_count() > 0)
    h.feed(_order(frames, attempts, 0.0, 5))
    h.spin_until(lambda: h.got() == len(frames) + len(attempts))
    h.fusion.flush()
    h.spin_until(lambda: len(got) == len(rows))
    live = [(cv.time_from_stamp(m.header.stamp), m.child_frame_id, od.odometry_to_state(m).x)
            for m in got]  # fmt: skip
    assert [(t, c) for t, c, _ in live] == [(t, c) for t, c, _ in rows]
    assert max(float(np.max(np.abs(a[2] - b[2]))) for a, b in zip(live, rows, strict=True)) < 1e-9
    markers = h.fusion.output.markers_message().markers
    assert {m.ns for m in markers} >= {"tracks", "tracks_covariance", "tracks_label"}
    diag = h.fusion.diagnostics()
    assert int(diag["tracks_published"]) == len(rows)
    h.destroy()


def test_output_delay_publishes_epochs_on_the_clock_and_the_schedule_reproduces_them(
    ctx: Context, flight_data: FlightData, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """output_delay_s 0: between inputs, and after the last one, the node publishes every
    fixed-rate epoch the sensor time has passed (its clock plus the inputs' stamp lead)
    without waiting for the next input; the clock's moves are rows of the arrival schedule,
    and the offline run of that schedule publishes the same epochs at the same points."""
    frames, attempts, _ = flight_data
    site = load_site()
    profile = load_profile("tracker")
    sched = tmp_path / "arrivals.csv"
    h = Harness(ctx, idle_flush_s=0.0, stall_timeout_s=0.0, output_delay_s=0.0,
                arrivals_file=str(sched))  # fmt: skip
    published: list[Outputs] = []
    publish = h.fusion.output.publish

    def record(out: Outputs) -> None:
        published.append(out)
        publish(out)

    monkeypatch.setattr(h.fusion.output, "publish", record)
    order = _order(frames, attempts, 0.0, 0)
    h.feed(order)
    h.spin_until(lambda: h.got() == len(frames) + len(attempts))
    last_t = h.fusion.pipeline.processed_t
    # no more input: the epochs after the last stamp still come, as the node's clock runs
    h.spin_until(
        lambda: bool(h.odom) and cv.time_from_stamp(h.odom[-1].header.stamp) > last_t + 0.5
    )
    rows = sched.read_text(encoding="utf-8").splitlines()
    clock_rows = [r for r in rows if r.startswith("clock,")]
    assert clock_rows, "the clock's moves are in the schedule"
    assert h.fusion.input.arrivals is not None
    h.fusion.input.arrivals.close()
    est = make_estimator(profile, site, 10.0, live=True)
    flight = load_flight(data_path(DEFAULT_FLIGHT), site)
    items = [x for x in est.flight_input(flight) if x.t <= last_t]
    arrivals = read_schedule(sched, items)
    outs, _, _ = simulate(lambda: make_estimator(profile, site, 10.0, live=True), arrivals)
    live_grid = [(g.k, repr(g.x.tolist())) for o in published for g in o.grid]
    off_grid = [(g.k, repr(g.x.tolist())) for o in outs for g in o.grid]
    assert live_grid == off_grid[: len(live_grid)] and len(live_grid) > 1000
    # without the clock rows the same inputs publish fewer epochs by the last one
    inputs_only = [a for a in arrivals if not isinstance(a[1], ClockTick)]
    outs2, _, _ = simulate(lambda: make_estimator(profile, site, 10.0, live=True), inputs_only)
    assert len([g for o in outs2[:-1] for g in o.grid]) < len(live_grid)
    h.destroy()
