"""The live timeline policy (uav_fusion.core.live.timeline) without ROS: duplicates, future stamps,
late runs and clock jumps back."""

from __future__ import annotations

import subprocess
import sys
from collections.abc import Sequence

import numpy as np

from uav_fusion.core.live.reorder import Batch
from uav_fusion.core.live.timeline import Timeline, TimelineConfig
from uav_fusion.core.records import RADAR, RF, Measurement

T0 = 1.7e9


class Sink:
    """Records what the timeline hands on."""

    def __init__(self) -> None:
        self.processed: list[tuple[str, float]] = []
        self.failed: list[tuple[str, float]] = []
        self.restarts: list[str] = []
        self.warnings: list[str] = []

    def process(self, batches: Sequence[Batch[Measurement]]) -> None:
        self.processed.extend((m.source, m.t) for b in batches for m in b.items)

    def failed_attempt(self, source: str, t: float) -> None:
        self.failed.append((source, t))

    def restart(self, reason: str) -> None:
        self.restarts.append(reason)

    def warn(self, text: str) -> None:
        self.warnings.append(text)


def radar(t: float, x: float = 1.0) -> Measurement:
    return Measurement(t=t, source=RADAR, z=np.array([x, 2.0, 3.0]), R=None)


def rf(t: float, x: float = 1.0) -> Measurement:
    return Measurement(t=t, source=RF, z=np.array([x, 2.0]), R=None)


def make(**kw: float) -> tuple[Timeline, Sink]:
    sink = Sink()
    return Timeline(TimelineConfig(**kw), sink), sink  # type: ignore[arg-type]


def test_no_rclpy_is_imported() -> None:
    code = (
        "import sys, uav_fusion.core.live.timeline, uav_fusion.core.estimators; "
        "print(sorted(m for m in sys.modules if m.split('.')[0] in ('rclpy', 'rosidl_parser')))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


def test_in_order_streams_pass_through_in_time_order() -> None:
    tl, sink = make()
    for k in range(10):
        tl.admit(RADAR, T0 + k, radar(T0 + k), None)
        tl.admit(RF, T0 + k + 0.5, rf(T0 + k + 0.5), None)
    tl.flush()
    assert sink.processed == sorted(sink.processed, key=lambda p: p[1])
    assert len(sink.processed) == 20 and not tl.dropped and not sink.restarts


def test_duplicate_is_dropped_and_counted_once_warned() -> None:
    tl, sink = make()
    tl.admit(RADAR, T0, radar(T0), None)
    tl.admit(RADAR, T0, radar(T0), None)  # same stamp, same values
    tl.admit(RADAR, T0, radar(T0, x=5.0), None)  # same stamp, another candidate: kept
    tl.admit(RF, T0 + 1, None, None)
    tl.admit(RF, T0 + 1, None, None)  # a repeated failed attempt
    tl.flush()
    assert tl.dropped == {"radar_duplicate": 1, "rf_duplicate": 1}
    assert sink.processed == [(RADAR, T0), (RADAR, T0)]
    assert sink.failed == [(RF, T0 + 1)]
    assert sum("repeats one already received" in w for w in sink.warnings) == 2


def test_duplicate_memory_is_bounded() -> None:
    tl, _ = make(duplicate_memory=3)
    for k in range(5):
        tl.admit(RF, T0 + k, rf(T0 + k), None)
    assert len(tl._seen[RF]) == 3


def test_lone_future_stamp_is_held_then_dropped() -> None:
    tl, sink = make(max_future_s=30.0)
    tl.admit(RADAR, T0, radar(T0), None)
    tl.admit(RADAR, T0 + 1000, radar(T0 + 1000), None)  # a bad stamp: held
    assert tl.holding and tl.pending == 1
    tl.admit(RADAR, T0 + 1, radar(T0 + 1), None)  # the stream goes on: the held one was bad
    tl.flush()
    assert tl.dropped == {"radar_future": 1}
    assert not tl.holding
    assert sink.processed == [(RADAR, T0), (RADAR, T0 + 1)]


def test_future_stamp_confirmed_by_the_next_message_is_followed() -> None:
    tl, sink = make(max_future_s=30.0)
    tl.admit(RF, T0, rf(T0), None)
    tl.admit(RF, T0 + 1000, rf(T0 + 1000), None)
    tl.admit(RF, T0 + 1001, rf(T0 + 1001), None)  # confirms the jump
    tl.flush()
    assert not tl.dropped
    assert [t for _, t in sink.processed] == [T0, T0 + 1000, T0 + 1001]
    assert any("following the jump" in w for w in sink.warnings)


def test_future_reference_is_the_simulated_clock_when_later() -> None:
    tl, _ = make(max_future_s=30.0)
    tl.admit(RADAR, T0, radar(T0), None)
    # 100 s ahead of the latest stamp but within 30 s of the simulated clock: not held
    tl.admit(RADAR, T0 + 100, radar(T0 + 100), T0 + 90)
    assert not tl.holding


def test_late_message_is_dropped_and_a_late_run_restarts_the_timeline() -> None:
    tl, sink = make(reorder_window_s=1.0, late_run_reset=5)
    for k in range(20):
        tl.admit(RADAR, T0 + k, radar(T0 + k), None)
    n_before = len(sink.processed)
    tl.admit(RADAR, T0 + 2.5, radar(T0 + 2.5), None)  # behind what was released
    assert tl.dropped == {"late_radar": 1} and not sink.restarts
    for k in range(4):  # the input went back in time: four more late ones in a row
        tl.admit(RADAR, T0 + 3.5 + k, radar(T0 + 3.5 + k), None)
    assert tl.timeline_resets == 1 and sink.restarts == ["timeline_back"]
    assert tl.dropped["late_radar"] == 5
    assert len(sink.processed) == 20 >= n_before  # the old timeline was finished
    # the new timeline accepts stamps earlier than the old one's
    tl.admit(RADAR, T0 + 1, radar(T0 + 1), None)
    tl.flush()
    assert sink.processed[-1] == (RADAR, T0 + 1)


def test_a_message_in_time_breaks_the_late_run() -> None:
    tl, sink = make(reorder_window_s=1.0, late_run_reset=3)
    for k in range(10):
        tl.admit(RADAR, T0 + k, radar(T0 + k), None)
    for k in range(2):
        tl.admit(RADAR, T0 + 1.05 + 0.1 * k, radar(T0 + 1.05 + 0.1 * k), None)  # late
    tl.admit(RADAR, T0 + 10, radar(T0 + 10), None)  # in time
    for k in range(2):
        tl.admit(RADAR, T0 + 2.05 + 0.1 * k, radar(T0 + 2.05 + 0.1 * k), None)  # late again
    assert tl.timeline_resets == 0 and not sink.restarts
    assert tl.dropped == {"late_radar": 4}


def test_late_run_reset_zero_never_restarts() -> None:
    tl, sink = make(reorder_window_s=1.0, late_run_reset=0)
    for k in range(10):
        tl.admit(RADAR, T0 + k, radar(T0 + k), None)
    for k in range(100):
        tl.admit(RADAR, T0 + 0.001 * (k + 1), radar(T0 + 0.001 * (k + 1)), None)
    assert tl.timeline_resets == 0 and not sink.restarts and tl.dropped["late_radar"] == 100


def test_clock_jump_back_processes_the_old_timeline_and_restarts() -> None:
    tl, sink = make(reorder_window_s=5.0, clock_jump_back_s=1.0)
    tl.check_clock(T0)
    for k in range(3):
        tl.admit(RADAR, T0 + k, radar(T0 + k), T0 + k)
        tl.check_clock(T0 + k)
    tl.admit(RADAR, T0 + 1000, radar(T0 + 1000), T0 + 2)  # held as far ahead
    assert tl.pending > 0 and tl.holding
    tl.check_clock(T0 + 1.5)  # back 0.5 s: within clock_jump_back_s, nothing happens
    assert not sink.restarts
    tl.check_clock(T0 - 5.0)  # a bag loop
    assert tl.clock_jumps_back == 1 and sink.restarts == ["clock_jump_back"]
    assert [t for _, t in sink.processed] == [T0, T0 + 1, T0 + 2]
    assert tl.pending == 0 and not tl.holding and tl.dropped == {"radar_future": 1}
    # the loop repeats the same messages: they are new again, not duplicates or late
    tl.admit(RADAR, T0, radar(T0), T0 - 5.0)
    tl.flush()
    assert sink.processed[-1] == (RADAR, T0) and tl.dropped == {"radar_future": 1}
    assert any("jumped back" in w for w in sink.warnings)


def test_no_clock_means_no_jump_detection() -> None:
    tl, sink = make()
    tl.check_clock(None)
    tl.check_clock(T0)
    tl.check_clock(None)
    tl.check_clock(T0 + 1)
    assert tl.clock_jumps_back == 0 and not sink.restarts


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
