"""Profiles: the schema, inheritance (``extends``), the generated README, and errors that name
the file and the key."""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml

from uav_fusion.cli import main
from uav_fusion.core.errors import ConfigError
from uav_fusion.core.profiles.checks import BASES, FITTED
from uav_fusion.core.profiles.model import (
    Profile,
    load_profile,
    profile_files,
    profile_from_dict,
)
from uav_fusion.core.profiles.reference import readme
from uav_fusion.core.profiles.schema import DERIVED, KEYS, SECTIONS
from uav_fusion.core.profiles.settings import MultiSettings, ScoreConfig
from uav_fusion.resources import config_path

SHIPPED = ("paper", "tracker", "tracker_smoothed")
# Every attribute of the shipped profiles as loaded before profiles had a schema, groups and
# extends (commit e0ffabd, the same files as 720647e), ``association: track_score`` read as
# ``estimator: tracker``.
FROZEN = json.loads((Path(__file__).parent / "data" / "profiles_e0ffabd.json").read_text())
# Attributes that have left the profiles since, and where they went.
MOVED = {
    "radar_az_bias_deg": "the site file's radar.calibration, refined online",
    "radar_el_bias_deg": "the site file's radar.calibration",
    "rf_ref_sensors": "gone: the number of sensors does not enter the RF R",
    "rf_sensor_exponent": "gone: it was fitted to 0",
    "score.ground_release_sigmas": "gone: the rule changed no tune flight of either benchmark",
    "score.class_prior_logit": "gone: a model of one classifier's output on young tracks",
    "score.class_age_tau_s": "gone with it",
    "score.class_min_weight": "gone with it",
    "score.class_range_scale_m": "gone with it",
    "score.class_range_age_s": "gone with it",
    "multi.class_by_age": "gone with it",
    "multi.class_range_scale_m": "gone with it",
    "multi.class_range_age_s": "gone with it",
    "notch_after_s": "update.hold_after_s (the climb-rate hold's, 5 s in both)",
    "notch_sigma_mps": "update.hold_sigma_mps (1 m/s; 0.5 gave the same tune figures)",
    "notch_range_m": "the 3D range gate (1000 m in both)",
    "multi.radar_output_s": "multi.output_coast_s (3 s in both)",
    "score.vehicle_min_rcs_dbsm": "association.size.large_rcs_dbsm (0 dBsm in both)",
    "score.age_full_s": "association.object.tau_s (5 s in both)",
    "score.skip_radar_coasts": "always: a coast is the radar's prediction, not a measurement",
    "score.rf_nearest_only": "always: a fix credits the one object it fits best",
    "init_velocity_std_mps": "half of track.max_speed_mps (15 m/s in all)",
    "rf_init_altitude_std_m": "track.rf_init_altitude_m (40 m in all)",
    "multi.birth_age_s": "association.stationary.min_age_s (null: that, in all)",
    "multi.continuity_bonus": "gone (0 in all: off)",
    "multi.merge_keeps_live": "always (true in all)",
    "multi.flat_below_ground": "always (true in all)",
    "multi.tentative_takes_radar": "never (false in all)",
    "score.rf_memory_s": "track.max_coast_s (20 s for the tracker, 30 s before)",
    "multi.early_birth_age_s": "association.object.tau_s (5 s for the tracker, 4 s before)",
    "multi.early_birth_speed_mps": "association.stationary.speed_mps (1.5 m/s, 3 m/s before)",
    "robust_dof": "a constant of the Student-t update (4 in all)",
    "robust_huber_k": "gone with the huber update (no profile used it)",
    "robust": "always Student-t in the trackers (student_t in both tracker profiles)",
    "radar_low_el_gain": "gone: the adaptive elevation sigma (2 in the tracker, 0 in paper)",
    "radar_low_el_deg": "gone with it",
    "score.ground_weight": "gone: a car is too large a radar target (association.size)",
    "score.erratic_nis": "gone: erratic motion is the classifier's to call",
    "score.bird_rcs_dbsm": "gone with it",
    "score.erratic_weight": "gone with it",
    "score.class_tau_s": "association.object.tau_s, the one time constant of an object's own "
    "history (5 s in the tracker)",
    "score.speed_tau_s": "association.object.tau_s (5 s in all)",
    "score.stationary_min_age_s": "association.object.tau_s (8 s before)",
    "score.class_weight": "gone: the score is in units of the class logit (1 in all)",
    "score.below_ground_weight": "the score's veto, all the other cues can give (8, as before)",
    "score.large_rcs_weight": "the score's veto (5 before)",
    "score.rf_window_s": "the radar's longest update interval, 1.3 s (3 s before)",
    "score.init_min_reports": "track.confirm_m (3 in all, 4 before)",
    "score.lost_sigma_m": "the report's own R against the track's horizontal variance (50 m "
    "in the tracker before)",
}
# Score attributes added since, or derived from another key, with their value in every
# shipped profile.
SCORE_NOW = {"score.tau_s": 5.0, "score.init_min_reports": 3}
# Attributes renamed since (old: new).
RENAMED = {"vz_hold_after_s": "hold_after_s", "vz_hold_sigma_mps": "hold_sigma_mps"}
# Values refitted since (the tracker's, on the tune halves of the accuracy and worlds
# benchmarks; docs/estimator.md says with what).
RETUNED: dict[str, dict[str, Any]] = {
    "tracker": {
        # the radar's datasheet angle accuracy (+-2 deg) in place of fitted sigmas
        "radar_sigma_az_deg": 2.0,
        "radar_sigma_el_deg": 2.0,
        # the allowance for correlated radar errors is estimated online (no fitted floor)
        "radar_floor_m": 0.0,
        "score.rf_tau_s": 20.0,  # its track.max_coast_s
        "max_consecutive_rejections": None,
        # the fitted fallback matrices went: the polar model gives every report its R, and a
        # fix without a CEP counts as max_cep_m
        "r_radar": None,
        "r_rf": None,
        # two vertical sigmas once the elevation sigma is the specification (no multipath term)
        "score.below_ground_sigmas": 2.0,
    },
}
# Defaults changed since, seen by the profiles that do not set them (the paper's estimator
# reads no association key).
DEFAULTS = {"paper": {"score.large_rcs_dbsm": 0.0, "score.rf_tau_s": 15.0}}


def _without(fields: dict[str, Any], paths: Iterable[str]) -> dict[str, Any]:
    """``fields`` without the (possibly dotted: ``score.x``) attributes ``paths``."""
    out: dict[str, Any] = json.loads(json.dumps(fields))
    for path in paths:
        *head, last = path.split(".")
        d = out
        for part in head:
            d = d[part]
        d.pop(last, None)
    return out


def _renamed(fields: dict[str, Any]) -> dict[str, Any]:
    return {RENAMED.get(k, k): v for k, v in fields.items()}


def _set(fields: dict[str, Any], values: dict[str, Any]) -> dict[str, Any]:
    out: dict[str, Any] = json.loads(json.dumps(fields))
    for path, v in values.items():
        *head, last = path.split(".")
        d = out
        for part in head:
            d = d[part]
        d[last] = v
    return out


def _plain(v: Any) -> Any:
    if dataclasses.is_dataclass(v) and not isinstance(v, type):
        return _plain(dataclasses.asdict(v))
    if isinstance(v, np.ndarray):
        return v.tolist()
    return json.loads(json.dumps(v))


def _fields(p: Profile) -> dict[str, Any]:
    return {f.name: _plain(getattr(p, f.name)) for f in dataclasses.fields(p) if f.name != "source"}


# Attributes added since, with the value the shipped profiles have (the feature off, except
# where ADDED_ON turns it on).
ADDED = {"adaptive_window": None, "adaptive_bound": 2.0}
ADDED_ON = {"tracker": {"adaptive_window": 200}, "tracker_smoothed": {"adaptive_window": 200}}


@pytest.mark.parametrize("name", SHIPPED)
def test_shipped_profiles_resolve_to_the_values_they_had(name: str) -> None:
    then = _set(_renamed(_without(FROZEN[name], MOVED)), RETUNED.get(name, {}))
    then = _set(_set(then, DEFAULTS.get(name, {})), SCORE_NOW)
    if name == "tracker_smoothed":  # it extends the tracker
        then = _set(then, RETUNED["tracker"])
    now = _fields(load_profile(name))
    assert {k: now.pop(k) for k in ADDED} == {**ADDED, **ADDED_ON.get(name, {})}
    assert now == then


@pytest.mark.parametrize("name", SHIPPED)
def test_as_dict_round_trips_every_attribute(name: str) -> None:
    p = load_profile(name)
    again = profile_from_dict(p.as_dict())
    assert _fields(again) == _fields(p)
    assert "extends" not in p.as_dict() and p.as_dict()["estimator"] == p.estimator


def test_tracker_smoothed_is_the_tracker_with_a_smoother() -> None:
    text = config_path("profiles/tracker_smoothed.yaml").read_text()
    assert len(text.splitlines()) <= 15 and "extends: tracker" in text
    a, b = _fields(load_profile("tracker")), _fields(load_profile("tracker_smoothed"))
    assert {k for k in a if a[k] != b[k]} == {"name", "smoother_lag_s"}
    assert profile_files("tracker_smoothed") == (
        config_path("profiles/tracker_smoothed.yaml"), config_path("profiles/tracker.yaml"))


def test_the_committed_readme_is_the_generated_one(capsys: pytest.CaptureFixture[str]) -> None:
    committed = config_path("profiles/README.md").read_text(encoding="utf-8")
    assert committed == readme(), (
        "config/profiles/README.md is stale: run `uav_fusion profile doc > "
        "config/profiles/README.md`"
    )
    assert main(["profile", "doc"]) == 0
    assert capsys.readouterr().out == committed


def test_profile_show_prints_the_resolved_profile(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["profile", "show", "tracker_smoothed"]) == 0
    doc = yaml.safe_load(capsys.readouterr().out)
    assert doc["name"] == "tracker_smoothed" and doc["smoother"] == {"lag_s": 3.0}
    assert doc["track"]["max_coast_s"] == 20.0 and "extends" not in doc


# --- the schema -------------------------------------------------------------------------------
def test_every_field_has_exactly_one_key() -> None:
    attrs = [k.attr for k in KEYS if k.attr]
    assert len(attrs) == len(set(attrs))
    assert len({k.path for k in KEYS}) == len(KEYS)
    want = {f.name for f in dataclasses.fields(Profile)} - {"source", "score", "multi"}
    want |= {f"score.{f.name}" for f in dataclasses.fields(ScoreConfig)} - set(DERIVED)
    want |= {f"multi.{f.name}" for f in dataclasses.fields(MultiSettings)}
    assert set(attrs) == want


def test_every_key_is_documented() -> None:
    for k in KEYS:
        assert k.basis in BASES, k.path
        assert k.meaning and "\n" not in k.meaning, k.path
        assert k.basis != FITTED or k.fit, f"{k.path}: a fitted value names its command"
        assert k.section in SECTIONS, k.path
    # the UAV score's keys sit in its cue groups, and only they do
    score = {k.path for k in KEYS if k.attr.startswith("score.")}
    assert score == {k.path for k in KEYS if k.section.startswith("association.")}
    assert all(k.section != "association" for k in KEYS)


# --- extends --------------------------------------------------------------------------------
def _write(path: Path, doc: object) -> Path:
    path.write_text(yaml.safe_dump(doc, sort_keys=False), encoding="utf-8")
    return path


def test_extends_merges_mappings_and_replaces_lists_and_values(tmp_path: Path) -> None:
    base = _write(tmp_path / "base.yaml", {
        "extends": "tracker",
        "name": "base",
        "track": {"init_sources": ["radar"], "max_coast_s": 30.0},
        "association": {"rf": {"max": 2.0}},
    })
    child = _write(tmp_path / "child.yaml", {
        "extends": "base.yaml",  # a path: relative to this file
        "track": {"tentative_sources": None, "max_consecutive_rejections": None},
        "multi": {"emitter_misses": None},
        "association": {"rf": {"weight": 2.5}},
    })
    tracker, p = load_profile("tracker"), load_profile(child)
    assert p.name == "child"  # the name is the file's own
    assert p.init_sources == ("radar",) and p.max_coast_s == 30.0  # from base, two deep
    assert p.tentative_sources == () and p.max_consecutive_rejections is None  # null sets null
    assert p.multi.emitter_misses is None and p.multi.merge_s == tracker.multi.merge_s
    assert (p.score.rf_max, p.score.rf_weight) == (2.0, 2.5)  # merged key by key
    assert p.score.rf_tau_s == 30.0  # RF evidence lasts as long as a coast
    assert p.score.follow_min == tracker.score.follow_min and p.estimator == "tracker"
    assert profile_files(child) == (child, base, config_path("profiles/tracker.yaml"))


def test_a_value_inherited_from_a_parent_is_blamed_on_the_parent(tmp_path: Path) -> None:
    parent = _write(
        tmp_path / "parent.yaml", {"extends": "tracker", "update": {"hold_sigma_mps": -1.0}}
    )
    child = _write(tmp_path / "child.yaml", {"extends": "./parent.yaml", "name": "c"})
    with pytest.raises(ConfigError, match=f"^{parent}: update.hold_sigma_mps must be a number > 0"):
        load_profile(child)


@pytest.mark.parametrize(
    ("docs", "message"),
    [
        ({"a": {"extends": "b.yaml"}, "b": {"extends": "./a.yaml"}},
         r"b.yaml: extends './a.yaml' makes a cycle: .*a.yaml -> .*b.yaml -> .*a.yaml"),
        ({"a": {"extends": "a.yaml"}}, r"a.yaml: extends 'a.yaml' makes a cycle"),
        ({"a": {"extends": "missing.yaml"}}, r"a.yaml: extends 'missing.yaml': no profile file "
         r".*missing.yaml"),
        ({"a": {"extends": "no_such_profile"}}, r"a.yaml: extends 'no_such_profile': no profile "
         r"file .*config/profiles/no_such_profile.yaml"),
        ({"a": {"extends": ["tracker"]}}, r"a.yaml: extends must be a profile name or a path"),
        ({"a": {"extends": "b.yaml"}, "b": {"extends": "tracker", "gate": 3}},
         r"b.yaml: unknown key 'gate'"),
    ],
)
def test_extends_errors_name_the_files(
    tmp_path: Path, docs: dict[str, object], message: str
) -> None:
    for stem, doc in docs.items():
        _write(tmp_path / f"{stem}.yaml", doc)
    with pytest.raises(ConfigError, match=message):
        load_profile(tmp_path / "a.yaml")


# --- bad keys and values -------------------------------------------------------------------
def _tracker_doc() -> dict[str, Any]:
    return dict(yaml.safe_load(config_path("profiles/tracker.yaml").read_text()))


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        # unknown
        (lambda d: d["association"]["rf"].update(tau=3.0),
         r"unknown key 'association\.rf\.tau' \(allowed: weight, max, support_max_cep_m\)"),
        (lambda d: d.update(colour="red"), r"unknown key 'colour' \(allowed: name, "),
        (lambda d: d["association"].update(cars={"weight": 1.0}), r"unknown key 'association\."
         r"cars'"),
        # misplaced: a known key in the wrong section, or under its old flat name
        (lambda d: d["gating"].update(max_coast_s=9.0),
         r"unknown key 'gating\.max_coast_s': it belongs at track\.max_coast_s"),
        (lambda d: d["association"].update(rf_max=9.0),
         r"unknown key 'association\.rf_max': it belongs at association\.rf\.max"),
        (lambda d: d["association"]["object"].update(challenge_s=2.0),
         r"'association\.object\.challenge_s': it belongs at association\.takeover\."
         r"challenge_s"),
        (lambda d: d.update(imm={}), r"unknown key 'imm': it belongs at motion\.imm"),
        (lambda d: d["association"].update(mode="track_score"),
         r"association\.mode is no longer a key: .*'estimator: paper \| tracker \| multi'"),
        # bad values
        (lambda d: d["association"]["object"].update(tau_s="slow"),
         r"association\.object\.tau_s must be a number >= 0, got 'slow'"),
        (lambda d: d["multi"].update(merge_s=-1), r"multi\.merge_s must be a number >= 0, got -1"),
        (lambda d: d["track"].update(confirm_n=2.5), r"track\.confirm_n must be an integer >= 1"),
        (lambda d: d["association"].update(rf=[1, 2]), r"'association\.rf' must be a mapping"),
        (lambda d: d.update(estimator="kalman"), r"estimator must be one of paper, tracker, multi"),
        # rules between keys
        (lambda d: d.update(radar_selection="online"),
         r"radar_selection and 'estimator: tracker' exclude each other"),
        (lambda d: d.update(estimator="paper"),
         r"association\.object\.tau_s needs 'estimator: tracker' or 'multi'"),
        (lambda d: (d.update(estimator="paper"), d.pop("association")),
         r"gating\.far_gate_m needs 'estimator: tracker' or 'multi'"),
        (lambda d: d["track"].update(max_coast_s=None),
         r"track\.max_coast_s is needed by 'estimator: tracker': it is also how long RF"),
    ],
)
def test_bad_profiles_name_the_file_and_the_key(
    tmp_path: Path, edit: Any, message: str
) -> None:
    doc = _tracker_doc()
    edit(doc)
    f = _write(tmp_path / "bad.yaml", doc)
    with pytest.raises(ConfigError, match=message) as exc:
        load_profile(f)
    assert str(exc.value).startswith(f"{f}: ")


def test_a_profile_without_estimator_is_the_papers() -> None:
    doc = load_profile("paper").as_dict()
    del doc["estimator"]
    p = profile_from_dict(doc)
    assert p.estimator == "paper" and not p.uses_tracker and p.radar_selection == "largest_track"


def test_estimator_multi_is_a_tracker_profile(tmp_path: Path) -> None:
    f = _write(tmp_path / "m.yaml", {"extends": "tracker", "estimator": "multi"})
    p = load_profile(f)
    assert p.estimator == "multi" and p.uses_tracker and p.radar_selection == "online"
    assert profile_from_dict(p.as_dict()).estimator == "multi"


def test_with_keys_sets_keys_by_path_and_checks_them() -> None:
    p = load_profile("tracker")
    q = p.with_keys({"association.object.tau_s": 7.0, "multi.merge_s": 2.0, "motion.q": (1.0,) * 3})
    assert (q.score.tau_s, q.multi.merge_s, q.q) == (7.0, 2.0, (1.0, 1.0, 1.0))
    assert q.score.follow_min == p.score.follow_min and p.score.tau_s == 5.0
    with pytest.raises(ConfigError, match=r"association\.object\.tau_s must be a number >= 0"):
        p.with_keys({"association.object.tau_s": -1.0})
    with pytest.raises(ConfigError, match=r"unknown key 'association\.object_tau_s'"):
        p.with_keys({"association.object_tau_s": 5.0})
    # a retired key says where it went, here as in a file
    with pytest.raises(ConfigError, match=r"'association\.class\.tau_s' is no longer a key: it "
                       r"is association\.object\.tau_s"):
        p.with_keys({"association.class.tau_s": 5.0})


@pytest.mark.parametrize("name", SHIPPED)
def test_derived_start_priors_keep_their_values(name: str) -> None:
    then, now = FROZEN[name], load_profile(name)
    assert now.init_velocity_std_mps == then["init_velocity_std_mps"]
    assert now.rf_init_altitude_std_m == then["rf_init_altitude_std_m"]


def test_merged_keys_keep_the_values_they_replace() -> None:
    then, now = FROZEN["tracker"], load_profile("tracker")
    assert then["notch_after_s"] == then["vz_hold_after_s"] == now.hold_after_s
    assert then["notch_range_m"] == now.range_gate_m
    assert then["multi"]["radar_output_s"] == now.multi.output_coast_s
    assert then["score"]["vehicle_min_rcs_dbsm"] == now.score.large_rcs_dbsm
    assert now.score.tau_s == then["score"]["age_full_s"] == then["score"]["speed_tau_s"]
    assert then["score"]["skip_radar_coasts"] and then["score"]["rf_nearest_only"]
    m = then["multi"]
    assert (m["birth_age_s"], m["continuity_bonus"], m["tentative_takes_radar"]) == (None, 0, False)
    assert m["merge_keeps_live"] and m["flat_below_ground"]
