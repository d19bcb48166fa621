"""The live pipeline (uav_fusion.core.live.pipeline) without ROS: time order, duplicates,
future stamps, late runs and clock jumps back, with a recording estimator."""

from __future__ import annotations

import math
import subprocess
import sys
from typing import Any

import numpy as np

from uav_fusion.core.estimators.base import Input
from uav_fusion.core.estimators.grid import Outputs
from uav_fusion.core.estimators.steps import Step
from uav_fusion.core.live.pipeline import Pipeline, PipelineConfig
from uav_fusion.core.profiles.model import load_profile
from uav_fusion.core.records import (
    RADAR,
    RF,
    Flight,
    FloatArray,
    Measurement,
    RadarFrame,
    RadarTrack,
    RfAttempt,
)

T0 = 1.7e9


class Recorder:
    """An estimator that records what the pipeline hands it."""

    kind = "recorder"
    fixed_rate = False
    reads = "frames"

    def __init__(self) -> None:
        self.profile = load_profile("paper")
        self.counters: dict[str, int] = {}
        self.processed: list[tuple[str, float]] = []
        self.restarts: list[str] = []

    def radar_frame(self, frame: RadarFrame) -> Outputs:
        self.processed.extend((RADAR, trk.t) for trk in frame.tracks)
        return Outputs()

    def rf_attempt(self, attempt: RfAttempt) -> Outputs:
        self.processed.append((RF, attempt.t))
        return Outputs()

    def advance(self, t: float) -> Outputs:
        return Outputs()

    def finish(self) -> Outputs:
        return Outputs()

    def restart(self, reason: str) -> None:
        self.restarts.append(reason)

    def measurement(self, step: Step) -> tuple[FloatArray, FloatArray | None] | None:
        return None  # it makes no steps

    def status(self) -> dict[str, object]:
        return {}

    def flight_input(self, flight: Flight) -> list[Input]:
        raise NotImplementedError("the pipeline feeds it; it reads no flight")


class Sink:
    """The recording estimator and the warnings."""

    def __init__(self) -> None:
        self.est = Recorder()
        self.warnings: list[str] = []

    @property
    def processed(self) -> list[tuple[str, float]]:
        return self.est.processed

    @property
    def restarts(self) -> list[str]:
        return self.est.restarts


def radar(t: float, x: float = 1.0) -> RadarFrame:
    trk = RadarTrack(t, 1, math.nan, math.nan, math.nan, x, 2.0, 3.0, None, None, None, None)
    return RadarFrame(t, (trk,))


def rf(t: float, x: float = 1.0) -> RfAttempt:
    return RfAttempt(t, 1, True, math.nan, math.nan, x, 2.0, None, None, None)


def failed(t: float) -> RfAttempt:
    return RfAttempt(t, 1, False, math.nan, math.nan, math.nan, math.nan, None, None, None)


def make(**kw: Any) -> tuple[Pipeline, Sink]:
    """A pipeline with a reorder window (2 s unless given); ``kw``: PipelineConfig fields."""
    kw.setdefault("reorder_window_s", 2.0)
    sink = Sink()
    pipe = Pipeline(sink.est, PipelineConfig(**kw), sink.warnings.append)
    return pipe, sink


def test_no_rclpy_is_imported() -> None:
    code = (
        "import sys, uav_fusion.core.live.pipeline, uav_fusion.core.estimators; "
        "print(sorted(m for m in sys.modules if m.split('.')[0] in ('rclpy', 'rosidl_parser')))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


def test_in_order_streams_pass_through_in_time_order() -> None:
    pl, sink = make()
    for k in range(10):
        pl.radar(radar(T0 + k), None)
        pl.rf([rf(T0 + k + 0.5)], None)
    pl.flush()
    assert sink.processed == sorted(sink.processed, key=lambda p: p[1])
    assert len(sink.processed) == 20 and not pl.dropped and not sink.restarts


def test_duplicate_is_dropped_and_counted_once_warned() -> None:
    pl, sink = make()
    pl.radar(radar(T0), None)
    pl.radar(radar(T0), None)  # same stamp, same values
    pl.radar(radar(T0, 5.0), None)  # same stamp, another candidate: kept
    pl.rf([failed(T0 + 1)], None)
    pl.rf([failed(T0 + 1)], None)  # a repeated failed attempt
    pl.flush()
    assert pl.dropped == {"radar_duplicate": 1, "rf_duplicate": 1}
    assert sink.processed == [(RADAR, T0), (RADAR, T0)]
    assert pl.empty == {"rf_failed_attempt": 1}
    assert sum("repeats one already received" in w for w in sink.warnings) == 2


def test_duplicate_memory_is_bounded() -> None:
    pl, _ = make(duplicate_memory=3)
    for k in range(5):
        pl.rf([rf(T0 + k)], None)
    assert len(pl._seen[RF]) == 3


def test_lone_future_stamp_is_held_then_dropped() -> None:
    pl, sink = make(max_future_s=30.0)
    pl.radar(radar(T0), None)
    pl.radar(radar(T0 + 1000), None)  # a bad stamp: held
    assert pl.holding and pl.pending == 1
    pl.radar(radar(T0 + 1), None)  # the stream goes on: the held one was bad
    pl.flush()
    assert pl.dropped == {"radar_future": 1}
    assert not pl.holding
    assert sink.processed == [(RADAR, T0), (RADAR, T0 + 1)]


def test_future_stamp_confirmed_by_the_next_message_is_followed() -> None:
    pl, sink = make(max_future_s=30.0)
    pl.rf([rf(T0)], None)
    pl.rf([rf(T0 + 1000)], None)
    pl.rf([rf(T0 + 1001)], None)  # confirms the jump
    pl.flush()
    assert not pl.dropped
    assert [t for _, t in sink.processed] == [T0, T0 + 1000, T0 + 1001]
    assert any("following the jump" in w for w in sink.warnings)


def test_future_reference_is_the_simulated_clock_when_later() -> None:
    pl, _ = make(max_future_s=30.0)
    pl.radar(radar(T0), None)
    # 100 s ahead of the latest stamp but within 30 s of the simulated clock: not held
    pl.radar(radar(T0 + 100), T0 + 90)
    assert not pl.holding


def test_late_message_is_dropped_and_a_late_run_restarts_the_timeline() -> None:
    pl, sink = make(reorder_window_s=1.0, late_run_reset=5)
    for k in range(20):
        pl.radar(radar(T0 + k), None)
    n_before = len(sink.processed)
    pl.radar(radar(T0 + 2.5), None)  # behind what was released
    assert pl.dropped == {"late_radar": 1} and not sink.restarts
    for k in range(4):  # the input went back in time: four more late ones in a row
        pl.radar(radar(T0 + 3.5 + k), None)
    assert pl.timeline_resets == 1 and sink.restarts == ["timeline_back"]
    assert pl.dropped["late_radar"] == 5
    assert len(sink.processed) == 20 >= n_before  # the old timeline was finished
    # the new timeline accepts stamps earlier than the old one's
    pl.radar(radar(T0 + 1), None)
    pl.flush()
    assert sink.processed[-1] == (RADAR, T0 + 1)


def test_a_message_in_time_breaks_the_late_run() -> None:
    pl, sink = make(reorder_window_s=1.0, late_run_reset=3)
    for k in range(10):
        pl.radar(radar(T0 + k), None)
    for k in range(2):
        pl.radar(radar(T0 + 1.05 + 0.1 * k), None)  # late
    pl.radar(radar(T0 + 10), None)  # in time
    for k in range(2):
        pl.radar(radar(T0 + 2.05 + 0.1 * k), None)  # late again
    assert pl.timeline_resets == 0 and not sink.restarts
    assert pl.dropped == {"late_radar": 4}


def test_late_run_reset_zero_never_restarts() -> None:
    pl, sink = make(reorder_window_s=1.0, late_run_reset=0)
    for k in range(10):
        pl.radar(radar(T0 + k), None)
    for k in range(100):
        pl.radar(radar(T0 + 0.001 * (k + 1)), None)
    assert pl.timeline_resets == 0 and not sink.restarts and pl.dropped["late_radar"] == 100


def test_clock_jump_back_processes_the_old_timeline_and_restarts() -> None:
    pl, sink = make(reorder_window_s=5.0, clock_jump_back_s=1.0)
    pl.check_clock(T0)
    for k in range(3):
        pl.radar(radar(T0 + k), T0 + k)
        pl.check_clock(T0 + k)
    pl.radar(radar(T0 + 1000), T0 + 2)  # held as far ahead
    assert pl.pending > 0 and pl.holding
    pl.check_clock(T0 + 1.5)  # back 0.5 s: within clock_jump_back_s, nothing happens
    assert not sink.restarts
    pl.check_clock(T0 - 5.0)  # a bag loop
    assert pl.clock_jumps_back == 1 and sink.restarts == ["clock_jump_back"]
    assert [t for _, t in sink.processed] == [T0, T0 + 1, T0 + 2]
    assert pl.pending == 0 and not pl.holding and pl.dropped == {"radar_future": 1}
    # the loop repeats the same messages: they are new again, not duplicates or late
    pl.radar(radar(T0), T0 - 5.0)
    pl.flush()
    assert sink.processed[-1] == (RADAR, T0) and pl.dropped == {"radar_future": 1}
    assert any("jumped back" in w for w in sink.warnings)


def test_no_clock_means_no_jump_detection() -> None:
    pl, sink = make()
    pl.check_clock(None)
    pl.check_clock(T0)
    pl.check_clock(None)
    pl.check_clock(T0 + 1)
    assert pl.clock_jumps_back == 0 and not sink.restarts


def test_estimator_restart_timeline_forgets_time() -> None:
    from uav_fusion.core.estimators import FusionEstimator, load_profile
    from uav_fusion.core.site import load_site

    est = FusionEstimator(load_profile("paper"), load_site(None))
    site = est.site
    z = np.asarray(site.radar.enu, dtype=float) + np.array([50.0, 50.0, 50.0])
    est.process(Measurement(t=T0 + 10, source=RADAR, z=z, R=None))
    assert est.active and est.t == T0 + 10
    est.restart_timeline("clock_jump_back")
    assert not est.active and est.t is None and est.last_used_t is None
    assert est.counters.get("reinit_clock_jump_back") == 1
    steps = est.process(Measurement(t=T0, source=RADAR, z=z, R=None))  # earlier: accepted
    assert steps[0].reason != "out_of_order" and est.active


# --- zero wait --------------------------------------------------------------------------------
def zero_wait(**kw: Any) -> tuple[Pipeline, Sink]:
    sink = Sink()
    cfg = PipelineConfig(reorder_window_s=0.0, **kw)
    return Pipeline(sink.est, cfg, sink.warnings.append), sink


def recorder(pl: Pipeline) -> Recorder:
    """The pipeline's estimator (zero wait: the copy a rewind went back to)."""
    assert isinstance(pl.estimator, Recorder)
    return pl.estimator


def test_zero_wait_fuses_every_input_on_arrival() -> None:
    pl, _ = zero_wait()
    pl.radar(radar(T0))
    assert recorder(pl).processed == [(RADAR, T0)]
    pl.rf([rf(T0 + 0.5)])
    pl.radar(radar(T0 + 1))
    assert recorder(pl).processed == [(RADAR, T0), (RF, T0 + 0.5), (RADAR, T0 + 1)]
    assert pl.pending == 0 and not pl.dropped


def test_zero_wait_late_input_is_refiltered_in_order() -> None:
    pl, _ = zero_wait(max_lag_s=10.0)
    for k in range(8):
        pl.radar(radar(T0 + k))
    pl.rf([rf(T0 + 2.5)])  # 5.5 s late: the estimator goes back and fuses it in its place
    got = recorder(pl).processed
    want = sorted([(RADAR, T0 + k) for k in range(8)] + [(RF, T0 + 2.5)], key=lambda p: p[1])
    assert got == want and pl.rewinder is not None and pl.rewinder.rewinds == 1
    assert not pl.dropped


def test_zero_wait_input_beyond_max_lag_is_dropped_as_late_and_a_run_restarts() -> None:
    pl, sink = zero_wait(max_lag_s=2.0, late_run_reset=3)
    for k in range(10):
        pl.radar(radar(T0 + k))
    pl.rf([rf(T0 + 1.0)])  # 8 s behind: beyond the lag
    assert pl.dropped == {"late_rf": 1} and not sink.restarts
    pl.rf([rf(T0 + 1.5)])
    pl.rf([rf(T0 + 2.0)])  # three late in a row: the input's time went back
    assert pl.timeline_resets == 1 and sink.est.restarts == ["timeline_back"]
