"""ament_python build for uav_fusion (also a plain pip-installable package)."""

import os
from glob import glob

from setuptools import find_packages, setup

PACKAGE = "uav_fusion"

NODES = [
    "radar_replay",
    "rf_replay",
    "truth_replay",
    "radar_stream",
    "rf_stream",
    "truth_stream",
    "fusion_node",
    "evaluator_node",
    "bag_player",
    "bag_recorder",
    "graph",
]


def tree(top: str) -> list[tuple[str, list[str]]]:
    """data_files entries installing every file under ``top`` into share/<pkg>/<top>."""
    entries = []
    for root, _dirs, files in os.walk(top):
        paths = [os.path.join(root, f) for f in files]
        if paths:
            entries.append((os.path.join("share", PACKAGE, root), paths))
    return entries


setup(
    name=PACKAGE,
    version="0.1.0",
    packages=find_packages(exclude=["test", "test.*"]),
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + PACKAGE]),
        ("share/" + PACKAGE, ["package.xml"]),
        ("share/" + PACKAGE + "/launch", glob("launch/*.py")),
        *tree("config"),
        *tree("bench"),
        *tree("data"),
        *tree("bags"),
    ],
    install_requires=["setuptools"],
    zip_safe=True,
    maintainer="uav_fusion maintainers",
    maintainer_email="maintainers@uav-fusion.invalid",
    description="Radar + passive RF fusion for UAV tracking (ROS 2 Jazzy)",
    license="Apache-2.0",
    tests_require=["pytest"],
    entry_points={
        "console_scripts": [
            *[f"{n} = {PACKAGE}.nodes.{n}:main" for n in NODES],
            f"uav_fusion = {PACKAGE}.cli:main",
        ],
    },
)
