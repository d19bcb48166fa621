"""Convert a flight folder (Dryad layout) into a rosbag2 MCAP bag of our message types.

The bag holds exactly what the replay nodes would publish for the same flight and profile
(see docs/graph.md), so playing it stands in for ``radar_replay``, ``rf_replay`` and
``truth_replay``:

- ``radar/pose``: the radar reports the profile's track selection keeps (paper: the largest
  continuous track), ``geometry_msgs/PoseWithCovarianceStamped``;
- ``radar/raw``: every UAV-class radar report, before selection, same type;
- ``rf/fix``: every RF localisation attempt, ``geometry_msgs/PointStamped`` (NaN for a
  failed attempt);
- ``truth/fix``: the RTK truth, ``sensor_msgs/NavSatFix``.

Topic names sit under an optional namespace. Every message is stored at its sensor UTC time
(receive time = stamp), so the player's ``/clock`` is sensor time. Messages come from
:mod:`uav_fusion.conversions` and the selection from the radar replay's own functions;
serialization is rclpy's, so the bytes are the ones a live publisher sends. The profile's name
and radar R are stored in ``metadata.yaml``'s ``custom_data``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from uav_fusion.bag.writer import BagWriter, WrittenBag
from uav_fusion.core.records import Flight
from uav_fusion.core.site import Site

FloatArray = npt.NDArray[np.float64]

#: Topic leaf names (docs/graph.md).
RADAR_POSE = "radar/pose"
RADAR_RAW = "radar/raw"
RF_FIX = "rf/fix"
TRUTH_FIX = "truth/fix"

_RELIABLE = ({"reliability": "reliable", "durability": "volatile", "history": "keep_last",
              "depth": 1000},)


@dataclass(frozen=True)
class ConvertResult:
    """What :func:`convert_flight` wrote."""

    bag: WrittenBag
    topics: dict[str, str]  # leaf name -> full topic name
    radar_cov: FloatArray  # the radar R written into the pose covariances (3x3, m^2)
    profile: str


def topic_name(namespace: str, leaf: str) -> str:
    """``/<namespace>/<leaf>`` (``/<leaf>`` for an empty namespace)."""
    ns = namespace.strip("/")
    return f"/{ns}/{leaf}" if ns else f"/{leaf}"


def convert_flight(
    flight: Flight,
    site: Site,
    out: str | Path,
    *,
    profile: str = "paper",
    track_selection: str = "profile",
    namespace: str = "",
    truth_frame: str = "gps",
    progress: Callable[[str], None] | None = None,
) -> ConvertResult:
    """Write ``flight`` as a bag at ``out`` (a directory that must not exist).

    ``profile`` names an estimator profile (its radar R, UAV-class threshold and track
    selection); ``track_selection`` overrides the selection ("profile": the profile's own).
    """
    from geometry_msgs.msg import PointStamped, PoseWithCovarianceStamped
    from rclpy.serialization import serialize_message
    from sensor_msgs.msg import NavSatFix

    from uav_fusion import conversions as conv
    from uav_fusion.core.estimator import load_profile
    from uav_fusion.nodes.radar_replay import selected_radar, uav_class_reports

    prof = load_profile(profile)
    if track_selection != "profile" and track_selection != prof.radar_selection:
        prof = prof.with_changes(radar_selection=track_selection)
    R = np.asarray(prof.r_radar, dtype=float)
    frame = site.frame_id
    names = {leaf: topic_name(namespace, leaf)
             for leaf in (RADAR_POSE, RADAR_RAW, RF_FIX, TRUTH_FIX)}
    types: dict[str, Any] = {
        RADAR_POSE: PoseWithCovarianceStamped,
        RADAR_RAW: PoseWithCovarianceStamped,
        RF_FIX: PointStamped,
        TRUTH_FIX: NavSatFix,
    }
    # (time, order, leaf, message): one stable time order across the four streams
    items: list[tuple[float, int, str, Any]] = []
    for group in selected_radar(flight, prof, site):
        for m in group:
            items.append((m.t, len(items), RADAR_POSE, conv.radar_measurement_to_msg(m, frame, R)))
    for trk in uav_class_reports(flight, prof):
        items.append((trk.t, len(items), RADAR_RAW, conv.radar_track_to_msg(trk, R, frame)))
    for a in flight.rf:
        items.append((a.t, len(items), RF_FIX, conv.rf_attempt_to_msg(a, frame)))
    for f in flight.truth:
        items.append((f.t, len(items), TRUTH_FIX, conv.truth_to_navsatfix(f, truth_frame)))
    items.sort(key=lambda it: (it[0], it[1]))

    writer = BagWriter(out)
    try:
        for leaf, cls in types.items():
            pkg = cls.__module__.split(".")[0]
            writer.add_topic(names[leaf], f"{pkg}/msg/{cls.__name__}", qos=_RELIABLE)
        for t, _k, leaf, msg in items:
            writer.write(names[leaf], conv.time_to_ns(t), serialize_message(msg))
        written = writer.close()
    except BaseException:
        writer.abort()
        raise
    if progress is not None:
        progress(f"profile {prof.name}: radar selection {prof.radar_selection}, "
                 f"radar R diag {np.diag(R).tolist()} m^2")
    _store_custom(written.path, R, prof.name, prof.radar_selection, flight.name)
    return ConvertResult(written, names, R, prof.name)


def _store_custom(path: Path, R: FloatArray, profile: str, selection: str, name: str) -> None:
    """Record the conversion settings in metadata.yaml's custom_data."""
    import yaml

    meta_path = path / "metadata.yaml"
    doc = yaml.safe_load(meta_path.read_text(encoding="utf-8"))
    doc["rosbag2_bagfile_information"]["custom_data"] = {
        "uav_fusion.flight": name,
        "uav_fusion.radar_R": " ".join(f"{v:.6g}" for v in np.asarray(R).reshape(-1)),
        "uav_fusion.profile": profile,
        "uav_fusion.radar_selection": selection,
    }
    meta_path.write_text(yaml.safe_dump(doc, default_flow_style=False, sort_keys=False),
                         encoding="utf-8")
