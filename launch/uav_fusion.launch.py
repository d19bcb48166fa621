"""Launch the live graph as separate processes (a real ROS 2 Jazzy install).

    ros2 launch uav_fusion uav_fusion.launch.py
    ros2 launch uav_fusion uav_fusion.launch.py flight_dir:=/data/Opt1 rate:=5.0

Parameters come from ``params_file`` (default: the package's config/graph.yaml); the
arguments below override the most used ones. truth_replay drives ``/clock``; it waits
until the four ``use_sim_time`` nodes of this launch (rf_replay, radar_replay, fusion_node,
evaluator_node) subscribe to it, so every replay follows one timeline from the start.
Set ``evaluator:=false`` to leave the evaluator out.
"""

from launch.actions import DeclareLaunchArgument
from launch.conditions import IfCondition
from launch.substitutions import LaunchConfiguration, PathJoinSubstitution
from launch_ros.actions import Node
from launch_ros.substitutions import FindPackageShare

from launch import LaunchDescription

PACKAGE = "uav_fusion"


def generate_launch_description() -> LaunchDescription:
    params_file = LaunchConfiguration("params_file")
    flight_dir = LaunchConfiguration("flight_dir")
    rate = LaunchConfiguration("rate")
    profile = LaunchConfiguration("profile")
    output_dir = LaunchConfiguration("output_dir")
    evaluator = LaunchConfiguration("evaluator")
    clock_subscribers = LaunchConfiguration("clock_subscribers")

    args = [
        DeclareLaunchArgument(
            "params_file",
            default_value=PathJoinSubstitution([FindPackageShare(PACKAGE), "config", "graph.yaml"]),
            description="YAML parameter file (sections = node names)",
        ),
        DeclareLaunchArgument(
            "flight_dir",
            default_value=PathJoinSubstitution(
                [FindPackageShare(PACKAGE), "data", "default_flight"]
            ),
            description="flight folder in the Dataset-28 layout (default: the bundled flight)",
        ),
        DeclareLaunchArgument(
            "rate",
            default_value="20.0",
            description=(
                "replay speed, times real time (> 0 here: with the evaluator in its own"
                " process, 0.0 is paced by DDS acknowledgements and runs slower than real"
                " time; for a fast lossless run use 'ros2 run uav_fusion uav_fusion demo')"
            ),
        ),
        DeclareLaunchArgument(
            "profile", default_value="tracker", description="estimator profile (tracker, paper)"
        ),
        DeclareLaunchArgument(
            "output_dir", default_value="out/report", description="evaluator report folder"
        ),
        DeclareLaunchArgument(
            "evaluator", default_value="true", description="start the evaluator node"
        ),
        DeclareLaunchArgument(
            "clock_subscribers",
            default_value="4",
            description="/clock subscribers truth_replay waits for (3 without the evaluator)",
        ),
    ]

    def replay(name: str, extra: dict) -> Node:
        return Node(
            package=PACKAGE,
            executable=name,
            name=name,
            output="screen",
            parameters=[params_file, {"flight_dir": flight_dir, **extra}],
        )

    nodes = [
        replay("rf_replay", {"use_sim_time": True}),
        replay("radar_replay", {"use_sim_time": True, "profile": profile}),
        Node(
            package=PACKAGE,
            executable="fusion_node",
            name="fusion_node",
            output="screen",
            parameters=[params_file, {"use_sim_time": True, "profile": profile}],
        ),
        Node(
            package=PACKAGE,
            executable="evaluator_node",
            name="evaluator_node",
            output="screen",
            parameters=[
                params_file,
                # the flight's radar file supplies RCS for the report's histogram
                {"use_sim_time": True, "output_dir": output_dir, "rcs_flight_dir": flight_dir},
            ],
            condition=IfCondition(evaluator),
        ),
        replay(
            "truth_replay",
            {
                "rate": rate,
                "publish_clock": True,
                "wait_for_clock_subscribers": clock_subscribers,
            },
        ),
    ]
    return LaunchDescription([*args, *nodes])
