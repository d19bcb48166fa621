"""Fixed-rate output (core/estimators/grid.py) and its scoring (core/scoring/fixed_rate.py) on
hand-made cases."""

from __future__ import annotations

import csv
import math
import struct
from pathlib import Path

import numpy as np
import pytest
from scipy.stats import chi2

from uav_fusion.core.estimators import load_profile
from uav_fusion.core.estimators.grid import GridEmitter, StepGrid, TrackSnapshot, cv_predictor
from uav_fusion.core.estimators.kalman import CvKalman
from uav_fusion.core.estimators.models import kf_predict
from uav_fusion.core.estimators.paper import FusionEstimator
from uav_fusion.core.estimators.steps import Step
from uav_fusion.core.estimators.synthetic import simulate_stream
from uav_fusion.core.profiles.model import Profile
from uav_fusion.core.scoring.fixed_rate import (
    FlightTruth,
    ScoreSettings,
    epoch_errors,
    grid_from_steps,
    nees,
    pool,
    score_grid,
)
from uav_fusion.core.site import load_site

T0 = 1_760_000_000.0
UP = 50.0  # truth height above take-off (airborne)


def truth_line(t_end: float = 20.0, up: float = UP) -> FlightTruth:
    """Flying east at 10 m/s: position (10 (t - T0), 0, up) at t; sampled every 0.5 s."""
    t = T0 + np.arange(0.0, t_end + 0.25, 0.5)
    enu = np.column_stack([10.0 * (t - T0), np.zeros(t.size), np.full(t.size, up)])
    return FlightTruth(t, enu, np.full(t.size, up))


def packed(x: np.ndarray, P: np.ndarray) -> bytes:
    upper = [P[i, j] for i in range(6) for j in range(i, 6)]
    return struct.pack("27d", *x, *upper)


def step(
    t: float,
    status: str,
    x: np.ndarray | None = None,
    P: np.ndarray | None = None,
    reason: str | None = None,
    source: str = "radar",
) -> Step:
    if x is None:
        state = struct.pack("27d", *(math.nan,) * 27)
    else:
        state = packed(x, P if P is not None else np.diag([4.0, 4.0, 4.0, 1.0, 1.0, 1.0]))
    return Step(t, source, status, reason, None, state, 3, None, 0)


def hand_profile(max_coast_s: float | None = 3.0) -> Profile:
    return load_profile("paper").with_changes(q=(0.0, 0.0, 0.0), max_coast_s=max_coast_s)


P0 = np.diag([4.0, 4.0, 4.0, 1.0, 1.0, 1.0])


def test_cv_predictor_is_the_filters_own_prediction_bit_for_bit() -> None:
    rng = np.random.default_rng(3)
    A = rng.normal(size=(6, 6))
    P = A @ A.T + np.eye(6)
    x = rng.normal(size=6) * 100
    kf = CvKalman((1.5, 2.0, 0.5))
    kf.set_state(x, P)
    kf.predict(0.731)
    gx, gP = cv_predictor((1.5, 2.0, 0.5))(kf.x_array(), kf.P_array(), 0.0 + 1.269)
    kf.predict(1.269)
    assert np.array_equal(gx, kf.x_array()) and np.array_equal(gP, kf.P_array())
    # and it is the textbook prediction
    rx, rP = kf_predict(x, P, 2.0, (1.5, 2.0, 0.5))
    x2, P2 = cv_predictor((1.5, 2.0, 0.5))(x, P, 2.0)
    np.testing.assert_allclose(x2, rx, rtol=1e-12)
    np.testing.assert_allclose(P2, rP, rtol=1e-12)


def test_gap_coast_beyond_the_maximum_restart_and_gross_error_by_hand() -> None:
    """A track started at T0+0.5 with a velocity 1 m/s off to the north, nothing until a
    restart at T0+10 that is 200 m too high. 1 Hz grid on [T0, T0+10], max coast 3 s, q = 0."""
    prof = hand_profile(3.0)
    x1 = np.array([5.0, 0.0, UP, 10.0, 1.0, 0.0])  # on truth at T0+0.5, north velocity wrong
    x2 = np.array([100.0, 0.0, UP + 200.0, 10.0, 0.0, 0.0])  # gross
    steps = [
        step(T0 + 0.5, "initialised", x1, P0),
        step(T0 + 10.0, "reset", x2, P0, source="rf"),
    ]
    g = grid_from_steps(steps, prof, 1.0, T0, T0 + 10.0)
    assert len(g) == 11
    np.testing.assert_array_equal(g.t, T0 + np.arange(11.0))
    assert g.has_track.tolist() == [False] + [True] * 10
    assert g.published.tolist() == [False, True, True, True] + [False] * 6 + [True]
    np.testing.assert_allclose(g.age_s[1:10], np.arange(1, 10) - 0.5)
    assert g.age_s[10] == 0.0
    assert g.track_id.tolist() == [-1] + [0] * 9 + [1]
    assert g.restarts == 1
    assert g.last_source.tolist() == [""] + ["radar"] * 9 + ["rf"]
    # coasted epochs are the prediction: north error = 1 m/s * dt, P_pos = 4 + dt^2 (q = 0)
    np.testing.assert_allclose(g.x[2, :3], [20.0, 1.5, UP])
    np.testing.assert_allclose(np.diag(g.P[2])[:3], 4.0 + 1.5**2)

    truth = truth_line(10.0)
    ee = epoch_errors(g, truth)
    np.testing.assert_allclose(ee.error_m[[1, 2, 3, 10]], [0.5, 1.5, 2.5, 200.0])
    assert np.isnan(ee.error_m[[0, 4, 9]]).all()
    s = score_grid(g, truth)
    assert (s.epochs, s.covered, s.fresh) == (11, 4, 2)  # fresh: ages 0.5 and 0
    sc = pool([s])
    assert sc.coverage_pct == pytest.approx(100 * 4 / 11)
    assert sc.fresh_coverage_pct == pytest.approx(100 * 2 / 11)
    assert sc.err_mean_m == pytest.approx((0.5 + 1.5 + 2.5 + 200.0) / 4)
    assert sc.err_p50_m == pytest.approx(2.0)
    assert sc.err_max_m == pytest.approx(200.0)
    assert sc.gross_pct == pytest.approx(25.0)
    assert sc.ttf_s == pytest.approx(1.0)
    assert sc.restarts == 1
    assert sc.gross_vertical_pct == 100.0 and sc.gross_age_p50_s == 0.0
    assert sc.gross_rf_pct == 100.0
    # NEES by hand: e = (0, dt, 0), P_pos = (4 + dt^2) I; the restart: 200^2 / 4
    hand = [dt**2 / (4 + dt**2) for dt in (0.5, 1.5, 2.5)] + [200.0**2 / 4]
    assert sc.anees == pytest.approx(np.mean(hand))
    lo, hi = chi2.ppf(0.025, 3), chi2.ppf(0.975, 3)
    assert sc.nees_in95_pct == pytest.approx(100 * sum(lo <= v <= hi for v in hand) / 4)
    assert sc.nees_in95_pct == 50.0  # 0.059 < 0.216 (low); 0.36, 0.61 inside; 10000 high


def test_tentative_tracks_and_lost_tracks_are_not_published() -> None:
    prof = hand_profile(None)  # no coast limit: only the track's state decides
    x = np.array([0.0, 0.0, UP, 10.0, 0.0, 0.0])
    steps = [
        step(T0 + 0.5, "tentative", x, P0, reason="start", source="rf"),
        step(T0 + 1.5, "tentative", x, P0, reason="hit", source="rf"),
        step(T0 + 2.5, "updated", x, P0, source="rf"),  # confirms
        step(T0 + 4.5, "coasted", x, P0, reason="nis"),
        step(T0 + 6.5, "discarded", None, None, reason="no_track"),  # the track was dropped
        step(T0 + 7.5, "tentative", x, P0, reason="start", source="rf"),  # a new tentative one
    ]
    g = grid_from_steps(steps, prof, 1.0, T0, T0 + 9.0)
    assert g.has_track.tolist() == [False] * 3 + [True] * 4 + [False] * 3
    assert g.published.tolist() == g.has_track.tolist()
    assert g.confirmed_tracks == 1 and g.restarts == 0
    # the coasted step keeps the age running from the last accepted measurement
    np.testing.assert_allclose(g.age_s[3:7], [0.5, 1.5, 2.5, 3.5])


def test_out_of_order_and_invalid_discards_do_not_move_the_snapshot() -> None:
    prof = hand_profile(None)
    x = np.array([0.0, 0.0, UP, 10.0, 0.0, 0.0])
    bogus = np.array([999.0, 0.0, UP, 0.0, 0.0, 0.0])
    steps = [
        step(T0 + 0.5, "initialised", x, P0),
        step(T0 + 1.2, "discarded", bogus, P0, reason="invalid"),
        step(T0 + 0.2, "discarded", bogus, P0, reason="out_of_order"),
    ]
    g = grid_from_steps(steps, prof, 1.0, T0, T0 + 2.0)
    np.testing.assert_allclose(g.x[1:, 0], [5.0, 15.0])


def test_epoch_equal_to_a_step_time_is_that_steps_state_and_error() -> None:
    """A real estimator run whose radar reports fall on the 10 Hz grid (every 0.5 s)."""
    site = load_site()
    prof = load_profile("paper")
    assert prof.r_radar is not None and prof.r_rf is not None
    stream = simulate_stream(
        5, 120.0, prof.q, prof.r_radar, prof.r_rf, radar_period_s=0.5, jitter=0.0,
        x0=np.array([300.0, -200.0, 60.0, 6.0, -3.0, 0.0]), t0=T0,
    )
    est = FusionEstimator(prof, site)
    steps = [s for m in stream.measurements for s in est.process(m)]
    ts = np.array([m.t for m in stream.measurements])
    truth = FlightTruth(ts, stream.truth[:, :3], np.full(ts.size, 100.0))  # always airborne
    g = grid_from_steps(steps, prof, 10.0, ts[0], ts[-1])
    ee = epoch_errors(g, truth, ScoreSettings())
    last = {}
    for s in steps:
        last[s.t] = s
    where = {t: i for i, t in enumerate(g.t.tolist())}
    checked = 0
    for t, s in last.items():
        if t not in where or not s.counted:
            continue
        i = where[t]
        assert np.array_equal(g.x[i], s.x) and np.array_equal(g.P[i], s.P)
        k = int(np.flatnonzero(ts == t)[0])
        assert ee.error_m[i] == pytest.approx(np.linalg.norm(s.x[:3] - stream.truth[k, :3]))
        checked += 1
    assert checked > 50
    # between steps: the last step predicted (the filter's own arithmetic)
    i = where[min(t for t in where if t > ts[10] and t not in last)]
    s = last[max(t for t in last if t < g.t[i])]
    assert s.counted
    px, pP = cv_predictor(prof.q)(s.x, s.P, g.t[i] - s.t)
    assert np.array_equal(g.x[i], px) and np.array_equal(g.P[i], pP)


def test_nees_against_a_hand_case() -> None:
    e = np.array([[1.0, 2.0, 2.0], [3.0, 0.0, 0.0]])
    P = np.array([np.diag([1.0, 4.0, 16.0]), [[2.0, 1.0, 0.0], [1.0, 2.0, 0.0], [0.0, 0.0, 1.0]]])
    # 1/1 + 4/4 + 4/16 = 2.25; [3 0 0] P^-1 [3 0 0]^T = 9 * 2/3 = 6
    np.testing.assert_allclose(nees(e, P), [2.25, 6.0])


def test_radar_observable_epochs_and_airborne_rule() -> None:
    prof = hand_profile(None)
    x = np.array([0.0, 0.0, UP, 10.0, 0.0, 0.0])
    steps = [step(T0, "initialised", x, P0)]
    truth = truth_line(10.0)
    # on the ground (4 m above take-off) for t < T0 + 4, airborne after
    above = np.where(truth.t < T0 + 4.0, 4.0, UP)
    truth = FlightTruth(truth.t, truth.enu, above)
    g = grid_from_steps(steps, prof, 1.0, T0, T0 + 10.0)
    s = score_grid(g, truth, uav_report_t=np.array([T0 + 3.0, T0 + 9.5]))
    assert s.epochs == 7  # T0+4 ... T0+10
    # observable: within 2 s of a report: T0+4, T0+5 (report at 3) and T0+8..T0+10 (9.5)
    assert s.observable == 5 and s.observable_covered == 5
    assert s.ttf_s == 0.0
    sc = pool([s])
    assert sc.observable_coverage_pct == 100.0 and sc.observable_gross_pct == 0.0
    assert np.isnan(pool([score_grid(g, truth)]).observable_coverage_pct)


def test_observable_coverage_after_the_start_up() -> None:
    """Radar-observable epochs before the first track are the start-up; the coverage after it
    counts only the later ones."""
    prof = hand_profile(3.0)
    x = np.array([0.0, 0.0, UP, 10.0, 0.0, 0.0])
    truth = truth_line(20.0)
    reports = np.arange(T0, T0 + 20.5, 0.5)  # the UAV is radar-observable throughout
    # the first track comes 4 s in and is dropped after a 3 s coast: epochs 4..7 covered
    steps = [step(T0 + 4.0, "initialised", x, P0)]
    g = grid_from_steps(steps, prof, 1.0, T0, T0 + 20.0)
    s = score_grid(g, truth, uav_report_t=reports)
    first = int(np.flatnonzero(g.has_track)[0])
    assert g.t[first] == T0 + 4.0
    assert s.observable == 21 and s.observable_startup == 4 and s.observable_covered == 4
    sc = pool([s])
    assert sc.observable_coverage_pct == pytest.approx(100.0 * s.observable_covered / 21)
    assert sc.observable_after_start_pct == pytest.approx(100.0 * s.observable_covered / 17)
    assert sc.observable_after_start_pct > sc.observable_coverage_pct
    # pooled over two flights: the start-up epochs of both are left out
    both = pool([s, s])
    assert both.observable_after_start_pct == pytest.approx(sc.observable_after_start_pct)
    # a flight never tracked: every observable epoch is start-up, nothing after it
    never = score_grid(grid_from_steps([], prof, 1.0, T0, T0 + 20.0), truth, reports)
    assert never.observable_startup == 21
    assert np.isnan(pool([never]).observable_after_start_pct)
    # without labels: NaN
    assert np.isnan(pool([score_grid(g, truth)]).observable_after_start_pct)


def test_emitter_rejects_going_back_and_emits_on_advance() -> None:
    em = GridEmitter(10.0, 0.2, cv_predictor((1.0, 1.0, 1.0)))
    snap = TrackSnapshot(T0 + 0.05, np.zeros(6), np.eye(6), T0 + 0.05, True, 0)
    assert em.feed(snap) == []
    out = em.advance(T0 + 0.3)
    assert [round((s.t - T0) * 10) for s in out] == [1, 2, 3]
    assert [s.published for s in out] == [True, True, False]  # ages 0.05, 0.15, 0.25
    with pytest.raises(ValueError, match="older"):
        em.feed(TrackSnapshot.none(T0))
    # a snapshot behind the emitted epochs (the output was moved on ahead of the input):
    # nothing is emitted again, and it is the state of the next epochs
    x = np.array([5.0, 0.0, 0.0, 1.0, 0.0, 0.0])
    assert em.feed(TrackSnapshot(T0 + 0.25, x, np.eye(6), T0 + 0.25, True, 0)) == []
    (nxt,) = em.advance(T0 + 0.4)
    assert nxt.t == T0 + 0.4 and nxt.x[0] == pytest.approx(5.15) and nxt.published


def test_run_command_writes_the_grid(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from uav_fusion.cli import main
    from uav_fusion.core.data import load_flight
    from uav_fusion.core.estimators import run_flight
    from uav_fusion.resources import DEFAULT_FLIGHT, data_path

    out = tmp_path / "grid.csv"
    assert main(["run", "--grid", str(out), "--grid-hz", "2"]) == 0
    assert f"grid: {out}" in capsys.readouterr().out
    with out.open() as fh:
        rows = list(csv.DictReader(fh))
    site = load_site()
    flight = load_flight(data_path(DEFAULT_FLIGHT), site)
    prof = load_profile("paper")
    truth = FlightTruth.from_flight(flight, site)
    g = grid_from_steps(run_flight(flight, prof, site).steps, prof, 2.0, *truth.span)
    assert len(rows) == len(g) > 1000
    assert [int(r["published"]) for r in rows] == g.published.astype(int).tolist()
    i = int(np.flatnonzero(g.published)[100])
    assert float(rows[i]["x"]) == pytest.approx(g.x[i, 0], abs=1e-6)
    assert float(rows[i]["age_s"]) == pytest.approx(g.age_s[i], abs=1e-6)
    assert [r["last_source"] for r in rows] == g.last_source.tolist()


def test_live_feeding_with_advance_equals_the_offline_grid() -> None:
    """Steps fed one at a time with ``advance`` after each (a live tracker) give the same
    epochs and states as ``grid_from_steps`` over the finished run."""
    site = load_site()
    prof = load_profile("paper")
    assert prof.r_radar is not None and prof.r_rf is not None
    stream = simulate_stream(9, 60.0, prof.q, prof.r_radar, prof.r_rf, t0=T0)
    est = FusionEstimator(prof, site)
    steps = [s for m in stream.measurements for s in est.process(m)]
    t1 = stream.measurements[-1].t
    offline = grid_from_steps(steps, prof, 10.0, T0, t1)
    live = StepGrid(prof, 10.0, T0, t1)
    states = []
    for i, s in enumerate(steps):
        states += live.feed_step(s)
        nxt = steps[i + 1].t if i + 1 < len(steps) else t1
        if nxt > s.t:  # everything up to just before the next step is processed
            states += live.advance(np.nextafter(nxt, -np.inf))
    states += live.emitter.finish()
    assert [s.t for s in states] == offline.t.tolist()
    assert np.array_equal(np.array([s.x for s in states]), offline.x, equal_nan=True)
    assert [s.published for s in states] == offline.published.tolist()
    assert offline.published.sum() > 400
