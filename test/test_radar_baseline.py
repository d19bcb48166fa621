"""The benchmarks' baseline, the radar's own tracks passed through
(core/bench/radar_baseline.py), and its comparison with a profile: multi-UAV and single-UAV."""

from __future__ import annotations

import json
import math
from dataclasses import replace

import numpy as np
import pytest

from uav_fusion.core.bench.multi import MultiFlightResult
from uav_fusion.core.bench.radar_baseline import (
    NAME,
    against_radar,
    against_radar_single,
    markdown_against_radar,
    radar_epochs,
    radar_grid,
)
from uav_fusion.core.bench.single import FlightResult
from uav_fusion.core.records import Flight, RadarFrame, RadarTrack
from uav_fusion.core.scoring.fixed_rate import GridSamples, nees
from uav_fusion.core.scoring.fixed_rate import pool as pool_grid
from uav_fusion.core.scoring.outcomes import FlightSamples, UavSamples
from uav_fusion.core.site import RadarCalibration, load_site


def _report(t: float, tid: int, prob: float | None, e: float, vel_ned: tuple[float, float, float]
            | None = (0.0, 4.0, -1.0)) -> RadarTrack:  # fmt: skip
    return RadarTrack(t, tid, 0.0, 0.0, 0.0, e, 500.0, 60.0, vel_ned, prob, 500.0, -10.0)


def _flight(frames: list[RadarFrame]) -> Flight:
    return Flight("hand", [], frames, [])


def test_each_epoch_passes_the_latest_frames_uav_reports_moved_to_it() -> None:
    frames = [
        RadarFrame(10.2, (_report(10.2, 1, 0.7, 0.0), _report(10.2, 2, 0.3, 50.0))),
        RadarFrame(11.0, (_report(11.0, 1, 0.5, 4.0), _report(11.0, 3, None, 90.0))),
        RadarFrame(11.9, ()),  # the radar has nothing at this frame
        RadarFrame(14.0, (_report(14.0, 5, 0.9, 7.0, None),)),
    ]
    eps = radar_epochs(_flight(frames), load_site(), 2.0, 10.0, 15.3)
    assert [e.t for e in eps] == [10.0 + 0.5 * k for k in range(11)]
    by_t = {e.t: e.tracks for e in eps}
    assert by_t[10.0] == ()  # no frame yet
    (a,) = by_t[10.5]  # track 2's class 0.3 is below 0.5
    assert a.track_id == 1
    # moved 0.3 s with its velocity: (north 0, east 4, down -1) m/s is +e and +u
    assert np.allclose(a.x, [1.2, 500.0, 60.0 + 0.3, 4.0, 0.0, 1.0])
    (b,) = by_t[11.0]  # class exactly 0.5 passes; no class does not
    assert b.track_id == 1 and b.x[0] == 4.0
    assert by_t[12.0] == ()  # the latest frame is empty
    assert by_t[13.0] == ()  # ... and by 13.2 s more than 1.3 s old
    (c,) = by_t[14.0]
    assert np.allclose(c.x[:3], [7.0, 500.0, 60.0])  # no velocity reported: held
    (d,) = by_t[15.0]  # 1 s later: still the latest frame's
    assert d.track_id == 5 and np.array_equal(d.x, c.x)
    assert 15.5 not in by_t  # beyond t1


def test_a_frame_is_passed_on_for_the_radars_longest_update_interval() -> None:
    """1.3 s (the R20's longest track update interval) after its frame a report still counts;
    a tenth of a second later it is gone."""
    frames = [RadarFrame(0.7, (_report(0.7, 1, 0.9, 0.0),))]
    eps = radar_epochs(_flight(frames), load_site(), 10.0, 0.0, 2.5)
    by_t = {round(e.t, 1): len(e.tracks) for e in eps}
    assert (by_t[0.6], by_t[0.7], by_t[2.0], by_t[2.1]) == (0, 1, 1, 0)


def test_the_site_calibration_corrects_the_positions() -> None:
    site = load_site()
    cal = replace(site, radar=replace(site.radar, calibration=RadarCalibration(1.0, 0.0, 0.1, 0.1)))
    frames = [RadarFrame(10.0, (_report(10.0, 1, 0.9, 300.0),))]
    raw = radar_epochs(_flight(frames), site, 1.0, 10.0, 10.0)[0].tracks[0].x
    turned = radar_epochs(_flight(frames), cal, 1.0, 10.0, 10.0)[0].tracks[0].x
    r = site.radar.enu
    d_raw = math.hypot(raw[0] - r[0], raw[1] - r[1])
    d_turned = math.hypot(turned[0] - r[0], turned[1] - r[1])
    assert d_turned == pytest.approx(d_raw)  # turned about the radar, not moved along
    assert math.hypot(*(turned[:2] - raw[:2])) == pytest.approx(d_raw * math.radians(1.0), rel=1e-3)


def _samples(errors_by_uav: dict[str, list[float | None]], gospa: float) -> FlightSamples:
    uavs = []
    for name, errs in errors_by_uav.items():
        ids = tuple(None if e is None else 1 for e in errs)
        uavs.append(UavSamples(
            name, len(errs), sum(e is not None for e in errs),
            np.array([e for e in errs if e is not None], dtype=float), ids, 0, 0,
            times=np.arange(len(errs), dtype=float),
        ))  # fmt: skip
    k = len(next(iter(errors_by_uav.values())))
    z = np.zeros(k)
    return FlightSamples(1.0, np.full(k, gospa), z, z, z, 0, tuple(uavs), ())


def _result(profile: str, flight: str, samples: FlightSamples) -> MultiFlightResult:
    return MultiFlightResult(flight, "plan", 1, "test", profile, samples, (), (), 3.0, 0.1)


def test_the_comparison_counts_flights_and_uavs_on_the_epochs_both_cover() -> None:
    """uav1: ours 10 / 30 (uncovered by the radar at the second epoch) against the radar's
    12 at the first: on the epoch both cover ours is lower. uav2: ours 20 against 20, equal
    counts as at most. A lower GOSPA on one flight of two."""
    ours = _result("tracker", "f1", _samples({"uav1": [10.0, 30.0], "uav2": [20.0, 20.0]}, 30.0))
    radar = _result(NAME, "f1", _samples({"uav1": [12.0, None], "uav2": [20.0, 20.0]}, 31.0))
    ours2 = _result("tracker", "f2", _samples({"uav1": [5.0, 5.0], "uav2": [None, None]}, 40.0))
    radar2 = _result(NAME, "f2", _samples({"uav1": [4.0, 4.0], "uav2": [9.0, 9.0]}, 40.0))
    text = against_radar([ours, radar, ours2, radar2])
    assert "tracker | f1 | 30.0 (31.0) | uav1 1, 10.0 (12.0); uav2 2, 20.0 (20.0)" in text
    assert "tracker | f2 | 40.0 (40.0) | uav1 2, 5.0 (4.0); uav2 -" in text
    assert text.endswith(
        "tracker: GOSPA below the radar's on 1 of 2 flights; mean error at most the radar's "
        "on 2 of 3 UAVs (epochs both cover)"
    )


# --- the single-UAV baseline ---------------------------------------------------------------


def test_the_single_uav_baseline_publishes_the_most_uav_like_report() -> None:
    """At each epoch the report with the highest class of at least 0.5 (the lower track id on
    a tie), moved to the epoch; its age; a new "track" whenever the chosen id changes, a gap
    included; no covariance."""
    frames = [
        RadarFrame(10.0, (_report(10.0, 1, 0.6, 0.0), _report(10.0, 2, 0.8, 50.0))),
        RadarFrame(11.0, (_report(11.0, 2, 0.7, 52.0), _report(11.0, 1, 0.7, 3.0))),
        RadarFrame(12.0, (_report(12.0, 2, 0.49, 54.0),)),  # below 0.5: nothing
        RadarFrame(13.0, (_report(13.0, 1, 0.5, 9.0, None),)),  # exactly 0.5 passes
    ]
    g = radar_grid(_flight(frames), load_site(), 2.0, 10.0, 13.5)
    assert g.t.tolist() == [10.0 + 0.5 * k for k in range(8)]
    assert g.track_id.tolist() == [2, 2, 1, 1, -1, -1, 1, 1]
    assert g.published.tolist() == [True, True, True, True, False, False, True, True]
    assert g.x[1, 0] == pytest.approx(50.0 + 4.0 * 0.5)  # moved 0.5 s at 4 m/s east
    assert g.x[2, 0] == 3.0  # the tie of 0.7 goes to track 1
    assert g.x[7, 0] == 9.0  # no velocity reported: held
    assert g.age_s[1] == pytest.approx(0.5) and math.isnan(g.age_s[4])
    assert set(g.last_source[g.published]) == {"radar"}
    assert g.confirmed_tracks == 3 and g.restarts == 2  # 2, then 1, then 1 again after a gap
    assert np.all(np.isnan(g.P))


def _grid_result(profile: str, flight: str, errors: list[float | None]) -> FlightResult:
    idx = np.array([k for k, e in enumerate(errors) if e is not None], dtype=np.int64)
    errs = np.array([e for e in errors if e is not None], dtype=float)
    z = np.zeros(idx.size)
    samples = GridSamples(
        len(errors), idx.size, idx.size, errs, z, z, z, np.zeros(idx.size, bool), -1, 0, 0,
        0.0, 0, epoch_index=idx,
    )  # fmt: skip
    return FlightResult(flight, "plan", 1, "test", profile, samples, 0, 0.0)


def test_a_profile_is_compared_with_the_radar_on_the_epochs_both_cover() -> None:
    """f1: ours 10 / 50 / - against the radar's - / 40 / 5: on the one epoch both cover ours
    is higher. f2: 20 against 20, equal counts as at most. f3: the radar covers nothing."""
    results = [
        _grid_result("tracker", "f1", [10.0, 50.0, None]),
        _grid_result(NAME, "f1", [None, 40.0, 5.0]),
        _grid_result("tracker", "f2", [20.0, 20.0]),
        _grid_result(NAME, "f2", [20.0, 20.0]),
        _grid_result("tracker", "f3", [1.0]),
        _grid_result(NAME, "f3", [None]),
    ]
    (c,) = against_radar_single(results)
    assert (c.profile, c.flights, c.at_most, c.epochs) == ("tracker", 2, 1, 3)
    assert c.mean_m == pytest.approx(30.0) and c.radar_mean_m == pytest.approx(80.0 / 3)
    assert [f.flight_id for f in c.above] == ["f1"]
    assert markdown_against_radar([c]).splitlines()[2:] == [
        "| tracker | f1 | 1 | 50.0 | 40.0 |",
        "| tracker | f2 | 2 | 20.0 | 20.0 |",
        "| tracker | f3 | 0 | - | - |",
    ]
    assert c.line() == (
        "tracker: mean error at most the radar's own track's on 1 of 2 flights (epochs both "
        "cover); pooled over 3 epochs 30.0 m against 26.7 m; above it: f1 50.0 (40.0)"
    )
    doc = c.as_dict()
    assert (doc["flights"], doc["at_most"], doc["epochs"]) == (2, 1, 3)
    per = doc["per_flight"]
    assert isinstance(per, dict)
    assert per["f3"] == {"epochs": 0, "mean_m": None, "radar_mean_m": None}
    json.dumps(doc, allow_nan=False)  # the summary JSON holds no NaN


def test_an_output_without_a_covariance_has_no_nees() -> None:
    """The baseline's NaN covariance gives NaN NEES per epoch, and the pool leaves it out."""
    err = np.array([[3.0, 0.0, 0.0], [0.0, 4.0, 0.0]])
    P = np.stack([np.eye(3) * 9.0, np.full((3, 3), math.nan)])
    ne = nees(err, P)
    assert ne[0] == pytest.approx(1.0) and math.isnan(ne[1])
    a = _grid_result("x", "f", [1.0, 2.0])
    with_nees = replace(a.samples, nees=np.array([1.0, math.nan]))
    score = pool_grid([with_nees])
    assert score.anees == 1.0 and score.nees_in95_pct == 100.0
    none = pool_grid([replace(a.samples, nees=np.array([math.nan, math.nan]))])
    assert math.isnan(none.anees) and math.isnan(none.nees_in95_pct)
