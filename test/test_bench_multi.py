"""The multi-UAV benchmark: definition, per-flight task, crossings, pooled figures, command."""

from __future__ import annotations

import csv
import json
import math
import pickle
from pathlib import Path

import numpy as np
import pytest
import yaml

from uav_fusion.cli import main
from uav_fusion.core.bench.cache import cached_flights
from uav_fusion.core.bench.definition import load_definition
from uav_fusion.core.bench.multi import (
    Crossing,
    MultiFlightResult,
    MultiScoreTask,
    UavOutcome,
    crossing_switches,
    crossings,
    multi_score_task,
    pool_multi,
)
from uav_fusion.core.bench.single import GenerateTask, generate_task
from uav_fusion.core.data import load_flight
from uav_fusion.core.errors import ConfigError
from uav_fusion.core.estimators import load_profile
from uav_fusion.core.estimators.multi import MultiTracker, run_multi
from uav_fusion.core.estimators.selection import frames_input
from uav_fusion.core.records import Flight, TruthFix
from uav_fusion.core.scoring.gospa import (
    EpochTracks,
    MultiScoreSettings,
    PublishedTrack,
    UavTruth,
    pool,
    score_flight,
)
from uav_fusion.core.site import load_site
from uav_fusion.resources import DEFAULT_SITE, config_path

SITE_FILE = config_path(DEFAULT_SITE)


def _def(tmp: Path, **changes: object) -> Path:
    doc: dict[str, object] = {
        "name": "multi_small",
        "targets": "multi",
        "plans": ["multi_crossing_pair"],
        "splits": {"tune": [3], "test": [4]},
        "duration_s": 200.0,
    }
    doc.update(changes)
    p = tmp / "multi_small.yaml"
    p.write_text(yaml.safe_dump(doc), encoding="utf-8")
    return p


def test_the_shipped_multi_definition() -> None:
    d = load_definition("multi")
    assert d.multi and d.grid_hz == 1.0
    assert len(d.flights("tune")) == len(d.flights("test")) == 6
    assert not {f.seed for f in d.flights("tune")} & {f.seed for f in d.flights("test")}


def test_an_unknown_targets_kind_is_refused(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match=r"multi_small\.yaml: targets must be one of"):
        load_definition(_def(tmp_path, targets="many"))


def _fixes(t: np.ndarray, e: np.ndarray, n: np.ndarray, u: np.ndarray) -> list[TruthFix]:
    return [
        TruthFix(float(a), 0.0, 0.0, 0.0, float(b), float(c), float(d), (0.0, 0.0, 0.0), 6, 18)
        for a, b, c, d in zip(t, e, n, u, strict=True)
    ]


def test_crossings_are_closest_approaches_of_airborne_uavs() -> None:
    t = np.arange(0.0, 200.0, 0.2)
    up = np.where(t > 10.0, 40.0, 0.0)  # both on the ground for 10 s
    # uav1 flies east along n = 0, uav2 north along e = 0: they meet at t = 100 s, 8 m apart
    # vertically; later uav2 turns back and passes again 150 m away (no crossing)
    a = _fixes(t, 10.0 * (t - 100.0), 0.0 * t, up)
    b = _fixes(t, 0.0 * t + 0.0, 10.0 * (t - 100.0), up + 8.0 * (t > 10.0))
    flight = Flight("x", a, [], [], vehicles={"uav1": a, "uav2": b})
    got = crossings(flight)
    assert len(got) == 1
    name_a, name_b, when, t_close, t_apart = got[0]
    assert (name_a, name_b) == ("uav1", "uav2") and when == pytest.approx(100.0, abs=0.5)
    # closer than 100 m while 200 (t - 100)^2 + 64 < 100^2: |t - 100| < 7.05 s
    assert t_close == pytest.approx(93.0, abs=0.3) and t_apart == pytest.approx(107.0, abs=0.3)
    far = _fixes(t, 0.0 * t + 150.0, 10.0 * (t - 100.0), up)
    assert crossings(Flight("x", a, [], [], vehicles={"uav1": a, "uav2": far})) == []


def test_id_switches_are_attributed_to_the_crossing_they_happen_at() -> None:
    """Two UAVs 10 m apart (north) fly head-on and pass at t0 + 20 s; their two tracks swap
    UAVs there (each follows the other UAV from then on), and at t0 + 60 s "a"'s track is
    replaced by a new one. The swap is two switches at the crossing (one per UAV; on GOSPA's
    assignment at the pass, on the kept correspondence once the tracks are 100 m from their
    old UAVs), the replacement one switch near no crossing."""
    t0 = 1_760_000_000.0
    t = t0 + np.arange(0.0, 80.5, 0.5)
    ea = -200.0 + 10.0 * (t - t0)
    up = np.where(t - t0 >= 0.5, 50.0, 0.0)  # airborne (5 m above the first sample) from 1 s
    truths = {
        "a": UavTruth(t, np.column_stack([ea, np.zeros(t.size), up])),
        "b": UavTruth(t, np.column_stack([-ea, np.full(t.size, 10.0), up])),
    }
    epochs = []
    for k in range(81):
        pa = np.array([-200.0 + 10.0 * k, 0.0, 50.0])
        pb = np.array([200.0 - 10.0 * k, 10.0, 50.0])
        on_a, on_b = (1, 2) if k < 20 else (2, 1)
        if k >= 60:
            on_a = 3
        epochs.append(
            EpochTracks(
                t0 + k,
                (PublishedTrack(on_a, np.r_[pa, 0.0, 0.0, 0.0]),
                 PublishedTrack(on_b, np.r_[pb, 0.0, 0.0, 0.0])),
            )
        )  # fmt: skip
    samples = score_flight(truths, epochs)
    res = MultiFlightResult(
        flight_id="pass", plan="pass", seed=0, split="test", profile="tracker",
        samples=samples, uavs=(UavOutcome("a", False, 0, 0), UavOutcome("b", True, 0, 0)),
        crossings=(Crossing("a", "b", t0 + 20.0, t0 + 15.0, t0 + 25.0),), flight_s=81.0,
        run_s=0.0,
    )  # fmt: skip
    ua, ub = samples.uavs
    assert (ua.switch_times - t0).tolist() == [20.0, 60.0]
    assert (ub.switch_times - t0).tolist() == [20.0]
    assert [x - t0 for x in ua.switch_times_kept.tolist()][-1] == 60.0
    assert 20.0 < ub.switch_times_kept[0] - t0 <= 26.0
    assert crossing_switches(res, kept=False) == ([2], 1)
    assert crossing_switches(res, kept=True) == ([2], 1)
    # the same switches with the crossing elsewhere in time (or of other UAVs) are away ...
    def with_crossing(c: Crossing) -> MultiFlightResult:
        return MultiFlightResult(**{**res.__dict__, "crossings": (c,)})

    far = with_crossing(Crossing("a", "b", t0 + 45.0, t0 + 44.0, t0 + 46.0))
    assert crossing_switches(far, kept=False) == ([0], 3)
    other = with_crossing(Crossing("a", "c", t0 + 20.0, t0 + 15.0, t0 + 25.0))
    assert crossing_switches(other, kept=False) == ([1], 2)
    # ... and a switch counts for a crossing whose span (UAVs within 100 m) reaches it, however
    # long before the closest approach was
    late = with_crossing(Crossing("a", "b", t0 + 0.0, t0 - 5.0, t0 + 18.0))
    assert crossing_switches(late, kept=False) == ([2], 1)
    sc = pool_multi([res])["tracker"]
    assert (sc.crossings, sc.crossings_over_one, sc.crossings_over_one_kept) == (1, 1, 1)
    assert (sc.id_switches, sc.id_switches_kept) == (3, 3)


@pytest.fixture(scope="module")
def small(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    tmp = tmp_path_factory.mktemp("multi")
    d = _def(tmp)
    cache = tmp / "cache"
    cf = cached_flights(load_definition(d), "test", cache, SITE_FILE)[0]
    assert generate_task(GenerateTask(cf, load_definition(d), load_site())) is True
    return d, cache


def test_the_task_scores_the_flight_as_run_multi_and_score_flight_do(
    small: tuple[Path, Path],
) -> None:
    d_path, cache = small
    d = load_definition(d_path)
    site = load_site()
    cf = cached_flights(d, "test", cache, SITE_FILE)[0]
    profile = load_profile("tracker")
    task = MultiScoreTask(cf, profile, site, d.grid_hz, 5.0, 2.0)
    res = pickle.loads(pickle.dumps(multi_score_task(pickle.loads(pickle.dumps(task)))))
    # the same by hand
    flight = load_flight(cf.folder, site)
    truths = {v: UavTruth(*flight.truth_arrays(v)) for v in flight.vehicles}
    t0 = min(float(x.t[0]) for x in truths.values())
    t1 = max(float(x.t[-1]) for x in truths.values())
    epochs = run_multi(MultiTracker(profile, site), list(frames_input(flight, profile)), 1.0,
                       t0, t1)  # fmt: skip
    ref = score_flight(truths, epochs, MultiScoreSettings())
    assert np.array_equal(res.samples.distance, ref.distance)
    assert [u.track_ids for u in res.samples.uavs] == [u.track_ids for u in ref.uavs]
    # uav2 is the silent one; both UAVs are seen by the radar, so both have observable epochs
    assert [(u.name, u.silent) for u in res.uavs] == [("uav1", False), ("uav2", True)]
    for u, s in zip(res.uavs, res.samples.uavs, strict=True):
        assert 0 < u.observable <= s.epochs
        assert u.observable_covered <= min(u.observable, s.assigned)
    assert res.flight_s == pytest.approx(ref.epochs * 1.0)
    pooled = pool_multi([res])["tracker"]
    sc = pool([ref])
    assert pooled.gospa_mean_m == pytest.approx(sc.gospa_mean_m)
    assert pooled.false_track_pct == pytest.approx(100.0 * sc.false_track_s / ref.epochs)
    assert pooled.worst_uav_coverage_pct == pytest.approx(min(u.coverage_pct for u in sc.uavs))
    assert math.isfinite(pooled.silent_observable_coverage_pct)
    # GOSPA's parts: the assigned pairs alone, and the shares of the summed squares
    assert pooled.gospa_localisation_m == pytest.approx(float(np.mean(np.sqrt(ref.localisation))))
    assert pooled.gospa_localisation_m <= pooled.gospa_mean_m
    total = float(np.sum(ref.distance**2))
    assert pooled.gospa_missed_share_pct == pytest.approx(100.0 * float(np.sum(ref.missed)) / total)
    assert pooled.gospa_false_share_pct == pytest.approx(100.0 * float(np.sum(ref.false)) / total)
    loc_share = 100.0 * float(np.sum(ref.localisation)) / total
    assert loc_share + pooled.gospa_missed_share_pct + pooled.gospa_false_share_pct == (
        pytest.approx(100.0)
    )


def test_the_bench_command_runs_the_multi_part(small: tuple[Path, Path], tmp_path: Path) -> None:
    d_path, cache = small
    out = tmp_path / "out"
    argv = ["bench", "--definition", str(d_path), "--profiles", "tracker", "--split", "test",
            "--cache", str(cache), "--out", str(out), "--threads", "--workers", "1"]  # fmt: skip
    assert main(argv) == 0
    doc = json.loads((out / "summary.json").read_text(encoding="utf-8"))
    sc = doc["profiles"]["tracker"]
    assert sc["flights"] == 1 and 0.0 < sc["coverage_pct"] <= 100.0
    # the radar's own tracks, passed through, are scored beside the profile
    assert doc["profiles"]["radar"]["flights"] == 1
    with (out / "per_flight_multi.csv").open(newline="", encoding="utf-8") as fh:
        rows = list(csv.DictReader(fh))
    assert [(r["profile"], r["uav"], r["silent"]) for r in rows] == [
        ("tracker", "uav1", "0"), ("tracker", "uav2", "1"),
        ("radar", "uav1", "0"), ("radar", "uav2", "1"),
    ]  # fmt: skip
    assert (out / "bench_multi.png").stat().st_size > 10_000
    table = (out / "table.md").read_text(encoding="utf-8")
    assert "| tracker | 1 |" in table and "| radar | 1 |" in table


def test_the_multi_part_needs_a_tracker_profile(small: tuple[Path, Path], tmp_path: Path) -> None:
    d_path, cache = small
    out = str(tmp_path / "o")
    argv = ["bench", "--definition", str(d_path), "--profiles", "paper", "--split", "test",
            "--cache", str(cache), "--out", out, "--threads", "--workers", "1"]  # fmt: skip
    assert main(argv) == 2
