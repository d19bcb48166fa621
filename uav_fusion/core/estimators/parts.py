"""The parts the trackers compose, each chosen by a profile: measurement models that own their
R, the radar's mounting alignment, robust update weights, M-of-N confirmation and deletion, and
the shared first stage of every radar frame.

Both trackers compose the same components, the way Stone Soup composes a tracker from
replaceable parts:

- :class:`RadarFront`: the first stage of every radar frame, the same for both: each report
  corrected for the radar's mounting misalignment (:class:`RadarAlignment`), given its error
  covariance (the radar measurement model, :class:`PolarRadarR` or :class:`FixedRadarR`),
  and fed to its radar object (the :class:`~uav_fusion.core.estimators.objects.ObjectTable`
  and its UAV score); what a tracker then does with the reports (gates, association) is its
  own;
- the RF measurement model (:class:`CepRfR` or :class:`FixedRfR`), the robust update weight
  (:class:`StudentTWeight`, :class:`NoRobust`), the motion filter of a
  new track (CV or IMM), the NIS gates, the :class:`Deleter` and M-of-N confirmation
  (:class:`MofN`): :class:`TrackParts`;
- track starts from a radar object's own filter (:func:`object_start`) or an RF fix
  (:func:`rf_start`).

Each family has a small typed protocol so that a profile can choose an implementation by
name. Covariances are returned packed as upper triangles
(:data:`~uav_fusion.core.estimators.kalman.PackedR`), the form the hand-unrolled kernels of
:class:`~uav_fusion.core.estimators.kalman.CvKalman` take, so no part builds a numpy array on
the per-measurement path.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Protocol

import numpy as np
import numpy.typing as npt

from uav_fusion.core.estimators.adaptive import CEP_PER_SIGMA, AdaptiveRadarR, AdaptiveRfR
from uav_fusion.core.estimators.imm import ImmFilter
from uav_fusion.core.estimators.kalman import CvFilter, MotionFilter, PackedR, expand_upper, pack_r
from uav_fusion.core.estimators.objects import ObjectTable, RadarObject
from uav_fusion.core.estimators.registration import Registration
from uav_fusion.core.estimators.steps import nis_gate
from uav_fusion.core.profiles.model import Profile
from uav_fusion.core.profiles.settings import ScoreConfig
from uav_fusion.core.records import RadarFrame, RadarTrack
from uav_fusion.core.site import Site

FloatArray = npt.NDArray[np.float64]



# --- measurement models -------------------------------------------------------------------
class RadarRModel(Protocol):
    """R (3x3, packed) of a radar position report at ENU ``(e, n, u)``."""

    def r_at(self, e: float, n: float, u: float) -> PackedR: ...


class RfRModel(Protocol):
    """R (2x2, packed) of an RF fix with its CEP (m)."""

    def r_for(self, cep_m: float | None) -> PackedR: ...


@dataclass(frozen=True)
class FixedRadarR:
    """The paper's model: one R for every radar report."""

    r: PackedR

    def r_at(self, e: float, n: float, u: float) -> PackedR:
        del e, n, u
        return self.r


@dataclass(frozen=True)
class FixedRfR:
    """The paper's model: one R for every RF fix."""

    r: PackedR

    def r_for(self, cep_m: float | None) -> PackedR:
        del cep_m
        return self.r


@dataclass(frozen=True)
class PolarRadarR:
    """R from the radar's polar errors, rotated into ENU at the report's position.

    With ``d`` the report minus the radar's phase centre, ``r = |d|`` and ``rho`` its
    horizontal length, the unit vectors along range ``u_r``, azimuth ``u_az`` (horizontal,
    perpendicular to ``u_r``) and elevation ``u_el`` give

        R = s_r^2 u_r u_r^T + (rho s_az)^2 u_az u_az^T + (r s_el)^2 u_el u_el^T + f^2 I

    (angle errors in radians become cross-range errors that grow with range; ``f`` is a floor
    for what the polar model leaves out, e.g. the onboard tracker's smoothing).
    """

    radar_enu: tuple[float, float, float]
    sigma_range_m: float
    sigma_az_rad: float
    sigma_el_rad: float
    floor_m: float = 0.0
    # (radar east, north, up, floor^2, sigma_range^2): read once per report
    _consts: tuple[float, float, float, float, float] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        e0, n0, u0 = self.radar_enu
        consts = (e0, n0, u0, self.floor_m * self.floor_m, self.sigma_range_m * self.sigma_range_m)
        object.__setattr__(self, "_consts", consts)

    def r_at(self, e: float, n: float, u: float) -> PackedR:
        ce, cn, cu, f2, sr2 = self._consts  # the radar's position, floor^2, sigma_range^2
        de = e - ce
        dn = n - cn
        du = u - cu
        rho = math.hypot(de, dn)
        r = math.sqrt(rho * rho + du * du)
        if r < 1e-6:
            v = sr2 + f2
            return (v, 0.0, 0.0, v, 0.0, v)
        u0, u1, u2 = de / r, dn / r, du / r
        if rho > 1e-9:
            a0, a1 = -dn / rho, de / rho  # azimuth direction (horizontal)
            k = -du / (rho * r)
            l0, l1, l2 = de * k, dn * k, rho / r  # elevation direction
        else:  # straight above: azimuth undefined, use east/north as the cross axes
            a0, a1 = 1.0, 0.0
            l0, l1, l2 = 0.0, 1.0, 0.0
        saz = rho * self.sigma_az_rad
        sel = r * self.sigma_el_rad
        a2 = saz * saz
        e2 = sel * sel
        ra0, ra1, ra2 = sr2 * u0, sr2 * u1, sr2 * u2
        aa0, aa1 = a2 * a0, a2 * a1
        el0, el1, el2 = e2 * l0, e2 * l1, e2 * l2
        return (
            ra0 * u0 + aa0 * a0 + el0 * l0 + f2,
            ra0 * u1 + aa0 * a1 + el0 * l1,
            ra0 * u2 + el0 * l2,
            ra1 * u1 + aa1 * a1 + el1 * l1 + f2,
            ra1 * u2 + el1 * l2,
            ra2 * u2 + el2 * l2 + f2,
        )


@dataclass(frozen=True)
class RadarAlignment:
    """Correct the radar's mounting misalignment: every report is turned about the radar's
    phase centre by ``-az_bias_deg`` in azimuth (clockwise from north, as the radar measures
    it) and lowered by ``el_bias_deg`` in elevation, at its own range.

    The biases are what :func:`uav_fusion.core.scoring.calibration.radar_alignment` measures against
    RTK truth (median report-minus-truth azimuth and elevation). Only the position changes:
    the velocity is left as reported (a turn of half a degree moves a 15 m/s velocity by
    0.13 m/s, far inside its noise) and the geodetic fields keep the radar's own report. The
    trackers correct each report's position on the fly (:meth:`point`, no new report
    object); :meth:`track` and :meth:`frame` give the corrected reports themselves.
    """

    radar_enu: tuple[float, float, float]
    az_bias_deg: float
    el_bias_deg: float
    # (cos, sin) of the azimuth and of the elevation correction: read once per report
    _trig: tuple[float, float, float, float] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        a = math.radians(self.az_bias_deg)
        b = math.radians(self.el_bias_deg)
        object.__setattr__(self, "_trig", (math.cos(a), math.sin(a), math.cos(b), math.sin(b)))

    @property
    def active(self) -> bool:
        return bool(self.az_bias_deg or self.el_bias_deg)

    def point(self, e: float, n: float, u: float) -> tuple[float, float, float]:
        """A reported ENU position, corrected."""
        e0, n0, u0 = self.radar_enu
        ca, sa, cb, sb = self._trig
        de = e - e0
        dn = n - n0
        du = u - u0
        rho = math.sqrt(de * de + dn * dn)
        # the elevation lowered by el_bias at the same slant range: (rho, du) turned down
        k = (rho * cb + du * sb) / rho if rho > 1e-9 else 0.0
        return e0 + (de * ca - dn * sa) * k, n0 + (dn * ca + de * sa) * k, u0 + du * cb - rho * sb

    def track(self, trk: RadarTrack) -> RadarTrack:
        """One report, corrected (what the trackers see of it)."""
        e, n, u = self.point(trk.e, trk.n, trk.u)
        return replace(trk, e=e, n=n, u=u)

    def frame(self, frame: RadarFrame) -> RadarFrame:
        """Every report of a frame, corrected (the frame itself when there is nothing to do)."""
        if not frame.tracks or not self.active:
            return frame
        one = self.track
        return RadarFrame(frame.t, tuple([one(t) for t in frame.tracks]), frame.line)


@dataclass(frozen=True)
class CepRfR:
    """R of an RF fix from its CEP.

    ``sigma = max(floor_m, scale * CEP / 1.1774)`` per axis (``R = sigma^2 I``): the CEP of
    the solver's geometry says how well the fix is conditioned. A fix without a CEP uses
    ``fallback``.
    """

    scale: float
    floor_m: float
    fallback: PackedR

    def r_for(self, cep_m: float | None) -> PackedR:
        if cep_m is None or not math.isfinite(cep_m) or cep_m <= 0:
            return self.fallback
        s = max(self.floor_m, self.scale * cep_m / CEP_PER_SIGMA)
        v = s * s
        return (v, 0.0, v)


def scale_packed(r: PackedR, factor: float) -> PackedR:
    """``factor * R`` of a packed covariance."""
    return tuple(factor * v for v in r)


def packed_to_array(r: PackedR) -> FloatArray:
    """Full symmetric array of a packed 2x2 (3 values) or 3x3 (6 values) covariance."""
    if len(r) == 3:
        return np.array([[r[0], r[1]], [r[1], r[2]]], dtype=float)
    if len(r) == 6:
        return np.array([[r[0], r[1], r[2]], [r[1], r[3], r[4]], [r[2], r[4], r[5]]], dtype=float)
    raise ValueError(f"packed covariance must have 3 or 6 values, got {len(r)}")


# --- robust update ------------------------------------------------------------------------
class RobustWeight(Protocol):
    """Weight ``w`` in (0, 1] of a measurement from its NIS; the update then uses ``R / w``."""

    def weight(self, nis: float, dim: int) -> float: ...


@dataclass(frozen=True)
class NoRobust:
    """Plain Kalman update (w = 1)."""

    def weight(self, nis: float, dim: int) -> float:
        del nis, dim
        return 1.0


#: The Student-t update's degrees of freedom: 4, the value Lange, Little and Taylor (1989,
#: "Robust statistical modeling using the t distribution") recommend as a default. It is a
#: constant, not a key: switching the update off moves the tune halves' errors by at most
#: 0.3 m mean (docs/estimator.md, "What each rule buys"), too little to fit a value on; the
#: update is a safeguard against outliers the gates let through.
STUDENT_T_DOF = 4.0


@dataclass(frozen=True)
class StudentTWeight:
    """Student-t scale-mixture weight ``w = (nu + m) / (nu + NIS)`` (m: measurement dimension).

    It is the expected precision scale of a Gaussian scale mixture with a Gamma(nu/2, nu/2)
    mixing density given the innovation, the single-iteration variational update of a
    Student-t measurement noise: ``w = 1`` at ``NIS = m`` (a typical innovation), smaller
    for larger innovations (an outlier is down-weighted, not only rejected), capped at
    ``max_weight`` so that an exceptionally small innovation does not over-trust the report.
    """

    dof: float
    max_weight: float = 1.0

    def weight(self, nis: float, dim: int) -> float:
        return min(self.max_weight, (self.dof + dim) / (self.dof + nis))


# --- IMM transition matrix ----------------------------------------------------------------
# --- track life cycle ---------------------------------------------------------------------
class MofN:
    """M-of-N confirmation: a candidate is confirmed by ``m`` hits among its first ``n``
    tests (the one that started it counts as a hit) and fails once that is out of reach."""

    __slots__ = ("hits", "m", "n", "tested")

    def __init__(self, m: int, n: int) -> None:
        if not 1 <= m <= n:
            raise ValueError(f"M-of-N needs 1 <= m <= n, got {m} of {n}")
        self.m = m
        self.n = n
        self.hits = 1
        self.tested = 1

    def record(self, hit: bool) -> str:
        """Record one test; returns ``confirmed``, ``failed`` or ``pending``."""
        self.tested += 1
        if hit:
            self.hits += 1
        if self.hits >= self.m:
            return "confirmed"
        if self.hits + (self.n - self.tested) < self.m:
            return "failed"
        return "pending"

    @property
    def confirmed(self) -> bool:
        return self.hits >= self.m


@dataclass(frozen=True)
class Deleter:
    """When a confirmed track is dropped: nothing accepted for ``max_coast_s`` or
    ``max_consecutive_rejections`` gate failures in a row (None: no limit)."""

    max_coast_s: float | None
    max_consecutive_rejections: int | None

    def coast_expired(self, t: float, last_used_t: float | None) -> bool:
        return (
            self.max_coast_s is not None
            and last_used_t is not None
            and t - last_used_t > self.max_coast_s
        )

    def too_many_rejections(self, consecutive: int) -> bool:
        n = self.max_consecutive_rejections
        return n is not None and consecutive >= n


def packed_r(R: FloatArray | Sequence[Sequence[float]]) -> PackedR:
    """``pack_r`` re-exported for callers that build a fixed model from a matrix."""
    return pack_r(np.asarray(R, dtype=float))


# --- what both trackers build from a profile --------------------------------------------
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
        )
    assert profile.r_radar is not None  # the profile's checks
    return FixedRadarR(pack_r(profile.r_radar))


def alignment_from_site(site: Site, az_deg: float | None = None) -> RadarAlignment | None:
    """The radar's misalignment correction: the site file's calibration (``az_deg``: another
    azimuth, e.g. an online estimate), or None when there is nothing to correct."""
    cal = site.radar.calibration
    az = cal.az_bias_deg if az_deg is None else az_deg
    if not (az or cal.el_bias_deg):
        return None
    return RadarAlignment(site.radar.enu, az, cal.el_bias_deg)


def rf_model_from_profile(profile: Profile) -> RfRModel:
    """The RF measurement model (``measurement.rf``)."""
    if profile.rf_model == "cep":
        model = CepRfR(profile.rf_cep_scale, profile.rf_floor_m, (0.0, 0.0, 0.0))
        if profile.r_rf is not None:
            return replace(model, fallback=pack_r(profile.r_rf))
        # a fix without a CEP counts as the coarsest that still updates (the profile's checks)
        assert profile.rf_max_cep_m is not None
        return replace(model, fallback=model.r_for(profile.rf_max_cep_m))
    assert profile.r_rf is not None  # the profile's checks
    return FixedRfR(pack_r(profile.r_rf))


def robust_from_profile(profile: Profile) -> RobustWeight:
    """The robust update weight: Student-t with ``STUDENT_T_DOF`` degrees of freedom for the
    trackers (an outlier inside the gate counts less, not only one outside it); none for the
    paper's estimator."""
    if profile.uses_tracker:
        return StudentTWeight(STUDENT_T_DOF)
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
    """A new track's state and covariance from a radar object's own filter, level: its climb
    rate 0 +- ``hold_sigma_mps``. The object's own climb rate comes from a few seconds of
    reports whose heights scatter by tens of metres, and the track's stiff vertical would keep
    a wrong one for a minute (a track born in a take-off climb overshoots the level-off by
    70 m); a UAV mostly holds its height, and a steady climb is learnt from the heights.
    ``flat`` (the object reported beyond the 3D range gate): no usable height either, so the
    RF start's height prior (``rf_init_altitude_m`` +- ``rf_init_altitude_std_m``)."""
    kf = obj.kf
    assert kf is not None
    x = list(kf.x)
    P = expand_upper(kf.P)
    x[5] = 0.0
    P[5, :] = P[:, 5] = 0.0
    P[5, 5] = profile.hold_sigma_mps**2
    if flat:
        x[2] = profile.rf_init_altitude_m
        P[2, :] = P[:, 2] = 0.0
        P[2, 2] = profile.rf_init_altitude_std_m**2
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
    (``association.object.floor_m``: close in, reports scatter more than the polar R, with
    the onboard tracker's lag) instead of the UAV track's ``floor_m``, which allows for errors
    correlated over seconds; a UAV track's update adds the difference back on each diagonal
    element (:attr:`extra_var`).
    """

    def __init__(self, profile: Profile, site: Site, cfg: ScoreConfig) -> None:
        self.site = site
        self.radar_r: RadarRModel | AdaptiveRadarR = radar_model_from_profile(profile, site)
        self.align = alignment_from_site(site)
        self.registration = Registration(site.radar.enu, site.radar.calibration)
        r_obj = self.radar_r
        self.extra_var = 0.0
        # with measurement.adaptive: the UAV track's R is estimated online (adaptive.py)
        self.adaptive: AdaptiveRadarR | None = None
        if isinstance(r_obj, PolarRadarR):
            if profile.adaptive_window is not None:
                window, bound = profile.adaptive_window, profile.adaptive_bound
                gate_m = math.sqrt(radar_gates2(profile, site)[0])
                self.adaptive = AdaptiveRadarR(r_obj, window, bound, gate_m)
                self.radar_r = self.adaptive
                f_obj = cfg.object_floor_m
            else:
                f_obj = min(r_obj.floor_m, cfg.object_floor_m)
                self.extra_var = r_obj.floor_m**2 - f_obj**2
            r_obj = replace(r_obj, floor_m=f_obj)
        self.r_obj = r_obj
        self.objects = ObjectTable(cfg, r_obj)
        self.gate2, self.far2 = radar_gates2(profile, site)  # far: 0 without a far gate
        self.radar_pos: tuple[float, float, float] = tuple(  # type: ignore[assignment]
            float(v) for v in site.radar.enu
        )

    def register(self, t: float, e: float, n: float, var_m2: float, obj: RadarObject) -> None:
        """An RF fix at (``e``, ``n``) credited to ``obj``, the object the UAV track follows:
        the registration's measurement of the mount's azimuth misalignment; the correction of
        the next reports follows the new estimate."""
        kf = obj.kf
        if kf is None:
            return
        dt = t - obj.kf_t
        x = kf.x
        oe, on = x[0] + dt * x[3], x[1] + dt * x[4]
        # the object's variance across the line of sight from the radar, predicted to t
        rx, ry = self.site.radar.enu[0], self.site.radar.enu[1]
        rho = math.hypot(oe - rx, on - ry) or 1.0
        u = ((on - ry) / rho, -(oe - rx) / rho)
        p = expand_upper(kf.P)
        pe = p[0, 0] + 2.0 * dt * p[0, 3] + dt * dt * p[3, 3]
        pn = p[1, 1] + 2.0 * dt * p[1, 4] + dt * dt * p[4, 4]
        pen = p[0, 1] + dt * (p[0, 4] + p[3, 1]) + dt * dt * p[3, 4]
        across = u[0] * u[0] * pe + 2.0 * u[0] * u[1] * pen + u[1] * u[1] * pn
        reg = self.registration
        if reg.pair((oe, on), (e, n), var_m2, float(max(across, 0.0))):
            self.align = alignment_from_site(self.site, reg.az_deg)

    def innovation(self, z: tuple[float, ...], f: MotionFilter) -> None:
        """A confirmed UAV track's 3D update with report ``z``, before the update: a sample
        of the radar's noise (``measurement.adaptive``)."""
        if self.adaptive is not None:
            x, p = f.mean()
            self.adaptive.observe(z, x, p)

    def status(self) -> dict[str, object]:
        """The radar's registration (and its online noise), for /diagnostics."""
        out = self.registration.status()
        if self.adaptive is not None:
            out.update(self.adaptive.status())
        return out

    def reports(self, frame: RadarFrame) -> tuple[list[int], list[Report]]:
        """The indices of the frame's non-finite reports, and every finite report (aligned,
        with its R and its squared range) after updating its radar object."""
        bad: list[int] = []
        out: list[Report] = []
        r_at = self.r_obj.r_at
        update = self.objects.update
        dv = self.extra_var
        adaptive = self.adaptive
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
            if adaptive is not None:
                r = adaptive.r_at(e, n, u)
            else:
                r = (ro[0] + dv, ro[1], ro[2], ro[3] + dv, ro[4], ro[5] + dv) if dv else ro
            out.append((i, trk, obj, p3, r, (e - rx) ** 2 + (n - ry) ** 2 + (u - rz) ** 2))
        return bad, out


class TrackParts:
    """The rest of what both trackers compose: measurement and robust models, NIS gates and
    the deleter (see the module text)."""

    def __init__(self, profile: Profile) -> None:
        rf_r = rf_model_from_profile(profile)
        # with measurement.adaptive: the CEP's scale is estimated online (adaptive.py)
        self.rf_adaptive: AdaptiveRfR | None = None
        if isinstance(rf_r, CepRfR) and profile.adaptive_window is not None:
            self.rf_adaptive = AdaptiveRfR(rf_r, profile.adaptive_window, profile.adaptive_bound)
        self.rf_r: RfRModel | AdaptiveRfR = self.rf_adaptive or rf_r
        self.robust = robust_from_profile(profile)
        self.deleter = Deleter(profile.max_coast_s, profile.max_consecutive_rejections)
        self.g2 = nis_gate(profile.nis_probability, 2)
        self.g3 = nis_gate(profile.nis_probability, 3)
