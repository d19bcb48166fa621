"""Estimator profiles: every setting of an estimator, loaded from YAML.

A profile (``config/profiles/*.yaml``) names the estimator (``estimator: paper | tracker |
multi``) and its settings; it may ``extends:`` another (:mod:`.inherit`). Every key is
documented once, in the schema (:mod:`.schema`: type, bounds, unit, meaning and whether it is
a sensor specification, a physical limit, a fitted value or a design choice); the loader
(:mod:`.model`) checks every key against it (:mod:`.checks`) and ``config/profiles/README.md``
is generated from it (:mod:`.reference`, ``uav_fusion profile doc``). The trackers' setting
groups are plain dataclasses (:mod:`.settings`).
"""

from uav_fusion.core.profiles.model import Profile, load_profile, profile_from_dict, profile_path
from uav_fusion.core.profiles.settings import MultiSettings, ScoreConfig

__all__ = [
    "MultiSettings",
    "Profile",
    "ScoreConfig",
    "load_profile",
    "profile_from_dict",
    "profile_path",
]
