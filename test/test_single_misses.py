"""The causes scripts/single_misses.py gives the single-UAV tracker's misses: observable
epochs with nothing published, and gross ones."""

from __future__ import annotations

from types import ModuleType

import numpy as np
import pytest
from script_util import load_script


@pytest.fixture(scope="module")
def sm() -> ModuleType:
    return load_script("single_misses")


def test_uncovered_epochs_are_start_up_re_entry_or_other(sm: ModuleType) -> None:
    t = np.arange(0.0, 40.0, 1.0)
    obs = np.ones(t.size, dtype=bool)
    obs[10:15] = False  # the UAV out of the radar's view; its next run starts at t = 15
    covered = obs.copy()
    covered[:3] = False  # before the first track (index 3)
    covered[16] = False  # 1 s into the new run
    covered[35] = False  # 20 s into it
    covered[12] = False  # not observable: not counted
    causes = sm.uncovered_causes(t, obs, covered, 3, 15.0)
    assert causes == ["start-up"] * 3 + ["re-entry", "other"]
    # a shorter re-entry window makes the second one "other" as well
    assert sm.uncovered_causes(t, obs, covered, 3, 1.0)[3] == "other"


@pytest.mark.parametrize(
    ("args", "cause"),
    [
        ((None, None, None, 0.0, False), "coast"),
        ((3.0, 2.0, "uav", 0.0, False), "coast"),  # last update 7 s before t = 10
        ((9.0, 3.0, "uav", 0.0, False), "rf"),  # an RF fix 1 s ago, the radar 7 s ago
        ((9.0, None, None, 0.0, False), "rf"),
        ((9.5, 9.5, "bird", 20.0, False), "other object: bird"),
        ((9.5, 9.5, "uav", 150.0, True), "UAV report off, far"),
        ((9.5, 9.5, "uav", 150.0, False), "UAV report off, near"),
        ((9.5, 9.5, "uav", 60.0, True), "UAV report close"),
    ],
)
def test_gross_epoch_causes(sm: ModuleType, args: tuple[object, ...], cause: str) -> None:
    assert sm.gross_cause(10.0, *args, 5.0, 100.0) == cause
