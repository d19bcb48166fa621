"""Convert a flight folder (Dryad layout) into a rosbag2 MCAP bag of our message types.

The bag holds exactly what the replay nodes would publish for the same flight and profile
(see docs/graph.md), so playing it stands in for ``radar_replay``, ``rf_replay`` and
``truth_replay``:

- ``radar/pose``: the radar reports the profile's track selection keeps (paper: the largest
  continuous track), ``geometry_msgs/PoseWithCovarianceStamped``;
- ``radar/raw``: every UAV-class radar report, before selection, same type;
- ``radar/tracks``: every report of every radar frame, one ``sensor_msgs/PointCloud2`` per
  frame (layout :mod:`uav_fusion.core.data.clouds`, covariance from the profile's radar model);
- ``rf/fix``: every RF localisation attempt, ``geometry_msgs/PointStamped`` (NaN for a
  failed attempt);
- ``rf/fixes``: the same attempts with CEP, sensor counts, centre frequency and RHO, one
  ``sensor_msgs/PointCloud2`` each;
- ``truth/fix``: the RTK truth, ``sensor_msgs/NavSatFix``.

Topic names sit under an optional namespace. Every message is stored at its sensor UTC time
(receive time = stamp), so the player's ``/clock`` is sensor time. The field rules are
:mod:`uav_fusion.core.data.encoding` (shared with the live conversions of
:mod:`uav_fusion.ros.conversions`) and the selection is :mod:`uav_fusion.core.estimators.selection`
(shared with ``radar_replay``); serialization is rosbags' CDR, whose bytes equal those of a
live rclpy publisher except alignment padding, which rosbags writes as zeros and rclpy leaves
as whatever was in memory (tested). No rclpy is needed. The profile's name and radar R
(``polar`` for a tracker profile: each report's own) are stored in ``metadata.yaml``'s
``custom_data``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from uav_fusion.bag.writer import BagWriter, WrittenBag, jazzy_typestore
from uav_fusion.core.data import encoding as enc
from uav_fusion.core.data.clouds import Cloud, radar_frame_to_cloud, rf_attempts_to_cloud
from uav_fusion.core.data.encoding import time_to_ns
from uav_fusion.core.estimators.selection import (
    pose_covariance,
    radar_profile,
    raw_radar_reports,
    report_covariance,
    selected_radar,
)
from uav_fusion.core.records import Flight, RfAttempt, TruthFix
from uav_fusion.core.site import Site

FloatArray = npt.NDArray[np.float64]

#: Topic leaf names (docs/graph.md).
RADAR_POSE = "radar/pose"
RADAR_RAW = "radar/raw"
RADAR_TRACKS = "radar/tracks"
RF_FIX = "rf/fix"
RF_FIXES = "rf/fixes"
TRUTH_FIX = "truth/fix"
#: Message type of every topic.
TYPES = {
    RADAR_POSE: "geometry_msgs/msg/PoseWithCovarianceStamped",
    RADAR_RAW: "geometry_msgs/msg/PoseWithCovarianceStamped",
    RADAR_TRACKS: "sensor_msgs/msg/PointCloud2",
    RF_FIX: "geometry_msgs/msg/PointStamped",
    RF_FIXES: "sensor_msgs/msg/PointCloud2",
    TRUTH_FIX: "sensor_msgs/msg/NavSatFix",
}

_RELIABLE = ({"reliability": "reliable", "durability": "volatile", "history": "keep_last",
              "depth": 1000},)


@dataclass(frozen=True)
class ConvertResult:
    """What :func:`convert_flight` wrote."""

    bag: WrittenBag
    topics: dict[str, str]  # leaf name -> full topic name
    # the radar R written into the pose covariances (3x3, m^2); None: each report's own (the
    # profile's polar model)
    radar_cov: FloatArray | None
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
    prof = radar_profile(profile, track_selection)
    R = pose_covariance(prof, site)
    fixed = None if prof.r_radar is None else np.asarray(prof.r_radar, dtype=float)
    frame = site.frame_id
    names = {leaf: topic_name(namespace, leaf) for leaf in TYPES}
    ts = jazzy_typestore()
    msgs = CdrMessages(ts)
    # (time, order, leaf, message): one stable time order across the four streams
    items: list[tuple[float, int, str, Any]] = []
    for group in selected_radar(flight, prof, site):
        for m in group:
            mR = m.R if m.R is not None else R(*m.z)
            items.append((m.t, len(items), RADAR_POSE, msgs.radar_pose(m.t, m.z, mR, frame)))
    for trk in raw_radar_reports(flight, prof):
        pos = (trk.e, trk.n, trk.u)
        items.append((trk.t, len(items), RADAR_RAW, msgs.radar_pose(trk.t, pos, R(*pos), frame)))
    cov = report_covariance(prof, site)
    for fr in flight.radar:
        items.append((fr.t, len(items), RADAR_TRACKS,
                      msgs.cloud(fr.t, radar_frame_to_cloud(fr, cov), frame)))
    for a in flight.rf:
        items.append((a.t, len(items), RF_FIX, msgs.rf_fix(a, frame)))
        items.append((a.t, len(items), RF_FIXES, msgs.cloud(a.t, rf_attempts_to_cloud([a]), frame)))
    for f in flight.truth:
        items.append((f.t, len(items), TRUTH_FIX, msgs.truth_fix(f, truth_frame)))
    items.sort(key=lambda it: (it[0], it[1]))

    writer = BagWriter(out)
    try:
        for leaf, msgtype in TYPES.items():
            writer.add_topic(names[leaf], msgtype, qos=_RELIABLE)
        for t, _k, leaf, msg in items:
            writer.write(names[leaf], time_to_ns(t), ts.serialize_cdr(msg, TYPES[leaf]))
        written = writer.close()
    except BaseException:
        writer.abort()
        raise
    if progress is not None:
        what = "polar, per report" if fixed is None else f"diag {np.diag(fixed).tolist()} m^2"
        progress(f"profile {prof.name}: radar selection {prof.radar_selection}, radar R {what}")
    _store_custom(written.path, fixed, prof.name, prof.radar_selection, flight.name)
    return ConvertResult(written, names, fixed, prof.name)


def _store_custom(
    path: Path, R: FloatArray | None, profile: str, selection: str, name: str
) -> None:
    """Record the conversion settings in metadata.yaml's custom_data."""
    import yaml

    meta_path = path / "metadata.yaml"
    doc = yaml.safe_load(meta_path.read_text(encoding="utf-8"))
    doc["rosbag2_bagfile_information"]["custom_data"] = {
        "uav_fusion.flight": name,
        "uav_fusion.radar_R": (
            "polar" if R is None else " ".join(f"{v:.6g}" for v in np.asarray(R).reshape(-1))
        ),
        "uav_fusion.profile": profile,
        "uav_fusion.radar_selection": selection,
    }
    meta_path.write_text(yaml.safe_dump(doc, default_flow_style=False, sort_keys=False),
                         encoding="utf-8")


class CdrMessages:
    """Our message types as rosbags message objects (rules:
    :mod:`uav_fusion.core.data.encoding`)."""

    def __init__(self, typestore: Any) -> None:
        t = typestore.types
        self._time = t["builtin_interfaces/msg/Time"]
        self._header = t["std_msgs/msg/Header"]
        self._point = t["geometry_msgs/msg/Point"]
        self._quat = t["geometry_msgs/msg/Quaternion"]
        self._pose = t["geometry_msgs/msg/Pose"]
        self._pose_cov = t["geometry_msgs/msg/PoseWithCovariance"]
        self._pose_stamped = t["geometry_msgs/msg/PoseWithCovarianceStamped"]
        self._point_stamped = t["geometry_msgs/msg/PointStamped"]
        self._status = t["sensor_msgs/msg/NavSatStatus"]
        self._fix = t["sensor_msgs/msg/NavSatFix"]
        self._cloud = t["sensor_msgs/msg/PointCloud2"]
        self._field = t["sensor_msgs/msg/PointField"]

    def header(self, t: float, frame_id: str) -> Any:
        sec, nsec = enc.stamp_parts(t)
        return self._header(stamp=self._time(sec=sec, nanosec=nsec), frame_id=frame_id)

    def radar_pose(
        self, t: float, enu: Any, R: FloatArray, frame_id: str
    ) -> Any:
        """A radar position (ENU metres) with its 3x3 covariance (PoseWithCovarianceStamped)."""
        Rm = np.asarray(R, dtype=float)
        if Rm.shape != (3, 3):
            raise enc.MessageError("bad_covariance", f"radar R must be 3x3, got {Rm.shape}")
        pose = self._pose(
            position=self._point(x=float(enu[0]), y=float(enu[1]), z=float(enu[2])),
            orientation=self._quat(x=0.0, y=0.0, z=0.0, w=1.0),
        )
        cov = np.array(enc.pose_covariance(Rm.tolist()), dtype=np.float64)
        return self._pose_stamped(
            header=self.header(t, frame_id), pose=self._pose_cov(pose=pose, covariance=cov)
        )

    def cloud(self, t: float, cloud: Cloud, frame_id: str) -> Any:
        """A core :class:`~uav_fusion.core.data.clouds.Cloud` as a stamped PointCloud2."""
        return self._cloud(
            header=self.header(t, frame_id),
            height=1,
            width=cloud.width,
            fields=[
                self._field(name=f.name, offset=f.offset, datatype=f.datatype, count=f.count)
                for f in cloud.fields
            ],
            is_bigendian=False,
            point_step=cloud.point_step,
            row_step=cloud.row_step,
            data=np.frombuffer(cloud.data, dtype=np.uint8),
            is_dense=False,
        )

    def rf_fix(self, a: RfAttempt, frame_id: str) -> Any:
        """An RF attempt (PointStamped; NaN for a failed one)."""
        x, y, z = enc.rf_point(a)
        return self._point_stamped(
            header=self.header(a.t, frame_id), point=self._point(x=x, y=y, z=z)
        )

    def truth_fix(self, f: TruthFix, frame_id: str) -> Any:
        """A truth sample (NavSatFix: lat, lon, HAE altitude, covariance unknown)."""
        return self._fix(
            header=self.header(f.t, frame_id),
            status=self._status(status=enc.navsat_status(f.fix_type), service=enc.SERVICE_GPS),
            latitude=float(f.lat),
            longitude=float(f.lon),
            altitude=float(f.h),
            position_covariance=np.zeros(9, dtype=np.float64),
            position_covariance_type=enc.COVARIANCE_TYPE_UNKNOWN,
        )
