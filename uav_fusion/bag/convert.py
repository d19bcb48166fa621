"""Convert a flight folder (Dryad layout) into a rosbag2 MCAP bag of our message types.

Topics (names as in docs/graph.md, under an optional namespace):

- ``radar/raw``: every radar track report of every frame (birds and clutter included),
  ``geometry_msgs/PoseWithCovarianceStamped``;
- ``radar/pose``: the UAV-class reports (``catProb[0] >= min_uav_prob``), same type;
- ``rf/fix``: every RF localisation attempt, ``geometry_msgs/PointStamped`` (NaN for a
  failed attempt);
- ``truth/fix``: the RTK truth, ``sensor_msgs/NavSatFix``.

Every message is stored at its sensor UTC time (the receive time of the bag equals the stamp),
so the player's ``/clock`` follows sensor time. Message conversion is the one of
:mod:`uav_fusion.conversions`; serialization is rclpy's, so the bytes are the ones a live
publisher sends.

Radar covariance: the radar's R as given, or else estimated from the flight the way the paper
estimates it: the covariance of (report - truth interpolated at the report's time) over the
UAV-class reports inside the radar range gate. The R used is stored in the bag's
``custom_data``.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from uav_fusion.bag.writer import BagWriter, WrittenBag
from uav_fusion.core.errors import DataError
from uav_fusion.core.metrics import interpolate_truth
from uav_fusion.core.records import Flight, RadarTrack
from uav_fusion.core.site import Site

FloatArray = npt.NDArray[np.float64]

#: Topic leaf names (docs/graph.md).
RADAR_RAW = "radar/raw"
RADAR_POSE = "radar/pose"
RF_FIX = "rf/fix"
TRUTH_FIX = "truth/fix"

_RELIABLE = ({"reliability": "reliable", "durability": "volatile", "history": "keep_last",
              "depth": 1000},)


@dataclass(frozen=True)
class ConvertResult:
    """What :func:`convert_flight` wrote."""

    bag: WrittenBag
    topics: dict[str, str]  # leaf name -> full topic name
    radar_cov: FloatArray  # the radar R used (3x3, m^2)
    radar_cov_source: str  # "given" or "estimated from N reports"


def topic_name(namespace: str, leaf: str) -> str:
    """``/<namespace>/<leaf>`` (``/<leaf>`` for an empty namespace)."""
    ns = namespace.strip("/")
    return f"/{ns}/{leaf}" if ns else f"/{leaf}"


def _is_uav(track: RadarTrack, min_uav_prob: float) -> bool:
    return track.uav_prob is not None and track.uav_prob >= min_uav_prob


def estimate_radar_R(flight: Flight, site: Site, min_uav_prob: float) -> tuple[FloatArray, int]:
    """Empirical 3x3 covariance of UAV-class radar errors (inside the range gate) against
    time-interpolated truth, and the number of reports it used. Raises DataError when fewer
    than 10 reports can be scored."""
    truth_t, truth_enu = flight.truth_arrays()
    if len(truth_t) < 2:
        raise DataError(flight.folder, None, "too little truth to estimate the radar R")
    radar = np.array(site.radar.enu, dtype=float)
    rows = [
        (tr.t, tr.e, tr.n, tr.u)
        for fr in flight.radar
        for tr in fr.tracks
        if _is_uav(tr, min_uav_prob)
        and math.dist((tr.e, tr.n, tr.u), radar) <= site.radar.range_gate_m
    ]
    if not rows:
        raise DataError(flight.folder, None, "no UAV-class radar report to estimate the radar R")
    arr = np.array(rows, dtype=float)
    ref = interpolate_truth(truth_t, truth_enu, arr[:, 0])
    err = arr[:, 1:4] - ref
    err = err[np.all(np.isfinite(err), axis=1)]
    if len(err) < 10:
        raise DataError(flight.folder, None,
                        f"only {len(err)} radar reports overlap truth; give the radar R")
    return np.asarray(np.cov(err, rowvar=False), dtype=float), len(err)


def convert_flight(
    flight: Flight,
    site: Site,
    out: str | Path,
    *,
    namespace: str = "",
    radar_R: FloatArray | None = None,
    min_uav_prob: float = 0.5,
    progress: Callable[[str], None] | None = None,
) -> ConvertResult:
    """Write ``flight`` as a bag at ``out`` (a directory that must not exist)."""
    from geometry_msgs.msg import PointStamped, PoseWithCovarianceStamped
    from rclpy.serialization import serialize_message
    from sensor_msgs.msg import NavSatFix

    from uav_fusion import conversions as conv

    if radar_R is None:
        R, n = estimate_radar_R(flight, site, min_uav_prob)
        source = f"estimated from {n} UAV-class reports against truth"
    else:
        R = np.asarray(radar_R, dtype=float)
        source = "given"
    frame = site.frame_id
    names = {leaf: topic_name(namespace, leaf) for leaf in (RADAR_RAW, RADAR_POSE, RF_FIX,
                                                            TRUTH_FIX)}
    types = {
        RADAR_RAW: PoseWithCovarianceStamped,
        RADAR_POSE: PoseWithCovarianceStamped,
        RF_FIX: PointStamped,
        TRUTH_FIX: NavSatFix,
    }
    # (time, order, leaf, message): a stable time order across sources
    items: list[tuple[float, int, str, Any]] = []
    k = 0
    for fr in flight.radar:
        for tr in fr.tracks:
            msg = conv.radar_track_to_msg(tr, R, frame)
            items.append((tr.t, k, RADAR_RAW, msg))
            k += 1
            if _is_uav(tr, min_uav_prob):
                items.append((tr.t, k, RADAR_POSE, msg))
                k += 1
    for a in flight.rf:
        items.append((a.t, k, RF_FIX, conv.rf_attempt_to_msg(a, frame)))
        k += 1
    for f in flight.truth:
        items.append((f.t, k, TRUTH_FIX, conv.truth_to_navsatfix(f, "gps")))
        k += 1
    items.sort(key=lambda it: (it[0], it[1]))

    writer = BagWriter(out)
    try:
        for leaf, cls in types.items():
            pkg, name = cls.__module__.split(".")[0], cls.__name__
            writer.add_topic(names[leaf], f"{pkg}/msg/{name}", qos=_RELIABLE)
        for t, _k, leaf, msg in items:
            writer.write(names[leaf], conv.time_to_ns(t), serialize_message(msg))
        written = writer.close()
    except BaseException:
        writer.abort()
        raise
    if progress is not None:
        progress(f"radar R ({source}): diag {np.sqrt(np.diag(R)).round(2).tolist()} m")
    _store_custom(written.path, R, source, min_uav_prob, flight.name)
    return ConvertResult(written, names, R, source)


def _store_custom(path: Path, R: FloatArray, source: str, min_uav_prob: float, name: str) -> None:
    """Record the conversion settings in metadata.yaml's custom_data."""
    import yaml

    meta_path = path / "metadata.yaml"
    doc = yaml.safe_load(meta_path.read_text(encoding="utf-8"))
    doc["rosbag2_bagfile_information"]["custom_data"] = {
        "uav_fusion.flight": name,
        "uav_fusion.radar_R": " ".join(f"{v:.6g}" for v in np.asarray(R).reshape(-1)),
        "uav_fusion.radar_R_source": source,
        "uav_fusion.min_uav_prob": f"{min_uav_prob:g}",
    }
    meta_path.write_text(yaml.safe_dump(doc, default_flow_style=False, sort_keys=False),
                         encoding="utf-8")
