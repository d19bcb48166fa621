"""The parts the single- and the multi-UAV tracker share, built from a profile.

Both trackers compose the same components, the way Stone Soup composes a tracker from
replaceable parts:

- :class:`RadarFront`: the first stage of every radar frame, the same for both: each report
  corrected for the radar's mounting misalignment (:class:`RadarAlignment`), given its error
  covariance (the radar measurement model, :class:`PolarRadarR` or :class:`FixedRadarR`),
  and fed to its radar object (the :class:`~uav_fusion.core.estimators.objects.ObjectTable`
  and its UAV score); what a tracker then does with the reports (gates, association) is its
  own;
- the RF measurement model (:class:`CepRfR` or :class:`FixedRfR`), the robust update weight,
  the motion filter of a new track (CV or IMM), the NIS gates, the
  :class:`~uav_fusion.core.estimators.components.Deleter` and M-of-N confirmation
  (:class:`~uav_fusion.core.estimators.components.MofN`);
- track starts from a radar object's own filter (:func:`object_start`).
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import numpy.typing as npt

from uav_fusion.core.estimators.components import (
    CepRfR,
    Deleter,
    FixedRadarR,
    FixedRfR,
    HuberWeight,
    NoRobust,
    PolarRadarR,
    RadarAlignment,
    RadarRModel,
    RfRModel,
    RobustWeight,
    StudentTWeight,
)
from uav_fusion.core.estimators.filters import CvFilter, ImmFilter, MotionFilter
from uav_fusion.core.estimators.kalman import PackedR, expand_upper, pack_r
from uav_fusion.core.estimators.objects import ObjectTable, RadarObject, ScoreConfig
from uav_fusion.core.estimators.profile import Profile
from uav_fusion.core.estimators.steps import nis_gate
from uav_fusion.core.records import RadarFrame, RadarTrack
from uav_fusion.core.site import Site

FloatArray = npt.NDArray[np.float64]

#: One finite report of a frame after :meth:`RadarFront.reports`: its index in the frame, the
#: report, its radar object, its position (aligned), the R of a UAV track's update with it,
#: and its squared distance from the radar.
Report = tuple[int, RadarTrack, RadarObject, tuple[float, float, float], PackedR, float]


def radar_model_from_profile(profile: Profile, site: Site) -> RadarRModel:
    """The radar measurement model a UAV track's update uses (``measurement.radar``)."""
    if profile.radar_model == "polar":
        return PolarRadarR(
            tuple(float(v) for v in site.radar.enu),  # type: ignore[arg-type]
            profile.radar_sigma_range_m,
            math.radians(profile.radar_sigma_az_deg),
            math.radians(profile.radar_sigma_el_deg),
            profile.radar_floor_m,
            profile.radar_low_el_gain,
            profile.radar_low_el_deg,
        )
    return FixedRadarR(pack_r(profile.r_radar))


def alignment_from_profile(profile: Profile, site: Site) -> RadarAlignment | None:
    """The radar's misalignment correction (``measurement.radar.az_bias_deg`` /
    ``el_bias_deg``), or None when both are 0."""
    if not (profile.radar_az_bias_deg or profile.radar_el_bias_deg):
        return None
    return RadarAlignment(site.radar.enu, profile.radar_az_bias_deg, profile.radar_el_bias_deg)


def rf_model_from_profile(profile: Profile) -> RfRModel:
    """The RF measurement model (``measurement.rf``)."""
    fixed = pack_r(profile.r_rf)
    if profile.rf_model == "cep":
        return CepRfR(
            profile.rf_cep_scale,
            profile.rf_floor_m,
            profile.rf_ref_sensors,
            profile.rf_sensor_exponent,
            fixed,
        )
    return FixedRfR(fixed)


def robust_from_profile(profile: Profile) -> RobustWeight:
    """The robust update weight (``update.robust``)."""
    if profile.robust == "student_t":
        return StudentTWeight(profile.robust_dof)
    if profile.robust == "huber":
        return HuberWeight(profile.robust_huber_k)
    return NoRobust()


def motion_filter_from_profile(profile: Profile) -> MotionFilter:
    """A new track's motion filter (``motion``)."""
    if profile.motion_model == "imm":
        return ImmFilter(profile.imm_q, profile.imm_transition, profile.imm_initial)
    return CvFilter(profile.q)


def radar_gates2(profile: Profile, site: Site) -> tuple[float, float]:
    """The squared 3D range gate (the profile's, else the site's) and the squared far gate
    (``far_gate_m``; 0 without one, or when it is not beyond the 3D gate)."""
    gate = profile.range_gate_m if profile.range_gate_m is not None else site.radar.range_gate_m
    far = profile.far_gate_m
    return float(gate) ** 2, (float(far) ** 2 if far is not None and far > gate else 0.0)


def object_start(obj: RadarObject, profile: Profile, flat: bool) -> tuple[list[float], FloatArray]:
    """A new track's state and covariance from a radar object's own filter; ``flat`` (the
    object reported beyond the 3D range gate): no usable height, so the RF start's height
    prior (``rf_init_altitude_m`` +- ``rf_init_altitude_std_m``) and no climb instead."""
    kf = obj.kf
    assert kf is not None
    x = list(kf.x)
    P = expand_upper(kf.P)
    if flat:
        x[2], x[5] = profile.rf_init_altitude_m, 0.0
        P[2, :] = P[:, 2] = P[5, :] = P[:, 5] = 0.0
        P[2, 2] = profile.rf_init_altitude_std_m**2
        P[5, 5] = profile.vz_hold_sigma_mps**2
    return x, P


def rf_start(z: tuple[float, ...], r: PackedR, profile: Profile) -> tuple[list[float], FloatArray]:
    """A new track's state and covariance from an RF fix ``z`` with R ``r``: at the fix, at
    the RF start's height prior (``rf_init_altitude_m`` +- ``rf_init_altitude_std_m``), at
    rest within the profile's velocity sigma."""
    x = [z[0], z[1], profile.rf_init_altitude_m, 0.0, 0.0, 0.0]
    P = np.zeros((6, 6))
    P[0, 0], P[0, 1], P[1, 0], P[1, 1] = r[0], r[1], r[1], r[2]
    P[2, 2] = profile.rf_init_altitude_std_m**2
    P[3, 3] = P[4, 4] = P[5, 5] = profile.init_velocity_std_mps**2
    return x, P


class RadarFront:
    """The trackers' shared first stage of a radar frame (see the module text).

    Every radar object's own filter sees the per-report error: its R uses the object floor
    (``association.object.floor_m``) instead of the UAV track's ``floor_m``, since an
    erratic-motion cue would vanish under a floor sized for correlated errors; a UAV track's
    update adds the difference back on each diagonal element (:attr:`extra_var`).
    """

    def __init__(self, profile: Profile, site: Site, cfg: ScoreConfig) -> None:
        self.radar_r = radar_model_from_profile(profile, site)
        self.align = alignment_from_profile(profile, site)
        r_obj = self.radar_r
        self.extra_var = 0.0
        if isinstance(r_obj, PolarRadarR):
            f_obj = min(r_obj.floor_m, cfg.object_floor_m)
            self.extra_var = r_obj.floor_m**2 - f_obj**2
            r_obj = replace(r_obj, floor_m=f_obj)
        self.r_obj = r_obj
        self.objects = ObjectTable(cfg, r_obj)
        self.gate2, self.far2 = radar_gates2(profile, site)  # far: 0 without a far gate
        self.radar_pos: tuple[float, float, float] = tuple(  # type: ignore[assignment]
            float(v) for v in site.radar.enu
        )

    def reports(self, frame: RadarFrame) -> tuple[list[int], list[Report]]:
        """The indices of the frame's non-finite reports, and every finite report (aligned,
        with its R and its squared range) after updating its radar object."""
        bad: list[int] = []
        out: list[Report] = []
        r_at = self.r_obj.r_at
        update = self.objects.update
        dv = self.extra_var
        rx, ry, rz = self.radar_pos
        align = self.align.point if self.align is not None else None
        isfinite = math.isfinite
        for i, trk in enumerate(frame.tracks):
            e, n, u = trk.e, trk.n, trk.u
            if not isfinite(trk.t + e + n + u):
                bad.append(i)
                continue
            if align is not None:  # the radar's misalignment
                e, n, u = align(e, n, u)
            p3 = (e, n, u)
            ro = r_at(e, n, u)
            obj = update(trk, ro, p3)
            r = (ro[0] + dv, ro[1], ro[2], ro[3] + dv, ro[4], ro[5] + dv) if dv else ro
            out.append((i, trk, obj, p3, r, (e - rx) ** 2 + (n - ry) ** 2 + (u - rz) ** 2))
        return bad, out


class TrackParts:
    """The rest of what both trackers compose: measurement and robust models, NIS gates and
    the deleter (see the module text)."""

    def __init__(self, profile: Profile) -> None:
        self.rf_r = rf_model_from_profile(profile)
        self.robust = robust_from_profile(profile)
        self.deleter = Deleter(profile.max_coast_s, profile.max_consecutive_rejections)
        self.g2 = nis_gate(profile.nis_probability, 2)
        self.g3 = nis_gate(profile.nis_probability, 3)
