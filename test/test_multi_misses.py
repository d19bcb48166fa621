"""The causes scripts/multi_misses.py gives the multi-UAV tracker's missed UAV-epochs."""

from __future__ import annotations

from types import ModuleType

import numpy as np
import pytest
from script_util import load_script


@pytest.fixture(scope="module")
def mm() -> ModuleType:
    return load_script("multi_misses")


def test_missed_epochs_are_start_up_low_beside_or_other(mm: ModuleType) -> None:
    n = 20
    covered = np.ones(n, dtype=bool)
    seen = np.ones(n, dtype=bool)
    low = np.zeros(n, dtype=bool)
    beside = np.zeros(n, dtype=bool)
    covered[:4] = False  # before the first track (index 4) ...
    seen[1] = False  # ... once unseen by the radar
    covered[[8, 10, 12, 14]] = False
    low[8] = True  # landing
    low[0] = True  # start-up comes first
    beside[10] = True  # another UAV close by
    beside[8] = True  # low comes before beside
    seen[14] = False
    causes = mm.miss_causes(covered, seen, low, beside)
    assert causes == [
        "start-up, seen",
        "start-up, unseen",
        "start-up, seen",
        "start-up, seen",
        "low",
        "beside another UAV",
        "other, seen",
        "other, unseen",
    ]


def test_a_uav_never_tracked_is_all_start_up(mm: ModuleType) -> None:
    n = 5
    no = np.zeros(n, dtype=bool)
    causes = mm.miss_causes(no, np.ones(n, dtype=bool), np.ones(n, dtype=bool), no)
    assert causes == ["start-up, seen"] * n
    assert mm.miss_causes(np.ones(n, dtype=bool), no, no, no) == []
