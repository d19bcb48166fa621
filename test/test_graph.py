"""The whole graph in one process equals the offline core run, at any rate and with late RF."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest
from nav_msgs.msg import Odometry
from rclpy.context import Context
from test_graph_flight import write_flight

from uav_fusion.core.data import load_flight
from uav_fusion.core.estimators import load_profile, make_estimator, run_flight
from uav_fusion.core.live.rewind import simulate
from uav_fusion.core.live.schedule import read_schedule
from uav_fusion.core.scoring.evaluation import Evaluator, feed_flight, feed_steps
from uav_fusion.core.site import load_site
from uav_fusion.nodes.graph import Graph
from uav_fusion.ros import conversions as cv
from uav_fusion.ros import odometry as od
from uav_fusion.ros.qos import stream_qos


@pytest.fixture(scope="module")
def flight_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return write_flight(tmp_path_factory.mktemp("flight") / "short", seconds=30.0)


def _overrides(flight_dir: Path, out: Path, rate: float, rf_delay: float = 0.0) -> dict[str, Any]:
    replay = {"flight_dir": str(flight_dir), "wait_for_subscribers_s": 5.0}
    return {
        "truth_replay": {**replay, "rate": rate, "clock_period_s": 0.005},
        "rf_replay": {**replay, "delay_s": rf_delay},
        "radar_replay": dict(replay),
        "fusion_node": {"use_sim_time": True, "idle_flush_s": 0.0},
        "evaluator_node": {
            "output_dir": str(out),
            "figures": False,
            "log_period_s": 0.0,
            "write_on_shutdown": False,
            "use_sim_time": True,
        },
    }


def _run_graph(ctx: Context, ov: dict[str, Any]) -> tuple[Graph, list[od.OdomState]]:
    graph = Graph(ctx, ov)
    got: list[od.OdomState] = []
    graph.evaluator.create_subscription(
        Odometry, "fusion/odom", lambda m: got.append(od.odometry_to_state(m)), stream_qos(5000)
    )
    res = graph.run(timeout_s=120.0)
    assert res.ok, res.message
    assert graph.spin_until(lambda: len(got) >= res.steps, 10.0)
    return graph, got


def _table_equal(live: Any, ref: Any) -> None:
    for a, b in zip(live.rows, ref.rows, strict=True):
        assert a.key == b.key
        assert a.stats.count == b.stats.count, a.key
        assert a.denominator == b.denominator, a.key
        if a.stats.count:
            assert a.stats.mean == pytest.approx(b.stats.mean, abs=1e-9), a.key
            assert a.stats.max == pytest.approx(b.stats.max, abs=1e-9), a.key


def _same_track(got: list[od.OdomState], steps: list[Any]) -> None:
    assert [g.t for g in got] == [s.t for s in steps]
    err = np.abs(np.array([g.x for g in got]) - np.array([s.x for s in steps]))
    assert float(err.max()) < 1e-9
    for g, s in zip(got, steps, strict=True):
        assert np.allclose(g.P[:3, :3], s.P[:3, :3], rtol=0, atol=1e-9)


@pytest.mark.parametrize(
    ("rate", "rf_delay", "window"),
    [(0.0, 0.0, 2.0), (25.0, 0.0, 2.0), (0.0, 1.5, 2.0), (25.0, 1.5, 2.0)],
    ids=["rate0", "rate25", "rate0-rf-late", "rate25-rf-late"],
)
def test_graph_with_a_reorder_window_equals_the_offline_run(
    ctx: Context, flight_dir: Path, tmp_path: Path, rate: float, rf_delay: float, window: float
) -> None:
    """With a reorder window nothing is fused out of order: the published track and the
    evaluator's table equal the offline in-order run."""
    site = load_site()
    flight = load_flight(flight_dir, site)
    offline = run_flight(flight, load_profile("paper"), site)
    steps = [s for s in offline.steps if s.updated or s.coasted]
    ov = _overrides(flight_dir, tmp_path, rate, rf_delay)
    ov["fusion_node"]["reorder_window_s"] = window
    graph, got = _run_graph(ctx, ov)
    try:
        assert len(got) == len(steps), str(graph.fusion.diagnostics())
        _same_track(got, steps)
        assert not graph.fusion.dropped
        assert graph.fusion.pipeline.empty["rf_failed_attempt"] == sum(not a.ok for a in flight.rf)
        # RF really arrived late in sensor time, and was reordered
        if rf_delay:
            assert graph.fusion.pipeline.buffer.max_depth > 1
        # the evaluator's table equals the offline evaluation of the same data
        ev = Evaluator(radar_enu=site.radar.enu)
        feed_flight(ev, flight)
        feed_steps(ev, offline.steps, [m for it in _stream(flight) for m in it])
        _table_equal(graph.evaluator.evaluate(), ev.evaluate())
        report = graph.evaluator.write_report()
        assert Path(report.markdown).is_file()
    finally:
        graph.destroy()


@pytest.mark.parametrize("rate", [0.0, 25.0], ids=["rate0", "rate25"])
def test_graph_zero_wait_with_late_rf_reproduces_offline_from_its_arrivals(
    ctx: Context, flight_dir: Path, tmp_path: Path, rate: float
) -> None:
    """Zero wait (the default), RF 1.5 s late: every input is fused on arrival; the final,
    re-filtered track equals the in-order run, and what the graph published (the track and
    the evaluator's table) equals the offline run of the arrival schedule the node wrote."""
    site = load_site()
    flight = load_flight(flight_dir, site)
    profile = load_profile("paper")
    offline = run_flight(flight, profile, site)
    ov = _overrides(flight_dir, tmp_path, rate, 1.5)
    arrivals_file = tmp_path / "arrivals.csv"
    ov["fusion_node"]["arrivals_file"] = str(arrivals_file)
    graph, got = _run_graph(ctx, ov)
    try:
        rw = graph.fusion.pipeline.rewinder
        assert rw is not None and rw.rewinds > 0 and not graph.fusion.dropped
        final = [(s.t, s.status, repr(s.values)) for s in rw.steps]
        assert final == [(s.t, s.status, repr(s.values)) for s in offline.steps]
        graph.fusion.flush()
        assert graph.fusion.input.arrivals is not None
        graph.fusion.input.arrivals.close()
        est = make_estimator(profile, site, live=True)
        arrivals = read_schedule(arrivals_file, est.flight_input(flight))
        _outs, _, published = simulate(lambda: make_estimator(profile, site, live=True), arrivals)
        shown = [p for p in published if p.updated or p.coasted]
        assert len(got) == len(shown)
        _same_track(got, [p.step for p in shown])
        ev = Evaluator(radar_enu=site.radar.enu)
        feed_flight(ev, flight)
        feed_steps(ev, published)
        _table_equal(graph.evaluator.evaluate(), ev.evaluate())
    finally:
        graph.destroy()


def _stream(flight: Any) -> list[list[Any]]:
    from uav_fusion.core.estimators import flight_measurements

    site = load_site()
    return [
        it if isinstance(it, list) else [it]
        for it in flight_measurements(flight, load_profile("paper"), site)
    ]


def test_graph_nodes_honour_use_sim_time(ctx: Context, flight_dir: Path, tmp_path: Path) -> None:
    graph, _ = _run_graph(ctx, _overrides(flight_dir, tmp_path, 0.0))
    try:
        flight = load_flight(flight_dir)
        end = max(flight.truth[-1].t, flight.rf[-1].t, flight.radar[-1].t)
        # the fusion node's clock is the replay's sensor time, not the wall clock
        now = cv.ns_to_time(graph.fusion.get_clock().now().nanoseconds)
        assert flight.truth[0].t <= now <= end
        assert graph.fusion.get_parameter("use_sim_time").value is True
    finally:
        graph.destroy()


def test_rf_later_than_the_window_is_counted_not_fused(
    ctx: Context, flight_dir: Path, tmp_path: Path
) -> None:
    ov = _overrides(flight_dir, tmp_path, 0.0, rf_delay=1.5)
    ov["fusion_node"]["reorder_window_s"] = 0.5
    graph, _ = _run_graph(ctx, ov)
    try:
        late = graph.fusion.dropped["late_rf"]
        assert late > 0
        assert graph.fusion.received["rf"] == len(load_flight(flight_dir).rf)
        assert int(graph.fusion.diagnostics()["dropped_late_rf"]) == late
    finally:
        graph.destroy()
