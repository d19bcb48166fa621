"""``uav_fusion calibrate``: raw radar and RF errors of a flight against its truth, and the
radar's mounting misalignment (of one flight, or pooled over several)."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from uav_fusion.core.data import load_flight
from uav_fusion.core.errors import ConfigError
from uav_fusion.core.scoring.calibration import (
    angle_residuals,
    calibrate,
    format_alignment,
    format_calibration,
    radar_alignment,
    site_calibration,
)
from uav_fusion.core.site import load_site, write_calibration
from uav_fusion.core.twin.writers import MANIFEST
from uav_fusion.resources import DEFAULT_FLIGHT, data_path

HELP = (
    "print each sensor's raw ('before fusion') error statistics against truth, and the "
    "radar's misalignment"
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "folder",
        nargs="*",
        help="flight folder (default: the bundled default flight); with several, one "
        "alignment line per flight and the radar's misalignment pooled over them",
    )
    parser.add_argument("--site", help="site YAML (default: the shipped Lake Wheeler site)")
    parser.add_argument(
        "--rf-file", default="AADM.csv", help="RF CSV name inside the folder (default: AADM.csv)"
    )
    parser.add_argument(
        "--uav-prob",
        type=float,
        default=None,
        help="a radar track is the UAV's when its mean catProb[0] is at least this "
        "(default: the paper profile's evaluation.raw_radar_min_mean_uav_prob, 0.5)",
    )
    parser.add_argument("--strict", action="store_true", help="stop at the first bad row")
    parser.add_argument(
        "--write-site",
        metavar="FILE",
        help="write a copy of the site file with the measured misalignment as its "
        "radar.calibration (the trackers correct every report by it)",
    )


def radar_position(
    folder: Path, default: tuple[float, float, float], site_path: str | None
) -> tuple[float, float, float]:
    """The radar position: from a twin manifest in the folder if there is one, else the site's."""
    man = folder / MANIFEST
    if not man.is_file():
        return default
    try:
        doc = json.loads(man.read_text(encoding="utf-8"))
        r = doc["radar"]
        lat, lon, h = float(r["lat"]), float(r["lon"]), float(r["h"])
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise ConfigError(f"{man}: unreadable twin manifest: {exc}") from None
    site = load_site(site_path)
    e, n, u = site.to_enu(lat, lon, h)
    return float(e), float(n), float(u)


def run(args: argparse.Namespace) -> int:
    if args.uav_prob is None:
        from uav_fusion.core.estimators import load_profile

        thr = load_profile("paper").raw_radar_min_mean_uav_prob
        args.uav_prob = 0.5 if thr is None else thr
    if not 0.0 <= args.uav_prob <= 1.0:
        raise ConfigError(f"--uav-prob must lie in [0, 1], got {args.uav_prob}")
    folders = [Path(f) for f in args.folder] or [data_path(DEFAULT_FLIGHT)]
    site = load_site(args.site)
    residuals = []
    for folder in folders:
        flight = load_flight(folder, site, rf_file=args.rf_file, strict=args.strict)
        radar = radar_position(folder, site.radar.enu, args.site)
        res = angle_residuals(flight, radar, args.uav_prob)
        residuals.append(res)
        if len(folders) == 1:
            result = calibrate(flight, radar, site.radar.range_gate_m, args.uav_prob)
            print(format_calibration(result))
            print()
        else:
            print(f"{folder}: {format_alignment(radar_alignment([res]), hint=False)}")
        for key in ("truth", "radar", "rf"):
            rep = flight.reports.get(key)
            if rep is not None and (rep.n_skipped or rep.notes):
                print(f"Load {key}: {rep.summary()}")
    if len(folders) > 1:
        print()
    al = radar_alignment(residuals)
    print(format_alignment(al))
    if args.write_site:
        if al is None:
            raise ConfigError("--write-site: no UAV report near truth, nothing to calibrate")
        note = f"uav_fusion calibrate over {len(folders)} flight(s): " + ", ".join(
            Path(f).name for f in folders
        )
        cal = site_calibration(al, residuals, note)
        out = write_calibration(site.source or args.site, args.write_site, cal)
        print(
            f"site with calibration az {cal.az_bias_deg:+.3f} +- {cal.az_sigma_deg:.3f} deg, "
            f"el {cal.el_bias_deg:+.3f} +- {cal.el_sigma_deg:.3f} deg: {out}"
        )
    return 0
