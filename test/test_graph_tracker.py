"""The live graph with the tracker on the bundled flight: Table II and the evaluator's score of
the fixed-rate fusion/odom equal the offline run's."""

from __future__ import annotations

from pathlib import Path

import pytest
from rclpy.context import Context

from uav_fusion.core.data import load_flight
from uav_fusion.core.estimators import load_profile, run_flight
from uav_fusion.core.estimators.consider import published_cov
from uav_fusion.core.scoring.fixed_rate import FlightTruth, grid_from_steps, pool, score_grid
from uav_fusion.core.site import load_site
from uav_fusion.nodes.graph import Graph
from uav_fusion.resources import DEFAULT_FLIGHT, data_path


@pytest.mark.parametrize("rate", [0.0, 50.0], ids=["rate0", "rate50"])
def test_live_tracker_graph_scores_its_fixed_rate_output_like_the_benchmark(
    ctx: Context, tmp_path: Path, rate: float
) -> None:
    flight_dir = data_path(DEFAULT_FLIGHT)
    replay = {"flight_dir": str(flight_dir), "wait_for_subscribers_s": 5.0}
    ov = {
        "truth_replay": {**replay, "rate": rate},
        "rf_replay": dict(replay),
        "radar_replay": {**replay, "profile": "tracker"},
        "fusion_node": {"profile": "tracker", "use_sim_time": True, "idle_flush_s": 0.0,
                        "stall_timeout_s": 0.0},
        "evaluator_node": {
            "output_dir": str(tmp_path / "report"), "figures": False, "log_period_s": 0.0,
            "write_on_shutdown": False, "use_sim_time": True, "grid_topic": "fusion/odom",
        },
    }  # fmt: skip
    graph = Graph(ctx, ov)
    try:
        res = graph.run(timeout_s=300.0, write_report=False)
        assert res.ok, res.message
        live = graph.evaluator.grid_score()
        steps_live = graph.fusion.steps_published
    finally:
        graph.destroy()
    site = load_site()
    flight = load_flight(flight_dir, site)
    profile = load_profile("tracker")
    run = run_flight(flight, profile, site)
    assert steps_live == sum(1 for s in run.steps if s.updated or s.coasted)  # nothing lost
    truth = FlightTruth.from_flight(flight, site)
    t0, t1 = truth.span
    grid = grid_from_steps(run.steps, profile, 10.0, t0, t1, consider=published_cov(profile, site))
    offline = pool([score_grid(grid, truth)])
    assert live is not None and live.epochs == offline.epochs > 5000
    for key in ("coverage_pct", "err_mean_m", "err_p50_m", "err_p95_m", "err_max_m",
                "gross_pct", "anees", "nees_in95_pct"):  # fmt: skip
        assert getattr(live, key) == pytest.approx(getattr(offline, key), rel=1e-9, abs=1e-9), key
    assert live.coverage_pct > 80.0
