"""Zero-wait fusion (uav_fusion.core.live.rewind): late inputs fused by rewinding and
re-filtering give exactly the in-order track, for every estimator."""

from __future__ import annotations

import math
import random
from dataclasses import replace

import pytest

from uav_fusion.core.data import load_flight
from uav_fusion.core.estimators import load_profile, make_estimator
from uav_fusion.core.estimators.base import Estimator, drive
from uav_fusion.core.estimators.multi import MultiTracker
from uav_fusion.core.estimators.steps import Step
from uav_fusion.core.live.rewind import Rewinder, simulate
from uav_fusion.core.live.schedule import CLOCK, ClockTick
from uav_fusion.core.records import RADAR, RF, Flight, RadarFrame, RfAttempt
from uav_fusion.core.site import load_site
from uav_fusion.resources import DEFAULT_FLIGHT, data_path

SPAN_S = 300.0


@pytest.fixture(scope="module")
def flight() -> Flight:
    return load_flight(data_path(DEFAULT_FLIGHT), load_site(None))


def _arrivals(
    items: list[RadarFrame | RfAttempt], delay_s: float, jitter_s: float, seed: int
) -> list[tuple[str, RadarFrame | RfAttempt]]:
    """The inputs in the order they arrive when RF comes ``delay_s`` +- ``jitter_s`` late."""
    rng = random.Random(seed)
    keyed = []
    for n, it in enumerate(items):
        late = isinstance(it, RfAttempt)
        at = it.t + (delay_s + rng.uniform(-jitter_s, jitter_s) if late else 0.0)
        keyed.append((at, n, RF if late else RADAR, it))
    keyed.sort(key=lambda e: (e[0], e[1]))
    return [(src, it) for _, _, src, it in keyed]


def _key(s: Step) -> tuple[object, ...]:
    return (s.t, s.source, s.status, s.reason, repr(s.values))  # repr: NaN equals NaN


@pytest.mark.parametrize("profile", ["paper", "tracker", "tracker_smoothed"])
def test_rf_three_seconds_late_gives_the_in_order_track(flight: Flight, profile: str) -> None:
    prof = load_profile(profile)
    site = load_site(None)
    est = make_estimator(prof, site, live=True)
    items = [it for it in est.flight_input(flight) if it.t < flight.radar[0].t + SPAN_S]
    in_order = drive(make_estimator(prof, site, live=True), items).steps
    arrivals = _arrivals(items, 3.0, 1.0, seed=7)
    assert [it for _, it in arrivals] != items  # the schedule does reorder
    outs, rw, _ = simulate(lambda: make_estimator(prof, site, live=True), list(arrivals))
    final = rw.steps
    assert [_key(s) for s in final] == [_key(s) for s in in_order]
    # every input's own step was passed on once, at its arrival
    assert sum(len(o.steps) for o in outs) == len(in_order)


def test_multi_uav_tracks_after_late_rf_equal_the_in_order_ones(flight: Flight) -> None:
    prof = load_profile("tracker")
    site = load_site(None)
    est = make_estimator(prof, site, kind="multi")
    items = [it for it in est.flight_input(flight) if it.t < flight.radar[0].t + SPAN_S]
    ref = make_estimator(prof, site, kind="multi")
    assert isinstance(ref, MultiTracker)
    drive(ref, items)
    rw = Rewinder(make_estimator(prof, site, kind="multi"), max_lag_s=10.0)
    for src, it in _arrivals(items, 3.0, 1.0, seed=3):
        assert rw.fuse(src, it.t, it) is not None
    t = items[-1].t
    assert isinstance(rw.estimator, MultiTracker)
    got = [(o.track_id, o.x.tolist()) for o in rw.estimator.outputs(t)]
    want = [(o.track_id, o.x.tolist()) for o in ref.outputs(t)]
    assert got == want and got
    assert rw.rewinds > 0


def test_max_lag_is_the_boundary_of_what_is_refiltered(flight: Flight) -> None:
    prof = load_profile("tracker")
    est = make_estimator(prof, load_site(None), live=True)
    items = [it for it in est.flight_input(flight) if isinstance(it, RadarFrame)][:200]
    rw = Rewinder(est, max_lag_s=5.0)
    for it in items:
        rw.fuse(RADAR, it.t, it)
    fix = next(a for a in flight.rf if a.ok)

    def late(t: float) -> RfAttempt:
        return replace(fix, t=t)

    assert rw.fuse(RF, rw.latest - 5.0 - 1e-6, late(rw.latest - 5.0 - 1e-6)) is None
    before = rw.rewinds
    assert rw.fuse(RF, rw.latest - 5.0, late(rw.latest - 5.0)) is not None
    assert rw.rewinds == before + 1


def test_a_second_message_of_a_fused_radar_stamp_joins_its_frame(flight: Flight) -> None:
    prof = load_profile("paper").with_changes(radar_selection="online")
    site = load_site(None)
    est = make_estimator(prof, site, live=True)
    frames = [f for f in flight.radar if len(f.tracks) >= 2][:50]
    whole = drive(make_estimator(prof, site, live=True), frames).steps
    rw = Rewinder(est)
    for f in frames:  # each report in its own message, as radar/pose sends them
        for trk in f.tracks:
            rw.fuse(RADAR, f.t, RadarFrame(f.t, (trk,), f.line))
    assert [_key(s) for s in rw.steps] == [_key(s) for s in whole]


def test_a_clock_move_that_publishes_nothing_changes_nothing(flight: Flight) -> None:
    """The fusion node's clock moves the fixed-rate output on between inputs, and its arrival
    schedule keeps only the moves that published an epoch. So a move that published none
    must leave the estimator as it was: an input older than the move (an RF fix that came
    late) is still the state of the epochs after it, and the schedule's replay publishes
    exactly what the live run did."""
    prof = load_profile("tracker")
    site = load_site(None)
    est = make_estimator(prof, site, 10.0, live=True)
    items = [it for it in est.flight_input(flight) if it.t < flight.radar[0].t + SPAN_S]
    rng = random.Random(5)
    live: list[tuple[str, RadarFrame | RfAttempt | ClockTick]] = []
    clock = -math.inf
    for src, it in _arrivals(items, 1.5, 0.5, seed=11):
        live.append((src, it))
        clock = max(clock, it.t)  # the sensor time the clock follows: the newest stamp
        for _ in range(2):  # the clock runs on between two inputs, at times past the next
            clock += rng.uniform(0.0, 0.2)
            live.append((CLOCK, ClockTick(clock)))

    def make() -> Estimator:
        return make_estimator(prof, site, 10.0, live=True)

    outs, _, _ = simulate(make, live)
    published = [(g.k, repr(g.x.tolist())) for o in outs for g in o.grid]
    moved = zip(live, outs[:-1], strict=True)  # the last output: after the end
    kept = [a for a, o in moved if not isinstance(a[1], ClockTick) or o.grid]
    assert 0 < len(kept) - len(items) < len(live) - len(items)  # some moves published nothing
    outs2, _, _ = simulate(make, kept)
    replayed = [(g.k, repr(g.x.tolist())) for o in outs2 for g in o.grid]
    assert replayed == published and len(published) > 2000
