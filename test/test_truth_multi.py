"""truth_replay with several UAVs: one NavSatFix topic per vehicle, truth/fix the first's."""

from __future__ import annotations

from pathlib import Path

import pytest
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from sensor_msgs.msg import NavSatFix
from test_graph_flight import write_flight
from test_replay_nodes import Collector, _params, spin_until

from uav_fusion.core.data import load_flight
from uav_fusion.nodes.truth_replay import TruthReplay
from uav_fusion.ros import conversions as cv
from uav_fusion.ros.params import ParamError


@pytest.fixture(scope="module")
def multi_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = write_flight(tmp_path_factory.mktemp("flight") / "multi", seconds=20.0)
    (base,) = folder.glob("*_vehicleOut.txt")
    stamp = "2025-10-07_15-40-00"
    text = base.read_text()
    base.unlink()
    (folder / f"{stamp}_vehicleOut.txt").write_text(text)
    lines = text.splitlines(keepends=True)
    (folder / f"{stamp}_uav2_vehicleOut.txt").write_text("".join(lines[: len(lines) // 2]))
    return folder


def test_one_truth_topic_per_vehicle(ctx: Context, multi_dir: Path) -> None:
    flight = load_flight(multi_dir)
    assert list(flight.vehicles) == ["uav1", "uav2"]
    node = TruthReplay(
        context=ctx,
        parameter_overrides=_params(
            flight_dir=str(multi_dir), rate=0.0, wait_for_subscribers_s=5.0
        ),
    )
    topics = {"truth/fix": NavSatFix, "truth/uav1/fix": NavSatFix, "truth/uav2/fix": NavSatFix}
    col = Collector(ctx, topics)
    ex = SingleThreadedExecutor(context=ctx)
    for n in (node, col):
        ex.add_node(n)
    node.start_standalone()
    want = {
        "truth/fix": flight.truth,
        "truth/uav1/fix": flight.vehicles["uav1"],
        "truth/uav2/fix": flight.vehicles["uav2"],
    }
    spin_until(ex, lambda: all(len(col.got[t]) == len(v) for t, v in want.items()))
    for topic, fixes in want.items():
        for f, msg in zip(fixes, col.got[topic], strict=True):
            back = cv.navsatfix_to_truth(msg, node.site)
            assert (back.t, back.e, back.n, back.u) == (f.t, f.e, f.n, f.u)
    assert len(col.got["truth/uav2/fix"]) < len(col.got["truth/uav1/fix"])
    for n in (node, col):
        n.destroy_node()


def test_single_uav_flights_publish_truth_fix_only_unless_asked(
    ctx: Context, tmp_path: Path
) -> None:
    folder = write_flight(tmp_path / "single", seconds=10.0)
    auto = TruthReplay(context=ctx, parameter_overrides=_params(flight_dir=str(folder)))
    assert auto.vehicle_pubs == {}
    always = TruthReplay(
        context=ctx, parameter_overrides=_params(flight_dir=str(folder), per_vehicle="always")
    )
    assert [p.topic_name for p in always.vehicle_pubs.values()] == ["/truth/uav1/fix"]
    for n in (auto, always):
        n.destroy_node()


def test_a_vehicle_topic_without_the_vehicle_is_refused(ctx: Context, multi_dir: Path) -> None:
    with pytest.raises(ParamError, match="vehicle_topic"):
        TruthReplay(
            context=ctx,
            parameter_overrides=_params(flight_dir=str(multi_dir), vehicle_topic="truth/x/fix"),
        )
