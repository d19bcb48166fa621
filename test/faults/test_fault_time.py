"""Fault cases, area "time": the simulated clock jumping back (bag loop), jumping ahead,
stalling, and not running at all yet."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from faultkit import (
    RADAR,
    RF,
    T0,
    EvaluatorHarness,
    FusionHarness,
    accounting,
    radar_msg,
    rf_msg,
    straight,
)
from rclpy.context import Context

from uav_fusion.core.site import load_site
from uav_fusion.ros import conversions as cv


def radar_track(t_from: float, t_to: float, dt: float = 0.25) -> list[object]:
    return [radar_msg(float(t), *straight(float(t))) for t in np.arange(t_from, t_to, dt)]


@pytest.mark.fault("TIME-01")
def test_clock_jump_back_resets_the_filter_and_says_so(
    ctx: Context, capfd: pytest.CaptureFixture[str]
) -> None:
    """A bag loop: the clock and the stamps start again from the beginning. The buffered
    end of the first pass is processed, the filter and reorder buffer are reset, a warning
    is logged and counted, and the second pass is fused like the first."""
    h = FusionHarness(ctx, use_sim_time=True)
    first = radar_track(T0, T0 + 10.0)
    for k in range(0, len(first), 4):
        h.clock(T0 + 0.25 * k)
        h.send(*first[k : k + 4])
    h.spin_until(lambda: h.fusion.steps_published >= 30)
    pass1 = h.fusion.steps_published
    h.clock(T0)  # loop: back to the start
    h.spin_until(lambda: h.fusion.pipeline.clock_jumps_back == 1)
    assert h.fusion.pipeline.buffer.pending == 0
    assert h.fusion.steps_published == 40  # the held end of pass 1 was processed, not lost
    assert pass1 <= 40
    second = radar_track(T0, T0 + 10.0)
    for k in range(0, len(second), 4):
        h.clock(T0 + 0.25 * k)
        h.send(*second[k : k + 4])
    h.settle()
    d = h.diagnostics()
    assert d["clock_jumps_back"] == "1"
    assert d["estimator_reinit_clock_jump_back"] == "1"
    assert d["steps_reset"] == "1"  # the second pass starts a new track, flagged as a reset
    assert int(d["used_radar"]) == 80 and not h.fusion.dropped
    err = capfd.readouterr().err
    assert "simulated clock jumped back 9.000 s" in err and "reset the filter" in err
    h.destroy()


@pytest.mark.fault("TIME-02")
def test_clock_jump_back_restarts_the_evaluation_with_a_report(
    ctx: Context, tmp_path: Path
) -> None:
    from sensor_msgs.msg import NavSatFix

    site = load_site()
    h = EvaluatorHarness(ctx, use_sim_time=True, output_dir=str(tmp_path / "rep"))

    def truth(t: float) -> NavSatFix:
        lat, lon, alt = site.to_geodetic(*straight(t))
        m = NavSatFix()
        m.header.stamp = cv.stamp_from_time(t)
        m.header.frame_id = "gps"
        m.status.status = 2
        m.latitude, m.longitude, m.altitude = float(lat), float(lon), float(alt)
        return m

    for t in np.arange(T0, T0 + 10.0, 1.0):
        h.clock(float(t))
        h.send("truth", truth(float(t)))
        h.send("radar_raw", radar_msg(float(t), *straight(float(t))))
    assert h.node.evaluate().radar_reports == 10
    h.clock(T0)  # bag loop
    h.spin_until(lambda: h.node.clock_jumps_back == 1)
    before = tmp_path / "rep" / "before_clock_jump_1"
    assert (before / "report.md").is_file()
    assert "Radar raw" in (before / "report.md").read_text()
    h.send("radar_raw", radar_msg(T0, *straight(T0)))
    ev = h.node.evaluate()
    assert ev.radar_reports == 1  # only the new pass
    files = h.node.write_report()
    assert "clock jumps back" in files.markdown.read_text()
    h.destroy()


@pytest.mark.fault("TIME-03")
def test_clock_jump_forward_releases_the_buffer_without_reset(ctx: Context) -> None:
    h = FusionHarness(ctx, use_sim_time=True, reorder_window_s=2.0)
    h.clock(T0)
    h.send(*radar_track(T0, T0 + 2.0))
    assert h.fusion.pipeline.buffer.pending > 0  # waiting for the RF stream
    h.clock(T0 + 3600.0)  # the player skipped an hour
    h.send(rf_msg(T0 + 3600.5, 300.0, 0.0))
    h.spin_until(lambda: h.fusion.steps_published >= 8)
    d = h.diagnostics()
    assert d["clock_jumps_back"] == "0" and "steps_reset" not in d
    assert not h.fusion.dropped
    h.destroy()


@pytest.mark.fault("TIME-04")
def test_stalled_clock_does_not_stop_fusion(ctx: Context) -> None:
    """The clock stops at T0 + 1 s while data keep coming for 60 s (beyond max_future_s of
    the stalled clock): the streams' own progress releases everything, nothing is dropped."""
    h = FusionHarness(ctx, use_sim_time=True, max_future_s=30.0)
    h.clock(T0 + 1.0)
    msgs = radar_track(T0, T0 + 60.0, dt=0.5)
    rfs = [rf_msg(T0 + 0.1 + 4.0 * k, *straight(T0 + 4.0 * k)[:2]) for k in range(15)]
    for k in range(15):
        h.send(*msgs[8 * k : 8 * k + 8], rfs[k])
    h.send(*msgs[120:])
    h.settle()
    d = h.diagnostics()
    assert not h.fusion.dropped, h.fusion.dropped
    for src, n in ((RADAR, 120), (RF, 15)):
        rec, used, rej, drop = accounting(d, src)
        assert rec == n == used + rej + drop
    assert int(d["used_radar"]) == 120
    h.destroy()


@pytest.mark.fault("TIME-05")
def test_sim_time_zero_before_the_first_clock_message(ctx: Context) -> None:
    """use_sim_time but no /clock yet (now() is 0): fusion runs on the streams alone and the
    idle flush (wall time) still empties the buffer at the end."""
    h = FusionHarness(ctx, use_sim_time=True, idle_flush_s=0.3)
    assert h.fusion.get_clock().now().nanoseconds == 0
    h.send(*radar_track(T0, T0 + 3.0))
    h.spin_until(lambda: h.fusion.steps_published == 12, limit_s=20.0)
    assert h.fusion.pipeline.buffer.pending == 0 and not h.fusion.dropped
    assert h.fusion.diagnostics()["used_radar"] == "12"
    h.destroy()


@pytest.mark.fault("TIME-06")
def test_timeline_going_back_without_a_clock_resets_after_a_run_of_stale_messages(
    ctx: Context, capfd: pytest.CaptureFixture[str]
) -> None:
    """A bag looped without /clock: the second pass repeats the first. The first
    ``late_run_reset`` messages of the repeat are dropped (counted as duplicates), then the
    node concludes the timeline went back, resets and fuses the rest of the repeat."""
    h = FusionHarness(ctx, late_run_reset=10)
    msgs = radar_track(T0, T0 + 10.0)
    for k in range(0, 40, 4):
        h.send(*msgs[k : k + 4])
    h.settle()
    for k in range(0, 40, 4):
        h.send(*msgs[k : k + 4])
    h.settle()
    d = h.diagnostics()
    assert d["timeline_resets"] == "1" and d["estimator_reinit_timeline_back"] == "1"
    assert h.fusion.dropped == {"radar_duplicate": 10}
    assert int(d["used_radar"]) == 40 + 30
    assert "the input timeline went back" in capfd.readouterr().err
    rec, used, rej, drop = accounting(d, RADAR)
    assert rec == used + rej + drop == 80
    h.destroy()
