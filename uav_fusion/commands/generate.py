"""``uav_fusion generate``: simulate a flight with the digital twin and write its folder."""

from __future__ import annotations

import argparse
from pathlib import Path

from uav_fusion.core.errors import ConfigError
from uav_fusion.core.site import load_site
from uav_fusion.core.twin.config import DEFAULT_WAYPOINTS, load_twin_config
from uav_fusion.core.twin.generate import generate_twin
from uav_fusion.core.twin.trajectory import load_flight_plan
from uav_fusion.core.twin.worlds import load_worlds
from uav_fusion.core.twin.writers import write_twin
from uav_fusion.resources import config_path

HELP = "simulate a flight (radar, RF, RTK truth) and write it in the Dataset-28 formats"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--out", required=True, help="output folder (created if missing)")
    parser.add_argument("--seed", type=int, help="random seed (default: the config's, 1)")
    parser.add_argument(
        "--waypoints",
        help="flight plan YAML (default: config/waypoints/lake_wheeler_default.yaml)",
    )
    parser.add_argument(
        "--duration",
        type=float,
        help="recording length in s (default: until shortly after landing); a shorter one "
        "cuts the flight, a longer one keeps the vehicle on the ground after landing",
    )
    parser.add_argument(
        "--radar-tower",
        help="tower the radar stands beside (default: the site's, LW3); elsewhere its "
        "boresight points at the centre of the flight plan",
    )
    parser.add_argument(
        "--sensors", help="comma-separated RF sensor towers (default: the site's, LW2,LW3,LW4,LW5)"
    )
    parser.add_argument("--config", help="twin parameter YAML (default: config/twin_default.yaml)")
    parser.add_argument(
        "--scene-scale",
        type=float,
        help="multiply the radar scene's clutter, car and bird rates (default: the plan's)",
    )
    parser.add_argument("--site", help="site YAML (default: the shipped Lake Wheeler site)")
    parser.add_argument(
        "--world",
        metavar="FAMILY",
        help="draw the flight's physics from this world family (docs/twin.md, \"Worlds\"); "
        "the folder gets world.yaml with the drawn values",
    )
    parser.add_argument(
        "--worlds", help="world families YAML for --world (default: config/worlds.yaml)"
    )


def run(args: argparse.Namespace) -> int:
    site = load_site(args.site)
    cfg = load_twin_config(args.config)
    wp = Path(args.waypoints) if args.waypoints else config_path(DEFAULT_WAYPOINTS)
    plan = load_flight_plan(wp, site)
    if args.worlds and not args.world:
        raise ConfigError("--worlds needs --world FAMILY")
    world = load_worlds(args.worlds).family(args.world) if args.world else None
    sensors = None
    if args.sensors:
        sensors = [s.strip() for s in args.sensors.split(",") if s.strip()]
    twin = generate_twin(
        site,
        cfg,
        plan,
        seed=args.seed,
        duration_s=args.duration,
        radar_tower=args.radar_tower,
        sensors=sensors,
        scene_scale=args.scene_scale,
        world=world,
    )
    paths = write_twin(twin, args.out)
    n_reports = sum(len(f.tracks) for f in twin.radar)
    n_fix = sum(1 for a in twin.rf if a.attempt.ok)
    print(
        f"flight '{plan.name}', seed {twin.seed}, {twin.traj.duration:.1f} s from "
        f"{twin.start_datetime:%Y-%m-%d %H:%M:%S} UTC"
    )
    print(f"  {paths['truth']}: {twin.truth.t_us.size} truth rows")
    print(f"  {paths['radar']}: {len(twin.radar)} frames, {n_reports} track reports")
    print(f"  {paths['rf']}: {len(twin.rf)} attempts, {n_fix} fixes")
    print(f"  {paths['manifest']}")
    if twin.world is not None:
        print(f"  {paths['world']}: world family '{twin.world.family}'")
    return 0
