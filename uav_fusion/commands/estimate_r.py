"""``uav_fusion estimate-r``: measurement covariances R from a flight, optionally into a profile."""

from __future__ import annotations

import argparse
import datetime as _dt
from pathlib import Path

import numpy as np
import yaml

from uav_fusion.core.errors import ConfigError
from uav_fusion.core.site import load_site
from uav_fusion.resources import DEFAULT_FLIGHT, data_path

HELP = "estimate the radar and RF measurement covariances R against truth (MATLAB cov)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "folder",
        nargs="?",
        help="flight folder in the Dataset-28 layout (default: the bundled default flight)",
    )
    parser.add_argument("--site", help="site YAML (default: the shipped Lake Wheeler site)")
    parser.add_argument(
        "--rf-file", default="AADM.csv", help="RF CSV name inside the folder (default: AADM.csv)"
    )
    parser.add_argument(
        "--radar-select",
        choices=("largest_gated", "largest", "all"),
        default="largest_gated",
        help="radar reports used: largest track inside the range gate (default), "
        "largest track, or every report",
    )
    parser.add_argument(
        "--radar-method",
        choices=("all", "trim"),
        default="all",
        help="radar: plain sample covariance (default) or chi-square trimmed",
    )
    parser.add_argument(
        "--rf-method",
        choices=("all", "trim"),
        default="trim",
        help="RF: chi-square trimmed (default; raw RF errors are heavy-tailed) or the "
        "plain sample covariance of every fix (the paper's literal procedure)",
    )
    parser.add_argument(
        "--trim-probability",
        type=float,
        default=0.99,
        help="chi-square probability of the trim (default: 0.99)",
    )
    parser.add_argument(
        "--range-gate", type=float, help="radar range gate in m (default: the site's)"
    )
    parser.add_argument(
        "--q-horizon",
        type=float,
        default=4.0,
        metavar="S",
        help="horizon of the truth velocity increments behind the suggested q (default: 4 s)",
    )
    parser.add_argument(
        "--write-profile",
        metavar="YAML",
        help="write the two R matrices into this profile file (other keys are kept)",
    )


def _fmt(R: np.ndarray) -> str:
    return "\n".join("    [" + ", ".join(f"{v:12.3f}" for v in row) + "]" for row in R)


def write_r_into_profile(path: Path, radar_R: np.ndarray, rf_R: np.ndarray, note: str) -> None:
    """Replace measurement.radar.R / measurement.rf.R (and the note) of a profile YAML."""
    from uav_fusion.core.profiles.model import profile_from_dict

    if not path.is_file():
        raise ConfigError(f"{path}: profile file not found")
    text = path.read_text(encoding="utf-8")
    try:
        doc = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        raise ConfigError(f"{path}: not valid YAML: {exc}") from None
    if not isinstance(doc, dict):
        raise ConfigError(f"{path}: expected a mapping at top level")
    meas = doc.setdefault("measurement", {})
    meas.setdefault("radar", {})["R"] = [[round(float(v), 3) for v in r] for r in radar_R]
    meas.setdefault("rf", {})["R"] = [[round(float(v), 3) for v in r] for r in rf_R]
    meas["note"] = note
    profile_from_dict(doc, path)  # validate before writing
    new = _replace_measurement_block(text, meas)
    if new is None:  # no recognisable block: rewrite the whole document
        new = yaml.safe_dump(doc, sort_keys=False)
    path.write_text(new, encoding="utf-8")


def _replace_measurement_block(text: str, meas: dict[str, object]) -> str | None:
    """Swap the top-level ``measurement:`` block of ``text`` keeping the rest (and comments)."""
    lines = text.splitlines(keepends=True)
    start = next((i for i, ln in enumerate(lines) if ln.startswith("measurement:")), None)
    if start is None:
        return None
    end = start + 1
    while end < len(lines) and (lines[end].startswith((" ", "#")) or not lines[end].strip()):
        end += 1
    while end > start + 1 and not lines[end - 1].strip():
        end -= 1
    block = yaml.safe_dump({"measurement": meas}, sort_keys=False, default_flow_style=None)
    return "".join(lines[:start]) + block + "".join(lines[end:])


def run(args: argparse.Namespace) -> int:
    from uav_fusion.core.data import load_flight
    from uav_fusion.core.scoring.noise import estimate_q_from_truth, estimate_r

    site = load_site(args.site)
    folder = Path(args.folder) if args.folder else data_path(DEFAULT_FLIGHT)
    flight = load_flight(folder, site, rf_file=args.rf_file)
    if not 0 < args.trim_probability < 1:
        raise ConfigError("--trim-probability must lie in (0, 1)")
    rad, rf = estimate_r(
        flight,
        site,
        radar_method=args.radar_method,
        rf_method=args.rf_method,
        radar_select=args.radar_select,
        range_gate_m=args.range_gate,
        trim_probability=args.trim_probability,
    )
    print(f"flight {flight.name}: errors against time-interpolated truth")
    for est in (rad, rf):
        print(est.describe())
        print(f"  R_{est.source} (m^2) =")
        print(_fmt(est.R))
    q = estimate_q_from_truth(flight, args.q_horizon)
    print(
        f"truth velocity increments over ~{args.q_horizon:g} s suggest q = "
        + ", ".join(f"{v:.3g}" for v in q)
        + " m^2/s^3 (east, north, up); not written into the profile"
    )
    if args.write_profile:
        date = _dt.datetime.now(_dt.UTC).strftime("%Y-%m-%d")
        note = (
            f"estimated {date} from flight {flight.name}: radar {rad.selection}, "
            f"method {rad.method}, n={rad.n_used}; rf {rf.selection}, method {rf.method}, "
            f"n={rf.n_used}/{rf.n_samples} (uav_fusion estimate-r --radar-select "
            f"{args.radar_select} --radar-method {args.radar_method} --rf-method {args.rf_method})"
        )
        write_r_into_profile(Path(args.write_profile), rad.R, rf.R, note)
        print(f"written into {args.write_profile}")
    return 0
