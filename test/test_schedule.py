"""Arrival schedules (uav_fusion.core.live.schedule) and ``uav_fusion run`` in live arrival
order: the offline run of a schedule reproduces the zero-wait pipeline, bad input is named."""

from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np
import pytest

from uav_fusion.cli import main
from uav_fusion.core.data import load_flight
from uav_fusion.core.errors import ConfigError, DataError
from uav_fusion.core.estimators import load_profile, make_estimator
from uav_fusion.core.estimators.base import Estimator, Input
from uav_fusion.core.live.rewind import simulate
from uav_fusion.core.live.schedule import (
    Arrival,
    delayed,
    parse_delay,
    read_schedule,
    write_schedule,
)
from uav_fusion.core.records import RADAR, RF
from uav_fusion.core.site import load_site
from uav_fusion.resources import DEFAULT_FLIGHT, data_path


@pytest.fixture(scope="module")
def items() -> list[Input]:
    site = load_site(None)
    flight = load_flight(data_path(DEFAULT_FLIGHT), site)
    est = make_estimator(load_profile("tracker"), site, live=True)
    return [it for it in est.flight_input(flight) if it.t < flight.radar[0].t + 200.0]


def test_parse_delay_reads_mean_and_jitter_and_names_bad_ones() -> None:
    assert parse_delay("rf=3+-1") == (RF, 3.0, 1.0)
    assert parse_delay("radar=0.25") == (RADAR, 0.25, 0.0)
    for bad in ("rf=x", "lidar=1", "rf=-1", "rf=1+-nan"):
        with pytest.raises(ConfigError, match="--delay"):
            parse_delay(bad)


def test_delayed_keeps_each_source_in_its_order_and_reorders_across(items: list[Input]) -> None:
    arr = delayed(items, {RF: (3.0, 1.0)}, seed=4)
    assert sorted(id(it) for _, it in arr) == sorted(id(it) for it in items)
    for src in (RADAR, RF):
        ts = [it.t for s, it in arr if s == src]
        assert ts == sorted(ts)
    assert [it for _, it in arr] != items


def test_a_written_schedule_reads_back_in_arrival_order(items: list[Input], tmp_path: Path) -> None:
    arr = delayed(items, {RF: (2.0, 0.5)}, seed=1)
    rows = [(src, it.t, n * 0.1) for n, (src, it) in enumerate(arr)]
    path = write_schedule(tmp_path / "arrivals.csv", reversed(rows))  # file order does not count
    back = read_schedule(path, items)
    assert [id(it) for _, it in back] == [id(it) for _, it in arr]


def test_schedule_errors_name_the_file_and_line(items: list[Input], tmp_path: Path) -> None:
    p = tmp_path / "s.csv"
    p.write_text("source,stamp,arrival\nrf,1.5,2.0\n", encoding="utf-8")
    with pytest.raises(DataError, match=r"s\.csv.*2.*no rf input"):
        read_schedule(p, items)
    p.write_text("src,t\n", encoding="utf-8")
    with pytest.raises(DataError, match="header"):
        read_schedule(p, items)
    p.write_text(f"source,stamp,arrival\nradar,{items[0].t!r},abc\n", encoding="utf-8")
    with pytest.raises(DataError, match="numbers"):
        read_schedule(p, items)


def test_run_with_delays_reports_an_exact_final_track_and_what_was_published(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    pub = tmp_path / "published.csv"
    assert main(["run", "--profile", "tracker", "--delay", "rf=3+-1", "--seed", "2",
                 "--published", str(pub), "--out", str(tmp_path / "steps.csv")]) == 0  # fmt: skip
    out = capsys.readouterr().out
    assert "rewinds" in out and "the final track equals the in-order run" in out
    with pub.open(encoding="utf-8") as fh:
        rows = list(csv.DictReader(fh))
    assert {r["topic"] for r in rows} == {"steps", "grid"}
    arrivals = [int(r["arrival"]) for r in rows]
    assert arrivals == sorted(arrivals)
    assert all(math.isfinite(float(r["x"])) for r in rows if r["topic"] == "grid")


def test_run_rejects_a_bad_delay(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["run", "--profile", "tracker", "--delay", "rf=soon"]) == 2
    assert "--delay 'rf=soon'" in capsys.readouterr().err


def test_simulated_schedule_equals_feeding_a_pipeline_message_by_message(
    items: list[Input],
) -> None:
    from uav_fusion.core.live.pipeline import Pipeline, PipelineConfig
    from uav_fusion.core.records import RadarFrame, RfAttempt

    site = load_site(None)
    prof = load_profile("tracker")
    arr = delayed(items, {RF: (3.0, 1.0)}, seed=9)
    outs, _, _ = simulate(lambda: make_estimator(prof, site, 10.0, live=True), arr)
    pipe = Pipeline(make_estimator(prof, site, 10.0, live=True), PipelineConfig())
    got = []
    for _src, it in arr:
        if isinstance(it, RadarFrame):
            got.append(pipe.radar(it))
        else:
            assert isinstance(it, RfAttempt)  # delayed() schedules the inputs only
            got.append(pipe.rf([it]))
    got.append(pipe.flush())
    key = [(s.t, s.status, repr(s.values)) for o in outs for s in o.steps]
    assert key == [(s.t, s.status, repr(s.values)) for o in got for s in o.steps]
    assert [g.k for o in outs for g in o.grid] == [g.k for o in got for g in o.grid]


def test_the_nodes_arrival_log_has_one_row_per_radar_frame(
    items: list[Input], tmp_path: Path
) -> None:
    from uav_fusion.ros.fusion_input import ArrivalLog

    # the paper's radar/pose brings a frame's candidates one message each, back to back
    log = ArrivalLog(tmp_path / "arrivals.csv")
    for it in items:
        src = RADAR if not hasattr(it, "ok") else RF
        for _ in range(3 if src == RADAR else 1):
            log.add(src, it.t)
    log.close()
    assert log.rows == len(items)
    back = read_schedule(log.path, items)
    assert [id(it) for _, it in back] == [id(it) for it in items]


def test_a_clock_row_publishes_epochs_before_a_late_input(
    items: list[Input], tmp_path: Path
) -> None:
    """An RF fix arrives 0.3 s late, after the node's clock moved the output past its stamp:
    the epochs up to the clock's time are published from the track without the fix (what a
    live node did), and differ from those an in-order run publishes after the fix."""
    from uav_fusion.core.live.schedule import CLOCK, ClockTick

    site = load_site(None)
    prof = load_profile("tracker")

    def make() -> Estimator:
        return make_estimator(prof, site, 10.0, live=True)

    steps = simulate(make, [(RADAR if not hasattr(it, "ok") else RF, it) for it in items])[1].steps
    used = [s for s in steps if s.source == RF and s.status == "updated" and s.t > items[0].t + 60]
    fix = next(it for it in items if hasattr(it, "ok") and it.t == used[0].t)
    k = items.index(fix)
    tick = ClockTick(fix.t + 0.3)
    later = [(RADAR if not hasattr(it, "ok") else RF, it) for it in items[k + 1 :]]
    before = [(RADAR if not hasattr(it, "ok") else RF, it) for it in items[:k]]
    late = [x for x in later if x[1].t <= tick.t]
    rest = [x for x in later if x[1].t > tick.t]
    live = [*before, *late, (CLOCK, tick), (RF, fix), *rest]
    in_order: list[Arrival] = [*before, (RF, fix), *late, *rest]
    outs, _, _ = simulate(make, live)
    at_tick = outs[len(before) + len(late)].grid
    assert at_tick and all(fix.t < g.t <= tick.t for g in at_tick)
    ref = {g.k: g.x for o in simulate(make, in_order)[0] for g in o.grid}
    assert any(not np.allclose(g.x, ref[g.k]) for g in at_tick)
    # the schedule file carries the clock's row, and reads back in place
    rows = [(s, x.t, n * 0.01) for n, (s, x) in enumerate(live)]
    back = read_schedule(write_schedule(tmp_path / "a.csv", rows), items)
    assert [type(x).__name__ for _, x in back] == [type(x).__name__ for _, x in live]
    assert back[len(before) + len(late)] == (CLOCK, tick)


def test_the_sensor_clock_runs_ahead_by_the_quickest_inputs_lead() -> None:
    from uav_fusion.core.live.sensor_clock import SensorClock

    clock = SensorClock(window=3)
    assert not clock.known and clock.at(100.0) == 100.0  # nothing seen: the node's clock
    # sensors 50 s ahead of the host; inputs 0.4, 0.1 and 2.0 s late
    for stamp, node in ((1050.0, 1000.4), (1051.0, 1001.1), (1052.0, 1004.0)):
        clock.observe(stamp, node)
    assert clock.known
    assert clock.at(1010.0) == pytest.approx(1010.0 + 49.9)  # the quickest input's lead
    clock.observe(1060.0, 1013.0)  # two more: the 0.4 s and 0.1 s inputs leave the window
    clock.observe(1061.0, 1013.5)
    assert clock.at(1020.0) == pytest.approx(1020.0 + 48.0)  # the 2.0 s input's lead now
