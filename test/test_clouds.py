"""radar/tracks and rf/fixes (PointCloud2): lossless round trip of every report and attempt,
malformed points dropped and counted, unusable layouts refused."""

from __future__ import annotations

import math
import struct

import numpy as np
import pytest
from rclpy.serialization import deserialize_message, serialize_message
from sensor_msgs.msg import PointCloud2, PointField

from uav_fusion.core.data import clouds, load_flight
from uav_fusion.core.data.encoding import MessageError
from uav_fusion.core.estimators import load_profile
from uav_fusion.core.estimators.selection import report_covariance
from uav_fusion.core.records import RadarFrame, RadarTrack, RfAttempt
from uav_fusion.core.site import Site, load_site
from uav_fusion.resources import DEFAULT_FLIGHT, data_path
from uav_fusion.ros import conversions as cv

FRAME = "enu_lw1"
RADAR_KEYS = ("track_id", "e", "n", "u", "vel_ned", "uav_prob", "range_m", "rcs_dbsm",
              "radial_velocity")  # fmt: skip
RF_KEYS = ("t", "ok", "meas_id", "cep", "valid_sensors", "total_sensors", "center_freq_hz", "rho")


@pytest.fixture(scope="module")
def site() -> Site:
    return load_site()


def _wire(msg: PointCloud2) -> PointCloud2:
    out: PointCloud2 = deserialize_message(serialize_message(msg), PointCloud2)
    return out


def test_every_report_and_attempt_of_the_flight_round_trips(site: Site) -> None:
    flight = load_flight(data_path(DEFAULT_FLIGHT), site)
    cov = report_covariance(load_profile("tracker"), site)
    n = 0
    for fr in flight.radar:
        got, dropped = cv.msg_to_radar_frame(_wire(cv.radar_frame_to_cloud_msg(fr, FRAME, cov)))
        assert not dropped and got.t == fr.t and len(got.tracks) == len(fr.tracks)
        for sent, back in zip(fr.tracks, got.tracks, strict=True):
            assert all(getattr(sent, k) == getattr(back, k) for k in RADAR_KEYS)
            n += 1
    assert n == sum(len(fr.tracks) for fr in flight.radar) > 1000
    for a in flight.rf:
        (b,), dropped = cv.msg_to_rf_attempts(_wire(cv.rf_attempts_to_cloud_msg([a], FRAME)))
        assert not dropped
        assert all(getattr(a, k) == getattr(b, k) for k in RF_KEYS)
        if a.ok:
            assert (b.e, b.n) == (a.e, a.n)
        else:
            assert math.isnan(b.e) and math.isnan(b.n)
    assert any(not a.ok for a in flight.rf) and all(a.center_freq_hz for a in flight.rf)


def test_the_published_covariance_is_the_profiles_radar_model(site: Site) -> None:
    paper = report_covariance(load_profile("paper"), site)
    tracker = report_covariance(load_profile("tracker"), site)
    R = load_profile("paper").r_radar
    assert R is not None
    assert tuple(paper(100.0, 200.0, 50.0)) == pytest.approx(
        (R[0, 0], R[0, 1], R[0, 2], R[1, 1], R[1, 2], R[2, 2])
    )
    e0, n0, u0 = (float(v) for v in site.radar.enu)
    near = tracker(e0, n0 + 300.0, u0 + 40.0)
    far = tracker(e0, n0 + 1200.0, u0 + 160.0)
    assert far[0] > near[0]  # the cross-range variance grows with range
    fr = RadarFrame(1.0e9, (RadarTrack(1.0e9, 3, 0, 0, 0, 10.0, 20.0, 30.0, None, None, None,
                                       None),))  # fmt: skip
    arr = np.frombuffer(clouds.radar_frame_to_cloud(fr, tracker).data, dtype=clouds.RADAR_DTYPE)
    assert tuple(arr[0][list(clouds.COV_FIELDS)]) == pytest.approx(tuple(tracker(10.0, 20.0, 30.0)))


def _track(e: float, v: tuple[float, float, float] | None = (1.0, 2.0, 0.5),
           prob: float | None = 0.7, rng: float | None = 500.0) -> RadarTrack:  # fmt: skip
    return RadarTrack(1.0e9, 7, 0.0, 0.0, 0.0, e, 20.0, 30.0, v, prob, rng, -3.0)


def test_malformed_points_are_dropped_and_counted_the_good_ones_kept() -> None:
    tracks = (
        _track(10.0),
        _track(math.nan),
        _track(math.inf),
        _track(2.0e7),
        _track(11.0, v=(1.0, math.nan, 0.0)),
        _track(12.0, prob=1.5),
        _track(13.0, rng=-4.0),
        _track(14.0, v=None, prob=None, rng=None),
    )
    cloud = clouds.radar_frame_to_cloud(RadarFrame(1.0e9, tracks))
    got, dropped = clouds.cloud_to_radar_frame(
        1.0e9, cloud.fields, cloud.point_step, cloud.width, 1, False, cloud.data
    )
    assert [t.e for t in got.tracks] == [10.0, 14.0]
    assert got.tracks[1].vel_ned is None and got.tracks[1].uav_prob is None
    assert dropped == {"nan": 3, "out_of_range": 1, "bad_value": 2}
    atts = [
        RfAttempt(1.0e9, 1, True, 0, 0, 5.0, 6.0, 9.0, 4, 4, center_freq_hz=2.4e9),
        RfAttempt(1.0e9, 2, False, 0, 0, math.nan, math.nan, None, None, None),
        RfAttempt(1.0e9, 3, True, 0, 0, 5.0, 6.0, -1.0, 4, 4),
    ]
    cloud = clouds.rf_attempts_to_cloud(atts)
    arr = np.frombuffer(cloud.data, dtype=clouds.RF_DTYPE).copy()
    arr[0]["y"] = math.nan  # partly NaN: malformed, not a failed attempt
    got_a, dropped = clouds.cloud_to_rf_attempts(
        1.0e9, cloud.fields, cloud.point_step, 3, 1, False, arr.tobytes()
    )
    assert [a.meas_id for a in got_a] == [2] and not got_a[0].ok
    assert dropped == {"nan": 1, "bad_value": 1}


def _msg(fields: list[tuple[str, int, int]], step: int, data: bytes, width: int) -> PointCloud2:
    m = PointCloud2()
    m.header.stamp = cv.stamp_from_time(1.0e9)
    m.header.frame_id = FRAME
    m.height, m.width = 1, width
    m.fields = [PointField(name=n, offset=o, datatype=d, count=1) for n, o, d in fields]
    m.point_step, m.row_step = step, step * width
    m.data = data
    return m


def test_fields_are_read_by_name_in_any_order_with_extras() -> None:
    # x, y, z last, an intensity field first, no velocity or covariance
    fields = [("intensity", 0, 7), ("track_id", 4, 5), ("x", 8, 8), ("y", 16, 8), ("z", 24, 8)]
    data = struct.pack("<fi3d", 0.5, 42, 1.0, 2.0, 3.0)
    got, dropped = cv.msg_to_radar_frame(_msg(fields, 32, data, 1), FRAME)
    assert not dropped
    (t,) = got.tracks
    assert (t.track_id, t.e, t.n, t.u, t.vel_ned, t.uav_prob) == (42, 1.0, 2.0, 3.0, None, None)


@pytest.mark.parametrize(
    ("fields", "step", "data", "width", "bigendian", "what"),
    [
        ([("x", 0, 8), ("y", 8, 8), ("track_id", 24, 5)], 28, bytes(28), 1, False, "missing"),
        ([("x", 0, 7), ("y", 4, 7), ("z", 8, 7), ("track_id", 12, 5)], 16, bytes(16), 1, False,
         "datatype 7"),
        ([("x", 0, 8), ("y", 8, 8), ("z", 16, 8), ("track_id", 24, 5)], 28, bytes(27), 1, False,
         "data bytes"),
        ([("x", 0, 8), ("y", 8, 8), ("z", 16, 8), ("track_id", 26, 5)], 28, bytes(28), 1, False,
         "beyond"),
        ([("x", 0, 8), ("y", 8, 8), ("z", 16, 8), ("track_id", 24, 5)], 28, bytes(28), 1, True,
         "big-endian"),
    ],
)  # fmt: skip
def test_unusable_layouts_are_refused(
    fields: list[tuple[str, int, int]], step: int, data: bytes, width: int, bigendian: bool,
    what: str,
) -> None:  # fmt: skip
    m = _msg(fields, step, data, width)
    m.is_bigendian = bigendian
    with pytest.raises(MessageError, match=what) as ei:
        cv.msg_to_radar_frame(m, FRAME)
    assert ei.value.reason == "bad_layout"


def test_stamp_and_frame_are_checked() -> None:
    fr = RadarFrame(1.0e9, (_track(1.0),))
    msg = cv.radar_frame_to_cloud_msg(fr, "map")
    with pytest.raises(MessageError) as ei:
        cv.msg_to_radar_frame(msg, FRAME)
    assert ei.value.reason == "wrong_frame"
    msg = cv.radar_frame_to_cloud_msg(fr, FRAME)
    msg.header.stamp.sec = 0
    msg.header.stamp.nanosec = 0
    with pytest.raises(MessageError) as ei:
        cv.msg_to_radar_frame(msg, FRAME)
    assert ei.value.reason == "zero_stamp"
