"""``uav_fusion``: the package's command line tool (generate, calibrate, run, demo, bench, ...)."""

from __future__ import annotations

import argparse
import importlib
import sys
from collections.abc import Sequence

from uav_fusion.core.errors import UavFusionError

# subcommand name -> module under uav_fusion.commands
COMMANDS: dict[str, str] = {
    "generate": "generate",
    "calibrate": "calibrate",
    "estimate-r": "estimate_r",
    "run": "run",
    "evaluate": "evaluate",
    "convert": "convert",
    "emulate": "emulate",
    "bag": "bag",
    "demo": "demo",
    "bench": "bench",
    "sweep": "sweep",
    "analyse": "analyse",
    "profile": "profile",
}


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="uav_fusion", description="Radar + passive RF UAV tracking tools."
    )
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for name, module in COMMANDS.items():
        try:
            mod = importlib.import_module(f"uav_fusion.commands.{module}")
        except ModuleNotFoundError as exc:
            if exc.name == f"uav_fusion.commands.{module}":
                continue  # command not available in this build
            raise
        p = sub.add_parser(name, help=mod.HELP, description=mod.HELP)
        mod.add_arguments(p)
        p.set_defaults(_run=mod.run)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return int(args._run(args))
    except UavFusionError as exc:
        print(f"uav_fusion {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130


if __name__ == "__main__":
    sys.exit(main())
