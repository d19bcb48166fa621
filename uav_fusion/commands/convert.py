"""``uav_fusion convert FOLDER --out BAG``: a flight folder as a rosbag2 MCAP bag."""

from __future__ import annotations

import argparse
from pathlib import Path

from uav_fusion.core.errors import ConfigError

HELP = "convert a flight folder (radar, RF, truth) into a rosbag2 MCAP bag"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("folder", type=Path, help="flight folder in the Dryad layout")
    parser.add_argument("--out", type=Path, required=True, help="bag directory to create")
    parser.add_argument("--site", type=Path, default=None, help="site YAML (default: bundled)")
    parser.add_argument("--rf-file", default="AADM.csv", help="RF CSV name (default AADM.csv)")
    parser.add_argument("--namespace", default="", help="topic namespace (default: none)")
    parser.add_argument("--profile", default="paper",
                        help="estimator profile: radar R, UAV class, track selection (paper)")
    parser.add_argument("--track-selection", default="profile",
                        help="radar track selection policy ('profile': the profile's own)")
    parser.add_argument("--truth-frame", default="gps", help="frame id of truth (gps)")
    parser.add_argument("--strict", action="store_true", help="fail on the first bad line")


def run(args: argparse.Namespace) -> int:
    from uav_fusion.bag.convert import convert_flight
    from uav_fusion.bag.reader import BagReader
    from uav_fusion.core.data.flight import load_flight
    from uav_fusion.core.site import load_site

    if args.out.exists():
        raise ConfigError(f"{args.out}: exists already; a bag is never overwritten")
    site = load_site(args.site)
    flight = load_flight(args.folder, site, rf_file=args.rf_file, strict=args.strict)
    result = convert_flight(flight, site, args.out, profile=args.profile,
                            track_selection=args.track_selection, namespace=args.namespace,
                            truth_frame=args.truth_frame, progress=print)
    reader = BagReader(result.bag.path)  # read back: what a player will see
    print(reader.summary())
    for w in reader.warnings:
        print(f"warning: {w}")
    size = sum(f.stat().st_size for f in result.bag.path.iterdir() if f.is_file())
    print(f"wrote {result.bag.path} ({size / 1e6:.2f} MB)")
    return 0
