"""Multi-target scoring (core/scoring/gospa.py): GOSPA on hand cases, against brute force and
against Stone Soup's GOSPAMetric; the per-flight scorer's coverage, errors, ID switches,
fragmentations, false-track time and pooling on hand-made flights."""

from __future__ import annotations

import datetime as dt
import itertools
import math

import numpy as np
import pytest

from uav_fusion.core.scoring.continuity import fragmentations, id_switches
from uav_fusion.core.scoring.gospa import (
    EpochTracks,
    GospaSettings,
    MultiScoreSettings,
    PublishedTrack,
    UavTruth,
    gospa,
    pool,
    score_flight,
)

C = 100.0
C2 = C**2  # c^p with p = 2
HALF = C2 / 2.0  # c^p / alpha with alpha = 2
RTOL = 1e-9


# --- GOSPA, one epoch ----------------------------------------------------------------------


def test_empty_truths_and_estimates() -> None:
    g = gospa(np.zeros((0, 3)), np.zeros((0, 3)))
    assert (g.distance, g.localisation, g.missed, g.false) == (0.0, 0.0, 0.0, 0.0)
    assert g.assignment == ()


def test_empty_truths_all_estimates_false() -> None:
    g = gospa(np.zeros((0, 3)), [[0.0, 0.0, 0.0], [5.0, 5.0, 5.0], [1e4, 0.0, 0.0]])
    assert g.n_false == 3 and g.n_missed == 0
    assert g.false == pytest.approx(3 * HALF, rel=RTOL)
    assert g.localisation == 0.0 and g.missed == 0.0
    assert g.distance == pytest.approx(math.sqrt(3 * HALF), rel=RTOL)


def test_empty_estimates_all_truths_missed() -> None:
    g = gospa([[0.0, 0.0, 50.0], [30.0, 0.0, 50.0]], [])
    assert g.assignment == (None, None)
    assert g.missed == pytest.approx(2 * HALF, rel=RTOL)
    assert g.false == 0.0
    assert g.distance == pytest.approx(math.sqrt(2 * HALF), rel=RTOL)


def test_one_far_estimate_is_one_missed_and_one_false() -> None:
    g = gospa([[0.0, 0.0, 0.0]], [[300.0, 400.0, 0.0]])
    assert g.assignment == (None,)
    assert (g.n_missed, g.n_false) == (1, 1)
    assert (g.localisation, g.missed, g.false) == (0.0, HALF, HALF)
    assert g.distance == pytest.approx(C, rel=RTOL)  # sqrt(c^2 / 2 + c^2 / 2)


def test_two_truths_two_estimates_known_assignment() -> None:
    # pairs: (0,0) 10 m, (0,1) 40 m, (1,0) 20 m, (1,1) 70 m; nearest-first takes (0,0) and is
    # left with (1,1): 100 + 4900 = 5000; the optimum crosses: 1600 + 400 = 2000
    X = [[0.0, 0.0, 0.0], [30.0, 0.0, 0.0]]
    Y = [[10.0, 0.0, 0.0], [-40.0, 0.0, 0.0]]
    g = gospa(X, Y)
    assert g.assignment == (1, 0)
    assert g.errors_m == (40.0, 20.0)
    assert g.localisation == pytest.approx(2000.0, rel=RTOL)
    assert (g.missed, g.false) == (0.0, 0.0)
    assert g.distance == pytest.approx(math.sqrt(2000.0), rel=RTOL)


def test_cut_off() -> None:
    # just inside c: one assigned pair of cost 99.9^2; at c and beyond: missed + false (c^2)
    inside = gospa([[0.0, 0.0, 0.0]], [[99.9, 0.0, 0.0]])
    assert inside.assignment == (0,)
    assert inside.localisation == pytest.approx(99.9**2, rel=RTOL)
    at_c = gospa([[0.0, 0.0, 0.0]], [[100.0, 0.0, 0.0]])
    assert at_c.assignment == (None,) and (at_c.missed, at_c.false) == (HALF, HALF)
    # another cut-off moves the boundary
    small = gospa([[0.0, 0.0, 0.0]], [[60.0, 0.0, 0.0]], GospaSettings(c_m=50.0))
    assert small.assignment == (None,)
    assert small.distance == pytest.approx(50.0, rel=RTOL)


def test_alpha_2_identity_total_is_sum_of_parts() -> None:
    rng = np.random.default_rng(7)
    for _ in range(100):
        X = rng.uniform(-150, 150, size=(int(rng.integers(0, 5)), 3))
        Y = rng.uniform(-150, 150, size=(int(rng.integers(0, 6)), 3))
        g = gospa(X, Y)
        assert g.distance**2 == pytest.approx(g.total, rel=RTOL, abs=1e-9)
        assert g.n_missed == X.shape[0] - sum(a is not None for a in g.assignment)
        assert g.n_false == Y.shape[0] - sum(a is not None for a in g.assignment)
        assert (g.missed, g.false) == (g.n_missed * HALF, g.n_false * HALF)
        pairs = [(i, j) for i, j in enumerate(g.assignment) if j is not None]
        assert all(np.linalg.norm(X[i] - Y[j]) < C for i, j in pairs)
        assert g.localisation == pytest.approx(
            sum(float(np.sum((X[i] - Y[j]) ** 2)) for i, j in pairs), rel=RTOL, abs=1e-9
        )


def _brute_force(X: np.ndarray, Y: np.ndarray, s: GospaSettings) -> float:
    """The GOSPA definition: minimum over all partial assignments, by enumeration."""
    m, n = len(X), len(Y)
    best = math.inf
    for k in range(min(m, n) + 1):
        for rows in itertools.combinations(range(m), k):
            for cols in itertools.permutations(range(n), k):
                cost = sum(
                    min(float(np.linalg.norm(X[i] - Y[j])), s.c_m) ** s.p
                    for i, j in zip(rows, cols, strict=True)
                )
                cost += s.c_m**s.p / s.alpha * (m + n - 2 * k)
                best = min(best, cost)
    return float(best ** (1.0 / s.p))


@pytest.mark.parametrize(
    "s", [GospaSettings(), GospaSettings(p=1.0, c_m=40.0, alpha=1.0), GospaSettings(p=3.0)]
)
def test_against_brute_force(s: GospaSettings) -> None:
    rng = np.random.default_rng(11)
    for _ in range(60):
        X = rng.uniform(-120, 120, size=(int(rng.integers(0, 4)), 3))
        Y = rng.uniform(-120, 120, size=(int(rng.integers(0, 5)), 3))
        assert gospa(X, Y, s).distance == pytest.approx(_brute_force(X, Y, s), rel=RTOL)


def test_bad_input_is_a_clear_error() -> None:
    with pytest.raises(ValueError, match=r"truths: expected an \(n, 3\)"):
        gospa([[1.0, 2.0]], [])
    with pytest.raises(ValueError, match="estimates: positions must be finite"):
        gospa([], [[1.0, math.nan, 0.0]])
    with pytest.raises(ValueError, match="alpha"):
        GospaSettings(alpha=3.0)
    with pytest.raises(ValueError, match="cut-off"):
        GospaSettings(c_m=0.0)


# --- the oracle: Stone Soup's GOSPAMetric --------------------------------------------------


def test_against_stone_soup_gospa_metric() -> None:
    """Stone Soup's ``compute_gospa_metric`` returns ``distance`` = (localisation + missed +
    false)^(1/p) and the three parts un-rooted, a pair at d >= c being missed + false; its
    assignment is per truth, -1 when unassigned (empty when either set is empty). Both sets
    empty have no timestamp there, so those epochs are checked against 0 only."""
    from stonesoup.measures import Euclidean
    from stonesoup.metricgenerator.ospametric import GOSPAMetric
    from stonesoup.types.groundtruth import GroundTruthState
    from stonesoup.types.state import State

    metric = GOSPAMetric(c=C, p=2.0, measure=Euclidean(mapping=(0, 1, 2)))
    assert metric.alpha == 2
    rng = np.random.default_rng(2025)
    t0 = dt.datetime(2025, 6, 1, 12, 0, 0)
    compared = 0
    for k in range(50):
        X = rng.uniform(-200, 200, size=(int(rng.integers(0, 5)), 3))
        # estimates near some truths (inside c), plus far ones
        Y = rng.uniform(-200, 200, size=(int(rng.integers(0, 6)), 3))
        for j in range(min(len(X), len(Y))):
            if rng.random() < 0.7:
                Y[j] = X[j] + rng.normal(0.0, 30.0, 3)
        ours = gospa(X, Y)
        if len(X) == 0 and len(Y) == 0:
            assert ours.distance == 0.0
            continue
        t = t0 + dt.timedelta(seconds=k)
        # 6D states (position, velocity): the measure compares the position only
        truths = [
            GroundTruthState(np.r_[x, rng.normal(0, 5, 3)].reshape(6, 1), timestamp=t) for x in X
        ]
        ests = [State(np.r_[y, rng.normal(0, 5, 3)].reshape(6, 1), timestamp=t) for y in Y]
        ref, assign = metric.compute_gospa_metric(ests, truths)
        v = ref.value
        assert ours.distance == pytest.approx(float(v["distance"]), rel=RTOL, abs=1e-12)
        assert ours.localisation == pytest.approx(float(v["localisation"]), rel=RTOL, abs=1e-12)
        assert ours.missed == pytest.approx(float(v["missed"]), rel=RTOL, abs=1e-12)
        assert ours.false == pytest.approx(float(v["false"]), rel=RTOL, abs=1e-12)
        if len(X) and len(Y):
            theirs = tuple(None if a == -1 else int(a) for a in assign)
            assert ours.assignment == theirs
        compared += 1
    assert compared >= 40


def test_against_stone_soup_over_time() -> None:
    """The whole sequence through ``compute_over_time`` (switching penalty 0): the per-epoch
    distances equal the scorer's GOSPA."""
    from stonesoup.metricgenerator.ospametric import GOSPAMetric
    from stonesoup.types.groundtruth import GroundTruthState
    from stonesoup.types.state import State

    metric = GOSPAMetric(c=C, p=2.0)
    rng = np.random.default_rng(5)
    t0 = dt.datetime(2025, 6, 1, 12, 0, 0)
    truth_states, truth_ids, est_states, est_ids = [], [], [], []
    ours = []
    for k in range(30):
        X = rng.uniform(-150, 150, size=(int(rng.integers(1, 4)), 3))
        Y = X + rng.normal(0.0, 40.0, X.shape)
        Y = np.vstack([Y, rng.uniform(-150, 150, size=(int(rng.integers(0, 3)), 3))])
        t = t0 + dt.timedelta(seconds=k)
        for i, x in enumerate(X):
            truth_states.append(GroundTruthState(x.reshape(3, 1), timestamp=t))
            truth_ids.append(i)
        for j, y in enumerate(Y):
            est_states.append(State(y.reshape(3, 1), timestamp=t))
            est_ids.append(j)
        ours.append(gospa(X, Y).distance)
    res = metric.compute_over_time(est_states, est_ids, truth_states, truth_ids)
    theirs = [float(m.value["distance"]) for m in res.value]
    np.testing.assert_allclose(ours, theirs, rtol=RTOL)


# --- ID switches and fragmentations --------------------------------------------------------


@pytest.mark.parametrize(
    ("seq", "switches", "frags"),
    [
        ([], 0, 0),
        ([None, None], 0, 0),
        ([1, 1, 1], 0, 0),
        ([None, 1, 1, None], 0, 0),  # late start and early end are no fragmentation
        ([1, 1, 2, 2], 1, 0),  # switch without a gap
        ([1, None, 1], 0, 1),  # gap, same id: fragmentation only
        ([1, None, None, 2], 1, 1),  # gap and a new id: both
        ([1, 2, 1, 2], 3, 0),
        ([1, None, 1, None, 3, 3, None], 1, 2),
    ],
)
def test_id_switches_and_fragmentations(seq: list[int | None], switches: int, frags: int) -> None:
    assert id_switches(seq) == switches
    assert fragmentations(seq) == frags


# --- per-flight scorer ---------------------------------------------------------------------

T0 = 1_760_000_000.0


def _truth(x0: float, y0: float, up: float = 50.0, t_end: float = 10.0) -> UavTruth:
    """On the ground (up 0) at T0, then at ``up`` from T0 + 0.5 on, flying east 10 m/s."""
    t = T0 + np.arange(0.0, t_end + 0.25, 0.5)
    u = np.where(t - T0 >= 0.5, up, 0.0)
    enu = np.column_stack([x0 + 10.0 * (t - T0), np.full(t.size, y0), u])
    return UavTruth(t, enu)


def _at(tr: UavTruth, t: float) -> np.ndarray:
    return np.array([np.interp(t, tr.t, tr.enu[:, i]) for i in range(3)])


def _est(
    tid: int, pos: np.ndarray, off: tuple[float, float, float] = (0.0, 0.0, 0.0)
) -> PublishedTrack:
    return PublishedTrack(tid, np.r_[pos + np.array(off), 0.0, 0.0, 0.0])


def test_flight_coverage_errors_switches_and_false_time() -> None:
    a, b = _truth(0.0, 0.0), _truth(0.0, 500.0)
    epochs = []
    for k in range(11):  # 1 Hz, T0 .. T0 + 10
        t = T0 + k
        tracks: list[PublishedTrack] = []
        # uav "a": track 1 at 3 m error, lost at epochs 5-6, back as track 2 from 7 on
        if k not in (5, 6):
            tracks.append(_est(1 if k < 5 else 2, _at(a, t), (3.0, 0.0, 0.0)))
        # uav "b": track 7 at 4 m error throughout
        tracks.append(_est(7, _at(b, t), (0.0, 0.0, 4.0)))
        # a clutter track far from both at epochs 2 and 3
        if k in (2, 3):
            tracks.append(_est(9, np.array([5000.0, 0.0, 100.0])))
        epochs.append(EpochTracks(t, tuple(tracks)))
    fs = score_flight({"a": a, "b": b}, epochs)
    sc = pool([fs])
    ua, ub = sc.uavs
    # epoch 0: both on the ground: tracks 1 and 7 are on them, excused (not false)
    assert (ua.name, ua.epochs, ub.epochs) == ("a", 10, 10)
    assert ua.coverage_pct == pytest.approx(80.0)
    assert ua.err_mean_m == pytest.approx(3.0) and ua.err_p95_m == pytest.approx(3.0)
    assert (ua.id_switches, ua.fragmentations) == (1, 1)
    assert (ub.coverage_pct, ub.id_switches, ub.fragmentations) == (100.0, 0, 0)
    assert ub.err_mean_m == pytest.approx(4.0)
    assert fs.uavs[0].track_ids == (1, 1, 1, 1, None, None, 2, 2, 2, 2)
    # false: the clutter at epochs 2, 3; excused: the 2 tracks at epoch 0
    assert sc.false_track_s == pytest.approx(2.0)
    assert sc.excused_track_s == pytest.approx(2.0)
    assert fs.assignments[0].excused == (("a", 1), ("b", 7))
    assert fs.assignments[0].false_ids == ()
    assert sc.coverage_pct == pytest.approx(90.0)
    assert (sc.id_switches, sc.fragmentations, sc.uav_epochs, sc.epochs) == (1, 1, 20, 11)
    # per-epoch GOSPA: epoch 0 nothing to score; epoch 1 both assigned (9 + 16); epoch 2 plus
    # clutter
    assert fs.distance[0] == pytest.approx(0.0)
    assert fs.distance[1] == pytest.approx(5.0)
    assert fs.distance[2] == pytest.approx(math.sqrt(25.0 + HALF))
    assert fs.distance[5] == pytest.approx(math.sqrt(16.0 + HALF))
    assert sc.gospa_mean_m == pytest.approx(float(np.mean(fs.distance)))
    assert sc.missed_mean == pytest.approx(2 * HALF / 11)
    assert sc.false_mean == pytest.approx(2 * HALF / 11)
    assert sc.localisation_mean == pytest.approx((10 * 16.0 + 8 * 9.0) / 11)
    assert fs.assignments[2].pairs == (("a", 1), ("b", 7))
    # without the rule the two tracks on the ground are false at epoch 0
    strict = score_flight({"a": a, "b": b}, epochs, MultiScoreSettings(excuse_grounded=False))
    st = pool([strict])
    assert st.false_track_s == pytest.approx(4.0) and st.excused_track_s == 0.0
    assert strict.distance[0] == pytest.approx(math.sqrt(2 * HALF))
    assert st.false_mean == pytest.approx(4 * HALF / 11)
    assert strict.assignments[0].false_ids == (1, 7)
    assert fs.assignments[2].false_ids == (9,)


def test_kept_correspondence_ignores_a_crosswise_assignment_for_an_epoch() -> None:
    """Two UAVs 10 m apart (north) flying east side by side, track 1 on "a" and track 2 on
    "b" (1 m off); at epochs 3 and 4 each track is 6 m off towards the other UAV, so GOSPA's
    per-epoch assignment crosses them (4 m + 4 m beats 6 m + 6 m): two switches per UAV on
    GOSPA's assignment, none on the kept correspondence."""
    a, b = _truth(0.0, 0.0), _truth(0.0, 10.0)
    epochs = []
    for k in range(11):
        t = T0 + k
        pa, pb = _at(a, t), _at(b, t)
        off = (0.0, 6.0, 0.0) if k in (3, 4) else (1.0, 0.0, 0.0)
        back = (0.0, -6.0, 0.0) if k in (3, 4) else (1.0, 0.0, 0.0)
        epochs.append(EpochTracks(t, (_est(1, pa, off), _est(2, pb, back))))
    fs = score_flight({"a": a, "b": b}, epochs)
    ua, ub = fs.uavs
    assert ua.track_ids == (1, 1, 2, 2, 1, 1, 1, 1, 1, 1)  # airborne from epoch 1
    assert ub.track_ids == (2, 2, 1, 1, 2, 2, 2, 2, 2, 2)
    assert (ua.id_switches, ub.id_switches) == (2, 2)
    assert (ua.id_switches_kept, ub.id_switches_kept) == (0, 0)
    # the switches happen where the crosswise pairing starts and ends (epochs 3 and 5)
    assert (ua.switch_times - T0).tolist() == [3.0, 5.0]
    assert (ub.switch_times - T0).tolist() == [3.0, 5.0]
    assert ua.switch_times_kept.size == 0 and ub.switch_times_kept.size == 0
    sc = pool([fs])
    assert (sc.id_switches, sc.id_switches_kept) == (4, 0)
    assert sc.uavs[0].id_switches_kept == 0


def test_kept_correspondence_counts_a_track_that_leaves_its_uav() -> None:
    """Track 1 on "a" (north 0) leaves it at epoch 4 (100 m north per epoch) and reaches "b"
    (north 300) at epoch 6; "a" gets track 5 at epoch 8: one switch for "a" on either
    assignment, none for "b" (it had no track before)."""
    a, b = _truth(0.0, 0.0), _truth(0.0, 300.0)
    epochs = []
    for k in range(11):
        t = T0 + k
        pa = _at(a, t)
        north = min(max(0.0, 100.0 * (k - 3)), 300.0)
        tracks = [_est(1, pa, (0.0, north, 0.0))]
        if k >= 8:
            tracks.append(_est(5, pa, (2.0, 0.0, 0.0)))
        epochs.append(EpochTracks(t, tuple(tracks)))
    fs = score_flight({"a": a, "b": b}, epochs)
    ua, ub = fs.uavs
    assert ua.track_ids == (1, 1, 1, None, None, None, None, 5, 5, 5)
    assert ub.track_ids == (None, None, None, None, None, 1, 1, 1, 1, 1)
    assert (ua.id_switches, ua.id_switches_kept) == (1, 1)
    assert (ub.id_switches, ub.id_switches_kept) == (0, 0)
    # "a" switches to track 5 when it appears (epoch 8) on both assignments
    assert (ua.switch_times - T0).tolist() == [8.0]
    assert (ua.switch_times_kept - T0).tolist() == [8.0]


def test_flight_airborne_mask_and_function() -> None:
    a = _truth(0.0, 0.0)
    # every UAV is airborne only between T0 + 3 and T0 + 6 (samples), by mask and by function
    mask = (a.t >= T0 + 3.0) & (a.t <= T0 + 6.0)
    epochs = [EpochTracks(T0 + k, (_est(1, _at(a, T0 + k)),)) for k in range(11)]
    by_mask = score_flight({"a": UavTruth(a.t, a.enu, mask)}, epochs)
    by_fn = score_flight(
        {"a": UavTruth(a.t, a.enu, lambda t, _p: (t >= T0 + 3.0) & (t <= T0 + 6.0))}, epochs
    )
    for fs in (by_mask, by_fn):
        assert fs.uavs[0].epochs == 4
        # the track is on the UAV at the 7 other epochs: excused, not false
        assert pool([fs]).false_track_s == 0.0
        assert pool([fs]).excused_track_s == pytest.approx(7.0)
    strict = score_flight(
        {"a": UavTruth(a.t, a.enu, mask)}, epochs, MultiScoreSettings(excuse_grounded=False)
    )
    assert pool([strict]).false_track_s == pytest.approx(7.0)
    # the default rule at another threshold: 50 m up is not above 60 m
    high = score_flight({"a": a}, epochs, MultiScoreSettings(airborne_min_m=60.0))
    assert high.uavs[0].epochs == 0
    assert math.isnan(pool([high]).coverage_pct)


def test_grounded_uav_excuses_one_close_track() -> None:
    a = _truth(0.0, 0.0)
    mask = a.t >= T0 + 100.0  # never airborne in these epochs
    truth = {"a": UavTruth(a.t, a.enu, mask)}
    at = _at(a, T0 + 1.0)
    # two tracks on the grounded UAV (3 and 20 m off) and one 150 m away
    ep = EpochTracks(
        T0 + 1.0,
        (_est(4, at, (20.0, 0.0, 0.0)), _est(5, at, (3.0, 0.0, 0.0)), _est(6, at, (150.0, 0, 0))),
    )
    fs = score_flight(truth, [ep])
    # the closer one is excused; the second track on the UAV and the far one stay false
    assert fs.assignments[0].excused == (("a", 5),)
    assert fs.assignments[0].false_ids == (4, 6)
    assert fs.false_estimates == 2 and fs.excused_estimates == 1
    assert fs.distance[0] == pytest.approx(math.sqrt(2 * HALF))
    # a track that GOSPA assigns to an airborne UAV is never excused by a grounded one
    b = _truth(0.0, 10.0)  # airborne, 10 m from "a"
    fs2 = score_flight({"a": UavTruth(a.t, a.enu, mask), "b": b}, [ep])
    assert fs2.assignments[0].pairs == (("b", 5),)
    assert fs2.assignments[0].excused == (("a", 4),)
    assert fs2.assignments[0].false_ids == (6,)


def test_pool_flights() -> None:
    a = _truth(0.0, 0.0)
    good = [EpochTracks(T0 + k, (_est(1, _at(a, T0 + k), (0, 0, 2.0)),)) for k in range(11)]
    bad = [
        EpochTracks(T0 + k, (_est(k % 2, _at(a, T0 + k), (0, 0, 6.0)),) if k % 3 else ())
        for k in range(11)
    ]
    f1, f2 = score_flight({"a": a}, good), score_flight({"a": a, "c": a}, bad)
    both = pool([f1, f2])
    assert both.flights == 2 and both.epochs == 22
    ua = next(u for u in both.uavs if u.name == "a")
    uc = next(u for u in both.uavs if u.name == "c")
    s1, s2 = pool([f1]).uavs[0], pool([f2]).uavs[0]
    assert ua.flights == 2 and uc.flights == 1
    assert ua.epochs == s1.epochs + s2.epochs
    assert ua.id_switches == s1.id_switches + s2.id_switches
    errs = np.concatenate([f1.uavs[0].errors, f2.uavs[0].errors])
    assert ua.err_p50_m == pytest.approx(float(np.percentile(errs, 50)))
    assert both.gospa_mean_m == pytest.approx(float(np.mean(np.r_[f1.distance, f2.distance])))
    assert both.false_track_s == pytest.approx(pool([f1]).false_track_s + pool([f2]).false_track_s)


def test_flight_bad_input_is_a_clear_error() -> None:
    a = _truth(0.0, 0.0)
    with pytest.raises(ValueError, match=r"1\.0 s apart"):
        score_flight({"a": a}, [EpochTracks(T0, ()), EpochTracks(T0 + 2.0, ())])
    with pytest.raises(ValueError, match="duplicate track ids"):
        p = _at(a, T0 + 1)
        score_flight({"a": a}, [EpochTracks(T0 + 1, (_est(3, p), _est(3, p)))])
    with pytest.raises(ValueError, match="track 4 has no finite ENU position"):
        score_flight({"a": a}, [EpochTracks(T0, (PublishedTrack(4, np.array([1.0, 2.0])),))])
    with pytest.raises(ValueError, match="truth of 'x': times must be strictly increasing"):
        score_flight({"x": UavTruth(np.array([1.0, 1.0]), np.zeros((2, 3)))}, [])
    with pytest.raises(ValueError, match="airborne mask has shape"):
        score_flight({"a": UavTruth(a.t, a.enu, np.ones(3, dtype=bool))}, [])
