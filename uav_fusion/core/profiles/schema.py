"""Every key of an estimator profile, documented once: its YAML path, type, bounds or choices,
unit, meaning and basis.

The loader (:mod:`~uav_fusion.core.profiles.model`) reads and checks a profile with this
table, ``config/profiles/README.md`` is generated from it (``uav_fusion profile doc``), and a
sweep's parameters are its paths. Defaults are not written here: they are those of the
dataclasses the keys land in (:class:`~uav_fusion.core.profiles.model.Profile`,
:class:`~uav_fusion.core.estimators.objects.ScoreConfig` for ``association.*`` and
:class:`~uav_fusion.core.profiles.settings.MultiSettings` for ``multi.*``).

A key's *basis* says where its value comes from: ``spec`` (a sensor's specification),
``physical`` (a physical limit), ``fitted`` (fitted on flights, by the command named in
``fit``) or ``design`` (a component choice or a design rule).
"""

from __future__ import annotations

from typing import Any

from uav_fusion.core.profiles.checks import (
    ALL,
    BOOL,
    CHOICE,
    DESIGN,
    ESTIMATORS,
    FITTED,
    INTEGER,
    MATRIX,
    MULTI,
    NUMBER,
    PAPER,
    PHYSICAL,
    PROBS,
    Q3,
    Q3_LIST,
    ROWS,
    SOURCE_LIST,
    SPEC,
    TEXT,
    TRACKER,
    Key,
)
from uav_fusion.core.records import RADAR, RF

TUNED = "uav_fusion sweep (tune half)"
CALIBRATE = "uav_fusion calibrate (errors against truth, tune flights)"


def _k(path: str, attr: str, kind: str, basis: str, meaning: str, **kw: Any) -> Key:
    return Key(path, attr, kind, basis, meaning, **kw)


def _group(prefix: str, used_by: str, *keys: Key) -> tuple[Key, ...]:
    """Keys of one section (their paths given relative to it), read by ``used_by`` unless a
    key says otherwise."""
    return tuple(
        Key(**{
            **k.__dict__,
            "path": f"{prefix}.{k.path}",
            "used_by": used_by if k.used_by == ALL else k.used_by,
        })
        for k in keys
    )


def _s(name: str, field: str, kind: str, basis: str, meaning: str, **kw: Any) -> Key:
    """An ``association`` key (a :class:`ScoreConfig` field)."""
    return Key(name, f"score.{field}", kind, basis, meaning, **kw)


def _m(name: str, kind: str, basis: str, meaning: str, **kw: Any) -> Key:
    """A ``multi`` key (a :class:`MultiSettings` field of the same name)."""
    return Key(name, f"multi.{name}", kind, basis, meaning, **kw)


#: Each section's one-line description (a section is a mapping of keys).
SECTIONS: dict[str, str] = {
    "": "the profile itself",
    "motion": "the motion model of the fused track",
    "motion.imm": "the IMM's modes (motion.model: imm)",
    "measurement": "the sensors' measurement models",
    "measurement.radar": "the radar's measurement model",
    "measurement.rf": "the RF fixes' measurement model",
    "measurement.adaptive": "online R from the UAV track's innovations (covariance matching)",
    "gating": "which radar reports may update the track",
    "sources": "which sensors are used at all",
    "track": "track start, confirmation and deletion",
    "update": "the Kalman update's pseudo-measurements",
    "association": "the UAV score of every radar object, by cue (core/estimators/objects.py)",
    "association.class": "the radar classifier's output, read over time",
    "association.stationary": "clutter: an object that stands still",
    "association.ground": "near the ground: with association.stationary, the physical gates' "
    "ground rule (a parked car, a mast or a reflector never becomes the UAV without RF "
    "corroboration)",
    "association.ghost": "a multipath ghost: clearly below the ground",
    "association.size": "too large a radar target for a small UAV",
    "association.rf": "support from RF fixes at the object's position",
    "association.fused": "agreement with the fused track",
    "association.age": "a track that persists is more likely real",
    "association.object": "each radar object's own filter and the radar's coasts",
    "association.thresholds": "the scores that let an object update or start a track",
    "association.takeover": "single-UAV tracker: when another object takes the track over",
    "smoother": "smoothing of the tracker's estimates",
    "multi": "the multi-UAV tracker's own rules",
    "evaluation": "evaluation settings that do not change the filter",
}

_TOP = (
    _k("name", "name", TEXT, DESIGN, "label in tables, outputs and topics"),
    _k("description", "description", TEXT, DESIGN, "free text"),
    _k("extends", "", TEXT, DESIGN, "a profile name or a path (relative to this file) whose keys "
       "this file starts from; mappings merge key by key, lists and values replace", null="none"),
    _k("estimator", "estimator", CHOICE, DESIGN, "paper: the paper's filter on one radar track; "
       "tracker: every radar object scored, one UAV track; multi: one track per UAV",
       choices=ESTIMATORS),
    _k("radar_selection", "radar_selection", CHOICE, DESIGN, "largest_track: only the radar "
       "track id with most reports; online: every report of a frame is a candidate",
       choices=("largest_track", "online"), used_by=PAPER),
)
_MOTION = (
    _k("motion.model", "motion_model", CHOICE, DESIGN, "cv: one constant-velocity model "
       "(motion.q); imm: an IMM of CV modes (motion.imm)", choices=("cv", "imm"), used_by=TRACKER),
    _k("motion.q", "q", Q3, FITTED, "white-acceleration spectral density per axis; Q = q "
       "[[T^3/3, T^2/2], [T^2/2, T]]", unit="m^2/s^3", bounds=">= 0",
       fit=f"uav_fusion estimate-r (suggests it); {TUNED}"),
    *_group("motion.imm", TRACKER,
        _k("q", "imm_q", Q3_LIST, DESIGN, "one q per IMM mode", unit="m^2/s^3", bounds=">= 0"),
        _k("transition", "imm_transition", ROWS, DESIGN, "Markov matrix applied once per "
           "prediction (row i: from mode i)"),
        _k("initial", "imm_initial", PROBS, DESIGN, "mode probabilities of a new track"),
    ),
)
_MEASUREMENT = (
    _k("measurement.note", "r_note", TEXT, FITTED, "where R came from",
       fit="uav_fusion estimate-r --write-profile"),
    _k("measurement.radar.R", "r_radar", MATRIX, FITTED, "radar covariance (east, north, up) "
       "of the paper's estimator and the fixed model", unit="m^2", size=3,
       null="none: the polar model's R at each report (trackers)",
       fit="uav_fusion estimate-r --write-profile"),
    *_group("measurement.radar", TRACKER,
        _k("model", "radar_model", CHOICE, DESIGN, "fixed: R for every report; polar: R from "
           "polar errors at the report's position (grows with range)",
           choices=("fixed", "polar")),
        _k("sigma_range_m", "radar_sigma_range_m", NUMBER, FITTED, "polar model: range "
           "standard deviation", unit="m", bounds=">= 0", fit=CALIBRATE),
        _k("sigma_az_deg", "radar_sigma_az_deg", NUMBER, SPEC, "polar model: azimuth "
           "standard deviation (the radar's datasheet angle accuracy)", unit="deg", bounds=">= 0"),
        _k("sigma_el_deg", "radar_sigma_el_deg", NUMBER, SPEC, "polar model: elevation "
           "standard deviation (as sigma_az_deg)", unit="deg", bounds=">= 0"),
        _k("floor_m", "radar_floor_m", NUMBER, FITTED, "polar model: standard deviation added "
           "on each axis (successive reports' errors are correlated)", unit="m",
           bounds=">= 0", fit=TUNED),
    ),
    _k("measurement.rf.R", "r_rf", MATRIX, FITTED, "RF covariance (east, north) of the paper's "
       "estimator and the fixed model", unit="m^2", size=2,
       null="none: the CEP model's R; a fix without a CEP counts as measurement.rf.max_cep_m",
       fit="uav_fusion estimate-r --write-profile"),
    *_group("measurement.rf", TRACKER,
        _k("model", "rf_model", CHOICE, DESIGN, "fixed: R for every fix; cep: sigma = max("
           "floor_m, cep_scale CEP / 1.1774)",
           choices=("fixed", "cep")),
        _k("cep_scale", "rf_cep_scale", NUMBER, FITTED, "cep model: the fix's CEP is scaled "
           "by this", bounds="> 0", fit=CALIBRATE),
        _k("floor_m", "rf_floor_m", NUMBER, FITTED, "cep model: smallest sigma per axis",
           unit="m", bounds=">= 0", fit=CALIBRATE),
        _k("max_cep_m", "rf_max_cep_m", NUMBER, FITTED, "fixes with a larger CEP are discarded "
           "(mostly non-line-of-sight)", unit="m", bounds="> 0", null="none discarded",
           fit=CALIBRATE),
    ),
)
_ADAPTIVE = _group(
    "measurement.adaptive", TRACKER,
    _k("window", "adaptive_window", INTEGER, DESIGN, "innovations each online sigma averages "
       "(radar range, azimuth, elevation; the RF CEP's scale); the radar's allowance for "
       "correlated errors follows the RF fixes instead of measurement.radar.floor_m, which "
       "must be 0", bounds=">= 2", null="off: R from the fixed sigmas and floor"),
    _k("bound", "adaptive_bound", NUMBER, SPEC, "each online sigma stays within [spec, spec x "
       "bound] (spec: the profile's sigma or cep_scale); the allowance within [f0 / bound, "
       "f0 x bound], f0 = sigma_az x the 3D range gate", bounds=">= 1"),
)
_GATING = _group(
    "gating", ALL,
    _k("range_gate_m", "range_gate_m", NUMBER, FITTED, "radar reports farther from the radar "
       "are discarded (trackers: updated in 3D out to here)", unit="m", bounds="> 0",
       null="the site's radar.range_gate_m", fit=TUNED),
    _k("nis_probability", "nis_probability", NUMBER, FITTED, "chi-square probability of the "
       "NIS gate", bounds="(0, 1)", fit="uav_fusion sweep bench/sweep_q.yaml (tune half)"),
    _k("min_uav_prob", "min_uav_prob", NUMBER, DESIGN, "radar reports with a lower (or no) UAV "
       "class probability are discarded", bounds="[0, 1]", null="no threshold"),
    _k("far_gate_m", "far_gate_m", NUMBER, FITTED, "radar reports between range_gate_m "
       "and this update a confirmed track horizontally only; must exceed range_gate_m",
       unit="m", bounds="> 0", null="off", fit=TUNED, used_by=TRACKER),
)
_SOURCES = _group(
    "sources", ALL,
    _k(RADAR, "use_radar", BOOL, DESIGN, "use the radar at all"),
    _k(RF, "use_rf", BOOL, DESIGN, "use the RF fixes at all"),
)
_TRACK = _group(
    "track", ALL,
    _k("init_sources", "init_sources", SOURCE_LIST, DESIGN, "sources whose measurement may "
       "start a track"),
    _k("rf_init_altitude_m", "rf_init_altitude_m", NUMBER, PHYSICAL, "ENU up given to a track "
       "started from a 2D RF fix, with a standard deviation as large (a 2D fix says only "
       "that the UAV is above the ground)", unit="m", bounds="> 0"),
    _k("tentative_sources", "tentative_sources", SOURCE_LIST, DESIGN, "sources whose tracks "
       "start tentative (not published) until confirm_m of confirm_n hits", null="none"),
    _k("confirm_m", "confirm_m", INTEGER, DESIGN, "hits that confirm a tentative track ...",
       bounds=">= 1"),
    _k("confirm_n", "confirm_n", INTEGER, DESIGN, "... among its first confirm_n "
       "measurements (the start included); needs confirm_m <= confirm_n", bounds=">= 1"),
    _k("max_speed_mps", "max_speed_mps", NUMBER, PHYSICAL, "a small UAV's top speed: a hit of "
       "a tentative track lies at most this far from the last hit per second, and a new "
       "track's velocity has a standard deviation of half of it per axis (2 sigma: the top "
       "speed)", unit="m/s", bounds="> 0"),
    _k("max_consecutive_rejections", "max_consecutive_rejections", INTEGER, DESIGN, "the track "
       "restarts after this many NIS rejections in a row", bounds=">= 1", null="never"),
    _k("max_coast_s", "max_coast_s", NUMBER, FITTED, "the track restarts when nothing was "
       "accepted for this long (a few RF intervals); the trackers' RF evidence lasts as "
       "long: an object's RF support decays with this time constant, and a fix that credits "
       "no object is kept this long for a new object in its gate (a UAV on its pad before "
       "the radar has a track on it)", unit="s", bounds="> 0", null="never (the paper's "
       "estimator only)", fit=TUNED),
)
_UPDATE = _group(
    "update", TRACKER,
    _k("hold_after_s", "hold_after_s", NUMBER, FITTED, "without a radar update for this long, "
       "pseudo-measurements hold what the radar no longer measures: each RF fix first applies "
       "climb rate = 0 (2D fixes cannot see it), and, for the single-UAV tracker inside the 3D "
       "range gate, each radar frame applies radial speed = 0 (the radar would see the UAV "
       "there unless it hovers in the Doppler notch)", unit="s", bounds=">= 0", null="never",
       fit=TUNED),
    _k("hold_sigma_mps", "hold_sigma_mps", NUMBER, FITTED, "standard deviation of those "
       "pseudo-measurements, and of the climb rate a track starts with (tracks start level)",
       unit="m/s", bounds="> 0", fit=TUNED),
)
_ASSOCIATION = (
    *_group("association.class", TRACKER,
        _s("clip", "class_clip", NUMBER, DESIGN, "the class history (moving average of the UAV "
           "class logit, the score's unit) clips each logit to +-clip", bounds=">= 0"),
    ),
    *_group("association.stationary", TRACKER,
        _s("speed_mps", "stationary_speed_mps", NUMBER, PHYSICAL, "an object whose mean speed "
           "stays below this ... (the physical gates' ground rule also counts one whose "
           "positions move slower: docs/estimator.md)", unit="m/s", bounds=">= 0"),
        _s("weight", "stationary_weight", NUMBER, DESIGN, "... once older than "
           "association.object.tau_s loses this much", bounds=">= 0"),
    ),
    *_group("association.ground", TRACKER,
        _s("alt_m", "ground_alt_m", NUMBER, PHYSICAL, "an object whose mean height lies below "
           "this plus two of its reports' vertical sigmas is near the ground; the track is "
           "airborne once a confirmed state stood higher by two of its own", unit="m",
           bounds=">= 0"),
    ),
    *_group("association.ghost", TRACKER,
        _s("below_ground_m", "below_ground_m", NUMBER, PHYSICAL, "an object whose mean height "
           "lies more than this below the ground ...", unit="m", bounds=">= 0"),
        _s("sigmas", "below_ground_sigmas", NUMBER, FITTED, "... and more than this many of "
           "its reports' vertical sigmas is no UAV (its score loses all that the other cues "
           "can give)", bounds=">= 0", fit=TUNED),
    ),
    *_group("association.size", TRACKER,
        _s("large_rcs_dbsm", "large_rcs_dbsm", NUMBER, PHYSICAL, "an RCS of at least this is "
           "too large for a small UAV: a report this large updates no track (large_rcs), and "
           "an object whose mean RCS is that large is no UAV (as a ghost)", unit="dBsm"),
    ),
    *_group("association.rf", TRACKER,
        _s("weight", "rf_weight", NUMBER, DESIGN, "weight of the RF support (fixes inside the "
           "object's 99 % gate)", bounds=">= 0"),
        _s("max", "rf_max", NUMBER, DESIGN, "the support is capped at this", bounds=">= 0"),
        _s("support_max_cep_m", "rf_support_max_cep_m", NUMBER, FITTED, "single-UAV tracker: "
           "a fix discarded for its CEP still credits when its CEP is at most this (0: never)",
           unit="m", bounds=">= 0", fit=TUNED),
    ),
    *_group("association.fused", TRACKER,
        _s("weight", "fused_weight", NUMBER, DESIGN, "weight of the agreement with the fused "
           "track", bounds=">= 0"),
        _s("tau_s", "fused_tau_s", NUMBER, DESIGN, "time constant of its moving average (the "
           "track's agreement builds up over longer than an object's own history)", unit="s",
           bounds=">= 0"),
        _s("nis", "fused_nis", NUMBER, DESIGN, "a report agrees at an NIS of at most this",
           bounds=">= 0"),
    ),
    *_group("association.age", TRACKER,
        _s("weight", "age_weight", NUMBER, DESIGN, "weight of the age term, full from an age of "
           "association.object.tau_s", bounds=">= 0"),
    ),
    *_group("association.object", TRACKER,
        _s("q", "object_q", NUMBER, DESIGN, "process noise of each object's CV filter",
           unit="m^2/s^3", bounds=">= 0"),
        _s("floor_m", "object_floor_m", NUMBER, DESIGN, "its polar R's floor (close in, an "
           "object's reports scatter more than the polar R: the onboard tracker's lag)",
           unit="m", bounds=">= 0"),
        _s("tau_s", "tau_s", NUMBER, FITTED, "time constant of every moving average of an "
           "object's own cues (class logit, speed, height, RCS): the time its history needs "
           "to say what it is; an object is judged stationary, and its age term is full, "
           "from this age", unit="s", bounds=">= 0", fit=TUNED),
    ),
    *_group("association.thresholds", TRACKER,
        _s("follow_min", "follow_min", NUMBER, FITTED, "objects scoring at least this may "
           "update a confirmed track", fit=TUNED),
        _s("init_min", "init_min", NUMBER, DESIGN, "an object scoring at least this ...", ),
    ),
    *_group("association.takeover", TRACKER,
        _s("challenge_s", "challenge_s", NUMBER, FITTED, "a strong object outside the gate "
           "that outscores the followed one for this long takes the track over (0: never)",
           unit="s", bounds=">= 0", fit=TUNED),
        _s("challenge_margin", "challenge_margin", NUMBER, FITTED, "... by this margin",
           bounds=">= 0", fit=TUNED),
        _s("reach_margin_m", "reach_margin_m", NUMBER, FITTED, "another object's report is "
           "outside the gate beyond track.max_speed_mps x time since the last update + this "
           "(0: off)", unit="m", bounds=">= 0", fit=TUNED),
    ),
)
_MULTI = _group(
    "multi", MULTI,
    _m("merge_nis", NUMBER, DESIGN, "two confirmed tracks closer than this (NIS, 3 dof) ...",
       bounds="> 0"),
    _m("merge_s", NUMBER, FITTED, "... for this long are one UAV (unless updated by different "
       "radar objects)", unit="s", bounds=">= 0", fit=TUNED),
    _m("emitter_doubt", NUMBER, DESIGN, "a track with an emitter: 1 - P(UAV) is multiplied by "
       "this", bounds="[0, 1]"),
    _m("velocity_weight", NUMBER, DESIGN, "weight of the reported velocity's NIS in the "
       "assignment cost", bounds=">= 0"),
    _m("velocity_sigma_mps", NUMBER, DESIGN, "error of a radar track's reported velocity, per "
       "axis", unit="m/s", bounds="> 0"),
    _m("birth_sep_m", NUMBER, DESIGN, "a strong object in a track's gate starts its own track "
       "when the track took a report this far away in the same frame", unit="m",
       bounds=">= 0", null="never"),
    _m("output_coast_s", NUMBER, FITTED, "a confirmed track is published while its last "
       "update is this recent and, inside radar cover, its last radar update too (an emitter "
       "there that the radar does not see is on the ground)", unit="s", bounds=">= 0",
       null="while it lives", fit=TUNED),
    _m("emitter_misses", INTEGER, DESIGN, "this many fixes of its emitter in a row outside a "
       "track's gate unlink the emitter", bounds=">= 1", null="never"),
    _m("emitter_follow_min", NUMBER, DESIGN, "an object scoring this (below follow_min) that "
       "its emitter's fixes credit may update the track carrying that emitter", null="off"),
)
_SMOOTHER = (
    _k("smoother.lag_s", "smoother_lag_s", NUMBER, DESIGN, "fixed-lag smoothing: each estimate "
       "uses the data up to this long after it (.inf: offline RTS per track segment)",
       unit="s", bounds="[0, inf]", null="none", used_by=TRACKER),
)
_EVALUATION = (
    _k("evaluation.raw_radar_min_mean_uav_prob", "raw_radar_min_mean_uav_prob", NUMBER, DESIGN,
       "the raw radar row counts reports of radar tracks whose mean UAV class probability "
       "reaches this (not a filter setting)", bounds="[0, 1]", null="every report"),
)

#: Every profile key, in the order of the README.
KEYS: tuple[Key, ...] = (
    *_TOP, *_MOTION, *_MEASUREMENT, *_ADAPTIVE, *_GATING, *_SOURCES, *_TRACK, *_UPDATE,
    *_ASSOCIATION, *_SMOOTHER, *_MULTI, *_EVALUATION,
)
BY_PATH: dict[str, Key] = {k.path: k for k in KEYS}

#: Attributes a profile derives from another key instead of reading a key of their own.
DERIVED: dict[str, str] = {
    "score.rf_tau_s": "track.max_coast_s",
    "score.init_min_reports": "track.confirm_m",
}

_EARLY_BIRTH = (
    "a strong object moving at association.stationary.speed_mps or more starts a track from "
    "the age association.object.tau_s"
)
_TAU = "it is association.object.tau_s, the one time constant of an object's own history"
_VETO = (
    "gone: an object that cannot be a small UAV loses all that the other cues can give "
    "(association.class.clip + association.rf.weight x association.rf.max + "
    "association.fused.weight + association.age.weight)"
)
_BIRD = "gone: a flock's erratic motion is the radar classifier's to call"
_LOW_EL = (
    "gone: the elevation sigma is the radar's specification, raised online where the "
    "innovations show more (measurement.adaptive)"
)
#: Keys that have left the schema, with what a profile that still sets one should do.
RETIRED: dict[str, str] = {
    "update.vz_hold_after_s": "it is update.hold_after_s",
    "update.vz_hold_sigma_mps": "it is update.hold_sigma_mps",
    "update.notch_after_s": "the Doppler-notch hold starts after update.hold_after_s",
    "update.notch_sigma_mps": "the Doppler-notch hold uses update.hold_sigma_mps",
    "update.notch_range_m": "the Doppler-notch hold applies inside the 3D range gate "
    "(gating.range_gate_m)",
    "association.vehicle.min_rcs_dbsm": "an object whose mean RCS is at least "
    "association.size.large_rcs_dbsm is too large for a small UAV",
    "association.age.full_s": "the age term is full from an age of association.object.tau_s",
    "association.rf.nearest_only": "a fix always credits only the object it fits best",
    "association.object.skip_radar_coasts": "a radar coast (a report repeating its track's "
    "velocity and RCS) never updates the track or the object",
    "track.init_velocity_std_mps": "a new track's velocity standard deviation is half of "
    "track.max_speed_mps",
    "track.rf_init_altitude_std_m": "the RF start's height standard deviation is "
    "track.rf_init_altitude_m",
    "multi.birth_age_s": "a strong object starts a track once older than "
    "association.object.tau_s",
    "multi.continuity_bonus": "gone: the assignment cost is the NIS and the velocity's NIS",
    "multi.merge_keeps_live": "always: a merge keeps the recently updated track",
    "multi.flat_below_ground": "always: a report below the ground updates east and north only",
    "multi.tentative_takes_radar": "never: a tentative (RF) track takes no radar report",
    "association.rf.memory_s": "a fix that credits no object is kept for track.max_coast_s",
    "association.rf.tau_s": "RF support decays with track.max_coast_s as its time constant, "
    "and a fix that credits no object is kept that long",
    "multi.radar_output_s": "inside radar cover, a track's last radar update must be as "
    "recent as multi.output_coast_s",
    "update.dof": "the Student-t update has 4 degrees of freedom, a constant",
    "update.huber_k": "gone with the huber update (the trackers' update is Student-t)",
    "update.robust": "the trackers' update is always Student-t with 4 degrees of freedom "
    "(R / w, w = (4 + m) / (4 + NIS) at most 1); the paper's estimator has none",
    "measurement.radar.low_el_gain": _LOW_EL,
    "measurement.radar.low_el_deg": _LOW_EL,
    "multi.early_birth_age_s": _EARLY_BIRTH,
    "multi.early_birth_speed_mps": _EARLY_BIRTH,
    "association.vehicle.ground_alt_m": "it is association.ground.alt_m",
    "association.vehicle.weight": "gone: a car is too large a radar target for a small UAV "
    "(association.size)",
    "association.bird.erratic_nis": _BIRD,
    "association.bird.max_rcs_dbsm": _BIRD,
    "association.bird.weight": _BIRD,
    "association.class.tau_s": _TAU,
    "association.object.speed_tau_s": _TAU,
    "association.stationary.min_age_s": "an object is judged stationary once older than "
    "association.object.tau_s",
    "association.class.weight": "gone: the score is in units of the class logit (scale the "
    "other weights and the thresholds instead)",
    "association.ghost.weight": _VETO,
    "association.size.weight": _VETO,
    "association.rf.window_s": "a fix credits objects reported within the radar's longest "
    "update interval (1.3 s, its datasheet)",
    "association.thresholds.init_min_reports": "an object needs track.confirm_m reports to "
    "start a track",
    "association.fused.lost_sigma_m": "the single-UAV tracker records no agreement while the "
    "track knows the UAV's horizontal position less well than the report does (its R)",
}


def find(path: str) -> Key | None:
    """The key at a YAML path, or None."""
    return BY_PATH.get(path)


def belongs(name: str) -> list[str]:
    """Where a key called ``name`` belongs: paths whose last part, or whose dataclass field
    (the flat name it had before its section was split), is ``name``; sections so named."""
    hits = [k.path for k in KEYS if name in (k.name, k.field)]
    hits += [s for s in SECTIONS if s and s.rsplit(".", 1)[-1] == name]
    return hits
