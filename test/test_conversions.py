"""Message conversions: exact round trips and rejection of malformed messages."""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
import pytest
from builtin_interfaces.msg import Time
from geometry_msgs.msg import PoseWithCovarianceStamped
from sensor_msgs.msg import NavSatStatus

from uav_fusion.core.records import RADAR, RF, Measurement, RfAttempt, TruthFix
from uav_fusion.core.site import load_site
from uav_fusion.ros import conversions as cv
from uav_fusion.ros import odometry as od

T0 = 1759866140.123456789  # a UTC time on the day of the real flights


def _rng() -> np.random.Generator:
    return np.random.default_rng(7)


def test_stamp_round_trip_is_exact_for_utc_times() -> None:
    rng = _rng()
    for t in T0 + rng.uniform(0, 3600, 2000):
        t = float(t)
        assert cv.time_from_stamp(cv.stamp_from_time(t)) == t
        assert cv.ns_to_time(cv.time_to_ns(t)) == t
    s = cv.stamp_from_time(1759866140.9999999999)
    assert s.nanosec < 1_000_000_000


def test_stamp_rejects_negative_and_nan() -> None:
    for bad in (-1.0, math.nan, math.inf):
        with pytest.raises(cv.MessageError):
            cv.stamp_from_time(bad)


def test_radar_measurement_round_trip_exact() -> None:
    rng = _rng()
    A = rng.normal(size=(3, 3))
    R = A @ A.T + np.eye(3)
    m = Measurement(t=T0, source=RADAR, z=rng.normal(size=3) * 300.0, R=R)
    msg = cv.radar_measurement_to_msg(m, "enu_lw1")
    assert msg.header.frame_id == "enu_lw1"
    cov = np.asarray(msg.pose.covariance).reshape(6, 6)
    assert cov[3, 3] == cov[4, 4] == cov[5, 5] == cv.UNKNOWN_VARIANCE
    assert msg.pose.pose.orientation.w == 1.0
    back = cv.msg_to_radar_measurement(msg, "enu_lw1", seq=4)
    assert back.t == m.t and back.source == RADAR and back.seq == 4
    assert np.array_equal(back.z, m.z)
    assert back.R is not None and np.array_equal(back.R, R)


def test_radar_default_R_used_when_measurement_has_none() -> None:
    m = Measurement(t=T0, source=RADAR, z=np.array([1.0, 2.0, 3.0]))
    with pytest.raises(cv.MessageError):
        cv.radar_measurement_to_msg(m, "enu")
    R = np.diag([4.0, 5.0, 6.0])
    back = cv.msg_to_radar_measurement(cv.radar_measurement_to_msg(m, "enu", R))
    assert back.R is not None and np.array_equal(back.R, R)


@pytest.mark.parametrize(
    ("mutate", "reason"),
    [
        (lambda m: setattr(m.pose.pose.position, "x", math.nan), "nan"),
        (lambda m: m.pose.covariance.__setitem__(0, math.nan), "bad_covariance"),
        (lambda m: m.pose.covariance.__setitem__(1, 5.0), "bad_covariance"),  # asymmetric
        (lambda m: m.pose.covariance.__setitem__(0, -1.0), "bad_covariance"),  # not PD
        (lambda m: setattr(m.header, "frame_id", "map"), "wrong_frame"),
        (lambda m: setattr(m.header, "stamp", Time()), "zero_stamp"),
    ],
)
def test_radar_bad_messages_rejected_with_reason(
    mutate: Callable[[PoseWithCovarianceStamped], object], reason: str
) -> None:
    m = Measurement(t=T0, source=RADAR, z=np.array([1.0, 2.0, 3.0]), R=np.eye(3))
    msg = cv.radar_measurement_to_msg(m, "enu")
    mutate(msg)
    with pytest.raises(cv.MessageError) as info:
        cv.msg_to_radar_measurement(msg, "enu")
    assert info.value.reason == reason


def test_rf_round_trip_and_failed_attempt() -> None:
    m = Measurement(t=T0, source=RF, z=np.array([-123.456789, 987.654321]))
    msg = cv.rf_measurement_to_msg(m, "enu")
    assert msg.point.z == 0.0
    back = cv.msg_to_rf_measurement(msg, "enu", seq=2)
    assert back is not None and back.t == T0 and np.array_equal(back.z, m.z) and back.seq == 2
    failed = RfAttempt(T0, 7, False, 0.0, 0.0, math.nan, math.nan, None, None, None)
    fmsg = cv.rf_attempt_to_msg(failed, "enu")
    assert cv.is_failed_rf(fmsg)
    assert cv.msg_to_rf_measurement(fmsg, "enu") is None
    fmsg.point.z = 0.0  # partly NaN: malformed, not a failed attempt
    with pytest.raises(cv.MessageError) as info:
        cv.msg_to_rf_measurement(fmsg, "enu")
    assert info.value.reason == "nan"


def test_truth_navsatfix_round_trip() -> None:
    site = load_site()
    lat, lon, h = 35.7262, -78.6950, 150.25
    e, n, u = site.to_enu(lat, lon, h)
    fix = TruthFix(T0, lat, lon, h, float(e), float(n), float(u), (1.0, 2.0, 0.5), 6, 20)
    msg = cv.truth_to_navsatfix(fix, "gps")
    assert msg.status.status == NavSatStatus.STATUS_GBAS_FIX
    assert msg.altitude == h
    back = cv.navsatfix_to_truth(msg, site)
    assert (back.t, back.lat, back.lon, back.h) == (T0, lat, lon, h)
    assert (back.e, back.n, back.u) == (fix.e, fix.n, fix.u)
    assert back.fix_type == 5


def test_odometry_round_trip_keeps_blocks() -> None:
    rng = _rng()
    A = rng.normal(size=(6, 6))
    P = A @ A.T
    x = rng.normal(size=6) * 100
    msg = od.state_to_odometry(T0, x, P, "enu_lw1", "uav")
    st = od.odometry_to_state(msg)
    assert st.t == T0 and st.frame_id == "enu_lw1" and st.child_frame_id == "uav"
    assert np.array_equal(st.x, x)
    assert np.array_equal(st.P[:3, :3], P[:3, :3])
    assert np.array_equal(st.P[3:, 3:], P[3:, 3:])
    assert not st.P[:3, 3:].any()


def test_scalar_covariance_check_decides_like_numpy() -> None:
    """check_cov3 (plain floats) accepts exactly what finite + allclose-symmetric + numpy's
    Cholesky accept, on random, singular, indefinite, asymmetric and non-finite matrices."""
    from uav_fusion.ros.conversions import SYMMETRY_RTOL, MessageError, check_cov3

    def numpy_ok(c: np.ndarray) -> bool:
        if not np.all(np.isfinite(c)):
            return False
        scale = float(np.max(np.abs(c))) or 1.0
        if not np.allclose(c, c.T, rtol=0.0, atol=SYMMETRY_RTOL * scale):
            return False
        try:
            np.linalg.cholesky(c)
        except np.linalg.LinAlgError:
            return False
        return True

    rng = np.random.default_rng(7)
    cases: list[np.ndarray] = []
    for _ in range(400):
        a = rng.normal(size=(3, 3)) * rng.choice([1e-3, 1.0, 1e3])
        cases.append(a @ a.T)  # positive (semi)definite
        cases.append(a + a.T)  # symmetric, often indefinite
        cases.append(a)  # asymmetric
    v = rng.normal(size=3)
    cases.append(np.outer(v, v))  # rank 1: singular
    cases.append(np.zeros((3, 3)))
    cases.append(np.diag([1.0, -1e-12, 1.0]))
    cases.append(np.diag([np.nan, 1.0, 1.0]))
    cases.append(np.diag([np.inf, 1.0, 1.0]))
    n_ok = 0
    for c in cases:
        try:
            (c00, c01, c02), (c10, c11, c12), (c20, c21, c22) = c.tolist()
            check_cov3(c00, c01, c02, c10, c11, c12, c20, c21, c22, what="x")
            ours = True
        except MessageError as exc:
            assert exc.reason == "bad_covariance"
            ours = False
        assert ours == numpy_ok(c), c
        n_ok += ours
    assert 300 < n_ok < len(cases) - 300  # both outcomes well represented


def test_odometry_from_values_equals_the_array_path() -> None:
    from uav_fusion.core.estimators import FusionEstimator, load_profile
    from uav_fusion.core.site import load_site
    from uav_fusion.ros.odometry import odometry_from_values, state_to_odometry

    est = FusionEstimator(load_profile("paper"), load_site())
    z0 = np.asarray(est.site.radar.enu) + 80.0
    steps = []
    for k in range(5):
        steps += est.process(
            Measurement(t=1759866140.25 + k, source=RADAR, z=z0 + k, R=None, seq=k)
        )
    assert len(steps) == 5
    for s in steps:
        a = odometry_from_values(s.t, s.values, "enu_lw1", "uav")
        b = state_to_odometry(s.t, s.x, s.P, "enu_lw1", "uav")
        assert a.header == b.header and a.child_frame_id == b.child_frame_id
        assert a.pose.pose == b.pose.pose and a.twist.twist == b.twist.twist
        assert np.array_equal(a.pose.covariance, b.pose.covariance)
        assert np.array_equal(a.twist.covariance, b.twist.covariance)
