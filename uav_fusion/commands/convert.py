"""``uav_fusion convert FOLDER --out BAG``: a flight folder as a rosbag2 MCAP bag."""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from uav_fusion.core.errors import ConfigError

HELP = "convert a flight folder (radar, RF, truth) into a rosbag2 MCAP bag"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("folder", type=Path, help="flight folder in the Dryad layout")
    parser.add_argument("--out", type=Path, required=True, help="bag directory to create")
    parser.add_argument("--site", type=Path, default=None, help="site YAML (default: bundled)")
    parser.add_argument("--rf-file", default="AADM.csv", help="RF CSV name (default AADM.csv)")
    parser.add_argument("--namespace", default="", help="topic namespace (default: none)")
    parser.add_argument(
        "--radar-sigma", type=float, nargs=3, metavar=("SE", "SN", "SU"), default=None,
        help="radar std devs (m) for the pose covariance; default: estimated against truth")
    parser.add_argument("--min-uav-prob", type=float, default=0.5,
                        help="catProb[0] needed for a report to go on radar/pose (default 0.5)")
    parser.add_argument("--strict", action="store_true", help="fail on the first bad line")


def run(args: argparse.Namespace) -> int:
    from uav_fusion.bag.convert import convert_flight
    from uav_fusion.bag.reader import BagReader
    from uav_fusion.core.dataset.flight import load_flight
    from uav_fusion.core.site import load_site

    if args.out.exists():
        raise ConfigError(f"{args.out}: exists already; a bag is never overwritten")
    site = load_site(args.site)
    flight = load_flight(args.folder, site, rf_file=args.rf_file, strict=args.strict)
    R = None
    if args.radar_sigma is not None:
        if any(not s > 0 for s in args.radar_sigma):
            raise ConfigError("--radar-sigma values must be > 0")
        R = np.diag(np.square(np.asarray(args.radar_sigma, dtype=float)))
    result = convert_flight(flight, site, args.out, namespace=args.namespace, radar_R=R,
                            min_uav_prob=args.min_uav_prob, progress=print)
    reader = BagReader(result.bag.path)  # read back: what a player will see
    print(reader.summary())
    for w in reader.warnings:
        print(f"warning: {w}")
    size = sum(f.stat().st_size for f in result.bag.path.iterdir() if f.is_file())
    print(f"wrote {result.bag.path} ({size / 1e6:.2f} MB)")
    return 0
