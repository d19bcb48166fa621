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
from uav_fusion.core.estimators import load_profile, run_flight
from uav_fusion.core.scoring.evaluation import Evaluator, feed_flight, feed_steps
from uav_fusion.core.site import load_site
from uav_fusion.nodes.graph import Graph
from uav_fusion.ros import conversions as cv
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


def _run_graph(ctx: Context, ov: dict[str, Any]) -> tuple[Graph, list[cv.OdomState]]:
    graph = Graph(ctx, ov)
    got: list[cv.OdomState] = []
    graph.evaluator.create_subscription(
        Odometry, "fusion/odom", lambda m: got.append(cv.odometry_to_state(m)), stream_qos(5000)
    )
    res = graph.run(timeout_s=120.0)
    assert res.ok, res.message
    assert graph.spin_until(lambda: len(got) >= res.steps, 10.0)
    return graph, got


@pytest.mark.parametrize(
    ("rate", "rf_delay"),
    [(0.0, 0.0), (25.0, 0.0), (0.0, 1.5), (25.0, 1.5)],
    ids=["rate0", "rate25", "rate0-rf-late", "rate25-rf-late"],
)
def test_graph_track_and_table_equal_the_offline_run(
    ctx: Context, flight_dir: Path, tmp_path: Path, rate: float, rf_delay: float
) -> None:
    site = load_site()
    flight = load_flight(flight_dir, site)
    offline = run_flight(flight, load_profile("paper"), site)
    steps = [s for s in offline.steps if s.updated or s.coasted]

    graph, got = _run_graph(ctx, _overrides(flight_dir, tmp_path, rate, rf_delay))
    try:
        # the fused track: same steps, same times, states equal to 1e-9
        assert len(got) == len(steps), str(graph.fusion.diagnostics())
        assert [g.t for g in got] == [s.t for s in steps]
        err = np.abs(np.array([g.x for g in got]) - np.array([s.x for s in steps]))
        assert float(err.max()) < 1e-9
        for g, s in zip(got, steps, strict=True):
            assert np.allclose(g.P[:3, :3], s.P[:3, :3], rtol=0, atol=1e-9)
        assert not graph.fusion.dropped
        assert graph.fusion.pipeline.empty["rf_failed_attempt"] == sum(not a.ok for a in flight.rf)
        # RF really arrived late in sensor time, and was reordered
        if rf_delay:
            assert graph.fusion.pipeline.buffer.max_depth > 1

        # the evaluator's table equals the offline evaluation of the same data
        live = graph.evaluator.evaluate()
        ev = Evaluator(radar_enu=site.radar.enu)
        feed_flight(ev, flight)
        ms = [m for it in _stream(flight) for m in it]
        feed_steps(ev, offline.steps, ms)
        ref = ev.evaluate()
        for a, b in zip(live.rows, ref.rows, strict=True):
            assert a.key == b.key
            assert a.stats.count == b.stats.count, a.key
            assert a.denominator == b.denominator, a.key
            if a.stats.count:
                assert a.stats.mean == pytest.approx(b.stats.mean, abs=1e-9), a.key
                assert a.stats.max == pytest.approx(b.stats.max, abs=1e-9), a.key
        report = graph.evaluator.write_report()
        assert Path(report.markdown).is_file()
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
