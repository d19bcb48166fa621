"""The Stone Soup multi-target baseline of scripts/multi_baseline.py: the same motion noise and
measurement covariances as ours, two confirmed tracks on two crossing UAVs, and the flights
``--split`` takes from a cache."""

from __future__ import annotations

import argparse
from datetime import timedelta
from pathlib import Path
from types import ModuleType

import numpy as np
import pytest
from script_util import load_script
from test_multi_tracker import Crossing

from uav_fusion.core.bench.cache import cached_flights
from uav_fusion.core.bench.definition import load_definition
from uav_fusion.core.estimators import load_profile
from uav_fusion.core.estimators.kalman import CvKalman
from uav_fusion.core.estimators.models import cv_process_noise
from uav_fusion.core.estimators.parts import (
    RadarFront,
    alignment_from_site,
    packed_to_array,
    rf_model_from_profile,
)
from uav_fusion.core.profiles.model import Profile
from uav_fusion.core.records import RadarFrame, RadarTrack, RfAttempt
from uav_fusion.core.site import RadarCalibration, Site, load_site
from uav_fusion.resources import DEFAULT_SITE, config_path

pytest.importorskip("stonesoup")


@pytest.fixture(scope="module")
def mb() -> ModuleType:
    return load_script("multi_baseline")


@pytest.fixture(scope="module")
def site() -> Site:
    return load_site()


@pytest.fixture(scope="module")
def profile() -> Profile:
    return load_profile("tracker")


@pytest.mark.parametrize("dt", [0.25, 1.0, 3.5])
def test_transition_noise_is_our_cv_q(mb: ModuleType, profile: Profile, dt: float) -> None:
    model = mb.transition_model(profile.q)
    idx = mb.SS_TO_OURS
    Q = np.asarray(model.covar(time_interval=timedelta(seconds=dt)))[np.ix_(idx, idx)]
    np.testing.assert_allclose(Q, cv_process_noise(dt, profile.q), rtol=0, atol=1e-12)
    # and the filter's own element-wise prediction from P = 0
    kf = CvKalman(profile.q)
    kf.predict(dt)
    np.testing.assert_allclose(Q, kf.P_array(), rtol=0, atol=1e-12)
    F = np.asarray(model.matrix(time_interval=timedelta(seconds=dt)))[np.ix_(idx, idx)]
    np.testing.assert_array_equal(
        F, np.block([[np.eye(3), dt * np.eye(3)], [np.zeros((3, 3)), np.eye(3)]])
    )


def test_gate_is_the_nis_gate(mb: ModuleType, profile: Profile, site: Site) -> None:
    from scipy.stats import chi2

    b = mb.build_baseline(profile, site)
    hyps = b.tracker.data_associator.hypothesiser.hypothesisers
    for dim in (2, 3):
        g = hyps[dim].missed_distance
        assert g**2 == pytest.approx(chi2.ppf(profile.nis_probability, dim), rel=1e-12)


def test_detections_carry_our_r_and_the_same_drops(
    mb: ModuleType, profile: Profile, site: Site
) -> None:
    site = site.calibrated(RadarCalibration(az_bias_deg=0.45, el_bias_deg=0.27))
    b = mb.build_baseline(profile, site)
    r0 = np.array(site.radar.enu, dtype=float)
    p = r0 + np.array([300.0, 400.0, 80.0])
    far = r0 + np.array([3000.0, 0.0, 50.0])  # beyond the profile's far gate (2500 m)

    def mk(tid: int, q: np.ndarray, v: tuple[float, float, float] | None) -> RadarTrack:
        e, n, u = map(float, q)
        return RadarTrack(10.0, tid, 0.0, 0.0, 0.0, e, n, u, v, 0.8, None, -10.0)

    dets = b.radar_detections(RadarFrame(10.0, (mk(1, p, (1.0, 2.0, 0.0)), mk(2, far, None))))
    (d,) = dets  # beyond the gate: dropped
    # the report as ours takes it: corrected for the radar's misalignment
    align = alignment_from_site(site)
    assert align is not None
    q = align.track(mk(1, p, (1.0, 2.0, 0.0)))
    z = np.array([q.e, q.n, q.u])
    assert 1.0 < float(np.linalg.norm(z - p)) < 10.0
    np.testing.assert_array_equal(np.asarray(d.state_vector).ravel(), z)
    # the UAV track's R as the tracker starts it (the online allowance at its start value)
    expected = packed_to_array(RadarFront(profile, site, profile.score).radar_r.r_at(*z))
    np.testing.assert_allclose(np.asarray(d.measurement_model.covar()), expected, rtol=0, atol=0)
    H = np.asarray(d.measurement_model.matrix())[:, mb.SS_TO_OURS]
    np.testing.assert_array_equal(H, np.hstack([np.eye(3), np.zeros((3, 3))]))
    # the same report again (velocity and RCS repeated): a coast, dropped
    assert not b.radar_detections(RadarFrame(10.5, (mk(1, p, (1.0, 2.0, 0.0)),)))
    assert b.dropped == {"range_gate": 1, "coast": 1}
    # the baseline has no horizontal-only updates: 3D detections out to the far gate (2000 m
    # kept), or out to the gate it is given
    assert profile.range_gate_m == 1000.0 and profile.far_gate_m == 2500.0
    mid = r0 + np.array([2000.0, 0.0, 50.0])
    assert len(b.radar_detections(RadarFrame(11.0, (mk(3, mid, (1.0, 0.0, 0.0)),)))) == 1
    b2 = mb.build_baseline(profile, site, range_gate_m=1500.0)
    assert not b2.radar_detections(RadarFrame(11.0, (mk(3, mid, (1.0, 0.0, 0.0)),)))
    # RF: R from the CEP model; a CEP above max_cep_m dropped
    att = RfAttempt(11.0, 1, True, 0.0, 0.0, 5.0, 6.0, 9.0, 4, 4)
    rd = b.rf_detection(att)
    expected2 = packed_to_array(rf_model_from_profile(profile).r_for(9.0))
    np.testing.assert_allclose(np.asarray(rd.measurement_model.covar()), expected2, atol=0)
    assert profile.rf_max_cep_m is not None
    bad = RfAttempt(12.0, 2, True, 0.0, 0.0, 5.0, 6.0, profile.rf_max_cep_m + 1.0, 4, 4)
    assert b.rf_detection(bad) is None
    # the variant that also drops reports the radar itself classes below a probability
    bc = mb.build_baseline(profile, site, 0.5)
    pe, pn, pu = map(float, p)
    low = RadarTrack(10.0, 3, 0.0, 0.0, 0.0, pe, pn, pu, None, 0.3, None, -10.0)
    unknown = RadarTrack(10.0, 4, 0.0, 0.0, 0.0, pe, pn, pu, None, None, None, -10.0)
    high = RadarTrack(10.0, 5, 0.0, 0.0, 0.0, pe, pn, pu, None, 0.5, None, -10.0)
    kept = bc.radar_detections(RadarFrame(10.0, (low, unknown, high)))
    assert [d.metadata["radar_track"] for d in kept] == [5] and bc.dropped == {"class": 2}


def test_two_crossing_uavs_get_two_confirmed_tracks(
    mb: ModuleType, profile: Profile, site: Site
) -> None:
    sc = Crossing(site, seed=1)
    b = mb.build_baseline(profile, site)
    epochs = mb.run_baseline_stream(b, sc.stream(), 1.0, 1000.0, 1099.0)
    assert len(epochs) == 100
    clutter = sc.r0 + np.array([100.0, 250.0, 30.0])
    ids: list[set[int]] = [set(), set(), set()]  # per object: UAV A, UAV B, clutter
    for ep in epochs[5:]:  # confirmed from the third frame on (M of N, 4 frames a second)
        objects = (sc.a(ep.t - 1000.0), sc.b(ep.t - 1000.0), clutter)
        dist = np.array([[np.linalg.norm(o.x[:3] - q) for o in ep.tracks] for q in objects])
        # every track is on one of the three objects
        assert dist.shape[1] > 0 and np.all(dist.min(axis=0) < 30.0)
        # each UAV's nearest track is within 30 m at every epoch, through the crossing (t = 50 s)
        for k in range(3):
            j = int(np.argmin(dist[k]))
            assert k == 2 or dist[k, j] < 30.0
            if dist[k, j] < 30.0:
                ids[k].add(ep.tracks[j].track_id)
        for o in ep.tracks:
            assert o.t == ep.t and o.x.shape == (6,) and o.P.shape == (6, 6)
            assert o.uav_prob == 1.0 and o.emitter is None
    # each UAV keeps one id, different from the other's; the baseline has no classifier, so
    # the clutter reflector has its track too
    assert len(ids[0]) == 1 and len(ids[1]) == 1 and ids[0] != ids[1]
    assert len(ids[2]) == 1 and not ids[2] & (ids[0] | ids[1])


def test_holding_deleter_is_our_m_of_n(mb: ModuleType) -> None:
    """The initiator confirms at m updates, then asks the deleter: together they decide as
    our MofN does, for every hit pattern (the starting detection a hit)."""
    import itertools
    from datetime import datetime

    from stonesoup.types.detection import Detection
    from stonesoup.types.hypothesis import SingleHypothesis
    from stonesoup.types.prediction import GaussianStatePrediction
    from stonesoup.types.track import Track
    from stonesoup.types.update import GaussianStateUpdate

    from uav_fusion.core.estimators.parts import MofN

    t0 = datetime(2026, 1, 1)
    x, P = np.zeros((6, 1)), np.eye(6)

    def state(k: int, hit: bool) -> GaussianStateUpdate | GaussianStatePrediction:
        ts = t0 + timedelta(seconds=k)
        if hit:
            det = Detection(np.zeros((3, 1)), timestamp=ts)
            return GaussianStateUpdate(x, P, SingleHypothesis(None, det), timestamp=ts)
        return GaussianStatePrediction(x, P, timestamp=ts)

    for m, n in ((1, 1), (2, 3), (3, 5), (3, 3)):
        deleter = mb.MofNDeleter(m=m, n=n)
        for pattern in itertools.product((True, False), repeat=n):
            ours = MofN(m, n)
            ours_state = "confirmed" if m == 1 else "pending"
            track = Track([state(0, True)])
            ss_state = "confirmed" if m == 1 else "pending"
            for k, hit in enumerate(pattern, start=1):
                if ours_state == "pending":
                    ours_state = ours.record(hit)
                if ss_state == "pending":
                    track.append(state(k, hit))
                    if sum(isinstance(s, GaussianStateUpdate) for s in track) >= m:
                        ss_state = "confirmed"
                    elif deleter.check_for_deletion(track):
                        ss_state = "failed"
            assert ss_state == ours_state, (m, n, pattern)


def test_jpda_variant_tracks_both_uavs(mb: ModuleType, profile: Profile, site: Site) -> None:
    sc = Crossing(site, seed=1)
    b = mb.build_baseline(profile, site, None, mb.JpdaSettings(prob_detect=0.9, max_detections=2))
    epochs = mb.run_baseline_stream(b, sc.stream(), 1.0, 1000.0, 1099.0)
    clutter = sc.r0 + np.array([100.0, 250.0, 30.0])
    for ep in epochs[5:]:
        objects = (sc.a(ep.t - 1000.0), sc.b(ep.t - 1000.0), clutter)
        dist = np.array([[np.linalg.norm(o.x[:3] - q) for o in ep.tracks] for q in objects])
        # one track per object (no duplicates), each UAV with a track within 50 m; JPDA's
        # shared detections may swap two ids where a UAV passes the reflector (t = 37 s)
        assert len(ep.tracks) == 3
        assert dist[0].min() < 50.0 and dist[1].min() < 50.0


def test_split_takes_the_current_twins_cache_folders_only(
    mb: ModuleType, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``--split`` picks a half's flights as ``uav_fusion bench`` names them for the current
    twin: a folder of an older twin beside them (what a glob would also pick up) is not
    taken, and a flight not generated yet stops the script naming it."""
    ap = argparse.ArgumentParser()
    args = argparse.Namespace(split="test", definition="multi", cache=tmp_path, site=None)
    with pytest.raises(SystemExit):
        mb.split_folders(ap, args)
    err = capsys.readouterr().err
    assert "not in the cache (6 of 6 flights of the test half missing)" in err
    assert str(tmp_path / "multi_crossing_pair-s201-") in err
    site_file = config_path(DEFAULT_SITE)
    current = [
        cf.folder for cf in cached_flights(load_definition("multi"), "test", tmp_path, site_file)
    ]
    for folder in current:
        folder.mkdir()
    (tmp_path / "multi_crossing_pair-s201-0123456789abcdef").mkdir()  # an older twin's
    assert mb.split_folders(ap, args) == current
    with pytest.raises(SystemExit):
        mb.main([str(current[0]), "--split", "test", "--cache", str(tmp_path)])
    assert "give flight folders or --split, not both" in capsys.readouterr().err
