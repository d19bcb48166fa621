"""scripts/single_oracle.py: the epochs where the radar itself had the UAV far off."""

from __future__ import annotations

from types import ModuleType

import numpy as np
import pytest
from script_util import load_script

from uav_fusion.core.records import RadarFrame, RadarTrack
from uav_fusion.core.twin import radar_model


@pytest.fixture(scope="module")
def so() -> ModuleType:
    return load_script("single_oracle")


def test_an_epoch_is_sensor_bound_when_its_recent_reports_are_far_off(so: ModuleType) -> None:
    rep_t = np.array([0.0, 1.0, 2.0, 3.0, 4.0, 10.0])
    rep_err = np.array([20.0, 150.0, 160.0, 170.0, 30.0, 500.0])
    epochs = np.array([-1.0, 0.5, 3.0, 4.0, 8.0, 9.5, 10.0, 16.0])
    off = so.sensor_off(epochs, rep_t, rep_err, 5.0, 100.0)
    # windows [t - 5, t]: -1 none; 0.5 [20]; 3 [20 150 160 170] -> 155; 4 [.. 30] -> 150;
    # 8 [170 30] -> 100, not above; 9.5 none; 10 [500]; 16 none
    assert off.tolist() == [False, False, True, True, False, False, True, False]


def test_only_reports_of_tracks_following_the_uav_are_read(so: ModuleType) -> None:
    uav = radar_model.uav_object_id(0)
    kinds = {
        1: (np.array([0.0, 2.0]), [(radar_model.UAV, uav), (radar_model.BIRD, 9)]),
        2: (np.array([0.0]), [(radar_model.UAV, radar_model.uav_object_id(1))]),
    }

    def rep(t: float, tid: int, e: float) -> RadarTrack:
        return RadarTrack(t, tid, 0.0, 0.0, 0.0, e, 0.0, 50.0, None, 0.8, None, -10.0)

    stream = [RadarFrame(t, (rep(t, 1, 30.0 * t), rep(t, 2, 999.0))) for t in (0.0, 1.0, 2.0)]
    truth_t = np.array([0.0, 10.0])
    truth_enu = np.array([[0.0, 0.0, 50.0], [100.0, 0.0, 50.0]])  # east at 10 m/s
    ts, errs = so.uav_report_errors(stream, kinds, uav, truth_t, truth_enu, None)
    # track 1 follows the UAV until t = 2 (then a bird); track 2 is another UAV
    assert ts.tolist() == [0.0, 1.0]
    assert errs.tolist() == pytest.approx([0.0, 20.0])
    shifted = so.uav_report_errors(
        stream, kinds, uav, truth_t, truth_enu, lambda e, n, u: (e - 20.0, n, u)
    )
    assert shifted[1].tolist() == pytest.approx([20.0, 0.0])
