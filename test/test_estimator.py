"""Behaviour of the estimator: models, gates, track life cycle, selection, runner, commands."""

from __future__ import annotations

import math
import re
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml

from uav_fusion.core.errors import ConfigError, DataError
from uav_fusion.core.estimators import (
    CvKalman,
    FusionEstimator,
    Profile,
    RunResult,
    Step,
    build_stream,
    cv_process_noise,
    cv_transition,
    flight_measurements,
    kf_predict,
    kf_update_joseph,
    largest_track_id,
    load_profile,
    pack_r,
    profile_from_dict,
    run_flight,
    run_stream,
)
from uav_fusion.core.estimators.synthetic import (
    SyntheticStream,
    simulate_stream,
    stream_to_flight,
)
from uav_fusion.core.records import RADAR, RF, Flight, Measurement, RadarFrame, RadarTrack
from uav_fusion.core.scoring.noise import estimate_r, sample_cov, trimmed_cov
from uav_fusion.core.site import Site, load_site

R3 = np.diag([100.0, 100.0, 150.0])
R2 = np.array([[900.0, 100.0], [100.0, 800.0]])


@pytest.fixture(scope="module")
def site() -> Site:
    return load_site()


def _profile(**kw: object) -> Profile:
    base: dict[str, object] = {"q": (2.0, 2.0, 2.0), "r_radar": R3, "r_rf": R2}
    base.update(kw)
    return load_profile("paper").with_changes(**base)


def radar(
    t: float,
    z: tuple[float, float, float],
    seq: int,
    track_id: int | None = None,
    uav_prob: float | None = None,
) -> Measurement:
    return Measurement(t, RADAR, np.array(z, float), seq=seq, track_id=track_id, uav_prob=uav_prob)


def rf(t: float, z: tuple[float, float], seq: int) -> Measurement:
    return Measurement(t, RF, np.array(z, float), seq=seq)


def _track(t: float, tid: int, e: float, n: float, u: float, p: float = 0.9) -> RadarTrack:
    return RadarTrack(t, tid, 0.0, 0.0, 0.0, e, n, u, None, p, None, None)


# --- models and kernel ---------------------------------------------------------------------
def test_gate_thresholds(site: Site) -> None:
    est = FusionEstimator(_profile(), site)
    assert est.gate_threshold[2] == pytest.approx(5.991, abs=5e-4)
    assert est.gate_threshold[3] == pytest.approx(7.815, abs=5e-4)


def test_cwna_q_is_exact_over_split_intervals() -> None:
    """Q(T1+T2) = F(T2) Q(T1) F(T2)^T + Q(T2): coasting in pieces equals one prediction."""
    q = (0.3, 1.1, 4.0)
    T1, T2 = 0.37, 2.9
    lhs = cv_process_noise(T1 + T2, q)
    rhs = cv_transition(T2) @ cv_process_noise(T1, q) @ cv_transition(T2).T + cv_process_noise(
        T2, q
    )
    np.testing.assert_allclose(lhs, rhs, rtol=1e-13)
    # and it is not the discrete T^4/4 model
    assert cv_process_noise(1.0, (1, 1, 1))[0, 0] == pytest.approx(1 / 3)


def test_kernel_matches_matrix_reference() -> None:
    rng = np.random.default_rng(0)
    q = (0.5, 1.0, 2.0)
    k = CvKalman(q)
    A = rng.normal(size=(6, 6))
    P = A @ A.T + np.eye(6)
    x = rng.normal(size=6) * 100
    k.set_state(x, P)
    R3f = np.array([[25.0, 3.0, 1.0], [3.0, 36.0, 2.0], [1.0, 2.0, 49.0]])
    for i in range(300):
        T = float(rng.uniform(0, 3))
        x, P = kf_predict(x, P, T, q)
        k.predict(T)
        if i % 3:
            z = x[:3] + rng.normal(size=3) * 5
            x, P, nis = kf_update_joseph(x, P, z, R3f)
            z0, z1, z2 = map(float, z)
            assert k.update3(z0, z1, z2, pack_r(R3f)) == pytest.approx(nis, rel=1e-10)
        else:
            z = x[:2] + rng.normal(size=2) * 20
            x, P, nis = kf_update_joseph(x, P, z, R2)
            z0, z1 = map(float, z)
            assert k.update2(z0, z1, pack_r(R2)) == pytest.approx(nis, rel=1e-10)
    np.testing.assert_allclose(k.x_array(), x, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(k.P_array(), P, rtol=1e-9, atol=1e-9 * np.abs(P).max())
    Pk = k.P_array()
    assert np.array_equal(Pk, Pk.T)
    assert np.all(np.linalg.eigvalsh(Pk) > 0)


def test_kernel_gate_leaves_state_untouched() -> None:
    k = CvKalman((1.0, 1.0, 1.0))
    k.set_state(np.zeros(6), np.eye(6) * 10)
    x0, P0 = list(k.x), list(k.P)
    nis = k.update3(100.0, 0.0, 0.0, pack_r(R3), 7.8)
    assert nis > 7.8 and k.x == x0 and k.P == P0
    assert math.isnan(k.update2(math.nan, 0.0, pack_r(R2), 5.99)) and k.x == x0


# --- gates and steps -------------------------------------------------------------------------
def test_first_radar_initialises_then_updates(site: Site) -> None:
    est = FusionEstimator(_profile(), site)
    s0 = est.process(radar(10.0, (300.0, -200.0, 50.0), 0, track_id=4))[0]
    assert s0.status == "initialised" and s0.updated and s0.counted and s0.track_id == 4
    np.testing.assert_array_equal(s0.x, [300, -200, 50, 0, 0, 0])
    np.testing.assert_array_equal(s0.P[:3, :3], R3)
    assert s0.P[3, 3] == pytest.approx(15.0**2)
    s1 = est.process(radar(10.25, (302.0, -199.0, 51.0), 1))[0]
    assert s1.status == "updated" and s1.nis is not None and s1.dim == 3 and s1.reason is None


def test_rf_initialisation_uses_altitude_prior(site: Site) -> None:
    p = _profile(rf_init_altitude_m=55.0, tentative_sources=())
    s = FusionEstimator(p, site).process(rf(5.0, (10.0, 700.0), 0))[0]
    assert s.status == "initialised" and s.dim == 2
    np.testing.assert_array_equal(s.x[:3], [10.0, 700.0, 55.0])
    assert s.P[2, 2] == pytest.approx(55.0**2)  # as uncertain as it is high
    np.testing.assert_array_equal(s.P[:2, :2], R2)


def test_rf_not_an_init_source(site: Site) -> None:
    est = FusionEstimator(_profile(init_sources=(RADAR,)), site)
    s = est.process(rf(5.0, (10.0, 700.0), 0))[0]
    assert s.status == "discarded" and s.reason == "no_track" and np.all(np.isnan(s.x))
    assert est.process(radar(6.0, (300.0, -200.0, 40.0), 1))[0].status == "initialised"


def test_range_gate_discards_without_touching_the_track(site: Site) -> None:
    est = FusionEstimator(_profile(), site)
    e0, n0, u0 = site.radar.enu
    est.process(radar(0.0, (e0 + 100, n0, u0 + 50), 0))
    far = radar(0.25, (e0 + 801 / math.sqrt(2), n0 + 801 / math.sqrt(2), u0), 1)
    s = est.process(far)[0]
    assert s.status == "discarded" and s.reason == "range_gate" and not s.counted
    assert est.counters["rejected_range_gate"] == 1
    inside = radar(0.5, (e0 + 799, n0, u0), 2)
    assert est.process(inside)[0].reason != "range_gate"
    # the configured gate wins over the site's
    est2 = FusionEstimator(_profile(range_gate_m=2000.0), site)
    est2.process(radar(0.0, (e0 + 100, n0, u0 + 50), 0))
    assert est2.process(far)[0].reason != "range_gate"


def test_range_gate_uses_the_slant_range_not_the_horizontal_distance(site: Site) -> None:
    # 600 m out and 600 m up: 849 m slant range (beyond the 800 m gate) though only 600 m
    # away over the ground; 500 m out and 600 m up (781 m slant) is inside
    est = FusionEstimator(_profile(), site)
    e0, n0, u0 = site.radar.enu
    est.process(radar(0.0, (e0 + 500, n0, u0 + 600), 0))
    high = est.process(radar(0.25, (e0 + 600, n0, u0 + 600), 1))[0]
    assert high.status == "discarded" and high.reason == "range_gate"
    below = est.process(radar(0.5, (e0 + 600, n0, u0 - 600), 2))[0]
    assert below.reason == "range_gate"
    inside = est.process(radar(0.75, (e0 + 500, n0, u0 + 600), 3))[0]
    assert inside.reason != "range_gate"
    assert est.counters["rejected_range_gate"] == 2


def test_nis_rejection_coasts_on_the_prediction(site: Site) -> None:
    est = FusionEstimator(_profile(), site)
    est.process(radar(0.0, (300.0, -200.0, 50.0), 0))
    est.process(radar(1.0, (310.0, -200.0, 50.0), 1))
    state = est.state()
    assert state is not None
    x1, P1 = state
    s = est.process(rf(3.0, (2300.0, -200.0), 2))[0]
    assert s.status == "coasted" and s.reason == "nis" and s.coasted and not s.updated
    assert s.nis is not None and s.nis > 5.991
    x_pred, P_pred = kf_predict(x1, P1, 2.0, (2.0, 2.0, 2.0))
    np.testing.assert_allclose(s.x, x_pred, rtol=1e-12)
    np.testing.assert_allclose(s.P, P_pred, rtol=1e-12)
    assert est.counters["coasted_rf"] == 1 and est.counters["rejected_nis"] == 1


def test_out_of_order_and_invalid_are_discarded(site: Site) -> None:
    est = FusionEstimator(_profile(), site)
    est.process(radar(10.0, (300.0, -200.0, 50.0), 0))
    s = est.process(radar(9.0, (300.0, -200.0, 50.0), 1))[0]
    assert (s.status, s.reason) == ("discarded", "out_of_order")
    s = est.process(radar(11.0, (math.nan, -200.0, 50.0), 2))[0]
    assert (s.status, s.reason) == ("discarded", "invalid")
    with pytest.raises(ValueError):
        est.process(Measurement(12.0, RF, np.zeros(3), seq=3))


def test_class_probability_gate(site: Site) -> None:
    est = FusionEstimator(_profile(min_uav_prob=0.5), site)
    s = est.process(radar(0.0, (300.0, -200.0, 50.0), 0, uav_prob=0.2))[0]
    assert (s.status, s.reason) == ("discarded", "class_prob")
    s = est.process(radar(0.1, (300.0, -200.0, 50.0), 1, uav_prob=None))[0]
    assert s.reason == "class_prob"
    assert est.process(radar(0.2, (300.0, -200.0, 50.0), 2, uav_prob=0.6))[0].status == (
        "initialised"
    )


# --- online radar candidates ---------------------------------------------------------------
def test_frame_picks_smallest_acceptable_nis(site: Site) -> None:
    est = FusionEstimator(_profile(radar_selection="online"), site)
    est.process(radar(0.0, (300.0, -200.0, 50.0), 0, track_id=1))
    frame = [
        radar(0.25, (420.0, -200.0, 50.0), 1, track_id=9),  # clutter, far from the track
        radar(0.25, (301.0, -199.0, 50.0), 2, track_id=1),
        radar(0.25, (305.0, -195.0, 52.0), 3, track_id=2),
    ]
    steps = est.process_frame(frame)
    assert [s.seq for s in steps] == [1, 2, 3]
    assert [s.status for s in steps] == ["discarded", "updated", "discarded"]
    assert steps[1].track_id == 1 and steps[0].reason == "not_selected"
    nis0, nis2 = steps[0].nis, steps[2].nis
    assert nis0 is not None and nis2 is not None and nis0 > nis2
    assert sum(s.counted for s in steps) == 1


def test_frame_without_acceptable_candidate_coasts_once(site: Site) -> None:
    est = FusionEstimator(_profile(radar_selection="online"), site)
    est.process(radar(0.0, (300.0, -200.0, 50.0), 0))
    steps = est.process_frame(
        [radar(0.25, (600.0, -200.0, 50.0), 1), radar(0.25, (300.0, 200.0, 50.0), 2)]
    )
    assert sorted(s.status for s in steps) == ["coasted", "discarded"]
    assert {s.reason for s in steps} == {"nis"}
    assert est.counters["coasted"] == 1


def test_frame_initialises_from_most_uav_like(site: Site) -> None:
    est = FusionEstimator(_profile(radar_selection="online"), site)
    steps = est.process_frame(
        [
            radar(0.0, (100.0, 0.0, 50.0), 0, uav_prob=0.3, track_id=5),
            radar(0.0, (300.0, -200.0, 50.0), 1, uav_prob=0.8, track_id=6),
        ]
    )
    assert [s.status for s in steps] == ["discarded", "initialised"]
    assert steps[1].track_id == 6
    with pytest.raises(ValueError):
        est.process_frame([radar(1.0, (0, 0, 0), 2), radar(1.5, (0, 0, 0), 3)])


# --- track life cycle ------------------------------------------------------------------------
def test_divergence_recovers_within_the_rejection_limit(site: Site) -> None:
    """Started on a 3 km RF outlier, the track locks onto garbage; after N consecutive
    rejections it restarts from a good measurement and then follows the truth."""
    n_max = 6
    prof = _profile(
        max_consecutive_rejections=n_max,
        max_coast_s=None,
        tentative_sources=(),
        max_speed_mps=4.0,  # a new track's velocity sigma: 2 m/s
    )
    s = simulate_stream(11, 60.0, (2.0, 2.0, 2.0), R3, R2, velocity_std=5.0)
    ms = [rf(s.measurements[0].t - 0.5, (3000.0, 2500.0), -1), *s.measurements]
    truth = np.vstack([s.truth[0], s.truth])
    est = FusionEstimator(prof, site)
    steps = run_stream(est, ms)
    assert steps[0].status == "initialised"
    err0 = np.linalg.norm(steps[0].x[:2] - truth[0, :2])
    assert err0 > 2000
    first_reset = next(i for i, st in enumerate(steps) if st.status == "reset")
    assert steps[first_reset].reason == "max_rejections"
    assert all(st.coasted for st in steps[1:first_reset])
    assert first_reset == n_max  # measurements 1..N-1 coast, the N-th restarts the track
    later = np.array(
        [
            np.linalg.norm(st.x[:3] - tr[:3])
            for st, tr in zip(steps[first_reset:], truth[first_reset:], strict=True)
        ]
    )
    assert later[20:].max() < 60.0
    assert est.counters["reinitialisations"] == 1
    # without the limit the filter never recovers
    literal = prof.with_changes(max_consecutive_rejections=None)
    stuck = run_stream(FusionEstimator(literal, site), ms)
    assert sum(st.updated for st in stuck) < 10


def _mofn(**kw: object) -> Profile:
    base: dict[str, object] = {
        "tentative_sources": (RF,),
        "confirm_m": 3,
        "confirm_n": 5,
        "max_speed_mps": 30.0,
        "max_consecutive_rejections": None,
        "max_coast_s": None,
    }
    base.update(kw)
    return _profile(**base)


def test_rf_track_is_tentative_until_m_of_n_hits(site: Site) -> None:
    est = FusionEstimator(_mofn(), site)
    s0 = est.process(rf(0.0, (100.0, 100.0), 0))[0]
    assert (s0.status, s0.reason) == ("tentative", "start") and est.tentative
    assert not (s0.counted or s0.updated or s0.coasted or s0.validated)
    s1 = est.process(rf(4.0, (130.0, 100.0), 1))[0]
    assert (s1.status, s1.reason) == ("tentative", "hit") and est.tentative
    s2 = est.process(rf(8.0, (3000.0, 100.0), 2))[0]  # 717 m/s from the last hit
    assert (s2.status, s2.reason) == ("tentative", "speed")
    s3 = est.process(rf(12.0, (190.0, 100.0), 3))[0]  # third hit of four: confirmed
    assert s3.status == "updated" and s3.validated and s3.counted and not est.tentative
    assert est.counters["confirmed"] == 1 and est.counters["tentative_hits"] == 1
    # a confirmed track coasts through an outlier instead of restarting
    assert est.process(rf(16.0, (2000.0, 95.0), 4))[0].status == "coasted"
    res = RunResult(steps=[s0, s1, s2, s3], counters={})
    pc = res.paper_counts()
    assert (pc["all_steps"], pc["tentative"], pc["rf_accepted"], pc["track_starts"]) == (1, 3, 1, 0)


def test_speed_bound_rejects_agreeing_fixes_too_far_apart(site: Site) -> None:
    """Inside the NIS gate (coarse fixes) but faster than the bound: a miss; with a bound
    above the fixes' speed the same fix is a hit."""
    fixes = [rf(0.0, (0.0, 0.0), 0), rf(4.0, (200.0, 0.0), 1)]  # 50 m/s
    wide = np.eye(2) * 2500.0  # 50 m per axis
    for vmax, reason in ((45.0, "speed"), (55.0, "hit")):
        steps = run_stream(FusionEstimator(_mofn(max_speed_mps=vmax, r_rf=wide), site), fixes)
        assert steps[1].reason == reason and steps[1].nis is not None
        assert steps[1].nis <= 5.991


def test_tentative_track_dropped_when_m_is_out_of_reach(site: Site) -> None:
    est = FusionEstimator(_mofn(), site)
    est.process(rf(0.0, (100.0, 100.0), 0))
    est.process(rf(4.0, (-2000.0, 100.0), 1))  # miss 1: 2 hits of the remaining 3 possible
    est.process(rf(8.0, (2500.0, -900.0), 2))  # miss 2: 2 of the remaining 2 still possible
    assert est.tentative and est.state() is not None and "tentative_dropped" not in est.counters
    s3 = est.process(rf(12.0, (-2200.0, 3000.0), 3))[0]  # miss 3: out of reach
    assert (s3.status, s3.reason) == ("tentative", "start")  # it starts the next track
    np.testing.assert_array_equal(s3.x[:2], [-2200.0, 3000.0])
    s4 = est.process(rf(16.0, (100.0, 100.0), 4))[0]
    assert (s4.status, s4.reason) == ("tentative", "speed")
    assert est.counters["tentative_dropped"] == 1 and est.counters["tentative_started"] == 2


def test_radar_confirms_or_supersedes_a_tentative_track(site: Site) -> None:
    est = FusionEstimator(_mofn(), site)
    est.process(rf(0.0, (3000.0, 2500.0), 0))
    s = est.process(radar(1.0, (300.0, -200.0, 50.0), 1))[0]
    assert (s.status, s.reason) == ("reset", "superseded") and s.counted
    np.testing.assert_array_equal(s.x[:3], [300.0, -200.0, 50.0])
    assert not est.tentative  # started from radar: confirmed at once
    assert est.counters["reinit_superseded"] == 1
    est2 = FusionEstimator(_mofn(), site)
    est2.process(rf(0.0, (300.0, -190.0), 0))
    s2 = est2.process(radar(1.0, (302.0, -200.0, 50.0), 1))[0]
    assert s2.status == "updated" and s2.validated and not est2.tentative
    # radar may not start tracks: the disagreeing report still ends the tentative track
    est3 = FusionEstimator(_mofn(init_sources=(RF,)), site)
    est3.process(rf(0.0, (3000.0, 2500.0), 0))
    s3 = est3.process(radar(1.0, (300.0, -200.0, 50.0), 1))[0]
    assert (s3.status, s3.reason) == ("discarded", "no_track") and est3.state() is None


def test_online_frame_confirms_or_supersedes_a_tentative_track(site: Site) -> None:
    est = FusionEstimator(_mofn(radar_selection="online"), site)
    est.process(rf(0.0, (300.0, -190.0), 0))
    frame = [radar(1.0, (700.0, 300.0, 50.0), 1), radar(1.0, (302.0, -200.0, 50.0), 2)]
    steps = est.process_frame(frame)
    assert [(s.status, s.reason) for s in steps] == [
        ("discarded", "not_selected"), ("updated", None)
    ]
    assert not est.tentative
    est2 = FusionEstimator(_mofn(radar_selection="online"), site)
    est2.process(rf(0.0, (3000.0, 2500.0), 0))
    steps2 = est2.process_frame(frame)  # neither inside the gate: the closer one takes over
    assert [(s.status, s.reason) for s in steps2] == [("reset", "superseded"), ("discarded", "nis")]
    assert not est2.tentative


def test_profile_without_tentative_sources_confirms_rf_at_once(site: Site) -> None:
    est = FusionEstimator(_mofn(tentative_sources=()), site)
    assert est.process(rf(0.0, (3000.0, 2500.0), 0))[0].status == "initialised"
    assert not est.tentative


def test_m_of_n_start_keeps_outlier_starts_out_of_the_estimates(site: Site) -> None:
    """A flight whose first RF fixes are kilometre outliers: with M-of-N confirmation no
    published estimate is more than 300 m off; starting on any single fix gives km errors."""
    s = simulate_stream(5, 120.0, (2.0, 2.0, 2.0), R3, R2, velocity_std=5.0)
    rng = np.random.default_rng(3)
    ms: list[Measurement] = []
    t0 = s.measurements[0].t
    for m in s.measurements:
        if m.source == RADAR and m.t - t0 < 60.0:
            continue  # radar only from 60 s
        if m.source == RF and m.t - t0 < 40.0 and (len(ms) < 2 or rng.random() < 0.6):
            e, n = map(float, m.z + rng.uniform(-3000, 3000, 2))
            m = rf(m.t, (e, n), m.seq)
        ms.append(m)
    t_truth = {m.seq: i for i, m in enumerate(s.measurements)}
    truth = {m.seq: s.truth[t_truth[m.seq]] for m in ms}

    def worst(prof: Profile) -> float:
        steps = run_stream(FusionEstimator(prof, site), ms)
        errs = [np.linalg.norm(st.x[:2] - truth[st.seq][:2]) for st in steps if st.counted]
        return float(max(errs))

    assert worst(_mofn()) < 300.0
    assert worst(_mofn(tentative_sources=())) > 1000.0


def test_max_coast_restarts_the_track(site: Site) -> None:
    est = FusionEstimator(_profile(max_coast_s=5.0), site)
    est.process(radar(0.0, (300.0, -200.0, 50.0), 0))
    est.process(rf(3.0, (2000.0, 0.0), 1))  # rejected
    s = est.process(radar(6.0, (900.0, -200.0, 50.0), 2))[0]
    assert (s.status, s.reason) == ("reset", "max_coast")
    np.testing.assert_array_equal(s.x[:3], [900.0, -200.0, 50.0])
    assert est.counters["reinit_max_coast"] == 1


def test_external_reset(site: Site) -> None:
    est = FusionEstimator(_profile(), site)
    est.reset("operator")  # no track yet: nothing to count
    assert est.counters.get("reinitialisations", 0) == 0
    est.process(radar(0.0, (300.0, -200.0, 50.0), 0))
    est.reset("operator")
    assert est.state() is None
    s = est.process(radar(1.0, (0.0, 0.0, 50.0), 1))[0]
    assert (s.status, s.reason) == ("reset", "operator")
    assert est.counters["reinit_operator"] == 1


# --- flights: selection, stream, runner ----------------------------------------------------
def _flight(site: Site, seed: int = 3) -> tuple[SyntheticStream, Flight]:
    s = simulate_stream(seed, 120.0, (2.0, 2.0, 2.0), R3, R2, velocity_std=5.0)
    return s, stream_to_flight(s, site)


def test_largest_track_selection(site: Site) -> None:
    frames = [
        RadarFrame(0.0, (_track(0.0, 7, 0, 0, 0), _track(0.0, 3, 1, 1, 1))),
        RadarFrame(0.5, (_track(0.5, 3, 1, 1, 1),)),
        RadarFrame(1.0, (_track(1.0, 7, 0, 0, 0),)),
    ]
    assert largest_track_id(frames) == 3  # tie 2:2 -> lowest id
    assert largest_track_id([*frames, RadarFrame(2.0, (_track(2.0, 7, 0, 0, 0),))]) == 7
    assert largest_track_id([]) is None


def test_stream_order_seq_and_selection(site: Site) -> None:
    s, _ = _flight(site)
    radar_ms = [m for m in s.measurements if m.source == RADAR]
    extra = [_track(m.t, 42, 0.0, 0.0, 10.0, 0.1) for m in radar_ms[:40:4]]
    fl = stream_to_flight(s, site, extra_tracks=extra, failed_rf_every=5)
    prof = _profile()
    items = flight_measurements(fl, prof, site)
    assert all(isinstance(i, Measurement) for i in items)
    flat = [i for i in items if isinstance(i, Measurement)]
    assert [m.seq for m in flat] == list(range(len(flat)))
    assert [(m.t, m.source == RF) for m in flat] == sorted((m.t, m.source == RF) for m in flat)
    assert {m.track_id for m in flat if m.source == RADAR} == {1}
    n_rf_ok = sum(a.ok for a in fl.rf)
    assert sum(m.source == RF for m in flat) == n_rf_ok < len(fl.rf)
    _, info = build_stream(fl, prof, site)
    assert info.not_selected == len(extra) and info.selected_track_id == 1
    online = flight_measurements(fl, prof.with_changes(radar_selection="online"), site)
    frames = [i for i in online if isinstance(i, list)]
    assert sum(len(f) == 2 for f in frames) == len(extra)
    again = flight_measurements(fl, prof, site)[5]
    assert isinstance(again, Measurement) and again.seq == flat[5].seq  # deterministic


def test_run_flight_counts_and_streaming_equivalence(site: Site, tmp_path: Path) -> None:
    _, fl = _flight(site)
    prof = _profile(radar_selection="online")
    res = run_flight(fl, prof, site)
    pc = res.paper_counts()
    assert pc["all_steps"] == pc["updated_estimates"] + pc["coasted_estimates"]
    assert pc["all_steps"] + pc["discarded"] == len(res.steps)
    assert pc["radar_accepted"] + pc["rf_accepted"] + pc["track_starts"] == pc["updated_estimates"]
    assert pc["track_starts"] == sum(s.status in ("initialised", "reset") for s in res.steps) >= 1
    assert all(s.validated == (s.status == "updated") for s in res.steps)
    assert res.counters["measurements"] == len(res.steps)
    # the streaming API fed by hand gives bit-identical output
    est = FusionEstimator(prof, site)
    manual: list[Step] = []
    for item in flight_measurements(fl, prof, site):
        manual.extend(est.process_frame(item) if isinstance(item, list) else est.process(item))
    assert len(manual) == len(res.steps)
    for a, b in zip(manual, res.steps, strict=True):
        assert (a.t, a.status, a.seq, a.nis) == (b.t, b.status, b.seq, b.nis)
        assert np.array_equal(a.x, b.x) and np.array_equal(a.P, b.P)
    path = res.write_csv(tmp_path / "steps.csv")
    rows = path.read_text().splitlines()
    assert len(rows) == len(res.steps) + 1 and rows[0].startswith("t,seq,source,status")


def test_single_source_runs(site: Site) -> None:
    _, fl = _flight(site)
    prof = _profile()
    r_only = run_flight(fl, prof.with_changes(use_rf=False), site)
    assert {s.source for s in r_only.steps} == {RADAR}
    f_only = run_flight(fl, prof.with_changes(use_radar=False), site)
    assert {s.source for s in f_only.steps} == {RF}
    assert f_only.steps[0].status == "tentative"  # the paper profile's RF starts
    assert any(s.counted for s in f_only.steps)


# --- profiles --------------------------------------------------------------------------------
def test_paper_profile() -> None:
    p = load_profile("paper")
    assert p.name == "paper" and p.range_gate_m == 800.0 and p.nis_probability == 0.95
    assert p.radar_selection == "largest_track" and p.min_uav_prob is None
    assert p.r_radar is not None and p.r_radar.shape == (3, 3)
    assert p.r_rf is not None and p.r_rf.shape == (2, 2)
    assert profile_from_dict(p.as_dict()).q == p.q


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        (lambda d: d["motion"].update(q=[1, 2]), "motion.q"),
        (lambda d: d["measurement"]["radar"].update(R=[[1, 0], [0, 1]]), "3x3"),
        (lambda d: d["measurement"]["rf"].update(R=[[1, 2], [2, 1]]), "positive definite"),
        (lambda d: d["gating"].update(nis_probability=1.5), "nis_probability"),
        (lambda d: d.update(radar_selection="best"), "radar_selection"),
        (lambda d: d["track"].update(init_sources=["sonar"]), "sonar"),
        (lambda d: d["track"].update(max_consecutive_rejections=0), "max_consecutive"),
        (lambda d: d["track"].update(confirm_m=4, confirm_n=3), "confirm_m"),
        (lambda d: d["track"].update(max_speed_mps=0), "max_speed_mps"),
        (lambda d: d["evaluation"].update(raw_radar_min_mean_uav_prob=2), "raw_radar_min"),
        (lambda d: d["motion"].update(model="ca"), "motion.model must be one of cv, imm"),
        (lambda d: d["track"].update(max_coast=30), "unknown key 'track.max_coast'"),
        (lambda d: d.update(gate=0.9), "unknown key 'gate'"),
    ],
)
def test_profile_errors_name_file_and_key(
    tmp_path: Path, edit: Callable[[dict[str, Any]], object], message: str
) -> None:
    doc = load_profile("paper").as_dict()
    edit(doc)
    f = tmp_path / "bad.yaml"
    f.write_text(yaml.safe_dump(doc))
    with pytest.raises(ConfigError, match=message) as exc:
        load_profile(f)
    assert str(f) in str(exc.value)


def test_missing_and_broken_profile(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="not found"):
        load_profile("no_such_profile")
    f = tmp_path / "x.yaml"
    f.write_text("motion: [unclosed\n")
    with pytest.raises(ConfigError, match="not valid YAML"):
        load_profile(f)


# --- R estimation ------------------------------------------------------------------------------
def test_q_from_truth_recovers_the_simulated_density(site: Site) -> None:
    from uav_fusion.core.scoring.noise import estimate_q_from_truth

    q = (3.0, 1.0, 0.2)
    s = simulate_stream(4, 4000.0, q, R3, R2, radar_period_s=0.5, jitter=0.0)
    fl = stream_to_flight(s, site, truth_period_s=0.5)
    est = estimate_q_from_truth(fl, horizon_s=4.0)
    np.testing.assert_allclose(est, q, rtol=0.12)


def test_sample_cov_is_matlab_cov() -> None:
    e = np.array([[1.0, 2.0], [3.0, 1.0], [0.0, 5.0], [2.0, 2.0]])
    mu = e.mean(axis=0)
    manual = (e - mu).T @ (e - mu) / (len(e) - 1)
    np.testing.assert_allclose(sample_cov(e), manual, rtol=1e-14)


def test_trimmed_cov_ignores_kilometre_outliers() -> None:
    rng = np.random.default_rng(2)
    C = np.array([[400.0, 150.0], [150.0, 900.0]])
    e = rng.multivariate_normal([5.0, -3.0], C, size=4000)
    e[:200] += rng.uniform(500, 4000, size=(200, 2)) * rng.choice([-1, 1], size=(200, 2))
    raw = sample_cov(e)
    assert raw[0, 0] > 20 * C[0, 0]
    est, mu, n = trimmed_cov(e, 0.99)
    np.testing.assert_allclose(est, C, rtol=0.1, atol=30)
    assert 3700 < n < 3850
    np.testing.assert_allclose(mu, [5.0, -3.0], atol=2.0)


def test_estimate_r_from_flight(site: Site) -> None:
    s = simulate_stream(8, 900.0, (0.5, 0.5, 0.5), R3, R2, velocity_std=3.0)
    fl = stream_to_flight(s, site, truth_period_s=0.05)
    rad, rfe = estimate_r(fl, site, radar_select="largest", rf_method="all")
    assert rad.n_samples > 3000 and rfe.n_samples > 200
    np.testing.assert_allclose(np.diag(rad.R), np.diag(R3), rtol=0.1)
    np.testing.assert_allclose(np.diag(rfe.R), np.diag(R2), rtol=0.3)
    tiny = stream_to_flight(simulate_stream(8, 3.0, (0.5,) * 3, R3, R2), site)
    with pytest.raises(DataError, match="rf errors"):
        estimate_r(tiny, site)


def test_estimate_r_writes_profile_keeping_comments(tmp_path: Path) -> None:
    from uav_fusion.commands.estimate_r import write_r_into_profile
    from uav_fusion.resources import config_path

    f = tmp_path / "p.yaml"
    f.write_text(config_path("profiles/paper.yaml").read_text())
    Rr = np.diag([11.0, 12.0, 13.0])
    Rf = np.array([[21.0, 1.0], [1.0, 22.0]])
    write_r_into_profile(f, Rr, Rf, "from a test")
    p = load_profile(f)
    np.testing.assert_array_equal(p.r_radar, Rr)
    np.testing.assert_array_equal(p.r_rf, Rf)
    assert p.r_note == "from a test"
    text = f.read_text()
    assert "# The paper's estimator" in text and "range_gate_m: 800.0" in text
    assert p.q == load_profile("paper").q


def test_run_command_on_the_default_flight(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from uav_fusion.cli import main

    out = tmp_path / "steps.csv"
    assert main(["run", "--profile", "paper", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    m = re.search(
        r"^  filter steps: (\d+) = (\d+) updated \+ (\d+) coasted", text, re.MULTILINE
    )
    assert m is not None, text
    steps, upd, coast = (int(g) for g in m.groups())
    assert steps == upd + coast > 0
    assert "largest_track" in text and "track restarts" in text and "tentative" in text
    rows = out.read_text().splitlines()
    n_meas = int(text.split(" measurements in ")[0].rsplit(maxsplit=1)[-1])
    assert len(rows) == n_meas + 1
    assert main(["run", str(tmp_path / "missing")]) == 2
    assert "flight folder not found" in capsys.readouterr().err


def test_estimate_r_command_writes_a_loadable_profile(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from uav_fusion.cli import main
    from uav_fusion.resources import config_path

    f = tmp_path / "p.yaml"
    f.write_text(config_path("profiles/paper.yaml").read_text())
    assert main(["estimate-r", "--rf-method", "all", "--write-profile", str(f)]) == 0
    text = capsys.readouterr().out
    assert "R_radar (m^2)" in text and "R_rf (m^2)" in text and "suggest q" in text
    p = load_profile(f)
    paper_r_rf = load_profile("paper").r_rf
    assert p.r_rf is not None and paper_r_rf is not None
    assert p.r_rf[0, 0] > 100 * paper_r_rf[0, 0]  # the literal, heavy-tailed R
    assert "--rf-method all" in p.r_note
