"""Physical gates (core/estimators/gates.py): what may restart the UAV track after it is lost,
and how far one RF fix may move a coasting track. Each rule has a hand case, and each case
also runs with the rule switched off to show that it is the rule that decides."""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
import pytest
from test_tracker import Scene

from uav_fusion.core.estimators import load_profile
from uav_fusion.core.estimators.gates import FAR_SIGMAS, PhysicalGates
from uav_fusion.core.estimators.objects import Drift, RadarObject
from uav_fusion.core.estimators.offline import run_tracker
from uav_fusion.core.estimators.steps import TrackerStep
from uav_fusion.core.estimators.tracker import Tracker
from uav_fusion.core.profiles.model import Profile
from uav_fusion.core.profiles.settings import ScoreConfig
from uav_fusion.core.records import RadarFrame, RadarTrack, RfAttempt
from uav_fusion.core.site import Site, load_site

GROUND_ID = 500
LOST_AT = 100.0  # the UAV vanishes from both sensors


@pytest.fixture(scope="module")
def site() -> Site:
    return load_site()


class Loop(Scene):
    """A slow loop ``radius`` from the radar at 50 m height."""

    radius = 600.0

    def uav(self, t: float) -> np.ndarray:
        a = 0.02 * t * 400.0 / self.radius  # 8 m/s
        return self.r0 + np.array(
            [self.radius * math.cos(a), self.radius * math.sin(a), 50.0], dtype=np.float64
        )


class FarLoop(Loop):
    """Beyond 1 km, where a coasting track is not held in the Doppler notch (its covariance
    grows freely, so a fix far off can pass the statistical gate)."""

    radius = 1200.0


def _lost_uav(site: Site, seed: int = 3, rf_after: bool = False) -> Scene:
    """The loop seen by radar and RF for 100 s, then by neither (or by RF only,
    ``rf_after``)."""
    sc = Loop(site, seed=seed)
    sc.build(
        200.0,
        uav_visible=lambda t: t < LOST_AT,
        rf_ok=lambda t: rf_after or t < LOST_AT,
    )
    return sc


def _add_object(sc: Scene, start: float, report: Callable[[float], RadarTrack]) -> None:
    """Add to every radar frame from ``start`` on the report ``report(t)`` of another object."""
    sc.frames = [
        RadarFrame(f.t, (*f.tracks, report(f.t))) if f.t >= start else f for f in sc.frames
    ]


def _with_ground_object(
    sc: Scene, at: np.ndarray, start: float, rf_from: float | None = None
) -> list[RadarFrame | RfAttempt]:
    """Add a stationary object on the ground at ``at`` (east, north), classed UAV (0.95)
    from its first report at ``start``; RF fixes at it every 4 s from ``rf_from``."""
    ground = np.array([at[0], at[1], 1.0])
    _add_object(sc, start, lambda t: sc.report(t, GROUND_ID, ground, 0.95, np.zeros(3), sd=3.0,
                                               rcs_dbsm=-12.0))  # fmt: skip
    if rf_from is not None:
        k = 10_000
        for t in np.arange(rf_from, sc.frames[-1].t, 4.0):
            e, n = at[:2] + sc.rng.normal(0.0, 5.0, 2)
            sc.fixes.append(RfAttempt(float(t) + 0.05, k, True, 0.0, 0.0, e, n, 8.0, 4, 4))
            k += 1
    return sc.stream()


def _started_on(steps: list[TrackerStep], track_id: int) -> list[TrackerStep]:
    return [s for s in steps if s.status in ("initialised", "reset") and s.track_id == track_id]


def _profile() -> Profile:
    """The tracker profile with the 3 s class history these scenes are timed for (an object
    classed UAV from its first report reaches the start threshold within a second or two;
    the gates under test do not depend on it)."""
    return load_profile("tracker").with_keys({"association.object.tau_s": 3.0})


def _far_point(sc: Scene, dist: float) -> np.ndarray:
    """A point ``dist`` from where the UAV was lost, across the radar (900 m beyond it for
    1500 m: inside the range gate, where new tracks start)."""
    p = sc.uav(LOST_AT)[:2]
    across = (sc.r0[:2] - p) / np.linalg.norm(p - sc.r0[:2])
    return np.asarray(p + dist * across)


def test_after_a_reset_a_ground_object_far_from_the_last_state_never_starts_the_track(
    site: Site, monkeypatch: pytest.MonkeyPatch
) -> None:
    sc = _lost_uav(site)
    # 1.5 km from the last state; it appears 60 s later, when the UAV could be there (30 m/s)
    stream = _with_ground_object(sc, _far_point(sc, 1500.0), start=LOST_AT + 60.0)
    tr = Tracker(_profile(), site)
    steps = run_tracker(tr, stream)
    assert tr.counters.get("reinit_max_coast") == 1 and tr.gates.airborne
    assert not _started_on(steps, GROUND_ID)
    assert tr.counters["init_refused_ground"] > 0
    refused = [s for s in steps if s.track_id == GROUND_ID and s.reason == "ground"]
    assert refused and refused[0].status == "discarded"
    # the rule decides: without it, the young object, classed UAV, starts the track
    monkeypatch.setattr(PhysicalGates, "grounded", lambda self, obj: False)
    steps = run_tracker(Tracker(_profile(), site), stream)
    assert _started_on(steps, GROUND_ID)


def test_a_ground_object_seen_through_its_moving_part_is_still_a_ground_object(
    site: Site, monkeypatch: pytest.MonkeyPatch
) -> None:
    # a fan or a flag: the radar sees it through its moving part, so its reports carry a
    # Doppler velocity of 4-8 m/s in changing directions, but their positions stand still;
    # classed unsure for its first 20 s, then UAV (0.95), 1.5 km from the last state
    sc = _lost_uav(site)
    at = _far_point(sc, 1500.0)
    seen = LOST_AT + 40.0

    def fan(t: float) -> RadarTrack:
        a = float(sc.rng.uniform(0.0, 2.0 * math.pi))
        vel = float(sc.rng.uniform(4.0, 8.0)) * np.array([math.cos(a), math.sin(a), 0.0])
        prob = 0.3 if t < seen + 20.0 else 0.95
        return sc.report(t, GROUND_ID, np.array([at[0], at[1], 1.0]), prob, vel, sd=3.0,
                         rcs_dbsm=-12.0)  # fmt: skip

    _add_object(sc, seen, fan)
    tr = Tracker(_profile(), site)
    steps = run_tracker(tr, sc.stream())
    obj = tr.objects.objects[GROUND_ID]
    assert obj.speed > 2.0 * tr.cfg.stationary_speed_mps  # its Doppler says it moves ...
    fit = obj.drift.speed()
    assert fit is not None and fit[0] < 0.2  # ... its positions say it does not
    assert not _started_on(steps, GROUND_ID) and tr.counters["init_refused_ground"] > 0
    # the positions decide: judged by its reports' velocity alone, it starts the track
    monkeypatch.setattr(Drift, "still", lambda self, speed_mps: False)
    assert _started_on(run_tracker(Tracker(_profile(), site), sc.stream()), GROUND_ID)


def test_the_drift_fit_at_its_edges() -> None:
    def fitted(speed: float, noise: float, n: int, seed: int = 1) -> Drift:
        rng = np.random.default_rng(seed)
        d = Drift(100.0)
        for k in range(n):
            t = 100.0 + 0.25 * k
            e, nn = 0.6 * speed * (t - 100.0), 0.8 * speed * (t - 100.0)
            d.add(t, e + float(rng.normal(0.0, noise)), nn + float(rng.normal(0.0, noise)))
        return d

    # exact positions: the fitted speed is the speed, known exactly
    fit = fitted(1.49, 0.0, 40).speed()
    assert fit is not None and fit[0] == pytest.approx(1.49) and fit[1] < 1e-6
    assert fitted(1.49, 0.0, 40).still(1.5) and not fitted(1.51, 0.0, 40).still(1.5)
    # standing still among scattered positions: still once the scatter pins the speed to
    # better than half the limit, not before
    few, many = fitted(0.0, 10.0, 12), fitted(0.0, 10.0, 240)
    fit_few, fit_many = few.speed(), many.speed()
    assert fit_few is not None and fit_few[1] > 0.75 and not few.still(1.5)
    assert fit_many is not None and fit_many[1] < 0.75 and many.still(1.5)
    # a reflector's radar track id that passes onto an object moving at 8 m/s: 20 s after 5
    # minutes, a fit over the whole history would still say it stands still; the fading
    # weights see the motion
    rng = np.random.default_rng(2)
    ts = 0.25 * np.arange(1280)
    east = np.where(ts < 300.0, 0.0, 8.0 * (ts - 300.0)) + rng.normal(0.0, 3.0, ts.size)
    north = rng.normal(0.0, 3.0, ts.size)
    swapped = Drift(0.0)
    for t, e, n in zip(ts, east, north, strict=True):
        swapped.add(float(t), float(e), float(n))
    assert abs(np.polyfit(ts, east, 1)[0]) < 1.5 and not swapped.still(1.5)
    fit_swapped = swapped.speed()
    assert fit_swapped is not None and fit_swapped[0] > 1.5
    # a reflector 1.5 km out (reports 35 m apart across the line of sight): still once about
    # 40 s of reports have averaged its scatter down, not after 20 s
    far = [Drift(0.0), Drift(0.0)]
    for d, seconds in zip(far, (20.0, 40.0), strict=True):
        for t in 0.25 * np.arange(int(4 * seconds)):
            d.add(float(t), float(rng.normal(0.0, 35.0)), float(rng.normal(0.0, 35.0)))
    assert not far[0].still(1.5) and far[1].still(1.5)
    # two positions, or none apart in time: no fit
    assert fitted(1.0, 0.0, 2).speed() is None
    d = Drift(0.0)
    for _ in range(5):
        d.add(3.0, 1.0, 1.0)
    assert d.speed() is None and not d.still(1.5)


def test_a_coasting_track_does_not_pass_onto_a_ground_object_inside_its_gate(
    site: Site, monkeypatch: pytest.MonkeyPatch
) -> None:
    # 3 s after the UAV vanishes, a stationary object classed UAV appears on the ground right
    # below where the coasting track is: inside its gate and reachable, so only the ground
    # rule stands between the track and the object
    sc = _lost_uav(site)
    t0 = LOST_AT + 3.0
    _with_ground_object(sc, sc.uav(t0)[:2], start=t0)
    stream = sc.stream()
    tr = Tracker(_profile(), site)
    steps = run_tracker(tr, stream)
    assert tr.gates.airborne and tr.counters["rejected_ground"] > 0
    assert not [s for s in steps if s.updated and s.track_id == GROUND_ID]
    # refused while the track coasts, not only at the restart after it (a report the frame's
    # rejection of the track is made of is a coasted step; the others are discarded as such)
    coasting = [s for s in steps if s.track_id == GROUND_ID and s.t < LOST_AT + 15.0]
    dropped = [s for s in coasting if s.status == "discarded"]
    assert dropped and all(s.reason == "ground" for s in dropped)
    assert all(s.status in ("discarded", "coasted") for s in coasting)
    assert tr.counters.get("reinit_max_coast") == 1  # the track coasted out instead
    # an RF fix credited to the object corroborates it: the track passes onto it then
    sc = _lost_uav(site)
    _with_ground_object(sc, sc.uav(t0)[:2], start=t0, rf_from=t0 + 2.0)
    steps = run_tracker(Tracker(_profile(), site), sc.stream())
    taken = [s for s in steps if s.updated and s.track_id == GROUND_ID]
    assert taken and t0 + 2.0 < taken[0].t < t0 + 3.0
    # the rule decides: without it the coasting track takes the object's first report
    monkeypatch.setattr(PhysicalGates, "refuse_ground", lambda self, obj, t: False)
    steps = run_tracker(Tracker(_profile(), site), stream)
    taken = [s for s in steps if s.updated and s.track_id == GROUND_ID]
    assert taken and taken[0].t < t0 + 1.0


def test_radar_and_rf_agreeing_corroborate_a_ground_object(site: Site) -> None:
    sc = _lost_uav(site)
    at = _far_point(sc, 1500.0)
    # the emitter is there (the UAV landed): an RF fix credited to the object corroborates it
    stream = _with_ground_object(sc, at, start=LOST_AT + 60.0, rf_from=LOST_AT + 62.0)
    tr = Tracker(_profile(), site)
    steps = run_tracker(tr, stream)
    # the first fix starts a tentative RF track; the object inside its gate confirms it
    assert tr.counters["init_refused_ground"] >= 1 and tr.counters["confirmed"] == 1
    followed = [s for s in steps if s.updated and s.track_id == GROUND_ID]
    assert followed and LOST_AT + 62.0 < followed[0].t < LOST_AT + 63.0


def test_an_object_the_uav_cannot_have_reached_starts_the_track_only_once_it_could(
    site: Site, monkeypatch: pytest.MonkeyPatch
) -> None:
    sc = _lost_uav(site)
    # an airborne object 1.5 km out appears 25 s after the loss: the UAV could be 30 m/s x
    # (25 s + its last update before the loss) + 200 m away, about 950 m
    at = _far_point(sc, 1500.0)
    def flyer(t: float) -> RadarTrack:  # east at 5 m/s
        p = np.array([at[0] + 5.0 * (t - LOST_AT), at[1], 60.0])
        return sc.report(t, GROUND_ID, p, 0.95, np.array([5.0, 0.0, 0.0]), sd=3.0,
                         rcs_dbsm=-12.0)  # fmt: skip

    _add_object(sc, LOST_AT + 25.0, flyer)
    tr = Tracker(_profile(), site)
    steps = run_tracker(tr, sc.stream())
    assert tr.counters["init_refused_unreachable"] > 0
    (start,) = _started_on(steps, GROUND_ID)
    anchor_t = max(s.t for s in steps if s.t < LOST_AT + 1.0 and s.updated)
    reach = 30.0 * (start.t - anchor_t) + 200.0
    dist = math.dist(start.z[:2], sc.uav(anchor_t)[:2])
    assert reach >= dist - 30.0  # it started once the UAV could be there ...
    assert 30.0 * (start.t - 1.0 - anchor_t) + 200.0 < dist + 30.0  # ... and not long before
    monkeypatch.setattr(PhysicalGates, "reachable", lambda self, t, e, n: True)
    early = _started_on(run_tracker(Tracker(_profile(), site), sc.stream()),
                        GROUND_ID)  # fmt: skip
    assert early and early[0].t < start.t - 5.0


def test_the_reach_gate_at_its_edge() -> None:
    gates = PhysicalGates(ScoreConfig(reach_margin_m=200.0), max_speed_mps=30.0)
    assert gates.reachable(10.0, 5000.0, 0.0)  # no confirmed state yet: anywhere
    gates.confirmed_state(0.0, [0.0, 0.0, 50.0, 0.0, 0.0, 0.0], 4.0)
    assert gates.airborne
    # 30 m/s x 10 s + 200 m = 500 m
    assert gates.reachable(10.0, 0.0, 499.9) and not gates.reachable(10.0, 0.0, 500.1)
    assert gates.reachable(10.0, 300.0, 399.9) and not gates.reachable(10.0, 300.0, 400.1)
    assert PhysicalGates(ScoreConfig(reach_margin_m=0.0), 30.0).reachable(10.0, 1e6, 0.0)


def test_the_ground_rule_at_its_edges() -> None:
    """Each condition of ``refuse_ground`` at its boundary: the track is airborne once a
    confirmed state stood more than ``ground_alt_m`` plus two of its own vertical sigmas up;
    an object is near the ground below ``ground_alt_m`` plus two of its reports' mean
    vertical sigmas; an RF fix corroborates it for ``rf_tau_s`` after it was credited."""
    cfg = ScoreConfig(ground_alt_m=4.0, stationary_speed_mps=1.5, rf_tau_s=20.0)
    gates = PhysicalGates(cfg, max_speed_mps=30.0)
    obj = RadarObject(GROUND_ID, 0.0)
    obj.last_t = 1.0  # young, its mean Doppler speed 0: stationary
    obj.up, obj.sd_up = 9.9, 3.0  # below 4 + 2 x 3 = 10 m: near the ground
    assert gates.grounded(obj)
    # not airborne yet: 9.9 m up with a vertical sigma of 3 m is not clearly off the ground
    gates.confirmed_state(0.0, [0.0, 0.0, 9.9, 0.0, 0.0, 0.0], 9.0)
    assert not gates.airborne and not gates.refuse_ground(obj, 1.0)
    gates.confirmed_state(0.5, [0.0, 0.0, 10.1, 0.0, 0.0, 0.0], 9.0)
    assert gates.airborne and gates.refuse_ground(obj, 1.0)
    obj.up = 10.1  # above 4 + 2 x 3 m: not near the ground, so not refused
    assert not gates.grounded(obj) and not gates.refuse_ground(obj, 1.0)
    obj.up = 9.9
    obj.speed = 1.6  # moving (and too young for its positions to say otherwise)
    assert not gates.grounded(obj)
    obj.speed = 1.4
    # an RF fix credited at 5 s corroborates it until 25 s, not after
    obj.rf_support, obj.rf_t = 1.0, 5.0
    assert not gates.refuse_ground(obj, 25.0) and gates.refuse_ground(obj, 25.1)
    assert gates.refuse_start(obj, 25.0, 0.0, 0.0) is None
    assert gates.refuse_start(obj, 25.1, 0.0, 0.0) == "ground"


def test_a_still_object_with_a_moving_part_counts_as_stationary_from_its_minimum_age() -> None:
    """Near the ground, an object whose Doppler speed says it moves (the radar sees a fan or
    a flag through its moving part) but whose positions stand still is stationary once it is
    ``association.object.tau_s`` old, not before: a young object's few positions say little."""
    cfg = ScoreConfig(ground_alt_m=4.0, stationary_speed_mps=1.5, tau_s=8.0)
    gates = PhysicalGates(cfg, max_speed_mps=30.0)
    obj = RadarObject(GROUND_ID, 0.0)
    obj.up, obj.sd_up, obj.speed = 2.0, 3.0, 5.0
    for k in range(32):  # 4 Hz up to 7.75 s, scattering by half a metre about one point
        obj.drift.add(0.25 * k, 100.0 + 0.5 * math.sin(1.3 * k), 200.0 + 0.5 * math.cos(0.7 * k))
    assert obj.drift.still(1.5)
    obj.last_t = 7.9
    assert not gates.grounded(obj)
    obj.last_t = 8.0
    assert gates.grounded(obj)


def test_the_takeover_reach_gate_at_its_edge(site: Site) -> None:
    tr = Tracker(_profile(), site)
    assert tr.cfg.reach_margin_m == 200.0 and tr.profile.max_speed_mps == 30.0
    tr._last_pos, tr.last_update_t = (100.0, -50.0), 20.0
    # a takeover candidate 30 m/s x 10 s + 200 m from the last update
    ok = tr.follow._reachable
    assert ok(30.0, 100.0 + 499.9, -50.0, 200.0) and not ok(30.0, 100.0 + 500.1, -50.0, 200.0)


def _coast_then_fix(
    site: Site, off_m: float, after_s: float, second: bool
) -> tuple[Tracker, list[TrackerStep]]:
    """Radar and RF for 100 s; then nothing for ``after_s``; then an RF fix ``off_m`` off
    the UAV, further out (CEP 5 m), and with ``second`` another 4 s later at the same place."""
    sc = FarLoop(site, seed=5)
    sc.build(130.0, uav_visible=lambda t: t < LOST_AT, rf_ok=lambda t: t < LOST_AT)
    t1 = LOST_AT + after_s
    p = sc.uav(t1)
    out = (p[:2] - sc.r0[:2]) / np.linalg.norm(p[:2] - sc.r0[:2])
    at = p[:2] + off_m * out
    e, n = map(float, at)
    sc.fixes.append(RfAttempt(t1, 90_000, True, 0.0, 0.0, e, n, 5.0, 4, 4))
    if second:
        e2, n2 = map(float, at + 3.0)
        sc.fixes.append(RfAttempt(t1 + 4.0, 90_001, True, 0.0, 0.0, e2, n2, 5.0, 4, 4))
    tr = Tracker(_profile(), site)
    return tr, run_tracker(tr, sc.stream())


def _moved(steps: list[TrackerStep], t0: float) -> float:
    """How far the track's horizontal position jumped at the step after time ``t0``."""
    before = [s for s in steps if s.t < t0 and s.x is not None][-1]
    after = next(s for s in steps if s.t >= t0 and s.x is not None)
    dt = after.t - before.t
    pred = before.x[:2] + dt * before.x[3:5]
    return float(np.linalg.norm(after.x[:2] - pred))


def test_during_a_coast_one_rf_fix_500_m_off_does_not_move_the_track(
    site: Site, monkeypatch: pytest.MonkeyPatch
) -> None:
    # 19 s into a coast the covariance is wide: the fix passes the statistical gate
    tr, steps = _coast_then_fix(site, 500.0, 19.0, second=False)
    (held,) = [s for s in steps if s.source == "rf" and s.reason == "held"]
    assert held.t == LOST_AT + 19.0 and tr.counters["rf_held"] == 1
    assert held.nis is not None and held.nis < 9.21  # inside the statistical gate ...
    assert _moved(steps, LOST_AT + 19.0) <= 50.0  # ... yet the track does not follow it
    # the rule decides: without it the fix pulls the coasting track hundreds of metres
    monkeypatch.setattr(PhysicalGates, "rf_move_allowed", lambda self, *a: True)
    _, free = _coast_then_fix(site, 500.0, 19.0, second=False)
    assert _moved(free, LOST_AT + 19.0) > 200.0


def test_a_second_fix_that_agrees_moves_the_track(site: Site) -> None:
    _tr, steps = _coast_then_fix(site, 150.0, 10.0, second=True)
    rf = [s for s in steps if s.source == "rf" and s.t > LOST_AT]
    assert [(s.t - LOST_AT, s.status, s.reason) for s in rf] == [
        (10.0, "discarded", "held"),
        (14.0, "updated", None),
    ]
    assert _moved(steps, LOST_AT + 14.0) > 100.0


def test_a_small_move_needs_no_second_fix() -> None:
    gates = PhysicalGates(ScoreConfig(reach_margin_m=200.0), 30.0)
    sd = 10.0
    assert gates.rf_move_allowed(0.0, 0.0, 0.0, sd * sd, FAR_SIGMAS * sd - 0.1)
    assert not gates.rf_move_allowed(1.0, 0.0, 0.0, sd * sd, FAR_SIGMAS * sd + 0.1)
    # the held fix and one 4 s later: agreement within 3 sigmas of both + 30 m/s x 4 s
    tol = FAR_SIGMAS * math.sqrt(2.0) * sd + 120.0
    assert not gates.rf_move_allowed(5.0, tol + 1.0, 0.0, sd * sd, 500.0)  # held in its place
    assert gates.rf_move_allowed(9.0, tol + 1.0 + tol - 1.0, 0.0, sd * sd, 500.0)


def test_agreeing_rf_fixes_outside_the_gate_end_the_track_at_the_third() -> None:
    gates = PhysicalGates(ScoreConfig(reach_margin_m=200.0), 30.0)
    gates.confirmed_state(0.0, [0.0, 0.0, 50.0, 0.0, 0.0, 0.0], 4.0)
    var = 10.0**2
    # two agreeing fixes 400 m off are not enough; the third ends the track ...
    assert not gates.rf_outside(4.0, 400.0, 0.0, var, 3)
    assert not gates.rf_outside(8.0, 410.0, 0.0, var, 3)
    assert gates.rf_outside(12.0, 420.0, 0.0, var, 3)
    # ... and the last fix becomes the state the next start must be reachable from
    assert gates.anchor is not None and (gates.anchor.t, gates.anchor.e) == (12.0, 420.0)
    assert not gates.reachable(12.0, 0.0, 0.0)
    # a fix that disagrees with the run starts a new one; a fix inside the gate ends it
    assert not gates.rf_outside(16.0, 400.0, 0.0, var, 3)
    assert not gates.rf_outside(20.0, 400.0, 900.0, var, 3)  # 900 m in 4 s: another emitter
    assert not gates.rf_outside(24.0, 400.0, 910.0, var, 3)
    gates.rf_inside()
    assert not gates.rf_outside(28.0, 400.0, 920.0, var, 3)
    assert not gates.rf_outside(32.0, 400.0, 930.0, var, 3)
    assert gates.rf_outside(36.0, 400.0, 940.0, var, 3)


def test_a_track_on_a_decoy_is_dropped_when_the_rf_fixes_say_the_uav_is_elsewhere(
    site: Site, monkeypatch: pytest.MonkeyPatch
) -> None:
    # the radar sees only a decoy 300 m from the UAV, classed UAV, moving like one; the RF
    # fixes (one every 4 s) are on the UAV
    sc = Loop(site, seed=7)

    def decoy(scene: Scene, t: float, k: int) -> RadarTrack:
        p = scene.uav(t) + np.array([300.0, 0.0, 0.0])
        vel = (scene.uav(t + 0.01) - scene.uav(t)) / 0.01
        return scene.report(t, GROUND_ID, p, 0.9, vel)

    sc.build(60.0, uav_visible=lambda t: False, decoy=decoy)
    tr = Tracker(_profile(), site)
    steps = run_tracker(tr, sc.stream())
    start = next(s for s in steps if s.status == "initialised")
    assert start.track_id == GROUND_ID and start.t < 4.0  # before the first RF fix
    rf = [s for s in steps if s.source == "rf" and s.t > start.t]
    # the first two fixes after the start are refused by the gate, the third ends the track
    # and starts an RF track at the emitter
    assert [(s.status, s.reason) for s in rf[:3]] == [
        ("coasted", "nis"), ("coasted", "nis"), ("tentative", "start"),
    ]  # fmt: skip
    assert tr.counters["reinit_rf_disagrees"] >= 1 and sc.error(rf[2]) < 30.0
    # the rule decides: without it the track stays on the decoy, 300 m off, all along
    monkeypatch.setattr(PhysicalGates, "rf_outside", lambda self, *a: False)
    tr = Tracker(_profile(), site)
    steps = run_tracker(tr, sc.stream())
    assert "reinit_rf_disagrees" not in tr.counters
    assert min(sc.error(s) for s in steps if s.counted and s.t > start.t) > 250.0
