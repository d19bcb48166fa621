"""``uav_fusion profile``: the profile reference and resolved profiles.

``uav_fusion profile doc`` prints ``config/profiles/README.md`` as the schema gives it
(``uav_fusion profile doc > config/profiles/README.md``); ``uav_fusion profile show NAME``
prints a profile as loaded, after ``extends``, every key with its value.
"""

from __future__ import annotations

import argparse
import sys

import yaml

from uav_fusion.core.profiles.model import load_profile
from uav_fusion.core.profiles.reference import readme

HELP = "profile reference (doc) and resolved profiles (show NAME)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    sub = parser.add_subparsers(dest="action", required=True, metavar="ACTION")
    sub.add_parser("doc", help="print config/profiles/README.md, generated from the schema")
    show = sub.add_parser("show", help="print profiles as resolved (after extends)")
    show.add_argument("profiles", nargs="+", metavar="NAME", help="profile names or YAML paths")


def run(args: argparse.Namespace) -> int:
    if args.action == "doc":
        sys.stdout.write(readme())
        return 0
    for i, name in enumerate(args.profiles):
        p = load_profile(name)
        if i:
            sys.stdout.write("---\n")
        sys.stdout.write(f"# {p.source} (resolved)\n")
        doc = p.as_dict()
        sys.stdout.write(yaml.safe_dump(doc, sort_keys=False, width=96, default_flow_style=None))
    return 0
