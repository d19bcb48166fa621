"""``uav_fusion bag reindex DIR``: rebuild a bag cut off by a kill (the MCAP summary where one
is missing, and ``metadata.yaml``; :mod:`uav_fusion.bag.reindex`), then check that it opens
in rosbags, in the mcap seeking reader and in the bag player's reader."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

HELP = "bag tools: reindex (rebuild a recording cut off by a kill)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    sub = parser.add_subparsers(dest="bag_command", required=True, metavar="TOOL")
    p = sub.add_parser(
        "reindex",
        help="rebuild metadata.yaml, and the MCAP summary where one is missing",
        description="rebuild metadata.yaml, and the MCAP summary where one is missing, of a "
        "bag whose recorder was killed; every whole chunk stays readable",
    )
    p.add_argument("bag", type=Path, help="the bag folder")
    p.add_argument("--dry-run", action="store_true", help="only say what would be done")
    p.add_argument("--no-check", action="store_true", help="skip reading the result back")


def check(bag: Path, expected: int) -> list[str]:
    """Read ``bag`` with rosbags, the mcap seeking reader and BagReader; problems found."""
    from mcap.reader import SeekingReader
    from rosbags.rosbag2 import Reader

    from uav_fusion.bag.reader import BagReader

    problems = []
    with Reader(bag) as r:
        n = sum(1 for _ in r.messages())
    if n != expected:
        problems.append(f"rosbags reads {n} messages, expected {expected}")
    m = 0
    for f in sorted(bag.glob("*.mcap")):
        with f.open("rb") as fh:
            m += sum(1 for _ in SeekingReader(fh).iter_messages())
    if m != expected:
        problems.append(f"the mcap seeking reader reads {m} messages, expected {expected}")
    br = BagReader(bag)
    k = sum(1 for _ in br.messages())
    if k != expected or br.warnings:
        warned = "; ".join(br.warnings) or "no warning"
        problems.append(f"BagReader reads {k} messages ({warned}), expected {expected}")
    return problems


def run(args: argparse.Namespace) -> int:
    from uav_fusion.bag.reindex import reindex

    rep = reindex(args.bag, dry_run=args.dry_run)
    print(rep.summary())
    if args.dry_run or args.no_check:
        return 0
    problems = check(args.bag, rep.message_count)
    for p in problems:
        print(f"uav_fusion bag reindex: {p}", file=sys.stderr)
    if not problems:
        print(f"checked: rosbags, the mcap seeking reader and the bag player's reader each read "
              f"all {rep.message_count} messages")
    return 1 if problems else 0
