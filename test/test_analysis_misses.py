"""The causes ``uav_fusion analyse misses`` gives the tracker's misses: the single-UAV
tracker's observable epochs with nothing published and its gross ones, and the multi-UAV
tracker's missed UAV-epochs."""

from __future__ import annotations

import numpy as np
import pytest

from uav_fusion.core.analysis.misses import gross_cause, miss_causes, uncovered_causes


def test_uncovered_epochs_are_start_up_re_entry_or_other() -> None:
    t = np.arange(0.0, 40.0, 1.0)
    obs = np.ones(t.size, dtype=bool)
    obs[10:15] = False  # the UAV out of the radar's view; its next run starts at t = 15
    covered = obs.copy()
    covered[:3] = False  # before the first track (index 3)
    covered[16] = False  # 1 s into the new run
    covered[35] = False  # 20 s into it
    covered[12] = False  # not observable: not counted
    causes = uncovered_causes(t, obs, covered, 3, 15.0)
    assert causes == ["start-up"] * 3 + ["re-entry", "other"]
    # a shorter re-entry window makes the second one "other" as well
    assert uncovered_causes(t, obs, covered, 3, 1.0)[3] == "other"


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
def test_gross_epoch_causes(
    args: tuple[float | None, float | None, str | None, float, bool], cause: str
) -> None:
    assert gross_cause(10.0, *args, 5.0, 100.0) == cause


def test_missed_epochs_are_start_up_low_beside_or_other() -> None:
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
    causes = miss_causes(covered, seen, low, beside)
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


def test_a_uav_never_tracked_is_all_start_up() -> None:
    n = 5
    no = np.zeros(n, dtype=bool)
    causes = miss_causes(no, np.ones(n, dtype=bool), np.ones(n, dtype=bool), no)
    assert causes == ["start-up, seen"] * n
    assert miss_causes(np.ones(n, dtype=bool), no, no, no) == []
