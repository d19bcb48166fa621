"""The trackers' setting groups: the UAV score of every radar object (:class:`ScoreConfig`, a
profile's ``association`` groups) and the multi-UAV tracker's own settings
(:class:`MultiSettings`, the ``multi`` section).

Plain dataclasses, so that the profile loader builds them without importing the trackers.
Every key is optional; an absent key keeps the default below (the values the benchmark
figures were measured with). Each key's meaning, type and bounds are in the profile schema
(:mod:`~uav_fusion.core.profiles.schema`; ``config/profiles/README.md``).
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class MultiSettings:
    """What the multi-UAV tracker adds to a tracker profile."""

    merge_nis: float = 3.0  # two tracks this close (NIS, 3 dof) are candidates for a merge
    merge_s: float = 3.0  # ... and are merged after this long
    emitter_doubt: float = 0.1  # 1 - P(UAV) is multiplied by this for a track with an emitter
    velocity_weight: float = 1.0  # weight of the reported-velocity NIS in the cost
    velocity_sigma_mps: float = 3.0  # error of a radar track's reported velocity, per axis
    output_coast_s: float | None = 3.0  # published while the last update is this recent
    # and, inside radar cover, the last radar update too (None: while it lives)
    emitter_misses: int | None = 3  # this many fixes of its emitter in a row outside a
    # track's gate unlink the emitter from it (None: never)
    birth_sep_m: float | None = 60.0  # a strong object inside a track's gate starts a track
    # when that track took another report of the frame this far away (None: never)
    emitter_follow_min: float | None = 0.0  # an object scoring this much (below follow_min)
    # that its emitter's fixes credit may update the track carrying that emitter (None: off)


@dataclass(frozen=True)
class ScoreConfig:
    """Weights and thresholds of the UAV score: a profile's ``association`` groups (each key
    and the field it sets: :mod:`~uav_fusion.core.profiles.schema`)."""

    # one time constant for an object's own history: the moving averages of its class logit,
    # speed, height and RCS; an object is judged stationary, and its age term is full, once
    # this old
    tau_s: float = 5.0
    class_clip: float = 3.0
    stationary_speed_mps: float = 1.5
    stationary_weight: float = 5.0
    ground_alt_m: float = 4.0
    below_ground_m: float = 5.0
    below_ground_sigmas: float = 0.0
    large_rcs_dbsm: float = 0.0  # a small UAV's RCS is below 1 m^2 (the paper: up to -2.6 dBsm)
    rf_weight: float = 1.0
    # RF support's time constant and a fix's wait for an object: a profile sets it to its
    # track.max_coast_s (Profile; infinite without one), not a key of its own
    rf_tau_s: float = 30.0
    rf_max: float = 3.0
    rf_support_max_cep_m: float = 0.0
    fused_weight: float = 1.5
    fused_tau_s: float = 10.0
    fused_nis: float = 3.0
    reach_margin_m: float = 0.0  # single-UAV tracker: 0: no reach gate (Tracker._reachable)
    age_weight: float = 0.5
    object_q: float = 5.0
    object_floor_m: float = 10.0
    follow_min: float = 0.0
    init_min: float = 1.0
    # reports an object needs before it may start a track: a profile sets it to its
    # track.confirm_m (Profile), not a key of its own
    init_min_reports: int = 3
    challenge_s: float = 0.0  # 0: a followed object is never challenged (tracker.py)
    challenge_margin: float = 0.5

    @property
    def veto(self) -> float:
        """What an object that cannot be a small UAV loses (a multipath ghost below the
        ground, a target too large): as much as every other cue can give at most (the
        clipped class logit, the capped RF support, full agreement and the full age term),
        so that its score stays at or below 0, where the shipped profile's ``follow_min`` and
        ``init_min`` lie above."""
        return self.class_clip + self.rf_weight * self.rf_max + self.fused_weight + self.age_weight
