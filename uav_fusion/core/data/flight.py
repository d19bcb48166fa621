"""Load one flight folder: RF CSV, radar JSON Lines and truth logs on one UTC timeline.

Folder rules for several UAVs (any tool can read such a folder): one truth file per UAV, each
``*_vehicleOut.txt`` in the single-UAV format and all with the same recording stamp
(``YYYY-MM-DD_HH-MM-SS``). The first UAV's is ``<stamp>_vehicleOut.txt`` (vehicle ``uav1``),
the others ``<stamp>_<vehicle>_vehicleOut.txt`` (e.g. ``..._uav2_vehicleOut.txt``: vehicle
``uav2``; names of letters, digits and ``-``). Every log covers the whole recording (a UAV not
yet flying sits on its pad). ``AADM.csv`` holds the fixes of every emitting UAV, each on its own
``Center Frequency``; the radar file holds every object's tracks. A folder with one truth file
is read as before, whatever that file's name.
"""

from __future__ import annotations

import re
from pathlib import Path

from uav_fusion.core.data._source import fmt_utc
from uav_fusion.core.data.radar import read_radar_jsonl
from uav_fusion.core.data.rf import read_rf_csv
from uav_fusion.core.data.truth import read_truth
from uav_fusion.core.errors import DataError
from uav_fusion.core.records import FIRST_VEHICLE, Flight, TruthFix
from uav_fusion.core.site import Site, load_site

RF_CANDIDATES = "AADM*.csv"
#: ``<stamp>[_<vehicle>]_vehicleOut.txt`` (the multi-UAV folder rule).
TRUTH_NAME = re.compile(
    r"^(?P<stamp>\d{4}-\d{2}-\d{2}_\d{2}-\d{2}-\d{2})"
    r"(?:_(?P<vehicle>[A-Za-z0-9][A-Za-z0-9-]*))?_vehicleOut\.txt$"
)
# Spans closer than this are not called disjoint: a clock-offset error is minutes to hours.
OVERLAP_TOLERANCE_S = 60.0


def _listing(folder: Path) -> str:
    names = sorted(p.name for p in folder.iterdir() if p.is_file())
    return ", ".join(names) if names else "(no files)"


def _find_one(folder: Path, pattern: str, what: str, arg: str) -> Path:
    matches = sorted(p for p in folder.glob(pattern) if p.is_file())
    if not matches:
        raise DataError(
            folder, None, f"no {what} file matches {pattern!r}; files here: {_listing(folder)}"
        )
    if len(matches) > 1:
        names = ", ".join(p.name for p in matches)
        raise DataError(
            folder,
            None,
            f"{len(matches)} {what} files match {pattern!r} ({names}); "
            f"choose one with {arg}=<file name>",
        )
    return matches[0]


def find_truth_files(folder: Path, pattern: str) -> list[tuple[str, Path]]:
    """(vehicle, path) of every truth file, the first UAV first (see the module's rules).

    One matching file is the first UAV's whatever its name; several must follow the naming
    rule with one stamp, exactly one of them without a vehicle name, and no vehicle twice.
    """
    matches = sorted(p for p in folder.glob(pattern) if p.is_file())
    if not matches:
        raise DataError(
            folder, None, f"no truth file matches {pattern!r}; files here: {_listing(folder)}"
        )
    if len(matches) == 1:
        return [(FIRST_VEHICLE, matches[0])]
    rule = "<stamp>_vehicleOut.txt for the first UAV, <stamp>_<vehicle>_vehicleOut.txt for others"
    stamps: dict[str, list[str]] = {}
    out: list[tuple[str, Path]] = []
    first: list[Path] = []
    for path in matches:
        m = TRUTH_NAME.match(path.name)
        if m is None:
            raise DataError(
                path,
                None,
                f"{len(matches)} truth files here, and this name breaks the rule ({rule})",
            )
        stamps.setdefault(m["stamp"], []).append(path.name)
        vehicle = m["vehicle"]
        if vehicle is None:
            first.append(path)
        elif vehicle == FIRST_VEHICLE:
            raise DataError(
                path, None, f"vehicle {FIRST_VEHICLE!r} is the file without a vehicle name ({rule})"
            )
        else:
            out.append((vehicle, path))
    if len(stamps) > 1:
        listed = "; ".join(f"{k}: {', '.join(v)}" for k, v in sorted(stamps.items()))
        raise DataError(folder, None, f"truth files with different recording stamps ({listed})")
    if len(first) != 1:
        names = ", ".join(p.name for p in matches)
        raise DataError(
            folder,
            None,
            f"{len(first)} truth files without a vehicle name among {names}: exactly one "
            f"(the first UAV's) is needed ({rule})",
        )
    seen: set[str] = set()
    for vehicle, path in out:
        key = vehicle.lower()
        if key in seen:
            raise DataError(path, None, f"vehicle {vehicle!r} has more than one truth file")
        seen.add(key)
    return [(FIRST_VEHICLE, first[0]), *out]


def _find_rf(folder: Path, rf_file: str) -> Path:
    p = folder / rf_file
    if p.is_file():
        return p
    cands = sorted(c.name for c in folder.glob(RF_CANDIDATES) if c.is_file())
    if cands:
        raise DataError(
            folder,
            None,
            f"RF file {rf_file!r} not found; candidates: {', '.join(cands)}; "
            "choose one with rf_file=<file name>",
        )
    raise DataError(
        folder,
        None,
        f"RF file {rf_file!r} not found and no file matches {RF_CANDIDATES!r}; "
        f"files here: {_listing(folder)}",
    )


def flight_files(
    folder: str | Path,
    *,
    rf_file: str = "AADM.csv",
    radar_glob: str = "radar_data_*.json",
    truth_glob: str = "*vehicleOut.txt",
) -> dict[str, Path]:
    """The files :func:`load_flight` reads: ``rf``, ``radar`` and ``truth`` (the first UAV's),
    found by the same rules (a missing or ambiguous file raises DataError)."""
    folder = Path(folder)
    if not folder.is_dir():
        raise DataError(folder, None, "flight folder not found")
    return {
        "radar": _find_one(folder, radar_glob, "radar", "radar_glob"),
        "rf": _find_rf(folder, rf_file),
        "truth": find_truth_files(folder, truth_glob)[0][1],
    }


def load_flight(
    folder: str | Path,
    site: Site | None = None,
    *,
    rf_file: str = "AADM.csv",
    radar_glob: str = "radar_data_*.json",
    truth_glob: str = "*vehicleOut.txt",
    strict: bool = False,
) -> Flight:
    """Read the three files of one flight folder and check that their timelines overlap.

    The RF file is named explicitly (``AADM.csv`` or a variant such as ``AADM_rerun.csv``);
    radar is found by glob and must match exactly one file; truth files too, one per UAV
    following the module's multi-UAV rules when there are several (``Flight.vehicles``). A
    missing or ambiguous file raises :class:`DataError` in both modes, listing what is there,
    and so does a truth file name breaking the rules. If truth
    and a sensor do not overlap in time (spans more than ``OVERLAP_TOLERANCE_S`` apart,
    typically a wrong clock offset), strict mode raises and lenient mode adds a ``WARNING``
    note to both reports, with the apparent offset error.
    """
    folder = Path(folder)
    if not folder.is_dir():
        raise DataError(folder, None, "flight folder not found")
    site = site if site is not None else load_site()
    rf_path = _find_rf(folder, rf_file)
    radar_path = _find_one(folder, radar_glob, "radar", "radar_glob")
    truth_files = find_truth_files(folder, truth_glob)
    truth_path = truth_files[0][1]

    rf, rf_rep = read_rf_csv(rf_path, site, strict=strict)
    radar, radar_rep = read_radar_jsonl(radar_path, site, strict=strict)
    vehicles: dict[str, list[TruthFix]] = {}
    reports = {"rf": rf_rep, "radar": radar_rep}
    for vehicle, path in truth_files:
        fixes, rep = read_truth(path, site, strict=strict)
        vehicles[vehicle] = fixes
        reports["truth" if vehicle == FIRST_VEHICLE else f"truth:{vehicle}"] = rep
    flight = Flight(
        name=folder.name,
        truth=vehicles[FIRST_VEHICLE],
        radar=radar,
        rf=rf,
        reports=reports,
        folder=folder,
        vehicles=vehicles,
    )
    _check_overlap(flight, site, truth_path, strict)
    return flight


def _check_overlap(flight: Flight, site: Site, truth_path: Path, strict: bool) -> None:
    truth_rep = flight.reports["truth"]
    spans = {
        "rf": [a.t for a in flight.rf],
        "radar": [f.t for f in flight.radar],
    }
    if not flight.truth:
        truth_rep.notes.append("WARNING: no truth fixes, the timelines could not be checked")
        return
    t0, t1 = flight.truth[0].t, flight.truth[-1].t
    cur_h = site.clock_offset_s("truth") / 3600.0
    for name, ts in spans.items():
        if not ts:
            flight.reports[name].notes.append(
                "WARNING: no data, the timeline could not be checked against truth"
            )
            continue
        s0, s1 = ts[0], ts[-1]
        if max(t0, s0) - min(t1, s1) <= OVERLAP_TOLERANCE_S:
            continue
        dh = ((s0 + s1) / 2.0 - (t0 + t1) / 2.0) / 3600.0
        shift = f"{dh:+.1f} h" if abs(dh) >= 1.0 else f"{60.0 * dh:+.0f} min"
        what = (
            f"truth ({fmt_utc(t0)} to {fmt_utc(t1)}) and {name} ({fmt_utc(s0)} to "
            f"{fmt_utc(s1)}) do not overlap in time: the {name} data lie about {shift} "
            f"from the truth; the truth clock offset (clock_offsets_h.truth = {cur_h:+g}) is "
            f"probably wrong by about {shift.lstrip('+-')}"
        )
        if round(dh) != 0:
            what += f" (try clock_offsets_h.truth: {cur_h - round(dh):+g})"
        if strict:
            raise DataError(truth_path, None, what)
        truth_rep.notes.append("WARNING: " + what)
        flight.reports[name].notes.append("WARNING: " + what)
