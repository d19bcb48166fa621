"""Fault cases, areas "load" and "accounting": the whole graph pushed faster than it accepts
(loss must be reported, not silent), and the invariant received = used + rejected (by
reason) + dropped (by reason) for every input stream, in /diagnostics and in the report."""

from __future__ import annotations

import json
import math
import random
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray
from faultkit import (
    FRAME,
    RADAR,
    RF,
    T0,
    FusionHarness,
    accounting,
    radar_msg,
    rf_msg,
    straight,
)
from rclpy.context import Context

from uav_fusion.nodes.graph import Graph
from uav_fusion.ros import conversions as cv


def overrides(flight_dir: Path, out: Path, rate: float, depth: int = 1000) -> dict[str, Any]:
    replay = {"flight_dir": str(flight_dir), "wait_for_subscribers_s": 5.0, "qos_depth": depth}
    return {
        "truth_replay": {**replay, "rate": rate, "clock_period_s": 0.005},
        "rf_replay": dict(replay),
        "radar_replay": dict(replay),
        "fusion_node": {"use_sim_time": True, "idle_flush_s": 0.0, "qos_depth": depth,
                        "diagnostics_period_s": 0.05},
        "evaluator_node": {
            "output_dir": str(out),
            "figures": False,
            "log_period_s": 0.05,
            "write_on_shutdown": False,
            "use_sim_time": True,
            "qos_depth": depth,
        },
    }


class DiagTap:
    """Keeps the latest /diagnostics values per status name."""

    def __init__(self, graph: Graph) -> None:
        self.values: dict[str, dict[str, str]] = {}
        graph.evaluator.create_subscription(DiagnosticArray, "/diagnostics", self._on, 100)

    def _on(self, msg: DiagnosticArray) -> None:
        for st in msg.status:
            self.values[st.name] = {kv.key: kv.value for kv in st.values}

    def named(self, suffix: str) -> dict[str, str]:
        for k, v in self.values.items():
            if k.endswith(suffix):
                return v
        return {}


@pytest.mark.fault("LOAD-01")
def test_lossless_rate_delivers_every_message_and_counts_agree(
    ctx: Context, short_flight: Path, tmp_path: Path
) -> None:
    g = Graph(ctx, overrides(short_flight, tmp_path / "rep", rate=0.0))
    try:
        res = g.run(timeout_s=120.0)
        assert res.ok, res.message
        assert res.lost == {} and g.lost_messages() == {}
        f = g.fusion
        assert f.received[RADAR] == g.driver.published_to(g.radar.pub)
        assert f.received[RF] == g.driver.published_to(g.rf.pub)
    finally:
        g.destroy()


@pytest.mark.fault("LOAD-02")
def test_loss_beyond_what_the_graph_accepts_is_reported_with_counts(
    ctx: Context, short_flight: Path, tmp_path: Path
) -> None:
    """Queues of depth 1 and a replay 2000x faster than real time: the reliable writer
    overwrites what the fusion node has not taken yet. The run fails with a message naming
    what was lost, and the counts equal published minus received."""
    g = Graph(ctx, overrides(short_flight, tmp_path / "rep", rate=2000.0, depth=1))
    try:
        res = g.run(timeout_s=60.0)
        assert not res.ok
        assert "messages were lost in transport" in res.message
        assert "the publishing rate is beyond what the graph accepts" in res.message
        lost = res.lost
        assert lost.get("fusion_node: radar", 0) > 0
        assert lost["fusion_node: radar"] == g.driver.published_to(g.radar.pub) - g.fusion.received[
            RADAR
        ]
        assert f"fusion_node: radar {lost['fusion_node: radar']}" in res.message
    finally:
        g.destroy()


@pytest.mark.fault("ACC-01")
def test_every_stream_balances_in_diagnostics_and_in_the_report(
    ctx: Context, short_flight: Path, tmp_path: Path
) -> None:
    """The short flight through the whole graph: for both fusion inputs received = used +
    rejected + dropped as published on /diagnostics; for every evaluator topic received =
    used + refused + dropped, and the report lists the same counts."""
    g = Graph(ctx, overrides(short_flight, tmp_path / "rep", rate=0.0))
    tap = DiagTap(g)
    try:
        res = g.run(timeout_s=120.0)
        assert res.ok, res.message
        want = g.fusion.diagnostics()
        assert g.spin_until(
            lambda: tap.named(": fusion").get("steps_published") == want["steps_published"]
            and tap.named(": inputs") != {},
            10.0,
        )
        fd = tap.named(": fusion")
        for src in (RADAR, RF):
            rec, used, rej, drop = accounting(fd, src)
            assert rec > 0 and rec == used + rej + drop, (src, fd)
        assert int(fd["rejected_rf_failed_attempt"]) > 0  # the flight has failed attempts
        assert int(fd.get("rejected_rf_nis", "0")) > 0  # and NLOS outliers
        ev = g.evaluator
        for topic, n in ev.received.items():
            dropped = sum(v for k, v in ev.dropped.items() if k.startswith(f"{topic}: "))
            assert n == ev.used[topic] + ev.refused[topic] + dropped, topic
        inputs = tap.named(": inputs")
        assert inputs[f"received {ev.truth_topic}"] == inputs[f"used {ev.truth_topic}"]
        md = Path(res.report or "").joinpath("report.md").read_text()
        assert f"{ev.truth_topic} {ev.received[ev.truth_topic]}" in md
        assert "messages used" in md and "messages dropped" in md
        meta = json.loads(Path(res.report or "").joinpath("metrics.json").read_text())
        assert meta["rf_attempts"] == ev.used[ev.rf_topic]
    finally:
        g.destroy()


@pytest.mark.fault("ACC-02")
def test_a_storm_of_mixed_faults_still_balances(ctx: Context) -> None:
    """400 radar and 60 RF messages with a random 30 % of them damaged in one of eight ways:
    every message is accounted for under exactly one reason."""
    rng = random.Random(11)
    h = FusionHarness(ctx, reorder_window_s=1.0)
    ts = [T0 + 0.25 * k for k in range(400)]
    damaged = 0
    feed: list[Any] = []
    for k, t in enumerate(ts):
        m = radar_msg(t, *straight(t))
        fault = rng.random() < 0.3 and k > 4
        if fault:
            damaged += 1
            kind = rng.choice(
                ["nan", "cov", "frame", "zero", "late", "dup", "future", "asym"]
            )
            if kind == "nan":
                m.pose.pose.position.x = math.nan
            elif kind == "cov":
                m.pose.covariance[0] = -1.0
            elif kind == "asym":
                m.pose.covariance[1] = 3.0
            elif kind == "frame":
                m.header.frame_id = "base_link"
            elif kind == "zero":
                m.header.stamp = Time()
            elif kind == "late":
                m = radar_msg(t - 30.0, *straight(t))
            elif kind == "dup":
                feed.append(m)  # sent twice
            elif kind == "future":
                m = radar_msg(t + rng.uniform(1000.0, 100000.0), *straight(t))
        feed.append(m)
        if k % 7 == 3:
            e, n, _ = straight(t + 0.1)
            feed.append(rf_msg(t + 0.1, e + rng.gauss(0, 15), n + rng.gauss(0, 15)))
        if k % 29 == 5:
            feed.append(cv.rf_to_msg(t + 0.2, None, FRAME))
    for k in range(0, len(feed), 10):
        h.send(*feed[k : k + 10])
    h.settle()
    d = h.diagnostics()
    for src in (RADAR, RF):
        rec, used, rej, drop = accounting(d, src)
        assert rec == used + rej + drop, (src, d)
    assert int(d["received_radar"]) == sum(
        1 for m in feed if not hasattr(m, "point")
    )
    drops = h.fusion.dropped
    assert set(drops) <= {
        "radar_nan", "radar_bad_covariance", "radar_wrong_frame", "radar_zero_stamp",
        "late_radar", "radar_duplicate", "radar_future",
    }, drops
    assert sum(drops.values()) == damaged
    assert int(d["used_radar"]) > 250  # the clean ones are still fused
    assert np.isfinite([o.pose.pose.position.x for o in h.odom]).all()
    h.destroy()
