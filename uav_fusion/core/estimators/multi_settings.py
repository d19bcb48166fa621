"""The multi-UAV tracker's own settings: a profile's ``multi`` section.

Kept apart from :mod:`~uav_fusion.core.estimators.multi` so that the profile loader can build
them without importing the tracker. Every key is optional; an absent key keeps the default
below (the values the benchmark figures were measured with). Each key's meaning, type and
bounds are in the profile schema (:mod:`~uav_fusion.core.estimators.schema`, ``multi.*``;
``config/profiles/README.md``).
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class MultiSettings:
    """What the multi-UAV tracker adds to a tracker profile."""

    merge_nis: float = 3.0  # two tracks this close (NIS, 3 dof) are candidates for a merge
    merge_s: float = 3.0  # ... and are merged after this long
    emitter_doubt: float = 0.1  # 1 - P(UAV) is multiplied by this for a track with an emitter
    birth_age_s: float | None = None  # None: the score's stationary_min_age_s
    continuity_bonus: float = 0.0  # NIS credit for the radar object a track took last
    velocity_weight: float = 1.0  # weight of the reported-velocity NIS in the cost
    velocity_sigma_mps: float = 3.0  # error of a radar track's reported velocity, per axis
    output_coast_s: float | None = 3.0  # published while the last update is this recent
    radar_output_s: float | None = 3.0  # inside radar cover: ... and the last radar update
    emitter_misses: int | None = 3  # this many fixes of its emitter in a row outside a
    # track's gate unlink the emitter from it (None: never)
    tentative_takes_radar: bool = False  # a tentative (RF) track may take radar reports
    merge_keeps_live: bool = True  # a merge keeps the recently updated track over the older
    flat_below_ground: bool = True  # a report below the ground updates east / north only
    birth_sep_m: float | None = 60.0  # a strong object inside a track's gate starts a track
    # when that track took another report of the frame this far away (None: never)
    early_birth_age_s: float | None = 4.0  # an object moving at early_birth_speed_mps or
    early_birth_speed_mps: float = 3.0  # more (mean speed) may start a track from this age
    # (None: only from birth_age_s, or with RF support)
    class_by_age: bool = True  # the profile's class_prior_logit reading of young radar
    # tracks (False: each report's class as it is)
    class_range_scale_m: float | None = 3000.0  # with class_by_age, a radar track younger
    class_range_age_s: float = 8.0  # than this has its class read for its range too (None: off)
    emitter_follow_min: float | None = 0.0  # an object scoring this much (below follow_min)
    # that its emitter's fixes credit may update the track carrying that emitter (None: off)
