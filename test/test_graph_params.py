"""config/graph.yaml: every key is a declared parameter, and the graph starts from it."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest
import rclpy
import yaml
from rclpy.context import Context
from test_graph_flight import write_flight

from uav_fusion.nodes.graph import Graph
from uav_fusion.resources import config_path

GRAPH_YAML = config_path("graph.yaml")


@pytest.fixture()
def ctx() -> Iterator[Context]:
    context = Context()
    rclpy.init(context=context, args=["graph", "--ros-args", "--params-file", str(GRAPH_YAML)])
    yield context
    rclpy.shutdown(context=context)


def test_every_key_of_graph_yaml_is_a_parameter_with_that_value(
    ctx: Context, tmp_path: Path
) -> None:
    doc = yaml.safe_load(GRAPH_YAML.read_text())
    flight = write_flight(tmp_path / "f", seconds=10.0)
    over = {n: {"flight_dir": str(flight)} for n in ("truth_replay", "rf_replay", "radar_replay")}
    graph = Graph(ctx, over)
    try:
        by_name = {n.get_name(): n for n in graph.nodes}
        assert set(doc) == set(by_name)
        for name, section in doc.items():
            node = by_name[name]
            for key, value in section["ros__parameters"].items():
                assert node.has_parameter(key), f"{name}: '{key}' is not a parameter"
                if key != "flight_dir":
                    assert node.get_parameter(key).value == value, f"{name}.{key}"
        assert graph.rate == doc["truth_replay"]["ros__parameters"]["rate"]
    finally:
        graph.destroy()


def test_a_bad_value_in_a_params_file_is_refused(tmp_path: Path) -> None:
    bad = tmp_path / "bad.yaml"
    bad.write_text("fusion_node:\n  ros__parameters:\n    reorder_window_s: -4.0\n")
    from uav_fusion.nodes.fusion_node import main

    assert main(["fusion_node", "--ros-args", "--params-file", str(bad)]) == 2


def test_launch_file_is_valid_python_naming_our_executables() -> None:
    import ast

    from uav_fusion.resources import share_dir

    path = share_dir() / "launch" / "uav_fusion.launch.py"
    tree = ast.parse(path.read_text(), filename=str(path))
    compile(tree, str(path), "exec")
    funcs = {n.name for n in ast.walk(tree) if isinstance(n, ast.FunctionDef)}
    assert "generate_launch_description" in funcs
    names = {
        n.value for n in ast.walk(tree) if isinstance(n, ast.Constant) and isinstance(n.value, str)
    }
    for exe in ("truth_replay", "rf_replay", "radar_replay", "fusion_node", "evaluator_node"):
        assert exe in names
