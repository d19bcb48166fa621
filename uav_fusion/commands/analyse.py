"""``uav_fusion analyse {misses,oracle,false-tracks,locks}``: where the tracker falls short on
the benchmark's flights, and why (:mod:`uav_fusion.core.analysis`).

Every analysis reads a benchmark definition's split (flights generated into the cache first
when missing) and regenerates each flight's twin in memory to learn which object each radar
track was following. The definition decides between the single-UAV tracker (``targets:
single``, e.g. ``--definition accuracy``, the default) and the multi-UAV tracker (``targets:
multi``, e.g. ``--definition multi``), as ``uav_fusion bench`` does:

* ``misses``: every missed epoch put down to one cause (single- and multi-UAV);
* ``oracle``: the tracker beside the same filter with association from the twin's labels
  (single- and multi-UAV);
* ``false-tracks``: what the multi-UAV tracker's false tracks follow (multi-UAV only;
  default definition ``multi``);
* ``locks``: what the single-UAV tracker follows, in seconds per kind of object (single-UAV
  only).

The figures go to standard output, one line per flight as it finishes and the pooled figures
at the end; progress (the flight being worked on) goes to standard error.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import Any

from uav_fusion.core.analysis import false_tracks, locks, misses, oracle
from uav_fusion.core.analysis.labels import FlightSet
from uav_fusion.core.bench.definition import SPLITS, load_definition
from uav_fusion.core.errors import ConfigError
from uav_fusion.core.profiles.model import Profile, load_profile
from uav_fusion.core.site import load_site
from uav_fusion.resources import DEFAULT_SITE, config_path

HELP = "analyses of the tracker on the benchmark's flights: misses, oracle, false tracks, locks"

# option -> (the targets it applies to, its default)
_SINGLE = "single"
_MULTI = "multi"
_MODE_OPTIONS: dict[str, dict[str, tuple[str, float]]] = {
    "misses": {
        "reentry_s": (_SINGLE, 15.0),
        "stale_s": (_SINGLE, 5.0),
        "far_m": (_SINGLE, 1500.0),
        "low_m": (_MULTI, 20.0),
        "near_m": (_MULTI, 100.0),
    },
    "oracle": {
        "coverage_pct": (_SINGLE, 99.0),
        "gross_pct": (_SINGLE, 1.0),
        "window_s": (_SINGLE, 5.0),
    },
}
_HELPS = {
    "reentry_s": "an uncovered epoch this soon after the UAV came into the radar's view is "
    "a re-entry",
    "stale_s": "a gross epoch whose last update (or last radar update) is older is a coast "
    "(or an RF one)",
    "far_m": "a gross epoch from the UAV's own report off is 'far' beyond this range",
    "low_m": "a missed epoch this close to the pad's height is 'low'",
    "near_m": "a missed epoch with another airborne UAV this close horizontally is 'beside'",
    "coverage_pct": "the coverage target per flight",
    "gross_pct": "the gross-error target per flight",
    "window_s": "the UAV's radar reports looked back at for each gross epoch",
}

_DESCRIPTIONS = {
    "misses": "Why the tracker misses the UAV where it should have it. Single-UAV: each "
    "radar-observable epoch with nothing published (start-up, re-entry, other) or more than "
    "100 m off (coast, rf, another object, the UAV's own report off, the track's own error). "
    "Multi-UAV: each airborne UAV-epoch with no track assigned (start-up, low, beside another "
    "UAV, other; seen by the radar or not). See uav_fusion/core/analysis/misses.py.",
    "oracle": "The tracker beside the same filter with association from the twin's labels "
    "(only the UAV's own radar tracks and control link), both scored as the benchmark scores "
    "them: what association costs, and what the sensors themselves allow. See "
    "uav_fusion/core/analysis/oracle.py.",
    "false-tracks": "What the multi-UAV tracker's false tracks follow (bird, clutter, ghost, "
    "a UAV with the track off it), per flight and pooled, and what the confirmed tracks were "
    "born on. See uav_fusion/core/analysis/false_tracks.py.",
    "locks": "What the single-UAV tracker's confirmed track follows, in seconds per kind of "
    "object, and for how long it is more than 100 m off the UAV while on another object. See "
    "uav_fusion/core/analysis/locks.py.",
}


def _common(p: argparse.ArgumentParser, default_definition: str, profiles: bool) -> None:
    p.add_argument(
        "--definition",
        default=default_definition,
        help="benchmark definition: a name under bench/ or a YAML path; its targets (single "
        f"or multi) choose the tracker (default: {default_definition})",
    )
    p.add_argument(
        "--split", choices=SPLITS, default="tune", help="which half to analyse (default: tune)"
    )
    if profiles:
        p.add_argument(
            "--profiles", nargs="+", default=["tracker"], metavar="PROFILE",
            help="tracker profiles: names (config/profiles/<name>.yaml) or YAML paths "
            "(default: tracker)",
        )  # fmt: skip
    else:
        p.add_argument(
            "--profile",
            default="tracker",
            help="tracker profile: a name (config/profiles/<name>.yaml) or a YAML path "
            "(default: tracker)",
        )
    p.add_argument(
        "--cache", default="out/bench_cache", help="flight cache folder (default: out/bench_cache)"
    )
    p.add_argument("--site", help="site YAML (default: the shipped Lake Wheeler site)")


def _mode_options(p: argparse.ArgumentParser, analysis: str) -> None:
    for dest, (targets, default) in _MODE_OPTIONS[analysis].items():
        p.add_argument(
            "--" + dest.replace("_", "-"),
            dest=dest,
            type=float,
            help=f"{_HELPS[dest]} ({targets}-UAV definitions; default: {default:g})",
        )


def add_arguments(parser: argparse.ArgumentParser) -> None:
    sub = parser.add_subparsers(dest="analysis", required=True, metavar="ANALYSIS")
    p = sub.add_parser(
        "misses",
        help="every missed epoch of the tracker put down to one cause",
        description=_DESCRIPTIONS["misses"],
    )
    _common(p, "accuracy", profiles=False)
    _mode_options(p, "misses")
    p = sub.add_parser(
        "oracle",
        help="the tracker beside the same filter with association from the twin's labels",
        description=_DESCRIPTIONS["oracle"],
    )
    _common(p, "accuracy", profiles=False)
    _mode_options(p, "oracle")
    p = sub.add_parser(
        "false-tracks",
        help="what the multi-UAV tracker's false tracks follow (multi-UAV definitions)",
        description=_DESCRIPTIONS["false-tracks"],
    )
    _common(p, "multi", profiles=False)
    p.add_argument(
        "--strict-grounded",
        action="store_true",
        help="a track on a UAV that is not airborne counts as false (default: one is excused)",
    )
    p = sub.add_parser(
        "locks",
        help="what the single-UAV tracker follows, in seconds per kind of object "
        "(single-UAV definitions)",
        description=_DESCRIPTIONS["locks"],
    )
    _common(p, "accuracy", profiles=True)


def _tracker_profile(name: str, flag: str, analysis: str) -> Profile:
    p = load_profile(name)
    if not p.uses_tracker:
        raise ConfigError(
            f"{flag} {name}: analyse {analysis} needs a tracker profile ('estimator: tracker' "
            f"or 'multi'); {p.source or p.name} is not one"
        )
    return p


def _resolve(args: argparse.Namespace, targets: str) -> dict[str, float]:
    """The analysis's mode options for ``targets``: those of the other targets must not be
    given; the others get their defaults."""
    out: dict[str, float] = {}
    for dest, (applies, default) in _MODE_OPTIONS.get(args.analysis, {}).items():
        value = getattr(args, dest)
        flag = "--" + dest.replace("_", "-")
        if applies != targets:
            if value is not None:
                raise ConfigError(
                    f"{flag} applies to {applies}-UAV definitions; --definition "
                    f"{args.definition} is a {targets}-UAV one"
                )
            continue
        out[dest] = default if value is None else float(value)
    return out


def _emit(lines: Sequence[str]) -> None:
    for line in lines:
        print(line)
    sys.stdout.flush()


def run(args: argparse.Namespace) -> int:
    definition = load_definition(args.definition)
    targets = _MULTI if definition.multi else _SINGLE
    only = {"false-tracks": _MULTI, "locks": _SINGLE}.get(args.analysis)
    if only is not None and only != targets:
        example = "multi" if only == _MULTI else "accuracy"
        raise ConfigError(
            f"--definition {args.definition}: analyse {args.analysis} needs a {only}-UAV "
            f"definition ({definition.source} has targets: {definition.targets}); e.g. "
            f"--definition {example}"
        )
    options = _resolve(args, targets)
    if args.analysis == "locks":
        profiles = [_tracker_profile(p, "--profiles", "locks") for p in args.profiles]
        names = [p.name for p in profiles]
        for p, arg in zip(profiles, args.profiles, strict=True):
            if names.count(p.name) > 1:
                raise ConfigError(
                    f"--profiles {arg}: profile name {p.name!r} is used by two of the listed "
                    "profiles (the figures are named by it)"
                )
    else:
        profiles = [_tracker_profile(args.profile, "--profile", args.analysis)]
        names = [profiles[0].name]
    site_file = Path(args.site) if args.site else config_path(DEFAULT_SITE)
    fs = FlightSet(definition, args.split, Path(args.cache), load_site(site_file), site_file)
    t_start = time.perf_counter()

    def progress(msg: str) -> None:
        print(
            f"analyse {args.analysis}: {msg} ({time.perf_counter() - t_start:.0f} s)",
            file=sys.stderr,
            flush=True,
        )

    n = len(definition.flights(args.split))
    progress(
        f"{definition.name} {args.split}, {n} flights, {targets}-UAV tracker, "
        f"profile{'s' if len(names) > 1 else ''} {', '.join(names)}"
    )
    flights, summarise = _plan(args, targets, fs, profiles, options, progress)
    done = []
    for f in flights:  # a line per flight as it finishes
        _emit([f.line()])
        done.append(f)
    _emit(summarise(done))
    return 0


Plan = tuple[Iterator[Any], Callable[[list[Any]], list[str]]]


def _plan(
    args: argparse.Namespace,
    targets: str,
    fs: FlightSet,
    profiles: list[Profile],
    o: dict[str, float],
    progress: Callable[[str], None],
) -> Plan:
    """The analysis's flights (each with its ``line()``) and how their pooled figures are
    printed."""
    p = profiles[0]
    what = (args.analysis, targets)
    if what == ("misses", _SINGLE):
        opt_m = misses.SingleOptions(o["reentry_s"], o["stale_s"], o["far_m"])
        return (
            misses.single_misses(fs, p, opt_m, progress),
            lambda done: misses.single_summary(done, p.name, fs),
        )
    if what == ("misses", _MULTI):
        opt_mm = misses.MultiOptions(o["low_m"], o["near_m"])
        return misses.multi_misses(fs, p, opt_mm, progress), misses.multi_summary
    if what == ("oracle", _SINGLE):
        opt_o = oracle.SingleOptions(o["coverage_pct"], o["gross_pct"], o["window_s"])
        return (
            oracle.single_oracle(fs, p, opt_o, progress),
            lambda done: oracle.single_summary(done, fs, opt_o),
        )
    if what == ("oracle", _MULTI):
        return oracle.multi_oracle(fs, p, progress), oracle.multi_summary
    if what == ("false-tracks", _MULTI):
        strict = bool(args.strict_grounded)
        return (
            false_tracks.false_tracks(fs, p, strict, progress),
            lambda done: false_tracks.summary(done, strict),
        )
    names = [q.name for q in profiles]  # locks, single-UAV: run() refused the other pairs
    return locks.locks(fs, profiles, progress), lambda done: locks.summary(done, names)
