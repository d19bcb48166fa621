"""The bag converter serialises with rosbags' CDR, without rclpy, and writes the bytes a live
rclpy publisher sends for the same messages (and the bytes of the bundled bag).

rclpy (Fast-CDR) leaves the alignment padding between fields uninitialised, so two rclpy
serialisations of one message may differ there; rosbags writes zeros. "The same bytes" is
therefore: same length, every byte equal except padding bytes, which are zero in ours, and
the other side's bytes decode to a message that re-encodes to exactly ours.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path
from typing import Any

from rosbags.highlevel import AnyReader

from uav_fusion.bag.convert import TYPES, convert_flight, topic_name
from uav_fusion.bag.writer import jazzy_typestore
from uav_fusion.core.data import load_flight
from uav_fusion.core.estimators.selection import (
    radar_profile,
    raw_radar_reports,
    report_covariance,
    selected_radar,
)
from uav_fusion.core.site import load_site
from uav_fusion.resources import DEFAULT_FLIGHT, data_path

ROOT = Path(__file__).resolve().parents[1]


def _read(path: Path) -> list[tuple[str, int, bytes]]:
    with AnyReader([path]) as r:
        return [(c.topic, t, bytes(d)) for c, t, d in r.messages()]


def same_up_to_padding(ts: Any, msgtype: str, ours: bytes, theirs: bytes) -> bool:
    if len(ours) != len(theirs):
        return False
    if any(a != b and a != 0 for a, b in zip(ours, theirs, strict=True)):
        return False  # a differing byte that is not zero padding on our side
    decoded = ts.deserialize_cdr(theirs, msgtype)
    return bytes(ts.serialize_cdr(decoded, msgtype)) == ours


def _rclpy_stream() -> list[tuple[str, int, bytes]]:
    """What the converter wrote before: rclpy messages from uav_fusion.ros.conversions,
    serialised by rclpy, in the converter's order."""
    from rclpy.serialization import serialize_message

    from uav_fusion.ros import conversions as cv

    site = load_site()
    flight = load_flight(data_path(DEFAULT_FLIGHT), site)
    prof = radar_profile("paper")
    R = prof.r_radar
    assert R is not None
    frame = site.frame_id
    items: list[tuple[float, int, str, Any]] = []
    for group in selected_radar(flight, prof, site):
        for m in group:
            items.append((m.t, len(items), "radar/pose", cv.radar_measurement_to_msg(m, frame, R)))
    for trk in raw_radar_reports(flight, prof):
        items.append((trk.t, len(items), "radar/raw", cv.radar_track_to_msg(trk, R, frame)))
    cov = report_covariance(prof, site)
    for fr in flight.radar:
        msg = cv.radar_frame_to_cloud_msg(fr, frame, cov)
        items.append((fr.t, len(items), "radar/tracks", msg))
    for a in flight.rf:
        items.append((a.t, len(items), "rf/fix", cv.rf_attempt_to_msg(a, frame)))
        items.append((a.t, len(items), "rf/fixes", cv.rf_attempts_to_cloud_msg([a], frame)))
    for f in flight.truth:
        items.append((f.t, len(items), "truth/fix", cv.truth_to_navsatfix(f, "gps")))
    items.sort(key=lambda it: (it[0], it[1]))
    return [
        (topic_name("", leaf), cv.time_to_ns(t), bytes(serialize_message(msg)))
        for t, _k, leaf, msg in items
    ]


def _bundled_count() -> int:
    """The message count the bundled bag's metadata.yaml states (the same flight)."""
    import yaml

    meta = yaml.safe_load((ROOT / "bags" / "default_flight" / "metadata.yaml").read_text())
    return int(meta["rosbag2_bagfile_information"]["message_count"])


def _check(ours: list[tuple[str, int, bytes]], theirs: list[tuple[str, int, bytes]]) -> int:
    ts = jazzy_typestore()
    types = {topic_name("", leaf): t for leaf, t in TYPES.items()}
    assert len(ours) == len(theirs) == _bundled_count()
    exact = 0
    for (ta, sa, da), (tb, sb, db) in zip(ours, theirs, strict=True):
        assert (ta, sa) == (tb, sb)
        assert same_up_to_padding(ts, types[ta], da, db), (ta, sa)
        exact += da == db
    return exact


def test_converter_bytes_equal_rclpy_serialisation(tmp_path: Path) -> None:
    site = load_site()
    flight = load_flight(data_path(DEFAULT_FLIGHT), site)
    convert_flight(flight, site, tmp_path / "bag")
    ours = _read(tmp_path / "bag")
    # how many are byte-identical including the padding depends on what rclpy's allocator
    # left there (in a busy test process: often none), so only the padding rule is asserted
    _check(ours, _rclpy_stream())


def test_converter_bytes_equal_the_bundled_bag(tmp_path: Path) -> None:
    site = load_site()
    flight = load_flight(data_path(DEFAULT_FLIGHT), site)
    convert_flight(flight, site, tmp_path / "bag")
    _check(_read(tmp_path / "bag"), _read(ROOT / "bags" / "default_flight"))


def test_padding_rule_catches_a_changed_value() -> None:
    ts = jazzy_typestore()
    stream = _rclpy_stream()[:50]
    _topic, _, data = next(s for s in stream if s[0] == "/truth/fix")
    msgtype = TYPES["truth/fix"]
    ours = bytes(ts.serialize_cdr(ts.deserialize_cdr(data, msgtype), msgtype))
    assert same_up_to_padding(ts, msgtype, ours, data)
    changed = bytearray(data)
    changed[-1] ^= 0x01  # last byte of position_covariance_type
    assert not same_up_to_padding(ts, msgtype, ours, bytes(changed))


def test_converter_imports_neither_rclpy_nor_nodes() -> None:
    code = (
        "import sys, uav_fusion.bag.convert, uav_fusion.bag.reader, uav_fusion.bag.writer; "
        "print(sorted(m for m in sys.modules if m.split('.')[0] == 'rclpy' "
        "or m.startswith(('uav_fusion.nodes', 'uav_fusion.ros'))))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"
