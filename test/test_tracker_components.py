"""Tracker components: measurement models (hand cases), robust weights (hand cases), the IMM
transition check, M-of-N and deleter, and the CV / IMM filters against filterpy."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest
from filterpy.kalman import IMMEstimator, KalmanFilter

from uav_fusion.core.errors import ConfigError
from uav_fusion.core.estimators import load_profile
from uav_fusion.core.estimators.adaptive import CEP_PER_SIGMA
from uav_fusion.core.estimators.imm import ImmFilter, packed_arrays
from uav_fusion.core.estimators.kalman import CvFilter, pack_r
from uav_fusion.core.estimators.models import (
    cv_process_noise,
    cv_transition,
    kf_predict,
    kf_update_joseph,
    position_h,
)
from uav_fusion.core.estimators.objects import RadarObject, too_large
from uav_fusion.core.estimators.parts import (
    CepRfR,
    Deleter,
    FixedRadarR,
    MofN,
    NoRobust,
    PolarRadarR,
    RadarAlignment,
    StudentTWeight,
    object_start,
    packed_to_array,
    robust_from_profile,
)
from uav_fusion.core.profiles.checks import validate_transition
from uav_fusion.core.profiles.settings import ScoreConfig
from uav_fusion.core.records import RadarFrame, RadarTrack

RAD = math.radians


# --- polar radar R ------------------------------------------------------------------------
def test_polar_r_due_north_is_diagonal_with_cross_range_growing_with_range() -> None:
    m = PolarRadarR((0.0, 0.0, 0.0), 2.0, RAD(1.0), RAD(0.5))
    for r in (100.0, 1000.0):
        R = packed_to_array(m.r_at(0.0, r, 0.0))
        # east = azimuth arc, north = range, up = elevation arc
        expect = np.diag([(r * RAD(1.0)) ** 2, 4.0, (r * RAD(0.5)) ** 2])
        np.testing.assert_allclose(R, expect, atol=1e-9)


def test_polar_r_due_east_and_the_floor() -> None:
    m = PolarRadarR((10.0, 20.0, 5.0), 3.0, RAD(2.0), RAD(1.0), floor_m=4.0)
    R = packed_to_array(m.r_at(510.0, 20.0, 5.0))  # 500 m east of the radar
    expect = np.diag([9.0 + 16.0, (500 * RAD(2.0)) ** 2 + 16.0, (500 * RAD(1.0)) ** 2 + 16.0])
    np.testing.assert_allclose(R, expect, atol=1e-9)


def test_polar_r_is_a_rotation_of_the_polar_covariance() -> None:
    m = PolarRadarR((0.0, 0.0, 0.0), 1.5, RAD(1.2), RAD(0.8))
    p = np.array([300.0, -400.0, 120.0])
    R = packed_to_array(m.r_at(*p))
    r = np.linalg.norm(p)
    rho = np.hypot(p[0], p[1])
    ev = np.sort(np.linalg.eigvalsh(R))
    expect = np.sort([1.5**2, (rho * RAD(1.2)) ** 2, (r * RAD(0.8)) ** 2])
    np.testing.assert_allclose(ev, expect, rtol=1e-9)
    u_r = p / r  # the range direction is an eigenvector with the range variance
    np.testing.assert_allclose(R @ u_r, 1.5**2 * u_r, atol=1e-9)


# --- radar misalignment ---------------------------------------------------------------------
def _polar_report(radar: tuple[float, float, float], az: float, el: float, r: float) -> RadarTrack:
    e0, n0, u0 = radar
    return RadarTrack(
        t=1.0, track_id=7, lat=35.7, lon=-78.7, h=123.0,
        e=e0 + r * math.cos(RAD(el)) * math.sin(RAD(az)),
        n=n0 + r * math.cos(RAD(el)) * math.cos(RAD(az)),
        u=u0 + r * math.sin(RAD(el)),
        vel_ned=(10.0, 0.0, -1.0), uav_prob=0.8, range_m=r, rcs_dbsm=-10.0,
    )  # fmt: skip


@pytest.mark.parametrize("az", [45.0, 180.0, 300.0, -0.2])
def test_radar_alignment_turns_a_report_back_to_the_true_angles(az: float) -> None:
    radar = (10.0, -20.0, 5.0)
    al = RadarAlignment(radar, az_bias_deg=0.5, el_bias_deg=0.3)
    # the radar reported az + 0.5 deg and el + 0.3 deg; the truth is at (az, 10 deg, 1000 m)
    got = al.track(_polar_report(radar, az + 0.5, 10.3, 1000.0))
    want = _polar_report(radar, az, 10.0, 1000.0)
    assert (got.e, got.n, got.u) == pytest.approx((want.e, want.n, want.u), abs=1e-9)
    # the slant range is kept; the point alone gives the same position
    d = math.dist((got.e, got.n, got.u), radar)
    assert d == pytest.approx(1000.0, abs=1e-9)
    raw = _polar_report(radar, az + 0.5, 10.3, 1000.0)
    assert al.point(raw.e, raw.n, raw.u) == (got.e, got.n, got.u)
    # everything else is the radar's own report, the velocity included
    assert (got.t, got.track_id, got.lat, got.lon, got.h, got.uav_prob, got.rcs_dbsm) == (
        1.0, 7, 35.7, -78.7, 123.0, 0.8, -10.0
    )  # fmt: skip
    assert got.vel_ned == (10.0, 0.0, -1.0)


def test_radar_alignment_of_a_frame_and_without_a_bias() -> None:
    radar = (0.0, 0.0, 0.0)
    frame = RadarFrame(
        1.0, (_polar_report(radar, 10.0, 5.0, 500.0), _polar_report(radar, 20.0, 3.0, 800.0))
    )
    assert RadarAlignment(radar, 0.0, 0.0).frame(frame) is frame  # nothing to do
    empty = RadarFrame(2.0, ())
    assert RadarAlignment(radar, 1.0, 0.0).frame(empty) is empty
    out = RadarAlignment(radar, 1.0, -0.5).frame(frame)
    assert out.t == 1.0 and len(out.tracks) == 2
    for trk, (az, el) in zip(out.tracks, [(9.0, 5.5), (19.0, 3.5)], strict=True):
        assert math.degrees(math.atan2(trk.e, trk.n)) == pytest.approx(az)
        assert math.degrees(math.atan2(trk.u, math.hypot(trk.e, trk.n))) == pytest.approx(el)


# --- RF R from CEP --------------------------------------------------------------------------
def test_cep_r_hand_cases() -> None:
    m = CepRfR(scale=2.0, floor_m=5.0, fallback=(9.0, 0.0, 9.0))
    s = 2.0 * 20.0 / CEP_PER_SIGMA  # CEP 20 m
    assert m.r_for(20.0) == pytest.approx((s * s, 0.0, s * s))
    assert m.r_for(1.0) == pytest.approx((25.0, 0.0, 25.0))  # the floor
    assert m.r_for(None) == (9.0, 0.0, 9.0)  # no CEP: the fallback
    assert m.r_for(0.0) == (9.0, 0.0, 9.0)
    assert m.r_for(float("nan")) == (9.0, 0.0, 9.0)


def test_a_fix_without_a_cep_counts_as_the_coarsest_that_updates() -> None:
    """The tracker's profile has no fixed RF R: a fix without a CEP gets the R of a fix at
    ``max_cep_m``; without either the profile stops, naming the key."""
    from uav_fusion.core.errors import ConfigError
    from uav_fusion.core.estimators import load_profile
    from uav_fusion.core.estimators.parts import rf_model_from_profile

    p = load_profile("tracker")
    assert p.r_rf is None and p.rf_max_cep_m is not None
    m = rf_model_from_profile(p)
    assert m.r_for(None) == pytest.approx(m.r_for(p.rf_max_cep_m))
    assert m.r_for(None) != m.r_for(p.rf_max_cep_m - 1.0)
    with pytest.raises(ConfigError, match=r"measurement\.rf\.R is needed"):
        p.with_changes(rf_max_cep_m=None)
    with pytest.raises(ConfigError, match=r"measurement\.radar\.R is needed"):
        p.with_changes(radar_model="fixed")


# --- robust weights -------------------------------------------------------------------------
def test_student_t_weight_hand_cases() -> None:
    w = StudentTWeight(dof=4.0)
    assert w.weight(3.0, 3) == pytest.approx(1.0)  # a typical innovation keeps its R
    assert w.weight(17.0, 3) == pytest.approx(7.0 / 21.0)  # (nu + m) / (nu + NIS)
    assert w.weight(0.0, 2) == pytest.approx(1.0)  # capped at 1
    assert w.weight(100.0, 2) < w.weight(10.0, 2) < 1.0  # monotone: outliers count less


def test_the_robust_update_is_student_t_with_four_dof_or_none(tmp_path: Path) -> None:
    assert robust_from_profile(load_profile("tracker")) == StudentTWeight(4.0)
    assert isinstance(robust_from_profile(load_profile("paper")), NoRobust)
    # every tracker profile gets it, whatever it extends (it is not a setting)
    as_tracker = load_profile("paper").with_changes(estimator="tracker")
    assert robust_from_profile(as_tracker) == StudentTWeight(4.0)
    # a profile that still sets a retired key is told where it went, with its file
    for key, text in (
        ("dof", "the Student-t update has 4 degrees of freedom"),
        ("huber_k", "gone with the huber update"),
        ("robust", "always Student-t with 4 degrees of freedom"),
    ):
        p = tmp_path / f"{key}.yaml"
        p.write_text(f"name: p\nextends: tracker\nupdate:\n  {key}: 6.0\n", encoding="utf-8")
        with pytest.raises(ConfigError, match=rf"{key}\.yaml.*'update\.{key}' is no longer") as e:
            load_profile(str(p))
        assert text in str(e.value)


# --- transition matrix, M-of-N, deleter ---------------------------------------------------
def test_transition_matrix_validation() -> None:
    good = validate_transition([[0.9, 0.1], [0.2, 0.8]], 2, "f.yaml: motion.imm.transition")
    assert good == ((0.9, 0.1), (0.2, 0.8))
    with pytest.raises(ValueError, match=r"f\.yaml: motion\.imm\.transition: row 1 sums to 0\.9"):
        validate_transition([[0.9, 0.1], [0.2, 0.7]], 2, "f.yaml: motion.imm.transition")
    with pytest.raises(ValueError, match="entries must lie in"):
        validate_transition([[1.1, -0.1], [0.2, 0.8]], 2, "x")
    with pytest.raises(ValueError, match="must be 2x2"):
        validate_transition([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]], 2, "x")


def test_m_of_n() -> None:
    m = MofN(3, 5)  # the start is a hit
    assert m.record(False) == "pending"
    assert m.record(True) == "pending"
    assert m.record(True) == "confirmed"
    m = MofN(3, 5)
    assert m.record(False) == "pending"
    assert m.record(False) == "pending"
    assert m.record(False) == "failed"  # 1 hit + 1 test left < 3
    with pytest.raises(ValueError):
        MofN(4, 3)


def test_deleter() -> None:
    d = Deleter(max_coast_s=10.0, max_consecutive_rejections=3)
    assert not d.coast_expired(19.9, 10.0)
    assert d.coast_expired(20.1, 10.0)
    assert not d.too_many_rejections(2)
    assert d.too_many_rejections(3)
    never = Deleter(None, None)
    assert not never.coast_expired(1e9, 0.0) and not never.too_many_rejections(10**6)


# --- filters against the references ---------------------------------------------------------
def _stream(seed: int, n: int) -> list[tuple[float, np.ndarray, np.ndarray]]:
    rng = np.random.default_rng(seed)
    out = []
    t = 0.0
    for k in range(n):
        t += float(rng.uniform(0.1, 2.0))
        if k % 4 == 3:
            R = np.array([[120.0, 20.0], [20.0, 80.0]])
            z = np.array([0.5 * t * t, 3.0 * t]) + rng.normal(0, 10.0, 2)
        else:
            R = np.array([[30.0, 2.0, -1.0], [2.0, 50.0, 4.0], [-1.0, 4.0, 60.0]])
            z = np.array([0.5 * t * t, 3.0 * t, 40.0]) + rng.normal(0, 6.0, 3)
        out.append((t, z, R))
    return out


def test_cv_filter_matches_the_matrix_reference() -> None:
    q = (1.5, 2.5, 0.7)
    f = CvFilter(q)
    x0 = np.array([0.0, 0.0, 40.0, 0.0, 0.0, 0.0])
    P0 = np.diag([30.0, 50.0, 60.0, 100.0, 100.0, 100.0])
    f.set_state(x0, P0)
    x, P = x0.copy(), P0.copy()
    t0 = 0.0
    for t, z, R in _stream(1, 60):
        f.predict(t - t0)
        x, P = kf_predict(x, P, t - t0, q)
        t0 = t
        nis_ours = f.update(z.tolist(), pack_r(R))
        x, P, nis = kf_update_joseph(x, P, z, R)
        xo, Po = packed_arrays(*f.mean())
        np.testing.assert_allclose(xo, x, rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(Po, P, rtol=1e-9, atol=1e-9)
        assert nis_ours == pytest.approx(nis, rel=1e-9)


@pytest.mark.parametrize("imm", [False, True])
def test_a_linear_pseudo_measurement_matches_filterpy(imm: bool) -> None:
    # the radial speed (unit vector u over the velocity) measured as 0 with sigma 0.5 m/s
    x0 = np.array([300.0, -200.0, 50.0, 6.0, -3.0, 1.0])
    A = np.random.default_rng(5).normal(size=(6, 6))
    P0 = A @ A.T + np.diag([400.0, 300.0, 200.0, 20.0, 30.0, 10.0])
    u = x0[:3] / np.linalg.norm(x0[:3])
    h = np.concatenate([np.zeros(3), u])
    ref = KalmanFilter(dim_x=6, dim_z=1)
    ref.x, ref.P, ref.H, ref.R = x0.copy(), P0.copy(), h[None, :], np.array([[0.25]])
    ref.update(np.array([0.0]))
    f: CvFilter | ImmFilter
    if imm:
        qs = ((0.5, 0.5, 0.2), (20.0, 20.0, 5.0))
        f = ImmFilter(qs, ((0.97, 0.03), (0.06, 0.94)), (0.5, 0.5))
    else:
        f = CvFilter((1.0, 1.0, 1.0))
    f.set_state(x0, P0)
    f.update_linear(h.tolist(), 0.0, 0.25)
    xo, Po = packed_arrays(*f.mean())
    np.testing.assert_allclose(xo, ref.x.ravel(), rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(Po, ref.P, rtol=1e-9, atol=1e-9)
    assert float(xo[3:] @ u) == pytest.approx(float(ref.x.ravel()[3:] @ u), abs=1e-12)
    assert abs(float(xo[3:] @ u)) < abs(float(x0[3:] @ u))  # pulled towards 0


def _filterpy_mode(q: tuple[float, float, float], x0: np.ndarray, P0: np.ndarray) -> KalmanFilter:
    kf = KalmanFilter(dim_x=6, dim_z=3)
    kf.x = x0.copy()
    kf.P = P0.copy()
    return kf


@pytest.mark.parametrize("seed", [3, 4])
def test_imm_matches_filterpy_imm_estimator(seed: int) -> None:
    qs = [(0.3, 0.3, 0.1), (15.0, 15.0, 4.0)]
    M = [[0.95, 0.05], [0.1, 0.9]]
    mu0 = [0.6, 0.4]
    x0 = np.array([0.0, 0.0, 40.0, 0.0, 0.0, 0.0])
    P0 = np.diag([30.0, 50.0, 60.0, 100.0, 100.0, 100.0])
    ours = ImmFilter(qs, M, mu0)
    ours.set_state(x0, P0)
    modes = [_filterpy_mode(q, x0, P0) for q in qs]
    ref = IMMEstimator(modes, np.array(mu0), np.array(M))
    t0 = 0.0
    for t, z, R in _stream(seed, 50):
        if z.shape[0] == 2:
            continue  # filterpy's IMM needs one measurement dimension for all its filters
        T = t - t0
        t0 = t
        for m, q in zip(modes, qs, strict=True):
            m.F = cv_transition(T)
            m.Q = cv_process_noise(T, q)
            m.H = position_h(3)
            m.R = R
        ref.predict()
        ours.predict(T)
        ref.update(z)
        ours.update(z.tolist(), pack_r(R))
        np.testing.assert_allclose(ours.mode_probabilities(), ref.mu, rtol=1e-9, atol=1e-12)
        xo, Po = packed_arrays(*ours.mean())
        np.testing.assert_allclose(xo, ref.x, rtol=1e-9, atol=1e-8)
        np.testing.assert_allclose(Po, ref.P, rtol=1e-8, atol=1e-8)
        for mine, theirs in zip(ours.modes, modes, strict=True):
            np.testing.assert_allclose(mine.x, theirs.x, rtol=1e-9, atol=1e-8)


def test_imm_comparison_detects_a_wrong_transition_matrix() -> None:
    qs = [(0.3, 0.3, 0.1), (15.0, 15.0, 4.0)]
    x0 = np.array([0.0, 0.0, 40.0, 0.0, 0.0, 0.0])
    P0 = np.diag([30.0, 50.0, 60.0, 100.0, 100.0, 100.0])
    a = ImmFilter(qs, [[0.95, 0.05], [0.1, 0.9]], [0.5, 0.5])
    b = ImmFilter(qs, [[0.94, 0.06], [0.1, 0.9]], [0.5, 0.5])
    for f in (a, b):
        f.set_state(x0, P0)
    t0 = 0.0
    for t, z, R in _stream(5, 20):
        for f in (a, b):
            f.predict(t - t0)
            f.update(z.tolist(), pack_r(R))
        t0 = t
    assert not np.allclose(a.mode_probabilities(), b.mode_probabilities(), rtol=1e-6)


def test_imm_predict_to_leaves_the_filter_alone_and_zero_time_is_no_step() -> None:
    f = ImmFilter([(0.3, 0.3, 0.1), (15.0, 15.0, 4.0)], [[0.9, 0.1], [0.1, 0.9]], [0.5, 0.5])
    f.set_state(np.array([0, 0, 40, 5, 0, 0], float), np.eye(6) * 10.0)
    before = (list(f.mean()[0]), list(f.mean()[1]), f.mode_probabilities())
    c = f.copy()
    c.predict(3.0)
    assert (list(f.mean()[0]), list(f.mean()[1]), f.mode_probabilities()) == before
    assert c.mean()[0][0] == pytest.approx(15.0)
    f.predict(0.0)
    assert f.mode_probabilities() == before[2]


# --- track start ----------------------------------------------------------------------------


@pytest.mark.parametrize("flat", [False, True])
def test_a_track_starts_level_from_an_object_seen_climbing(flat: bool) -> None:
    """The object's filter has followed a take-off climb at 3 m/s for 8 s; a track started
    from it keeps the object's position but starts level (climb 0 +- hold_sigma_mps)."""
    from uav_fusion.core.estimators import load_profile
    from uav_fusion.core.estimators.objects import ObjectTable
    from uav_fusion.core.profiles.settings import ScoreConfig

    profile = load_profile("tracker")
    table = ObjectTable(ScoreConfig(), FixedRadarR((25.0, 0.0, 0.0, 25.0, 0.0, 25.0)))
    for k in range(33):
        t = 0.25 * k
        obj = table.update(RadarTrack(t, 7, 0.0, 0.0, 0.0, 300.0, 200.0, 3.0 * t,
                                      (0.0, 0.0, -3.0), 0.9, None, -12.0 - 0.01 * k))  # fmt: skip
    assert obj.kf is not None and obj.kf.x[5] > 2.0  # the object climbs
    x, P = object_start(obj, profile, flat)
    assert x[5] == 0.0 and P[5, 5] == pytest.approx(profile.hold_sigma_mps**2)
    assert not P[5, :5].any() and not P[:5, 5].any()
    assert x[:2] == pytest.approx(list(obj.kf.x[:2]))
    if flat:  # beyond the 3D gate: the RF start's height prior instead of the object's
        assert x[2] == profile.rf_init_altitude_m
        assert P[2, 2] == pytest.approx(profile.rf_init_altitude_std_m**2)
    else:
        assert x[2] == pytest.approx(obj.kf.x[2])


# --- the UAV score's cues -------------------------------------------------------------------
def _airborne_object(**fields: float) -> RadarObject:
    """A radar object 20 s old, 60 m up, moving at 8 m/s with a small UAV's RCS: none of the
    score's penalties applies; ``fields`` change that."""
    obj = RadarObject(7, 0.0)
    obj.last_t, obj.n_reports = 20.0, 80
    obj.up, obj.sd_up, obj.speed = 60.0, 3.0, 8.0
    obj.rcs_mean, obj.rcs_seen = -10.0, True
    for name, value in fields.items():
        setattr(obj, name, value)
    return obj


def test_the_uav_score_cues_at_their_edges() -> None:
    """Each penalty of the UAV score either side of its threshold: the score differs by
    exactly that penalty; a low object that moves costs nothing of itself."""
    cfg = ScoreConfig(tau_s=5.0, below_ground_sigmas=2.0)
    base = _airborne_object().score(cfg)

    def lost(**fields: float) -> float:
        return base - _airborne_object(**fields).score(cfg)

    def still_cost(age: float) -> float:  # standing still against moving, at the same age
        moving = _airborne_object(speed=1.6, last_t=age).score(cfg)
        return moving - _airborne_object(speed=1.4, last_t=age).score(cfg)

    # stationary: slower than stationary_speed_mps (1.5 m/s) from an age of tau_s (5 s)
    assert still_cost(5.0) == pytest.approx(cfg.stationary_weight)
    assert still_cost(4.99) == pytest.approx(0.0)
    # too large for a small UAV: a mean RCS of large_rcs_dbsm (0 dBsm) and up, when known
    assert lost(rcs_mean=0.0) == pytest.approx(cfg.veto)
    assert lost(rcs_mean=-0.1) == pytest.approx(0.0)
    assert lost(rcs_mean=9.0, rcs_seen=False) == pytest.approx(0.0)
    # a ghost: more than below_ground_m (5 m) and two vertical sigmas of its reports below
    assert lost(up=-6.1, sd_up=3.0) == pytest.approx(cfg.veto)
    assert lost(up=-5.9, sd_up=3.0) == pytest.approx(0.0)
    assert lost(up=-5.1, sd_up=1.0) == pytest.approx(cfg.veto)
    assert lost(up=-4.9, sd_up=1.0) == pytest.approx(0.0)
    # low and moving: only a car's RCS costs (the size rule), not the height
    assert lost(up=1.0, speed=12.0) == pytest.approx(0.0)
    assert lost(up=1.0, speed=12.0, rcs_mean=9.0) == pytest.approx(cfg.veto)


@pytest.mark.parametrize("cue", [{"up": -60.0}, {"rcs_mean": 3.0}])
def test_an_object_that_cannot_be_a_uav_scores_at_most_zero_whatever_its_other_cues(
    cue: dict[str, float],
) -> None:
    """The veto is all that the other cues can give: a ghost or a target too large, with a
    class history, RF support, agreement and age each at their largest, scores exactly 0 (no
    threshold that lets an object update or start a track is reached); with one of those a
    little short of its largest, below 0."""
    cfg = ScoreConfig(rf_max=3.0, rf_weight=1.0, fused_weight=1.5, age_weight=0.5)
    assert cfg.veto == pytest.approx(cfg.class_clip + 3.0 + 1.5 + 0.5)

    def scored(class_logit: float) -> float:
        obj = _airborne_object(**cue)
        obj.class_logit, obj.fused = class_logit, 1.0
        obj.rf_support, obj.rf_t = 10.0, obj.last_t
        return obj.score(cfg)

    assert scored(cfg.class_clip) == pytest.approx(0.0)
    assert scored(cfg.class_clip - 0.01) < 0.0
    tracker = load_profile("tracker").score
    assert 0.0 < tracker.follow_min <= tracker.init_min


def test_a_report_is_too_large_for_a_small_uav_from_large_rcs_dbsm_on() -> None:
    """The per-report bound (``too_large``) at its edge; a report without an RCS is not
    judged, nor is one whose RCS is not a number."""
    cfg = ScoreConfig(large_rcs_dbsm=0.0)

    def rep(rcs: float | None) -> RadarTrack:
        return RadarTrack(0.0, 1, 0.0, 0.0, 0.0, 100.0, 0.0, 10.0, None, 0.5, None, rcs)

    assert too_large(rep(0.0), cfg) and too_large(rep(9.0), cfg)
    assert not too_large(rep(-0.01), cfg) and not too_large(rep(-15.0), cfg)
    assert not too_large(rep(None), cfg) and not too_large(rep(math.nan), cfg)
    assert too_large(rep(-3.0), dataclasses.replace(cfg, large_rcs_dbsm=-3.0))
