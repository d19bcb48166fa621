"""The tracker: profile schema errors, track-level association behaviour on synthetic radar
frames and RF fixes, the fixed-rate accessors, and the offline runner."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml

from uav_fusion.core.errors import ConfigError
from uav_fusion.core.estimators import Profile, follow, load_profile, run_flight
from uav_fusion.core.estimators.adaptive import HELD_S
from uav_fusion.core.estimators.base import feed
from uav_fusion.core.estimators.gates import PhysicalGates
from uav_fusion.core.estimators.objects import ObjectTable, RadarObject
from uav_fusion.core.estimators.offline import run_tracker
from uav_fusion.core.estimators.parts import FixedRadarR, PolarRadarR, RadarAlignment
from uav_fusion.core.estimators.steps import Step, TrackerStep
from uav_fusion.core.estimators.tracker import Tracker
from uav_fusion.core.profiles.settings import ScoreConfig
from uav_fusion.core.records import Flight, RadarFrame, RadarTrack, RfAttempt, TruthFix
from uav_fusion.core.site import RadarCalibration, Site, load_site

CLUTTER_ID = 999


@pytest.fixture(scope="module")
def site() -> Site:
    return load_site()


# --- profile schema -------------------------------------------------------------------------
def _edit_tracker(tmp_path: Path, edit: Callable[[dict[str, Any]], None]) -> Path:
    doc = yaml.safe_load(Path(str(load_profile("tracker").source)).read_text())
    edit(doc)
    f = tmp_path / "bad.yaml"
    f.write_text(yaml.safe_dump(doc))
    return f


def _imm(**changes: Any) -> dict[str, Any]:
    imm: dict[str, Any] = {
        "q": [[0.5, 0.5, 0.2], [20.0, 20.0, 5.0]],
        "transition": [[0.97, 0.03], [0.06, 0.94]],
        "initial": [0.5, 0.5],
    }
    imm.update(changes)
    return {"model": "imm", "q": [2.0, 2.0, 2.0], "imm": imm}


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        (lambda d: d["measurement"]["radar"].update(model="lidar"), "measurement.radar.model"),
        (lambda d: d["measurement"]["rf"].update(model="magic"), "measurement.rf.model"),
        (
            lambda d: d["update"].update(robust="none"),
            r"'update\.robust' is no longer a key: the trackers' update is always Student-t",
        ),
        (lambda d: d["association"].update(mode="track_score"), "association.mode is no longer"),
        (lambda d: d.update(estimator="nearest"), "estimator must be one of paper, tracker, multi"),
        (lambda d: d["motion"].update(model="ct"), "motion.model"),
        (
            lambda d: d.update(motion=_imm(transition=[[0.9, 0.2], [0.1, 0.9]])),
            r"motion\.imm\.transition: row 0 sums to 1\.1",
        ),
        (
            lambda d: d.update(motion=_imm(transition=[[1.1, -0.1], [0.1, 0.9]])),
            r"motion\.imm\.transition: entries must lie in \[0, 1\]",
        ),
        (
            lambda d: d.update(motion=_imm(transition=[[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])),
            r"motion\.imm\.transition: must be 2x2",
        ),
        (lambda d: d.update(motion=_imm(q=[[1, 1, 1], [2, -2, 2]])), r"motion\.imm\.q\[1\]"),
        (lambda d: d.update(motion=_imm(initial=[0.7, 0.7])), r"motion\.imm\.initial"),
        (lambda d: d["measurement"]["radar"].update(sigma_az_deg=-1.0), "sigma_az_deg"),
        (lambda d: d["measurement"]["radar"].update(sigma_range_m=-0.5), "sigma_range_m"),
        (lambda d: d["measurement"]["rf"].update(floor_m=-2.0), r"measurement\.rf\.floor_m"),
        (lambda d: d["association"]["rf"].update(tau_s=-1.0), r"association\.rf\.tau_s"),
        (lambda d: d["association"].update(speed=3), "unknown key 'association.speed'"),
        (lambda d: d.update(smoother={"lag_s": -1.0}), r"smoother\.lag_s"),
        (
            lambda d: d["association"].update(object={"skip_radar_coasts": True}),
            r"'association\.object\.skip_radar_coasts' is no longer a key: a radar coast",
        ),
        (
            lambda d: d["association"].update(bird={"weight": 2.0}),
            r"'association\.bird\.weight' is no longer a key: .*the radar classifier's",
        ),
        (
            lambda d: d["association"].update(vehicle={"ground_alt_m": 5.0}),
            r"'association\.vehicle\.ground_alt_m' is no longer a key: it is "
            r"association\.ground\.alt_m",
        ),
        (
            lambda d: d["measurement"]["radar"].update(low_el_gain=2.0),
            r"'measurement\.radar\.low_el_gain' is no longer a key: .*specification",
        ),
        (
            lambda d: d["measurement"]["radar"].update(sigma_el_deg=-2.0),
            r"measurement\.radar\.sigma_el_deg must be a number >= 0",
        ),
        (
            lambda d: d["gating"].update(range_gate_m=1500.0, far_gate_m=1200.0),
            r"gating\.far_gate_m \(1200\) must exceed gating\.range_gate_m \(1500\)",
        ),
        (lambda d: d["gating"].update(far_gate_m=-1.0), r"gating\.far_gate_m must be a number > 0"),
        (
            lambda d: d["association"]["ghost"].update(sigmas=-1.0),
            r"association\.ghost\.sigmas must be a number >= 0",
        ),
        (
            lambda d: d["update"].update(hold_sigma_mps=-0.5),
            r"update\.hold_sigma_mps must be a number > 0",
        ),
        (
            lambda d: d["update"].update(hold_after_s=-1.0),
            r"update\.hold_after_s must be a number >= 0 or null",
        ),
        (
            lambda d: d["update"].update(notch_range_m=1000.0),
            r"'update\.notch_range_m' is no longer a key: .*inside the 3D range gate",
        ),
        (
            lambda d: d["association"]["takeover"].update(reach_margin_m=-5.0),
            r"association\.takeover\.reach_margin_m must be a number >= 0",
        ),
    ],
)
def test_tracker_profile_errors_name_file_and_key(
    tmp_path: Path, edit: Callable[[dict[str, Any]], None], message: str
) -> None:
    f = _edit_tracker(tmp_path, edit)
    with pytest.raises(ConfigError, match=message) as exc:
        load_profile(f)
    assert str(f) in str(exc.value)


def test_tracker_profiles_load_and_round_trip() -> None:
    from uav_fusion.core.profiles.model import profile_from_dict

    for name in ("tracker", "tracker_smoothed"):
        p = load_profile(name)
        assert p.uses_tracker and p.estimator == "tracker"
        assert p.motion_model == "cv" and p.radar_model == "polar" and p.rf_model == "cep"
        again = profile_from_dict(p.as_dict())
        assert again.imm_transition == p.imm_transition and again.score == p.score
        assert again.smoother_lag_s == p.smoother_lag_s
    assert load_profile("tracker_smoothed").smoother_lag_s == 3.0
    assert not load_profile("paper").uses_tracker


def test_an_imm_profile_runs_and_round_trips(tmp_path: Path, site: Site) -> None:
    from uav_fusion.core.estimators.imm import ImmFilter
    from uav_fusion.core.profiles.model import profile_from_dict

    f = _edit_tracker(tmp_path, lambda d: d.update(motion=_imm()))
    p = load_profile(f)
    assert p.motion_model == "imm" and p.imm_transition == ((0.97, 0.03), (0.06, 0.94))
    assert profile_from_dict(p.as_dict()).imm_q == p.imm_q
    sc = Scene(site, seed=8)
    sc.build(60.0)
    tracker = Tracker(p, site)
    steps = run_tracker(tracker, sc.stream())
    assert isinstance(tracker.filter, ImmFilter)
    used = [s for s in steps if s.updated]
    assert used and len(used[-1].mode_probs) == 2
    assert all(sc.error(s) < 40.0 for s in used[10:])


# --- synthetic scenes -----------------------------------------------------------------------
class Scene:
    """A UAV path with radar frames (4 Hz) and RF fixes (every 4 s) built around the radar."""

    def __init__(self, site: Site, seed: int = 0) -> None:
        self.rng = np.random.default_rng(seed)
        self.r0 = np.array(site.radar.enu, dtype=float)
        self.frames: list[RadarFrame] = []
        self.fixes: list[RfAttempt] = []
        self.truth: dict[float, np.ndarray] = {}

    def uav(self, t: float) -> np.ndarray:
        """A slow loop 300-500 m from the radar at 50 m height."""
        a = 0.02 * t
        return self.r0 + np.array(
            [400.0 * math.cos(a), 400.0 * math.sin(a), 50.0], dtype=np.float64
        )

    def report(
        self,
        t: float,
        tid: int,
        p: np.ndarray,
        prob: float,
        vel: np.ndarray,
        sd: float = 5.0,
        rcs_dbsm: float = -10.0,
    ) -> RadarTrack:
        z = p + self.rng.normal(0.0, sd, 3)
        v = (float(vel[1]), float(vel[0]), float(-vel[2]))  # NED
        rcs = round(rcs_dbsm + float(self.rng.normal(0.0, 2.0)), 3)  # fluctuates look to look
        e, n, u = map(float, z)
        return RadarTrack(t, tid, 0.0, 0.0, 0.0, e, n, u, v, prob, None, rcs)

    def build(
        self,
        duration_s: float,
        uav_prob: Callable[[float], float] = lambda t: 0.8,
        uav_visible: Callable[[float], bool] = lambda t: True,
        rf_ok: Callable[[float], bool] = lambda t: True,
        clutter: bool = False,
        fragment_s: float = 60.0,
        fragment_gap_s: float = 0.0,
        decoy: Callable[[Scene, float, int], RadarTrack | None] | None = None,
    ) -> None:
        n = int(duration_s * 4)
        for k in range(n):
            t = k * 0.25
            p = self.uav(t)
            self.truth[t] = p
            tracks = []
            if uav_visible(t) and t % fragment_s >= fragment_gap_s:
                vel = (self.uav(t + 0.01) - p) / 0.01
                tid = 10 + int(t // fragment_s)  # the onboard tracker fragments the UAV
                tracks.append(self.report(t, tid, p, uav_prob(t), vel))
            if clutter:  # a stationary reflector 30 m off the loop, mostly classed UAV
                c = self.r0 + 430.0 * np.array([math.cos(3.0), math.sin(3.0), 0.0])
                c[2] += 45.0
                prob = 0.3 if (k // 40) % 3 == 0 else 0.8
                tracks.append(self.report(t, CLUTTER_ID, c, prob, np.zeros(3), sd=3.0))
            if decoy is not None:
                d = decoy(self, t, k)
                if d is not None:
                    tracks.append(d)
            self.frames.append(RadarFrame(t, tuple(tracks)))
            if k % 16 == 8 and rf_ok(t):
                e, nn = p[:2] + self.rng.normal(0.0, 8.0, 2)
                self.fixes.append(RfAttempt(t + 0.05, k, True, 0.0, 0.0, e, nn, 9.0, 4, 4))

    def stream(self) -> list[RadarFrame | RfAttempt]:
        items: list[tuple[float, int, RadarFrame | RfAttempt]] = [(f.t, 0, f) for f in self.frames]
        items += [(a.t, 1, a) for a in self.fixes]
        items.sort(key=lambda x: (x[0], x[1]))
        return [x[2] for x in items]

    def error(self, s: Step) -> float:
        t = round(s.t * 4) / 4
        return float(np.linalg.norm(s.x[:3] - self.truth[t]))


def _run(scene: Scene, site: Site) -> tuple[Tracker, list[TrackerStep]]:
    tr = Tracker(load_profile("tracker"), site)
    return tr, run_tracker(tr, scene.stream())


def test_a_clutter_track_that_is_largest_for_minutes_and_at_times_classed_uav_is_never_followed(
    site: Site,
) -> None:
    sc = Scene(site, seed=1)
    # the UAV's onboard track breaks every 50 s with a 4 s gap (the reflector is the only
    # report then, 30 m from the track when the loop passes it at t = 150 s)
    sc.build(300.0, clutter=True, fragment_s=50.0, fragment_gap_s=4.0)
    counts: dict[int, int] = {}
    for f in sc.frames:
        for trk in f.tracks:
            counts[trk.track_id] = counts.get(trk.track_id, 0) + 1
    assert max(counts, key=lambda k: counts[k]) == CLUTTER_ID
    tracker, steps = _run(sc, site)
    used = [s for s in steps if s.updated and s.source == "radar"]
    assert used and all(s.track_id != CLUTTER_ID for s in used)
    assert all(s.track_id != CLUTTER_ID for s in steps if s.coasted)
    # the loop passes within 30 m of the reflector: it was a candidate, never a track
    near = [s for s in steps if s.track_id == CLUTTER_ID and s.nis is not None and s.nis < 50]
    assert near
    published = [s for s in steps if s.counted]
    assert max(sc.error(s) for s in published[20:]) < 40.0
    assert tracker.objects.objects[CLUTTER_ID].score(tracker.cfg) < 0


DECOY_ID = 777


def _ghost(sc: Scene, t: float, k: int) -> RadarTrack:
    """Multipath ghost: the UAV mirrored below the ground, classed UAV at times."""
    p = sc.uav(t)
    g = np.array([p[0], p[1], -p[2]])
    v = (sc.uav(t + 0.01) - p) / 0.01
    v[2] = -v[2]
    return sc.report(t, DECOY_ID, g, 0.7 if (k // 30) % 2 else 0.4, v, sd=8.0)


def _vehicle(sc: Scene, t: float, k: int) -> RadarTrack:
    """A car on a straight road at 12 m/s, 1 m above the ground, classed UAV at times (with a
    car's RCS, 8 m^2: a small target moving low is not taken for a car)."""
    p = sc.r0 + np.array([-600.0 + 12.0 * (t % 100.0), 300.0, 0.0])
    p[2] = 1.0
    prob = 0.65 if (k // 30) % 2 else 0.35
    return sc.report(t, DECOY_ID, p, prob, np.array([12.0, 0, 0]), rcs_dbsm=9.0)


def _birds(sc: Scene, t: float, k: int) -> RadarTrack:
    """A flock wandering erratically (jumps of tens of metres), small RCS, classed UAV at
    times."""
    rng = sc.rng
    c = sc.r0 + np.array([250.0 * math.cos(0.01 * t), -300.0, 30.0])
    p = c + rng.normal(0.0, 25.0, 3)
    trk = sc.report(t, DECOY_ID, p, 0.6 if (k // 30) % 2 else 0.3, rng.normal(0, 8.0, 3))
    return dataclasses.replace(trk, rcs_dbsm=-25.0)


@pytest.mark.parametrize("decoy", [_ghost, _vehicle, _birds], ids=["ghost", "vehicle", "birds"])
def test_decoys_classed_uav_at_times_are_never_followed(
    site: Site, decoy: Callable[[Scene, float, int], RadarTrack]
) -> None:
    sc = Scene(site, seed=9)
    sc.build(240.0, decoy=decoy, fragment_s=40.0, fragment_gap_s=3.0)
    _, steps = _run(sc, site)
    assert not any(s.track_id == DECOY_ID and (s.updated or s.coasted) for s in steps)
    published = [s for s in steps if s.counted]
    assert published and max(sc.error(s) for s in published[20:]) < 40.0


class LowScene(Scene):
    """The loop of :class:`Scene` flown 15 m up."""

    def uav(self, t: float) -> np.ndarray:
        p: np.ndarray = super().uav(t) - np.array([0.0, 0.0, 35.0])
        return p


def _alternating_car_scene(site: Site) -> tuple[Scene, tuple[float, float]]:
    """From 60 to 120 s the radar's track on the UAV (15 m up, id 10) passes back and forth,
    frame by frame, between the UAV and a car on the ground 40 m beside it (a car's RCS,
    9 dBsm); no RF fix comes in that minute."""
    window = (60.0, 120.0)
    sc = LowScene(site, seed=21)
    sc.build(180.0, rf_ok=lambda t: not window[0] - 4.0 <= t < window[1], fragment_s=1000.0)
    frames = []
    for k, fr in enumerate(sc.frames):
        if window[0] <= fr.t < window[1] and k % 2:
            p = sc.uav(fr.t)
            side = (p - sc.r0) * np.array([1.0, 1.0, 0.0])
            car = p + 40.0 * side / np.linalg.norm(side)
            car[2] = sc.r0[2] + 1.0
            rep = sc.report(fr.t, 10, car, 0.6, np.zeros(3), sd=3.0, rcs_dbsm=9.0)
            fr = RadarFrame(fr.t, (rep, *fr.tracks[1:]))
        frames.append(fr)
    sc.frames = frames
    return sc, window


def test_reports_too_large_for_a_small_uav_never_move_the_track(site: Site) -> None:
    """Every other report of the UAV's own radar track is a car's: each is discarded as
    ``large_rcs`` and the track stays on the UAV; with the bound raised out of the way the
    car's reports pull the track off it."""
    sc, (t0, t1) = _alternating_car_scene(site)
    _, steps = _run(sc, site)
    def car(s: Step) -> bool:  # the odd frames of the window
        return s.source == "radar" and t0 <= s.t < t1 and round(s.t * 4) % 2 == 1

    cars = [s for s in steps if car(s)]
    assert len(cars) == 120 and all(s.reason == "large_rcs" and not s.counted for s in cars)
    inside = [s for s in steps if s.counted and t0 <= s.t < t1]
    err_on = max(sc.error(s) for s in inside)
    assert err_on < 15.0
    base = load_profile("tracker")
    off = dataclasses.replace(base, score=dataclasses.replace(base.score, large_rcs_dbsm=50.0))
    steps0 = run_tracker(Tracker(off, site), sc.stream())
    assert any(s.updated and car(s) for s in steps0)
    inside0 = [s for s in steps0 if s.counted and t0 <= s.t < t1]
    # the track sits between the two: the car's reports count as much as the UAV's
    assert max(sc.error(s) for s in inside0) > 2.0 * err_on + 5.0


class PadScene(Scene):
    """The UAV waits 30 s on its pad (RF on, radar blind to it: no Doppler) before its loop."""

    def uav(self, t: float) -> np.ndarray:
        return super().uav(max(0.0, t - 30.0))


def test_a_large_reflector_beside_the_uav_on_its_pad_is_not_taken_for_it(site: Site) -> None:
    # a reflector 30 m from the pad, moving a little (2 m/s: not stationary), classed 0.5,
    # with a 4 dBsm RCS: the nearest radar object to the emitter while the UAV waits
    refl_id = 444

    def reflector(sc: Scene, t: float, k: int) -> RadarTrack:
        a = 0.7 * t
        c = sc.uav(0.0) + np.array([0.0, 30.0, -5.0])
        p = c + 3.0 * np.array([math.cos(a), math.sin(a), 0.0])
        v = 2.1 * np.array([-math.sin(a), math.cos(a), 0.0])
        return sc.report(t, refl_id, p, 0.5, v, sd=2.0, rcs_dbsm=4.0)

    def scene() -> PadScene:
        sc = PadScene(site, seed=12)
        sc.build(150.0, uav_visible=lambda t: t >= 30.0, decoy=reflector)
        return sc

    sc = scene()
    tracker, steps = _run(sc, site)
    obj = tracker.objects.objects[refl_id]
    assert obj.rcs_seen and obj.rcs_mean > 0.0
    assert not any(s.track_id == refl_id and (s.updated or s.coasted or s.counted) for s in steps)
    late = [s for s in steps if s.counted and s.t > 45.0]
    assert late and max(sc.error(s) for s in late) < 40.0
    # without the RCS term the emitter's support starts the track on the reflector
    prof = load_profile("tracker")
    off = dataclasses.replace(prof, score=dataclasses.replace(prof.score, large_rcs_dbsm=100.0))
    steps0 = run_tracker(Tracker(off, site), scene().stream())
    assert any(s.track_id == refl_id and s.counted for s in steps0)


def test_the_large_rcs_term_needs_an_rcs(site: Site) -> None:
    cfg = ScoreConfig(large_rcs_dbsm=0.0, age_weight=0.0)
    table = ObjectTable(cfg, FixedRadarR((25.0, 0.0, 0.0, 25.0, 0.0, 25.0)))
    r0 = np.array(site.radar.enu, dtype=float)

    def feed(tid: int, rcs: float | None) -> float:
        for k in range(20):
            p = r0 + np.array([300.0 + 2.0 * 0.25 * k, 0.0, 40.0])
            e, n, u = map(float, p)
            trk = RadarTrack(k * 0.25, tid, 0.0, 0.0, 0.0, e, n, u, (0.0, 2.0, 0.0), 0.5, None, rcs)
            obj = table.update(trk)
        return obj.score(cfg)

    assert feed(1, 4.0) == pytest.approx(-cfg.veto)  # class logit 0, moving, aloft: the veto
    assert feed(2, -10.0) == pytest.approx(0.0)
    assert feed(3, None) == pytest.approx(0.0)  # no RCS reports: nothing known
    assert feed(4, float("nan")) == pytest.approx(0.0)
    assert not table.objects[4].rcs_seen


def test_a_coasted_report_leaves_the_objects_filter_where_it_was(site: Site) -> None:
    """A report repeating its radar track's velocity and RCS is the radar's prediction: the
    object's filter does not take it, the next real report is predicted over the whole gap,
    and an RF fix meets the filter's state at its own time."""
    r0 = np.array(site.radar.enu, dtype=float)
    vel = (0.0, 6.0, 0.0)  # NED: 6 m/s east

    def report(t: float, east: float, rcs: float) -> RadarTrack:
        e, n, u = map(float, r0 + np.array([east, 300.0, 40.0]))
        return RadarTrack(t, 5, 0.0, 0.0, 0.0, e, n, u, vel, 0.6, None, rcs)

    table = ObjectTable(ScoreConfig(), FixedRadarR((25.0, 0.0, 0.0, 25.0, 0.0, 25.0)))
    for k in range(40):  # 10 s of real reports along the track
        table.update(report(0.25 * k, 200.0 + 1.5 * k, -10.0 - 0.01 * k))
    obj = table.objects[5]
    assert obj.kf is not None
    x_before = list(obj.kf.x)
    for k in range(40, 56):  # 4 s of coasts: a report 40 m off, velocity and RCS repeated
        table.update(report(0.25 * k, 260.0 + 40.0, -10.39))
    assert obj.coasting and obj.last_t == pytest.approx(13.75)
    assert obj.kf is not None and obj.kf.x == x_before and obj.kf_t == pytest.approx(9.75)
    # a fine RF fix where the object's own motion puts it at 14 s is credited (had the
    # coasts updated the filter, it would sit 40 m east of there)
    e14, n14 = map(float, r0[:2] + np.array([200.0 + 6.0 * 14.0, 300.0]))
    assert table.rf_fix(14.0, e14, n14, 4.0) == 1
    # the next real report breaks the coast and updates the filter again
    table.update(report(14.0, 200.0 + 6.0 * 14.0, -10.5))
    assert not obj.coasting and obj.kf_t == pytest.approx(14.0)


def test_a_low_class_probability_uav_with_rf_agreement_is_kept(site: Site) -> None:
    sc = Scene(site, seed=2)
    sc.build(200.0, uav_prob=lambda t: 0.3, clutter=True)
    tracker, steps = _run(sc, site)
    radar = [s for s in steps if s.source == "radar" and s.track_id != CLUTTER_ID and s.t > 40]
    used = [s for s in radar if s.updated]
    assert len(used) > 0.95 * len(radar)
    assert tracker.best_track() is not None
    assert all(sc.error(s) < 40.0 for s in used)
    # the same scene without RF: the classifier alone never makes this object a UAV
    sc2 = Scene(site, seed=2)
    sc2.build(200.0, uav_prob=lambda t: 0.3, rf_ok=lambda t: False)
    _, steps2 = _run(sc2, site)
    assert not any(s.updated for s in steps2)


def test_a_hover_in_the_doppler_notch_is_coasted_through(site: Site) -> None:
    sc = Scene(site, seed=3)
    notch = (100.0, 150.0)  # 50 s without a radar report; RF continues

    def visible(t: float) -> bool:
        return not notch[0] <= t < notch[1]

    sc.build(220.0, uav_visible=visible)
    tracker, steps = _run(sc, site)
    assert tracker.counters.get("reinitialisations", 0) == 0
    segs = {s.segment for s in steps if s.counted}
    assert len(segs) == 1  # one track all along
    during = [s for s in steps if s.counted and notch[0] <= s.t < notch[1]]
    assert during and all(s.source == "rf" for s in during)
    assert max(sc.error(s) for s in during) < 60.0
    after = [s for s in steps if s.updated and s.source == "radar" and s.t >= notch[1]]
    assert after and after[0].t < notch[1] + 1.0  # radar picked up again at once


class HoverScene(Scene):
    """Out from the radar at 6 m/s, a hover from ``HOVER[0]`` to ``HOVER[1]`` 560 m out, and on."""

    HOVER = (60.0, 80.0)

    def uav(self, t: float) -> np.ndarray:
        a, b = self.HOVER
        s = 200.0 + 6.0 * (min(t, a) + max(0.0, t - b))
        return self.r0 + np.array([0.8 * s, 0.6 * s, 50.0], dtype=np.float64)


def test_a_hover_the_radar_cannot_see_stops_the_coast_drifting(site: Site) -> None:
    # in the hover the radar has no report (the Doppler notch) and no RF fix comes: the
    # track coasts 20 s; the radar would see the UAV there unless its radial speed were
    # about 0, so after update.hold_after_s the track's radial speed is measured as 0
    a, b = HoverScene.HOVER
    t_end = b - 0.25  # the last radar frame of the hover

    def seen(t: float) -> bool:
        return not a <= t < b

    def error_at_hover_end(prof: Profile) -> tuple[float, Tracker]:
        sc = HoverScene(site, seed=12)
        sc.build(120.0, uav_visible=seen, rf_ok=seen, clutter=True)
        tracker = Tracker(prof, site)
        for item in sc.stream():
            if item.t > t_end:
                break
            # as the offline runner and the node feed it: frames without a report are skipped
            # (a reflector elsewhere keeps the radar's frames coming through the hover)
            if not isinstance(item, RadarFrame) or item.tracks:
                feed(tracker, item)
        assert tracker.confirmed and tracker.t == t_end
        x, _ = tracker.predict_to(t_end)
        return float(np.linalg.norm(np.asarray(x[:3]) - sc.uav(t_end))), tracker

    prof = load_profile("tracker")
    assert prof.hold_after_s is not None and prof.hold_after_s < 10.0
    err, tracker = error_at_hover_end(prof)
    assert tracker.counters.get("notch", 0) > 0
    assert err < 40.0
    # without it the track flies on at 6 m/s: more than 80 m off by the end of the hover
    err0, tracker0 = error_at_hover_end(dataclasses.replace(prof, hold_after_s=None))
    assert tracker0.counters.get("notch", 0) == 0
    assert err0 > 80.0
    # the radar would see the UAV only inside its 3D range gate: a gate ending 20 m short of
    # the hover holds nothing; one 60 m beyond it does (the coasting track has flown on
    # 6 m/s x 5 s = 30 m outwards when the hold starts)
    rng = float(np.linalg.norm(HoverScene(site).uav(a) - site.radar.enu))
    for gate, held in ((rng - 20.0, False), (rng + 60.0, True)):
        _, t_gate = error_at_hover_end(prof.with_changes(range_gate_m=gate))
        assert (t_gate.counters.get("notch", 0) > 0) is held, gate


class LevelOffScene(Scene):
    """The loop of :class:`Scene`, climbing at 1 m/s from 40 m until ``LEVEL_S``, then level."""

    LEVEL_S = 60.0

    def uav(self, t: float) -> np.ndarray:
        p = super().uav(t)
        p[2] = 40.0 + min(t, self.LEVEL_S)
        return p


@pytest.mark.parametrize("hold", [5.0, 6.0, 6.5])
def test_the_climb_rate_hold_starts_with_the_first_fix_after_its_delay(
    site: Site, hold: float
) -> None:
    """The radar loses the UAV as it levels off; RF fixes go on every 4 s (2D: they say
    nothing of height). The first fix more than ``update.hold_after_s`` after the last 3D
    update, and every later one, holds the climb rate near 0; the fixes before leave it.
    The delays 6 and 6.5 s lie either side of the second fix (6.3 s after the last 3D
    update)."""
    level = LevelOffScene.LEVEL_S
    prof = load_profile("tracker").with_changes(hold_after_s=hold)
    sc = LevelOffScene(site, seed=21)
    sc.build(100.0, uav_visible=lambda t: t < level)
    tracker = Tracker(prof, site)
    fixes: list[tuple[float, bool, float]] = []  # (t, held, climb rate after) per fix
    for item in sc.stream():
        if isinstance(item, RadarFrame) and not item.tracks:
            continue  # frames without a report are skipped, as the runners do
        held0 = tracker.counters.get("vz_hold", 0)
        feed(tracker, item)
        if isinstance(item, RfAttempt) and item.t > level:
            x, _ = tracker.predict_to(item.t)
            fixes.append((item.t, tracker.counters.get("vz_hold", 0) > held0, float(x[5])))
    last_3d = tracker.last_3d_t
    assert last_3d is not None and level - 1.0 < last_3d < level
    assert [held for _, held, _ in fixes] == [t - last_3d > hold for t, _, _ in fixes]
    before = [vz for t, held, vz in fixes if not held]
    after = [vz for t, held, vz in fixes if held]
    assert before and after
    assert min(before) > 0.7  # the climb rate the radar last saw, still running
    assert after[-1] < before[-1]  # held towards 0


@pytest.mark.parametrize("n", [2, 4, 6])
def test_a_strong_radar_object_starts_or_confirms_the_track_at_its_nth_report(
    site: Site, n: int
) -> None:
    """A radar object classed UAV at 0.9 scores enough to start a track from its first
    report, so ``track.confirm_m`` (the reports an object needs) alone says when: it starts the
    track with its n-th report, and it confirms at its n-th report a tentative track that an
    RF fix started before the radar saw the UAV (its earlier reports are discarded)."""
    prof = load_profile("tracker")
    prof = dataclasses.replace(prof, confirm_m=n, confirm_n=max(n, prof.confirm_n))
    sc = Scene(site, seed=3)
    sc.build(20.0, rf_ok=lambda t: False, uav_prob=lambda t: 0.9)
    steps = run_tracker(Tracker(prof, site), sc.stream())
    first = next(s for s in steps if s.source == "radar" and s.updated)
    assert (first.t, first.status) == ((n - 1) * 0.25, "initialised")

    sc = Scene(site, seed=3)
    sc.build(20.0, uav_visible=lambda t: t >= 3.0, uav_prob=lambda t: 0.9)
    tracker = Tracker(prof, site)
    steps = run_tracker(tracker, sc.stream())
    rf = [s for s in steps if s.source == "rf"]
    assert rf[0].t == pytest.approx(2.05) and rf[0].status == "tentative"
    radar = [s for s in steps if s.source == "radar" and s.t < 6.0]
    assert [s.reason for s in radar[: n - 1]] == ["tentative_track"] * (n - 1)
    assert radar[n - 1].updated and radar[n - 1].t == 3.0 + (n - 1) * 0.25
    assert tracker.counters.get("confirmed", 0) == 1


def test_a_leg_out_of_coverage_recovers(site: Site) -> None:
    sc = Scene(site, seed=4)
    gap = (80.0, 140.0)  # neither radar nor RF for 60 s (beyond max_coast_s)

    def seen(t: float) -> bool:
        return not gap[0] <= t < gap[1]

    sc.build(240.0, uav_visible=seen, rf_ok=seen)
    tracker, steps = _run(sc, site)
    assert tracker.counters.get("reinit_max_coast", 0) == 1
    # the track starts again (on the radar or on the RF fixes) within 3 s of the UAV's return
    restart = [s for s in steps if s.t >= gap[0] and s.status in ("reset", "tentative")]
    assert restart and gap[1] <= restart[0].t < gap[1] + 3.0
    later = [s for s in steps if s.counted and s.t > gap[1] + 5.0]
    assert later and max(sc.error(s) for s in later) < 40.0


def _rule_alone() -> Profile:
    """The tracker without the radial-speed pseudo-measurement (which narrows the gate)."""
    return dataclasses.replace(load_profile("tracker"), hold_after_s=None)


# the UAV is lost to both sensors for 16 s; 10 s in, a bird-like object (classed 0.3, small,
# smooth) appears 150 m from where the track predicts it, well inside the grown gate; the UAV
# comes back under a new radar id at 116 s
COAST_GAP = (100.0, 116.0)
BIRD_ID = 555
T_BIRD = 110.0


def _coast_with_bird(site: Site) -> Scene:
    def seen(t: float) -> bool:
        return not COAST_GAP[0] <= t < COAST_GAP[1]

    def bird(sc: Scene, t: float, k: int) -> RadarTrack | None:
        if t < T_BIRD:
            return None
        p = sc.uav(T_BIRD) + np.array([150.0, 0.0, 0.0]) + np.array([0.0, 8.0, 0.0]) * (t - T_BIRD)
        return sc.report(t, BIRD_ID, p, 0.3, np.array([0.0, 8.0, 0.0]), rcs_dbsm=-24.0)

    sc = Scene(site, seed=6)
    sc.build(200.0, uav_visible=seen, rf_ok=seen, fragment_s=116.0, decoy=bird)
    return sc


def test_an_object_that_appears_inside_a_long_coasting_gate_is_not_followed(
    site: Site, monkeypatch: pytest.MonkeyPatch
) -> None:
    gap, bird_id, t_bird = COAST_GAP, BIRD_ID, T_BIRD
    sc = _coast_with_bird(site)
    base = _rule_alone()
    items = sc.stream()
    first = min(f.t for f in sc.frames if any(r.track_id == bird_id for r in f.tracks))
    probe = Tracker(base, site)
    run_tracker(probe, [i for i in items if i.t < first])
    _, P = probe.predict_to(first)
    assert math.sqrt(max(P[0, 0], P[1, 1])) > 60.0  # a coast of 10 s
    tracker = Tracker(base, site)
    steps = run_tracker(tracker, items)
    assert not any(s.track_id == bird_id and (s.updated or s.coasted) for s in steps)
    back = [s for s in steps if s.updated and s.source == "radar" and s.t >= gap[1]]
    assert back and back[0].t < gap[1] + 1.0 and back[0].track_id != bird_id
    late = [s for s in steps if s.counted and s.t > gap[1] + 5.0]
    assert late and max(sc.error(s) for s in late) < 40.0
    # without the rule the object's first report inside the wide gate counts as agreement
    # with the track, which is enough to follow it (the track jumps 150 m and stays there)
    monkeypatch.setattr(follow, "informative", lambda var, r: True)
    steps0 = run_tracker(Tracker(base, site), _coast_with_bird(site).stream())
    taken = [s for s in steps0 if s.updated and s.track_id == bird_id]
    assert taken and taken[0].t < t_bird + 1.0


@pytest.mark.parametrize(
    "r", [(400.0, 0.0, 0.0, 900.0, 0.0, 100.0), (900.0, 0.0, 400.0)], ids=["3d", "2d"]
)
def test_agreement_is_informative_up_to_the_reports_own_horizontal_variance(
    r: tuple[float, ...],
) -> None:
    """A report's agreement with the track counts while the track's largest horizontal
    variance is at most the report's (here 900 m^2: its north variance in 3D, its east one
    in 2D; the vertical one does not enter)."""
    assert follow.informative(900.0, r) and follow.informative(0.0, r)
    assert not follow.informative(900.01, r)


def test_an_object_out_of_reach_of_a_coasting_track_is_not_followed(site: Site) -> None:
    # both sensors lose the UAV for 19.5 s; 17 s in, an object classed 0.75 appears 800 m
    # beyond where the track last was: inside the coasting track's grown gate, but farther
    # than the UAV could have flown (track.max_speed_mps 30 x 17 s + reach_margin_m 200)
    gap = (100.0, 119.5)
    decoy_id = 777
    t_decoy = 117.0

    def seen(t: float) -> bool:
        return not gap[0] <= t < gap[1]

    def decoy(sc: Scene, t: float, k: int) -> RadarTrack | None:
        if t < t_decoy:
            return None
        p0 = sc.uav(gap[0])
        away = (p0 - sc.r0) * np.array([1.0, 1.0, 0.0])
        p = p0 + 800.0 * away / np.linalg.norm(away) + np.array([3.0, 0.0, 0.0]) * (t - t_decoy)
        return sc.report(t, decoy_id, p, 0.75, np.array([3.0, 0.0, 0.0]), rcs_dbsm=-22.0)

    def stream() -> Scene:
        sc = Scene(site, seed=6)
        sc.build(170.0, uav_visible=seen, rf_ok=seen, fragment_s=gap[1], decoy=decoy)
        return sc

    sc = stream()
    # a fixed 40 m allowance for correlated radar errors: in this clean scene the online one
    # falls to its lower bound, and the track then never meets the object without the rule
    base = dataclasses.replace(_rule_alone(), radar_floor_m=40.0, adaptive_window=None)
    tracker = Tracker(base, site)
    steps = run_tracker(tracker, sc.stream())
    assert tracker.cfg.reach_margin_m == 200.0
    assert not any(s.track_id == decoy_id and s.updated for s in steps)
    back = [s for s in steps if s.updated and s.source == "radar" and s.t >= gap[1]]
    assert back and back[0].t < gap[1] + 1.0
    late = [s for s in steps if s.counted and s.t > gap[1] + 10.0]
    assert late and max(sc.error(s) for s in late) < 40.0
    # without the reach gate the track takes the object and stays on it for seconds after the
    # UAV is back, 800 m and more off
    off = dataclasses.replace(base, score=dataclasses.replace(base.score, reach_margin_m=0.0))
    sc0 = stream()
    steps0 = run_tracker(Tracker(off, site), sc0.stream())
    assert any(s.updated and s.track_id == decoy_id for s in steps0)
    after0 = [s for s in steps0 if s.counted and gap[1] <= s.t < gap[1] + 5.0]
    assert after0 and min(sc0.error(s) for s in after0) > 500.0


def _swap_scene(
    site: Site, swap_t: float = 120.0, duration_s: float = 200.0, new_coasts: bool = False
) -> Scene:
    """The radar's track on the UAV (id 10) swaps at ``swap_t`` onto another object that flies
    off at 12 m/s while its class probability decays; the UAV gets a new track id (11) a
    second later whose class probability climbs from the new-track prior; RF fixes go on.
    With ``new_coasts`` every other report of id 11 is a radar coast (the previous report's
    velocity and RCS repeated)."""
    sc = Scene(site, seed=11)
    last11: RadarTrack | None = None
    p_swap = sc.uav(swap_t)
    away = (p_swap - sc.r0) * np.array([1.0, 1.0, 0.0])
    away /= np.linalg.norm(away)
    for k in range(int(duration_s * 4)):
        t = k * 0.25
        p = sc.uav(t)
        sc.truth[t] = p
        vel = (sc.uav(t + 0.01) - p) / 0.01
        tracks = []
        if t < swap_t:
            tracks.append(sc.report(t, 10, p, 0.85, vel))
        else:
            q = p_swap + 12.0 * (t - swap_t) * away
            prob = max(0.25, 0.85 - 0.06 * (t - swap_t))
            tracks.append(sc.report(t, 10, q, prob, 12.0 * away))
            if t >= swap_t + 1.0:
                prob = min(0.85, 0.3 + 0.07 * (t - swap_t - 1.0))
                r11 = sc.report(t, 11, p, prob, vel)
                if new_coasts and k % 2 and last11 is not None:
                    r11 = dataclasses.replace(r11, vel_ned=last11.vel_ned, rcs_dbsm=last11.rcs_dbsm)
                tracks.append(r11)
                last11 = r11
        sc.frames.append(RadarFrame(t, tuple(tracks)))
        if k % 16 == 8:
            e, nn = p[:2] + sc.rng.normal(0.0, 8.0, 2)
            sc.fixes.append(RfAttempt(t + 0.05, k, True, 0.0, 0.0, e, nn, 9.0, 4, 4))
    return sc


def test_a_radar_track_that_swaps_off_the_uav_is_left_for_the_uavs_new_track(
    site: Site, monkeypatch: pytest.MonkeyPatch
) -> None:
    swap_t = 120.0
    sc = _swap_scene(site, swap_t)
    tracker, steps = _run(sc, site)
    assert tracker.counters.get("reinit_challenged", 0) == 1
    # the old id stays the UAV's while it is; the new id takes over within seconds
    after = [s for s in steps if s.updated and s.source == "radar" and s.t >= swap_t]
    first_new = min(s.t for s in after if s.track_id == 11)
    assert first_new < swap_t + 20.0
    assert not any(s.track_id == 10 for s in after if s.t >= first_new)
    late = [s for s in steps if s.counted and s.t > first_new + 2.0]
    assert late and max(sc.error(s) for s in late) < 40.0
    # without the rule the RF fixes, which go on from the UAV, end the track on the swapped
    # radar track (gates.py: three agreeing fixes outside the gate) ...
    prof = load_profile("tracker")
    off = dataclasses.replace(prof, score=dataclasses.replace(prof.score, challenge_s=0.0))
    rf_only = Tracker(off, site)
    run_tracker(rf_only, sc.stream())
    assert rf_only.counters.get("reinit_rf_disagrees", 0) >= 1
    # ... and without either the track rides the swapped radar track away from the UAV
    monkeypatch.setattr(PhysicalGates, "rf_outside", lambda self, *a: False)
    steps0 = run_tracker(Tracker(off, site), sc.stream())
    at = [s for s in steps0 if s.counted and swap_t + 20.0 <= s.t < swap_t + 21.0]
    assert at and min(sc.error(s) for s in at) > 100.0


def test_a_challenger_whose_radar_track_coasts_every_other_frame_still_takes_over(
    site: Site,
) -> None:
    # the coasted reports are not candidates; they must not restart the challenger's clock
    swap_t = 120.0
    sc = _swap_scene(site, swap_t, new_coasts=True)
    coasts = [
        (a, b)
        for a, b in zip(sc.frames, sc.frames[1:], strict=False)
        if len(a.tracks) == len(b.tracks) == 2 and b.tracks[1].rcs_dbsm == a.tracks[1].rcs_dbsm
    ]
    assert len(coasts) > 100
    tracker, steps = _run(sc, site)
    assert tracker.counters.get("rejected_coast", 0) > 100
    assert tracker.counters.get("reinit_challenged", 0) == 1
    after = [s for s in steps if s.updated and s.source == "radar" and s.t >= swap_t]
    first_new = min(s.t for s in after if s.track_id == 11)
    assert first_new < swap_t + 20.0
    late = [s for s in steps if s.counted and s.t > first_new + 2.0]
    assert late and max(sc.error(s) for s in late) < 40.0


@pytest.mark.parametrize(("above", "challenged"), [(0.05, True), (-0.05, False)])
def test_the_challenge_compares_scores_without_the_agreement_with_the_fused_track(
    site: Site, above: float, challenged: bool
) -> None:
    # the followed object agrees fully with the track (the track follows it); a challenger
    # outside the gate outscores it by the margin +-0.05 on everything else. Counted with the
    # agreement, no challenger short of margin + fused_weight could ever take the track over.
    tracker = Tracker(load_profile("tracker"), site)
    cfg = tracker.cfg
    assert cfg.fused_weight >= 1.0 and cfg.challenge_s > 0.0
    fol = tracker.objects.objects.setdefault(1, RadarObject(1, 0.0))
    ch = tracker.objects.objects.setdefault(2, RadarObject(2, 0.0))
    for obj in (fol, ch):
        obj.n_reports = cfg.init_min_reports
        obj.speed = 10.0
        obj.up = 60.0
    fol.fused = 1.0
    fol.class_logit = 1.0
    ch.class_logit = 1.0 + cfg.challenge_margin + above
    tracker.followed = 1
    assert ch.score(cfg) >= cfg.init_min
    assert ch.score(cfg) < fol.score(cfg)  # with the agreement, the followed object leads
    follow = tracker.follow

    def frame(t: float) -> bool:
        for obj in (fol, ch):
            obj.last_t = t
        def rep(i: int) -> RadarTrack:
            return RadarTrack(t, i, 0.0, 0.0, 60.0, 0.0, 0.0, 60.0, None, None, None, None)

        z, r = (0.0, 0.0, 60.0), (1.0, 0.0, 0.0, 1.0, 0.0, 1.0)
        scored = [
            (0, rep(1), fol, fol.score(cfg), z, r, 1.0, True),  # inside the gate
            (1, rep(2), ch, ch.score(cfg), z, r, 50.0, False),  # outside it
        ]
        return follow._challenged(t, scored)

    assert not frame(100.0)  # the challenger's clock starts
    assert frame(100.0 + cfg.challenge_s) is challenged


@pytest.mark.parametrize(("key", "value"), [("challenge_margin", 20.0), ("challenge_s", 1000.0)])
def test_a_challenger_must_outscore_the_followed_object_by_the_margin_for_the_time(
    site: Site, key: str, value: float, monkeypatch: pytest.MonkeyPatch
) -> None:
    # the same swap: a margin no object reaches, or a time longer than the flight, and the
    # track never leaves the swapped radar track (the RF rule of gates.py, which would end
    # it, switched off)
    monkeypatch.setattr(PhysicalGates, "rf_outside", lambda self, *a: False)
    sc = _swap_scene(site)
    prof = load_profile("tracker")
    change: dict[str, Any] = {key: value}
    strict = dataclasses.replace(prof, score=dataclasses.replace(prof.score, **change))
    tracker = Tracker(strict, site)
    steps = run_tracker(tracker, sc.stream())
    assert tracker.counters.get("reinit_challenged", 0) == 0
    assert not any(s.updated and s.track_id == 11 for s in steps)


class OutboundScene(Scene):
    """The UAV flies out from 600 m to 2100 m from the radar (15 m/s) and back, at 50 m height;
    beyond 1500 m its reports carry a +150 m elevation error (low-elevation multipath) and RF
    is silent."""

    def uav(self, t: float) -> np.ndarray:
        out = 600.0 + 15.0 * min(max(0.0, t - 40.0), 100.0, max(0.0, 260.0 - t))
        a = 0.3 + 0.0005 * t
        return self.r0 + np.array([out * math.cos(a), out * math.sin(a), 50.0], dtype=np.float64)

    def far(self, p: np.ndarray) -> bool:
        return float(np.linalg.norm(p[:2] - self.r0[:2])) > 1500.0

    def build_far(self, duration_s: float) -> None:
        self.build(duration_s, rf_ok=lambda t: not self.far(self.uav(t)))
        lifted = []
        for f in self.frames:
            tracks = tuple(
                dataclasses.replace(trk, u=trk.u + 150.0)
                if self.far(np.array([trk.e, trk.n, trk.u]))
                else trk
                for trk in f.tracks
            )
            lifted.append(RadarFrame(f.t, tracks))
        self.frames = lifted


def test_far_gate_keeps_the_track_beyond_the_range_gate_with_horizontal_updates(
    site: Site,
) -> None:
    sc = OutboundScene(site, seed=11)
    sc.build_far(300.0)
    base = load_profile("tracker").with_changes(range_gate_m=1500.0, far_gate_m=None)
    far = base.with_changes(far_gate_m=2500.0)
    far_s = [(t, p) for t, p in sc.truth.items() if sc.far(p)]
    t0, t1 = far_s[0][0], far_s[-1][0]  # about 100 s beyond the range gate
    assert t1 - t0 > 90.0

    # without a far gate the reports out there are discarded and the track times out
    tr = Tracker(base, site)
    steps = run_tracker(tr, sc.stream())
    out = [s for s in steps if s.source == "radar" and t0 + 1 <= s.t <= t1 - 1]
    assert out and all(s.reason == "range_gate" for s in out)
    assert tr.counters.get("reinit_max_coast", 0) == 1

    # with it they update the track horizontally (2D z), the height is held, one track
    tr2 = Tracker(far, site)
    steps2 = run_tracker(tr2, sc.stream())
    used = [s for s in steps2 if s.updated and s.source == "radar" and t0 + 1 <= s.t <= t1 - 1]
    assert len(used) > 0.95 * 4 * (t1 - t0 - 2)
    assert all(len(s.z) == 2 for s in used)
    assert tr2.counters.get("reinitialisations", 0) == 0
    assert tr2.counters.get("vz_hold", 0) > 0
    err = [s.x[:3] - sc.truth[round(s.t * 4) / 4] for s in used]
    assert max(abs(float(e[2])) for e in err) < 30.0  # the +150 m elevation error never got in
    assert max(float(np.hypot(e[0], e[1])) for e in err) < 40.0
    # inside the range gate nothing changes: the same steps up to the first far report
    first_far = min(s.t for s in steps2 if s.source == "radar" and len(s.z) == 2)
    before = [(s.status, s._state) for s in steps if s.t < first_far]
    assert before == [(s.status, s._state) for s in steps2 if s.t < first_far]


def test_a_radar_mount_misalignment_is_corrected_with_the_sites_calibration(site: Site) -> None:
    # the radar reports every angle 2 deg too far clockwise and 1 deg too high (turning the
    # reports by minus the bias adds it); the RF fixes are unbiased
    sc = Scene(site, seed=12)
    sc.build(200.0)
    r0 = (float(sc.r0[0]), float(sc.r0[1]), float(sc.r0[2]))
    skew = RadarAlignment(r0, -2.0, -1.0)
    stream = [skew.frame(x) if isinstance(x, RadarFrame) else x for x in sc.stream()]
    profile = load_profile("tracker")
    exact = RadarCalibration(az_sigma_deg=0.0, el_sigma_deg=0.0)  # surveyed: not refined
    plain = site.calibrated(exact)
    aligned = site.calibrated(dataclasses.replace(exact, az_bias_deg=2.0, el_bias_deg=1.0))

    def mean_error(
        s: Site, items: list[RadarFrame | RfAttempt]
    ) -> tuple[float, list[TrackerStep]]:
        steps = run_tracker(Tracker(profile, s), items)
        late = [s for s in steps if s.counted and s.t >= 30.0]
        assert len(late) > 500
        return float(np.mean([sc.error(s) for s in late])), steps

    e_plain, _ = mean_error(plain, stream)
    e_aligned, steps = mean_error(aligned, stream)
    # 2 deg at 400 m is 14 m across the beam, 1 deg is 7 m in height
    assert e_plain > 10.0
    assert e_aligned < 0.5 * e_plain
    # the correction is the same as feeding the tracker the corrected reports
    fixed = RadarAlignment(r0, 2.0, 1.0)
    again = run_tracker(
        Tracker(profile, plain),
        [fixed.frame(x) if isinstance(x, RadarFrame) else x for x in stream],
    )
    assert [(s.status, s._state) for s in again] == [(s.status, s._state) for s in steps]


def test_a_track_started_beyond_the_range_gate_takes_the_height_prior(site: Site) -> None:
    sc = OutboundScene(site, seed=12)
    sc.build_far(300.0)
    start = min(t for t, p in sc.truth.items() if sc.far(p)) + 5.0
    sc.frames = [f for f in sc.frames if f.t >= start]  # the radar sees it only out there
    sc.fixes = []
    far = load_profile("tracker").with_changes(range_gate_m=1500.0, far_gate_m=2500.0)
    tr = Tracker(far, site)
    steps = run_tracker(tr, sc.stream())
    out = [s for s in steps if sc.far(sc.truth[round(s.t * 4) / 4])]
    started = [s for s in out if s.status == "initialised"]
    assert len(started) == 1 and len(started[0].z) == 3  # the step shows the report it used
    assert started[0].x[2] == pytest.approx(far.rf_init_altitude_m)  # not the report's height
    used = [s for s in out if s.status == "updated" and s.source == "radar"]
    assert len(used) > 100 and all(len(s.z) == 2 for s in used)
    # the reports' +150 m never got into the height: the prior (40 m) against a 50 m truth
    assert max(abs(float(s.x[2] - sc.truth[round(s.t * 4) / 4][2])) for s in used) < 20.0


def test_fixed_rate_accessors(site: Site) -> None:
    sc = Scene(site, seed=5)
    sc.build(60.0)
    tracker, steps = _run(sc, site)
    best = tracker.best_track()
    assert best is not None and tracker.confirmed
    assert tracker.last_update_t == max(s.t for s in steps if s.updated)
    before = tracker.best_track()
    x, P = tracker.predict_to(best.t + 2.0)
    after = tracker.best_track()
    assert before is not None and after is not None
    np.testing.assert_array_equal(before.x, after.x)
    np.testing.assert_array_equal(before.P, after.P)
    np.testing.assert_allclose(x[:3], best.x[:3] + 2.0 * best.x[3:], atol=1e-6)
    assert np.all(np.diag(P) > np.diag(best.P))
    with pytest.raises(ValueError):
        tracker.predict_to(best.t - 1.0)


def test_invalid_reports_never_reach_the_state(site: Site) -> None:
    sc = Scene(site, seed=6)
    sc.build(40.0)
    bad = RadarTrack(20.1, 10, 0.0, 0.0, 0.0, math.nan, 0.0, 0.0, None, 0.9, None, None)
    stream = sc.stream()
    stream.insert(next(i for i, x in enumerate(stream) if x.t > 20.1), RadarFrame(20.1, (bad,)))
    tracker = Tracker(load_profile("tracker"), site)
    steps = run_tracker(tracker, stream)
    assert any(s.reason == "invalid" for s in steps)
    assert all(np.all(np.isfinite(s.x)) for s in steps if s.counted)


def _coasting_scene(site: Site) -> Scene:
    """The loop 400 m out, its onboard radar track coasting from 30 to 34 s: each report then
    repeats the previous one's velocity and RCS."""
    sc = Scene(site, seed=7)
    sc.build(60.0)
    frames: list[RadarFrame] = []
    for f in sc.frames:
        if 30.0 <= f.t < 34.0 and f.tracks:  # the onboard track coasts for 4 s
            prev = frames[-1].tracks[0]
            tr = f.tracks[0]
            coast = RadarTrack(
                f.t,
                tr.track_id,
                0.0,
                0.0,
                0.0,
                tr.e,
                tr.n,
                tr.u,
                prev.vel_ned,
                tr.uav_prob,
                None,
                prev.rcs_dbsm,
            )
            f = RadarFrame(f.t, (coast,))
        frames.append(f)
    sc.frames = frames
    return sc


def test_coasted_reports_are_not_fused_as_measurements(site: Site) -> None:
    """A report repeating its radar track's velocity and RCS is the radar's own prediction
    (a coast): the fused track does not take it; the same reports with a fresh RCS are
    fused."""
    sc = _coasting_scene(site)
    prof = load_profile("tracker")
    steps = run_tracker(Tracker(prof, site), sc.stream())
    coasts = [s for s in steps if s.reason == "coast"]
    # every report of the coast repeats the one before it (4 s at 4 Hz); none other does
    assert len(coasts) == 16 and all(30.0 <= s.t < 34.0 for s in coasts)
    assert all(s.status == "discarded" for s in coasts)
    # the same positions with an RCS that changes from report to report are measurements
    sc.frames = [
        RadarFrame(f.t, tuple(
            dataclasses.replace(r, rcs_dbsm=(r.rcs_dbsm or -10.0) - 0.01 * k) for r in f.tracks
        )) if 30.0 <= f.t < 34.0 else f
        for k, f in enumerate(sc.frames)
    ]  # fmt: skip
    steps_fresh = run_tracker(Tracker(prof, site), sc.stream())
    assert not any(s.reason == "coast" for s in steps_fresh)
    used = [s for s in steps_fresh if 30.0 <= s.t < 34.0 and s.updated and s.source == "radar"]
    assert len(used) == 16


@pytest.mark.parametrize(
    ("gate_m", "far_m", "why"), [(300.0, 600.0, "coast"), (200.0, 300.0, "range_gate")]
)
def test_a_coast_between_the_gates_is_a_coast_and_beyond_the_far_gate_out_of_range(
    site: Site, gate_m: float, far_m: float, why: str
) -> None:
    # the loop runs 400 m out: between the gates (its reports horizontal-only candidates) or
    # beyond both; the onboard coast's reports are counted by the reason that discards them
    sc = _coasting_scene(site)
    prof = load_profile("tracker").with_changes(range_gate_m=gate_m, far_gate_m=far_m)
    tr = Tracker(prof, site)
    steps = run_tracker(tr, sc.stream())
    during = [s for s in steps if s.source == "radar" and 30.0 <= s.t < 34.0]
    assert len(during) == 16 and all(s.status == "discarded" and s.reason == why for s in during)
    other = "range_gate" if why == "coast" else "coast"
    assert tr.counters.get(f"rejected_{why}", 0) >= 16 and not tr.counters.get(f"rejected_{other}")
    if why == "coast":  # the reports either side of the coast update the track in 2D
        used = [s for s in steps if s.status == "updated" and s.source == "radar"]
        assert len(used) > 100 and all(len(s.z) == 2 for s in used)


# --- the runner -----------------------------------------------------------------------------
def _flight(scene: Scene) -> Flight:
    truth = [
        TruthFix(t, 0.0, 0.0, 0.0, float(p[0]), float(p[1]), float(p[2]), (0.0, 0.0, 0.0), 6, 20)
        for t, p in sorted(scene.truth.items())
    ]
    return Flight("synthetic", truth, scene.frames, scene.fixes)


def test_run_flight_with_tracker_profiles(site: Site) -> None:
    sc = Scene(site, seed=7)
    sc.build(120.0, clutter=True)
    fl = _flight(sc)
    res = run_flight(fl, load_profile("tracker"), site)
    n_reports = sum(len(f.tracks) for f in fl.radar)
    assert len(res.steps) == n_reports + len(fl.rf)  # one step per report and per fix
    pc = res.paper_counts()
    assert pc["radar_accepted"] > 0 and pc["rf_accepted"] > 0
    assert res.info is not None and res.info.radar_reports == n_reports
    smooth = run_flight(fl, load_profile("tracker_smoothed"), site)
    assert [s.status for s in smooth.steps] == [s.status for s in res.steps]
    e_f = [sc.error(s) for s in res.steps if s.counted]
    e_s = [sc.error(s) for s in smooth.steps if s.counted]
    assert np.mean(e_s) < np.mean(e_f)


def test_streaming_equals_the_offline_run_bit_for_bit(site: Site) -> None:
    sc = Scene(site, seed=10)
    sc.build(90.0, clutter=True)
    fl = _flight(sc)
    offline = run_flight(fl, load_profile("tracker"), site).steps
    tracker = Tracker(load_profile("tracker"), site)
    live: list[TrackerStep] = []
    for item in sc.stream():  # what a node would do, one message at a time
        if isinstance(item, RadarFrame):
            live.extend(tracker.process_radar_frame(item))
        else:
            live.extend(tracker.process_rf(item))
    assert len(live) == len(offline)
    for a, b in zip(live, offline, strict=True):
        assert (a.t, a.status, a.reason, a.track_id) == (b.t, b.status, b.reason, b.track_id)
        assert a._state == b._state  # the packed doubles: bit-identical


@pytest.mark.parametrize(
    ("height_m", "sd_up_m", "sigmas", "ghost"),
    [
        (-20.0, 40.0, 0.0, True),  # 20 m below: beyond below_ground_m (5 m)
        (-20.0, 40.0, 1.0, False),  # ... but inside its reports' vertical sigma (a low pass)
        (-60.0, 15.0, 1.0, True),  # a mirror image well below its sigma
        (-3.0, 1.0, 1.0, False),  # never closer than below_ground_m
    ],
)
def test_below_ground_means_beyond_the_reports_vertical_sigma(
    height_m: float, sd_up_m: float, sigmas: float, ghost: bool
) -> None:
    cfg = dataclasses.replace(ScoreConfig(), below_ground_sigmas=sigmas)
    table = ObjectTable(cfg, FixedRadarR((100.0, 0.0, 0.0, 100.0, 0.0, sd_up_m**2)))
    for k in range(8):
        obj = table.update(
            RadarTrack(10.0 + 0.25 * k, 1, 0.0, 0.0, 0.0, 400.0, 300.0, height_m,
                       (0.0, 5.0, 0.0), 0.5, None, -10.0)
        )  # fmt: skip
    assert obj.sd_up == pytest.approx(sd_up_m)
    assert obj.below_ground(cfg) is ghost
    base = dataclasses.replace(cfg, below_ground_m=1e9)  # no ghost at all
    assert obj.score(cfg) == pytest.approx(obj.score(base) - (cfg.veto if ghost else 0.0))


@pytest.mark.parametrize(
    ("support_max_cep_m", "cep_m", "supported"),
    [
        (0.0, 40.0, False),  # off: a fix discarded for its CEP is no evidence at all
        (60.0, 40.0, True),  # too coarse to update a track, still evidence of an emitter
        (60.0, 80.0, False),  # too coarse for either
    ],
)
def test_a_fix_too_coarse_for_an_update_may_still_support_the_object_it_fits(
    site: Site, support_max_cep_m: float, cep_m: float, supported: bool
) -> None:
    prof = load_profile("tracker")
    assert prof.rf_max_cep_m == 20.0
    score = dataclasses.replace(prof.score, rf_support_max_cep_m=support_max_cep_m)
    tr = Tracker(dataclasses.replace(prof, score=score), site)
    for k in range(5):
        t = 100.0 + 0.25 * k
        rep = RadarTrack(t, 7, 0.0, 0.0, 0.0, 400.0, 300.0, 30.0, (0.0, 0.0, 0.0), 0.3, None,
                         -10.0)  # fmt: skip
        tr.process_radar_frame(RadarFrame(t, (rep,)))
    steps = tr.process_rf(RfAttempt(101.1, 1, True, 0.0, 0.0, 410.0, 305.0, cep_m, 4, 4))
    assert [(s.status, s.reason) for s in steps] == [("discarded", "cep")]  # never an update
    obj = tr.objects.objects[7]
    assert obj.rf_support == (1.0 if supported else 0.0)


@pytest.mark.parametrize(
    ("rcs_dbsm", "large_rcs", "large"),
    [
        (-12.0, 0.0, False),  # a small target moving low: a UAV far out or taking off
        (9.0, 0.0, True),  # a car-sized one
        (None, 0.0, False),  # no RCS reported: not judged by its size
        (-12.0, -20.0, True),  # a bound below its RCS: too large for a small UAV
    ],
)
def test_a_low_moving_object_loses_score_only_for_a_cars_rcs(
    rcs_dbsm: float | None, large_rcs: float, large: bool
) -> None:
    """A low moving object is not judged by its height or speed (a UAV taking off or far out
    flies so too); a car's RCS is what costs, through the size term."""
    cfg = dataclasses.replace(ScoreConfig(), large_rcs_dbsm=large_rcs)
    table = ObjectTable(cfg, FixedRadarR((100.0, 0.0, 0.0, 100.0, 0.0, 20.0**2)))
    rng = np.random.default_rng(3)
    for k in range(40):  # 10 s at 13 m/s, 1 m up
        rcs = None if rcs_dbsm is None else rcs_dbsm + float(rng.normal(0.0, 3.0))
        obj = table.update(
            RadarTrack(10.0 + 0.25 * k, 1, 0.0, 0.0, 0.0, 600.0 + 3.25 * k, 300.0, 1.0,
                       (0.0, 13.0, 0.0), 0.3, None, rcs)
        )  # fmt: skip
    assert obj.up < cfg.ground_alt_m and obj.speed > cfg.stationary_speed_mps
    no_size = dataclasses.replace(cfg, large_rcs_dbsm=1e9)
    lost = cfg.veto if large else 0.0
    assert obj.score(cfg) == pytest.approx(obj.score(no_size) - lost)


@pytest.mark.parametrize("tau_s", [5.0, 15.0])
def test_an_emitter_the_radar_does_not_see_yet_supports_the_object_that_appears_there(
    tau_s: float,
) -> None:
    """Fixes that credit no object (a UAV on its pad, link on, no radar track) are kept for
    the profile's ``track.max_coast_s``; the first object that appears inside their gate takes
    their support, decayed since; an object elsewhere, a fix too old or an object seen before
    get none."""
    cfg = load_profile("tracker").with_changes(max_coast_s=tau_s).score
    assert cfg.rf_tau_s == tau_s
    table = ObjectTable(cfg, FixedRadarR((100.0, 0.0, 0.0, 100.0, 0.0, 100.0)))

    def report(t: float, tid: int, east: float) -> RadarTrack:
        return RadarTrack(t, tid, 0.0, 0.0, 0.0, east, 300.0, 20.0, (0.0, 0.0, 0.0), 0.3,
                          None, -10.0)  # fmt: skip

    table.update(report(0.0, 9, 2000.0))  # an object far away, seen before the fixes
    assert table.rf_fix(10.0, 500.0, 300.0, 400.0) == 0  # an old fix, beyond the memory
    assert table.rf_fix(50.0, 505.0, 300.0, 400.0) == 0
    assert table.rf_fix(54.0, 495.0, 302.0, 400.0) == 0
    far = table.update(report(60.0, 2, 900.0))  # a new object, but not where the fixes are
    assert far.rf_support == 0.0
    obj = table.update(report(60.0, 1, 500.0))  # appears at the emitter
    if tau_s > 10.0:  # the fixes 10 and 6 s old are kept; at 5 s neither is
        want = math.exp(-10.0 / 15.0) + math.exp(-6.0 / 15.0)
        assert obj.rf_support == pytest.approx(want) and obj.rf_t == 60.0
        # used up: the next object there gets nothing
        assert table.update(report(60.5, 3, 500.0)).rf_support == 0.0
    else:
        assert obj.rf_support == 0.0
    assert table.objects[9].rf_support == 0.0


def test_an_rf_fix_credits_only_the_object_it_fits_best() -> None:
    """Two radar objects 20 m apart, both inside the gate of an RF fix: only the nearer gains
    RF support (clutter beside a UAV must not share its emitter)."""
    table = ObjectTable(ScoreConfig(), FixedRadarR((100.0, 0.0, 0.0, 100.0, 0.0, 100.0)))
    for k in range(5):
        t = 100.0 + k
        for tid, east in ((1, 500.0), (2, 520.0)):
            table.update(
                RadarTrack(t, tid, 0.0, 0.0, 0.0, east, 300.0, 50.0, (0.0, 0.0, 0.0), 0.5,
                           None, -10.0)
            )  # fmt: skip
    a, b = table.objects[1], table.objects[2]
    assert table.rf_fix(104.5, 509.0, 300.0, 400.0) == 1 and table.credited is a
    assert (a.rf_support, b.rf_support) == (1.0, 0.0)
    # 1 m past the midpoint the other one is nearer
    assert table.rf_fix(104.5, 511.0, 300.0, 400.0) == 1 and table.credited is b
    assert (a.rf_support, b.rf_support) == (1.0, 1.0)  # the first kept its own fix only
    # a fix outside both gates credits nobody
    assert table.rf_fix(104.5, 900.0, 300.0, 400.0) == 0


def _classifier(target_logit: float) -> Callable[[float], float]:
    """A radar classifier's output for a track of age ``t``: it starts at the prior (logit -1)
    and moves towards ``target_logit`` as features accumulate (time constant 5 s)."""

    def prob(t: float) -> float:
        lg = -1.0 + (1.0 - math.exp(-t / 5.0)) * (target_logit + 1.0)
        return 1.0 / (1.0 + math.exp(-lg))

    return prob


def test_the_class_history_is_an_average_of_the_reports_logits() -> None:
    """The first report's logit starts the history; later ones are averaged with the time
    constant tau_s; each logit is clipped to +-class_clip (hand values)."""
    cfg = dataclasses.replace(ScoreConfig(), tau_s=3.0, class_clip=3.0)
    table = ObjectTable(cfg, FixedRadarR((25.0, 0.0, 0.0, 25.0, 0.0, 25.0)))

    def rep(t: float, p: float) -> RadarTrack:
        return RadarTrack(t, 7, 0.0, 0.0, 0.0, 100.0, 200.0, 50.0, (0.0, 1.0, 0.0), p, None, -10.0)

    assert table.update(rep(10.0, 0.5)).class_logit == 0.0
    obj = table.update(rep(11.0, 0.8))
    a = math.exp(-1.0 / 3.0)
    assert obj.class_logit == pytest.approx((1.0 - a) * math.log(4.0), abs=1e-12)
    prev = obj.class_logit
    obj = table.update(rep(13.0, 0.9999))  # logit 9.2, clipped to 3
    a = math.exp(-2.0 / 3.0)
    assert obj.class_logit == pytest.approx(prev * a + 3.0 * (1.0 - a), abs=1e-12)


def test_an_rf_fix_credits_an_object_reported_within_the_window() -> None:
    """The radar's longest update interval (``HELD_S``, 1.3 s) at its edge: a fix credits an
    object whose last report is at most that long before (or after) it, and no object
    reported longer ago (the radar no longer holds it)."""
    cfg = ScoreConfig()
    w = HELD_S
    assert w > 0.0
    for gap, credited in ((0.99 * w, True), (1.01 * w, False), (-0.99 * w, True)):
        table = ObjectTable(cfg, FixedRadarR((100.0, 0.0, 0.0, 100.0, 0.0, 100.0)))
        for k in range(5):
            table.update(
                RadarTrack(100.0 + k, 1, 0.0, 0.0, 0.0, 500.0, 300.0, 50.0, (0.0, 0.0, 0.0),
                           0.5, None, -10.0)
            )  # fmt: skip
        assert table.rf_fix(104.0 + gap, 505.0, 300.0, 400.0) == int(credited)
        assert (table.credited is table.objects[1]) == credited


def _contra_scene(site: Site, decoy_from: float) -> Scene:
    """The UAV on its loop, lost to the radar for 20 s from t = 100 s (RF goes on); a decoy
    classed 0.7, moving at 3 m/s 1 km beyond the loop, reports from ``decoy_from``: always
    outside the track's gate, and out of reach."""

    def seen(t: float) -> bool:
        return not 100.0 <= t < 120.0

    def decoy(sc: Scene, t: float, k: int) -> RadarTrack | None:
        if t < decoy_from:
            return None
        p = sc.r0 + np.array([-1500.0 + 3.0 * t, 200.0, 60.0])
        return sc.report(t, DECOY_ID, p, 0.7, np.array([3.0, 0.0, 0.0]))

    sc = Scene(site, seed=12)
    sc.build(130.0, uav_visible=seen, fragment_s=1000.0, decoy=decoy)
    return sc


def test_a_strong_object_outside_the_gate_makes_a_rejection_only_from_init_min(
    site: Site,
) -> None:
    """While the object the track follows is silent, another object's report outside the gate
    is a rejection of the track (a ``coasted`` step) only when that object could start a
    track: a score of at least ``init_min``; otherwise it is discarded (``nis``). The decoy's
    score is constant once its class history and age term are full, so ``init_min`` set a
    hair either side of it decides."""
    sc = _contra_scene(site, 0.0)
    items = sc.stream()
    base = load_profile("tracker")
    probe = Tracker(base, site)
    run_tracker(probe, items)
    s = probe.objects.objects[DECOY_ID].score(probe.cfg)
    assert base.score.follow_min < s

    def rejections(init_min: float) -> list[TrackerStep]:
        prof = dataclasses.replace(base, score=dataclasses.replace(base.score, init_min=init_min))
        steps = run_tracker(Tracker(prof, site), items)
        gap = [x for x in steps if 101.0 <= x.t < 120.0 and x.track_id == DECOY_ID]
        assert len(gap) > 60 and not any(x.updated for x in gap)
        return [x for x in gap if x.coasted]

    assert len(rejections(s - 0.01)) > 60
    assert rejections(s + 0.01) == []


@pytest.mark.parametrize("n", [4, 6])
def test_an_object_outside_the_gate_makes_a_rejection_from_its_nth_report(
    site: Site, n: int
) -> None:
    """The decoy above first reports 2 s into the radar gap: its reports are rejections of the
    track from its ``track.confirm_m``-th on, not before."""
    sc = _contra_scene(site, 102.0)
    base = load_profile("tracker")
    prof = dataclasses.replace(
        base,
        score=dataclasses.replace(base.score, init_min=0.0),
        confirm_m=n,
        confirm_n=max(n, base.confirm_n),
    )
    steps = run_tracker(Tracker(prof, site), sc.stream())
    mine = [x for x in steps if x.track_id == DECOY_ID]
    assert len(mine) > 40 and all(x.t >= 102.0 for x in mine)
    first = next(k for k, x in enumerate(mine) if x.coasted)
    assert first == n - 1


@pytest.mark.parametrize("adaptive", [True, False])
def test_an_objects_own_filter_takes_a_report_with_the_object_floor(
    site: Site, adaptive: bool
) -> None:
    """A radar object's own filter starts from its first report with the report's polar R
    plus ``object_floor_m`` squared on each axis (the radar's polar R 150 m out is a few
    metres; an object's reports scatter more than that), with the online allowance or with a
    fixed track floor above it."""
    prof = load_profile("tracker")
    if not adaptive:
        prof = dataclasses.replace(prof, radar_floor_m=40.0, adaptive_window=None)
    tr = Tracker(prof, site)
    f = tr.cfg.object_floor_m
    assert f == 10.0
    r0 = np.array(site.radar.enu, dtype=float)
    e, n, u = map(float, r0 + np.array([150.0, 0.0, 20.0]))
    feed(tr, RadarFrame(50.0, (RadarTrack(50.0, 3, 0.0, 0.0, 0.0, e, n, u, (0.0, 0.0, 0.0), 0.5,
                                          None, -10.0),)))  # fmt: skip
    kf = tr.objects.objects[3].kf
    assert kf is not None
    p = tr.profile
    polar = PolarRadarR(
        site.radar.enu, p.radar_sigma_range_m, math.radians(p.radar_sigma_az_deg),
        math.radians(p.radar_sigma_el_deg),
    ).r_at(e, n, u)  # fmt: skip
    assert kf.P[0] == pytest.approx(polar[0] + f * f)
    assert kf.P[6] == pytest.approx(polar[3] + f * f)
