"""The multi-UAV tracker on synthetic scenes: two UAVs crossing near the radar, one emitting
and one silent, a clutter reflector; every confirmed track with a stable id."""

from __future__ import annotations

import csv
import itertools
import math
from pathlib import Path

import numpy as np
import pytest

from uav_fusion.core.estimator import load_profile
from uav_fusion.core.estimator.multi import (
    UNKNOWN_EMITTER,
    MultiTracker,
    emitter_key,
    run_multi,
)
from uav_fusion.core.records import RadarFrame, RadarTrack, RfAttempt
from uav_fusion.core.site import Site, load_site

FREQ_A = 2437e6


@pytest.fixture(scope="module")
def site() -> Site:
    return load_site()


class Crossing:
    """UAV A flies west, UAV B east, 20 m apart across track and 10 m in height where they
    cross (t = 50 s), 300 m north of the radar; A emits on 2437 MHz, B is silent."""

    def __init__(self, site: Site, seed: int = 0, swap_ids: bool = False) -> None:
        self.r0 = np.array(site.radar.enu, dtype=float)
        self.rng = np.random.default_rng(seed)
        self.swap_ids = swap_ids

    def a(self, t: float) -> np.ndarray:
        return self.r0 + np.array([400.0 - 8.0 * t, 300.0, 50.0])

    def b(self, t: float) -> np.ndarray:
        return self.r0 + np.array([-400.0 + 8.0 * t, 320.0, 60.0])

    def report(self, t: float, tid: int, p: np.ndarray, v: np.ndarray, prob: float) -> RadarTrack:
        z = p + self.rng.normal(0.0, 4.0, 3)
        rcs = round(-10.0 + float(self.rng.normal(0.0, 2.0)), 3)
        ned = (float(v[1]), float(v[0]), float(-v[2]))
        return RadarTrack(t, tid, 0.0, 0.0, 0.0, *map(float, z), ned, prob, None, rcs)

    def stream(self, duration_s: float = 100.0) -> list[RadarFrame | RfAttempt]:
        items: list[tuple[float, int, RadarFrame | RfAttempt]] = []
        clutter = self.r0 + np.array([100.0, 250.0, 30.0])
        for k in range(int(duration_s * 4)):
            t = 1000.0 + k * 0.25
            tau = t - 1000.0
            ida, idb = 10, 20
            if self.swap_ids and tau >= 50.0:  # the radar's own tracker swaps them
                ida, idb = 20, 10
            reps = (
                self.report(t, ida, self.a(tau), np.array([-8.0, 0.0, 0.0]), 0.8),
                self.report(t, idb, self.b(tau), np.array([8.0, 0.0, 0.0]), 0.8),
                self.report(t, 99, clutter, np.zeros(3), 0.7 if k % 50 < 25 else 0.3),
            )
            items.append((t, 0, RadarFrame(t, reps)))
            if k % 16 == 8:
                e, n = self.a(tau)[:2] + self.rng.normal(0.0, 6.0, 2)
                att = RfAttempt(
                    t + 0.05, k, True, 0.0, 0.0, float(e), float(n), 8.0, 4, 4,
                    center_freq_hz=FREQ_A,
                )  # fmt: skip
                items.append((t + 0.05, 1, att))
        items.sort(key=lambda x: (x[0], x[1]))
        return [x[2] for x in items]


def _ids_near(epochs: list, truth, within: float = 60.0) -> list[int | None]:  # type: ignore[no-untyped-def]
    out: list[int | None] = []
    for ep in epochs:
        p = truth(ep.t - 1000.0)
        near = [o for o in ep.tracks if np.linalg.norm(o.x[:3] - p) < within]
        out.append(min(near, key=lambda o: np.linalg.norm(o.x[:3] - p)).track_id if near else None)
    return out


def test_two_uavs_crossing_keep_their_ids_and_no_clutter_track(site: Site) -> None:
    sc = Crossing(site, seed=1)
    mt = MultiTracker(load_profile("tracker"), site)
    epochs = run_multi(mt, sc.stream(), 1.0, 1000.0, 1099.0)
    assert len(epochs) == 100
    ids_a, ids_b = _ids_near(epochs, sc.a), _ids_near(epochs, sc.b)
    late = slice(20, None)  # after both tracks are up
    a_ids = {i for i in ids_a[late] if i is not None}
    b_ids = {i for i in ids_b[late] if i is not None}
    assert len(a_ids) == 1 and len(b_ids) == 1 and a_ids != b_ids
    assert sum(i is not None for i in ids_a[late]) >= 78
    assert sum(i is not None for i in ids_b[late]) >= 78
    # no track on the clutter, none twice on one UAV
    clutter = sc.r0 + np.array([100.0, 250.0, 30.0])
    for ep in epochs:
        assert all(np.linalg.norm(o.x[:3] - clutter) > 40.0 for o in ep.tracks)
    assert max(len(ep.tracks) for ep in epochs[20:]) == 2
    # the emitting UAV's track carries its emitter and the higher probability
    last = {o.track_id: o for o in epochs[-1].tracks}
    (ta,) = a_ids
    (tb,) = b_ids
    assert last[ta].emitter == emitter_key(FREQ_A) and last[tb].emitter is None
    assert last[ta].uav_prob > last[tb].uav_prob > 0.5


def test_a_swap_in_the_radars_own_tracker_does_not_swap_our_ids(site: Site) -> None:
    sc = Crossing(site, seed=2, swap_ids=True)
    mt = MultiTracker(load_profile("tracker"), site)
    epochs = run_multi(mt, sc.stream(), 1.0, 1000.0, 1099.0)
    ids_a = [i for i in _ids_near(epochs, sc.a)[20:] if i is not None]
    ids_b = [i for i in _ids_near(epochs, sc.b)[20:] if i is not None]
    switches = sum(x != y for x, y in itertools.pairwise(ids_a))
    switches += sum(x != y for x, y in itertools.pairwise(ids_b))
    assert switches <= 1


def test_emitter_keys() -> None:
    assert emitter_key(2437e6) == "2437000kHz"
    assert emitter_key(None) == emitter_key(math.nan) == UNKNOWN_EMITTER


def test_an_rf_only_emitter_gets_a_confirmed_track(site: Site) -> None:
    rng = np.random.default_rng(3)
    r0 = np.array(site.radar.enu, dtype=float)
    stream: list[RadarFrame | RfAttempt] = []
    for k in range(30):
        t = 2000.0 + 4.0 * k
        p = r0 + np.array([2500.0, 2500.0, 0.0]) + np.array([2.0 * k, 0.0, 0.0])
        e, n = p[:2] + rng.normal(0.0, 5.0, 2)
        stream.append(
            RfAttempt(t, k, True, 0.0, 0.0, float(e), float(n), 8.0, 4, 4, center_freq_hz=5745e6)
        )
    mt = MultiTracker(load_profile("tracker"), site)
    epochs = run_multi(mt, stream, 1.0, 2000.0, 2116.0)
    last = epochs[-1].tracks
    assert len(last) == 1 and last[0].emitter == emitter_key(5745e6)


def test_a_uav_split_into_two_radar_tracks_gives_one_output(site: Site) -> None:
    sc = Crossing(site, seed=4)
    stream = []
    for item in sc.stream(60.0):
        if isinstance(item, RadarFrame) and item.t >= 1020.0:
            a = item.tracks[0]  # UAV A's report; the radar also keeps a second track on it
            twin = RadarTrack(
                a.t, 77, 0.0, 0.0, 0.0, a.e + 6.0, a.n - 4.0, a.u + 3.0, a.vel_ned, 0.9, None,
                a.rcs_dbsm,
            )  # fmt: skip
            item = RadarFrame(item.t, (*item.tracks, twin))
        stream.append(item)
    mt = MultiTracker(load_profile("tracker"), site)
    epochs = run_multi(mt, stream, 1.0, 1000.0, 1059.0)
    for ep in epochs[25:41]:  # both radar tracks on A; B still more than 100 m away
        near_a = [o for o in ep.tracks if np.linalg.norm(o.x[:3] - sc.a(ep.t - 1000.0)) < 60.0]
        assert len(near_a) == 1


def test_a_wrong_emitter_link_is_undone_without_losing_the_track(site: Site) -> None:
    """The silent UAV B's track takes a 5745 MHz fix from a UAV still on its pad nearby; the
    next fixes of that emitter come from far away: B's track drops the emitter, is not
    dropped, and the emitter gets a track of its own."""
    sc = Crossing(site, seed=5)
    pad = sc.b(20.0)[:2]  # where B is at t = 20 s
    far = sc.r0[:2] + np.array([-1500.0, 1800.0])
    stream: list[RadarFrame | RfAttempt] = []
    k = 1000
    for item in sc.stream(100.0):
        stream.append(item)
        tau = item.t - 1000.0
        if isinstance(item, RadarFrame) and abs(tau - 20.0) < 1e-9:
            stream.append(RfAttempt(item.t + 0.01, k, True, 0.0, 0.0, *map(float, pad), 8.0, 4, 4,
                                    center_freq_hz=5745e6))  # fmt: skip
            k += 1
        elif isinstance(item, RadarFrame) and tau > 24.0 and int(tau * 4) % 16 == 0:
            stream.append(RfAttempt(item.t + 0.01, k, True, 0.0, 0.0, *map(float, far), 8.0,
                                    4, 4, center_freq_hz=5745e6))  # fmt: skip
            k += 1
    mt = MultiTracker(load_profile("tracker"), site)
    epochs = run_multi(mt, stream, 1.0, 1000.0, 1099.0)
    assert mt.counters.get("emitter_unlinked", 0) == 1
    ids_b = {i for i in _ids_near(epochs, sc.b)[25:] if i is not None}
    assert len(ids_b) == 1  # B's track lived on
    last = {o.track_id: o for o in epochs[-1].tracks}
    (tb,) = ids_b
    assert last[tb].emitter is None
    assert any(
        o.emitter == emitter_key(5745e6) and np.hypot(*(o.x[:2] - far)) < 100.0
        for o in epochs[-1].tracks
    )


def test_a_track_without_measurements_stops_being_output_but_keeps_its_id(site: Site) -> None:
    """UAV B's reports stop for 10 s (> output_coast_s, < max_coast_s): no output for B in
    the gap, then B comes back with the same id."""
    sc = Crossing(site, seed=6)
    stream: list[RadarFrame | RfAttempt] = []
    for item in sc.stream(100.0):
        if isinstance(item, RadarFrame) and 1060.0 <= item.t < 1070.0:
            item = RadarFrame(item.t, tuple(r for r in item.tracks if r.track_id != 20))
        stream.append(item)
    mt = MultiTracker(load_profile("tracker"), site)
    coast = mt.settings.output_coast_s
    assert coast is not None and coast < 10.0 < (mt.profile.max_coast_s or math.inf)
    epochs = run_multi(mt, stream, 1.0, 1000.0, 1099.0)
    ids_b = _ids_near(epochs, sc.b, within=100.0)
    before = {i for i in ids_b[40:60] if i is not None}
    after = {i for i in ids_b[72:] if i is not None}
    assert len(before) == 1 and after == before
    gap = ids_b[int(60 + coast) + 1 : 70]
    assert gap and all(i is None for i in gap)


def test_run_writes_every_target_and_scores_them(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from uav_fusion.cli import main

    out = tmp_path / "targets.csv"
    assert main(["run", "--profile", "tracker", "--targets", str(out)]) == 0
    rows = list(csv.DictReader(out.open()))
    assert rows and set(rows[0]) >= {"t", "target", "e", "n", "u", "uav_prob", "emitter"}
    ts = sorted({float(r["t"]) for r in rows})
    assert all(abs(b - a - round(b - a)) < 1e-6 for a, b in itertools.pairwise(ts))
    assert all(0.0 <= float(r["uav_prob"]) <= 1.0 for r in rows)
    text = capsys.readouterr().out
    assert "GOSPA (p 2, c 100 m, alpha 2) mean" in text and "uav1: coverage" in text
    assert main(["run", "--profile", "paper", "--targets", str(out)]) == 2
    assert "--targets needs a tracker profile" in capsys.readouterr().err
