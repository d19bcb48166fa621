"""Scoring against truth: the paper's Table II rows plus a time-based coverage.

:class:`Evaluator` is an accumulator. It is fed one item at a time — truth fixes, raw radar
reports, raw RF attempts (successful or failed), the measurements the filter accepted, and the
filter's output steps — and scores everything only when :meth:`Evaluator.evaluate` is called.
Because nothing is scored on arrival, the order in which items arrive does not matter: the
live evaluator node (items arrive as ROS messages, estimates possibly before the truth that
brackets them) and the offline path (items come from records) give identical numbers for the
same data. Inputs are sorted by time (ties broken by value) before scoring, so even the
floating-point summation order is fixed.

Rows (DESIGN §2, the paper's Table II) and their count-coverage denominators:

=================  ======  ==========================================  ====================
key                dims    samples                                     denominator
=================  ======  ==========================================  ====================
``rf_raw``         2D      successful RF attempts                      RF attempts
``radar_raw``      3D      every raw radar report fed                  raw radar reports
``rf_validated``   2D      RF measurements the filter accepted         RF attempts
``radar_valid..``  3D      radar measurements the filter accepted      raw radar reports
``kf_all``         3D      filter steps, updated or coasted            filter steps
``kf_updated``     3D      filter steps that were updates              filter steps
``kf_coasted``     3D      filter steps that coasted                   filter steps
=================  ======  ==========================================  ====================

Time-based coverage of a row is the fraction of truth epochs inside the evaluation window
that have a sample of that row no older than ``tolerance_s`` (the sample at or before the
epoch, at most ``tolerance_s`` earlier). The window runs from the first to the last raw sensor
report (radar report or RF attempt, failed ones included) unless given explicitly.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from uav_fusion.core.data.uav_class import DEFAULT_MIN_MEAN_UAV_PROB, uav_class_tracks
from uav_fusion.core.records import Flight, Measurement, RadarTrack
from uav_fusion.core.scoring.metrics import (
    ErrorStats,
    error_stats,
    interpolate_truth,
    position_errors,
)

FloatArray = npt.NDArray[np.float64]
Values = Sequence[float] | npt.NDArray[np.floating[Any]]

UPDATED = "updated"
COASTED = "coasted"


@dataclass(frozen=True)
class RowSpec:
    """Definition of one Table II row."""

    key: str
    label: str
    dims: int
    denominator: str  # "rf_attempts", "radar_reports" or "steps"
    group: str  # "raw", "validated" or "fused"


ROWS: tuple[RowSpec, ...] = (
    RowSpec("rf_raw", "RF sensor raw (2D)", 2, "rf_attempts", "raw"),
    RowSpec("radar_raw", "Radar raw (3D)", 3, "radar_reports", "raw"),
    RowSpec("rf_validated", "RF sensor after validation (NIS, 2D)", 2, "rf_attempts", "validated"),
    RowSpec(
        "radar_validated",
        "Radar after validation (largest track, range gate, NIS; 3D)",
        3,
        "radar_reports",
        "validated",
    ),
    RowSpec("kf_all", "KF fused track, all steps (3D)", 3, "steps", "fused"),
    RowSpec("kf_updated", "KF updated estimates (3D)", 3, "steps", "fused"),
    RowSpec("kf_coasted", "KF coasted estimates (3D)", 3, "steps", "fused"),
)
ROW_KEYS: tuple[str, ...] = tuple(r.key for r in ROWS)

DENOMINATOR_LABELS = {
    "rf_attempts": "RF attempts",
    "radar_reports": "raw radar reports",
    "steps": "filter steps",
}


@dataclass(frozen=True)
class RowSamples:
    """Per-sample data of one row, sorted by time: times, positions (ENU), errors."""

    t: FloatArray  # (N,)
    pos: FloatArray  # (N, 3); RF rows have NaN up
    err: FloatArray  # (N,); NaN where no truth brackets the sample


@dataclass(frozen=True)
class TableRow:
    """One scored row: the paper's statistics plus time coverage and bookkeeping."""

    spec: RowSpec
    stats: ErrorStats  # count / min / max / mean / std / count-coverage %
    denominator: int
    samples: int  # samples fed (scored or not)
    unscored: int  # samples without bracketing truth (excluded from the stats)
    time_coverage_pct: float

    @property
    def key(self) -> str:
        return self.spec.key

    def as_dict(self) -> dict[str, Any]:
        d: dict[str, Any] = {
            "key": self.spec.key,
            "label": self.spec.label,
            "dims": self.spec.dims,
            "group": self.spec.group,
        }
        d.update(self.stats.as_dict())
        d.update(
            {
                "denominator": self.denominator,
                "denominator_of": DENOMINATOR_LABELS[self.spec.denominator],
                "samples": self.samples,
                "unscored": self.unscored,
                "time_coverage_pct": self.time_coverage_pct,
            }
        )
        return {k: _json_number(v) for k, v in d.items()}


def _json_number(v: Any) -> Any:
    if isinstance(v, float) and not math.isfinite(v):
        return None
    return v


@dataclass(frozen=True)
class Evaluation:
    """Result of :meth:`Evaluator.evaluate`: the table and what the figures need."""

    rows: tuple[TableRow, ...]
    samples: dict[str, RowSamples]
    truth_t: FloatArray
    truth_enu: FloatArray
    radar_range: FloatArray  # 3D distance of each raw radar report from the radar (m)
    radar_rcs_dbsm: FloatArray  # RCS of each raw radar report (NaN where unknown)
    radar_validated_range: FloatArray
    rf_failed_t: FloatArray  # times of failed RF attempts
    rf_attempts: int
    radar_reports: int
    steps: int
    step_status: dict[str, int]
    dropped: dict[str, int]
    window: tuple[float, float]
    tolerance_s: float
    truth_epochs_in_window: int
    max_truth_gap_s: float
    radar_horizontal: int = 0  # accepted radar measurements without height (not in the rows)

    def row(self, key: str) -> TableRow:
        for r in self.rows:
            if r.spec.key == key:
                return r
        raise KeyError(key)

    def mean_interval_s(self, key: str) -> float:
        """Mean time between consecutive samples of a row (NaN with fewer than two)."""
        t = self.samples[key].t
        return float(np.mean(np.diff(t))) if t.size > 1 else float("nan")

    def as_dict(self) -> dict[str, Any]:
        return {
            "rows": [r.as_dict() for r in self.rows],
            "rf_attempts": self.rf_attempts,
            "radar_reports": self.radar_reports,
            "steps": self.steps,
            "step_status": dict(sorted(self.step_status.items())),
            "dropped": dict(sorted(self.dropped.items())),
            "radar_validated_horizontal": self.radar_horizontal,
            "window_utc_s": [_json_number(self.window[0]), _json_number(self.window[1])],
            "time_coverage_tolerance_s": self.tolerance_s,
            "truth_epochs_in_window": self.truth_epochs_in_window,
            "truth_samples": int(self.truth_t.size),
            "max_truth_gap_s": self.max_truth_gap_s,
            "mean_interval_s": {
                k: _json_number(self.mean_interval_s(k)) for k in ROW_KEYS
            },
        }


@dataclass
class _Points:
    t: list[float] = field(default_factory=list)
    xyz: list[tuple[float, float, float]] = field(default_factory=list)
    extra: list[tuple[float, float]] = field(default_factory=list)

    def add(self, t: float, xyz: tuple[float, float, float], extra: tuple[float, float]) -> None:
        self.t.append(t)
        self.xyz.append(xyz)
        self.extra.append(extra)

    def __len__(self) -> int:
        return len(self.t)

    def arrays(self) -> tuple[FloatArray, FloatArray, FloatArray]:
        """(t, xyz, extra) sorted by time, ties broken by the values themselves."""
        t = np.asarray(self.t, dtype=float)
        xyz = np.asarray(self.xyz, dtype=float).reshape(-1, 3)
        ex = np.asarray(self.extra, dtype=float).reshape(-1, 2)
        if t.size:
            keys = [np.nan_to_num(c, nan=np.inf) for c in (ex[:, 1], ex[:, 0])]
            keys += [np.nan_to_num(xyz[:, i], nan=np.inf) for i in (2, 1, 0)]
            order = np.lexsort((*keys, t))
            t, xyz, ex = t[order], xyz[order], ex[order]
        return t, xyz, ex


def _finite(*vals: float) -> bool:
    return all(math.isfinite(v) for v in vals)


class Evaluator:
    """Accumulates truth, raw sensor data, accepted measurements and filter steps; scores them.

    Every ``add_*`` method returns True when the item was kept and False when it was dropped;
    dropped items are counted by reason in :attr:`dropped` (for example ``"radar: non-finite
    position"``) and never raise.

    Parameters: ``radar_enu`` is the radar's ENU position (for the 3D range of each report),
    ``tolerance_s`` the age limit of the time-based coverage, ``max_truth_gap_s`` the longest
    truth gap across which truth is still interpolated.
    """

    def __init__(
        self,
        radar_enu: Values = (0.0, 0.0, 0.0),
        tolerance_s: float = 1.0,
        max_truth_gap_s: float = 2.0,
        window: tuple[float, float] | None = None,
    ) -> None:
        if not (math.isfinite(tolerance_s) and tolerance_s >= 0):
            raise ValueError(f"tolerance_s must be finite and >= 0, got {tolerance_s}")
        if not (math.isfinite(max_truth_gap_s) and max_truth_gap_s > 0):
            raise ValueError(f"max_truth_gap_s must be finite and > 0, got {max_truth_gap_s}")
        self.radar_enu = np.asarray(radar_enu, dtype=float).reshape(3)
        self.tolerance_s = float(tolerance_s)
        self.max_truth_gap_s = float(max_truth_gap_s)
        self.window = window
        self.dropped: Counter[str] = Counter()
        self.step_status: Counter[str] = Counter()
        self.radar_horizontal = 0  # accepted horizontal-only radar measurements (far gate)
        self._truth = _Points()
        self._radar = _Points()  # extra = (rcs_dbsm, 0)
        self._rf = _Points()
        self._rf_failed: list[float] = []
        self._valid: dict[str, _Points] = {"rf": _Points(), "radar": _Points()}
        self._steps: dict[str, _Points] = {UPDATED: _Points(), COASTED: _Points()}

    # --- feeding ---------------------------------------------------------------------------
    def _drop(self, reason: str) -> bool:
        self.dropped[reason] += 1
        return False

    def add_truth(self, t: float, e: float, n: float, u: float) -> bool:
        """A truth position (ENU metres) at UTC time ``t``."""
        t, e, n, u = float(t), float(e), float(n), float(u)
        if not _finite(t):
            return self._drop("truth: non-finite time")
        if not _finite(e, n, u):
            return self._drop("truth: non-finite position")
        self._truth.add(t, (e, n, u), (0.0, 0.0))
        return True

    def add_radar_report(
        self, t: float, e: float, n: float, u: float, rcs_dbsm: float | None = None
    ) -> bool:
        """One raw radar report (a track position of a radar frame), ENU metres."""
        t, e, n, u = float(t), float(e), float(n), float(u)
        if not _finite(t):
            return self._drop("radar: non-finite time")
        if not _finite(e, n, u):
            return self._drop("radar: non-finite position")
        rcs = float("nan") if rcs_dbsm is None else float(rcs_dbsm)
        if not math.isfinite(rcs):
            rcs = float("nan")
        self._radar.add(t, (e, n, u), (rcs, 0.0))
        return True

    def add_rf_attempt(
        self, t: float, ok: bool, e: float = math.nan, n: float = math.nan
    ) -> bool:
        """One RF localisation attempt; a failed attempt (``ok`` False) still counts."""
        t = float(t)
        if not _finite(t):
            return self._drop("rf: non-finite time")
        if not ok:
            self._rf_failed.append(t)
            return True
        e, n = float(e), float(n)
        if not _finite(e, n):
            return self._drop("rf: non-finite position")
        self._rf.add(t, (e, n, math.nan), (0.0, 0.0))
        return True

    def add_validated(self, t: float, source: str, z: Values) -> bool:
        """A measurement the filter accepted (``z``: 3 values for radar, 2 for RF). A radar
        measurement with 2 values (horizontal only, beyond the tracker's 3D range gate) is
        counted in :attr:`radar_horizontal`; the 3D radar rows leave it out."""
        t = float(t)
        if source not in self._valid:
            return self._drop(f"validated: unknown source {source!r}")
        zz = [float(v) for v in z]
        if source == "radar" and len(zz) == 2:
            if not _finite(t, *zz):
                return self._drop("validated radar: non-finite horizontal position")
            self.radar_horizontal += 1
            return True
        need = 3 if source == "radar" else 2
        if len(zz) < need:
            return self._drop(f"validated {source}: {len(zz)} values, need {need}")
        if not _finite(t):
            return self._drop(f"validated {source}: non-finite time")
        if not _finite(*zz[:need]):
            return self._drop(f"validated {source}: non-finite position")
        xyz = (zz[0], zz[1], zz[2] if need == 3 else math.nan)
        self._valid[source].add(t, xyz, (0.0, 0.0))
        return True

    def add_step(self, t: float, status: str, x: Values) -> bool:
        """One filter output step: ``status`` "updated" or "coasted", ``x`` the state (≥3).

        Other statuses (``discarded``, ``tentative``) are counted in :attr:`step_status` but
        are not filter estimates scored in Table II; their state may be NaN (no track).
        """
        if status not in self._steps:
            self.step_status[status] += 1
            return True
        t = float(t)
        xs = [float(v) for v in x]
        if len(xs) < 3:
            return self._drop(f"step: state has {len(xs)} values, need 3")
        if not _finite(t):
            return self._drop("step: non-finite time")
        if not _finite(*xs[:3]):
            return self._drop("step: non-finite position")
        self.step_status[status] += 1
        if status in self._steps:
            self._steps[status].add(t, (xs[0], xs[1], xs[2]), (0.0, 0.0))
        return True

    def count(self, what: str) -> int:
        """Number of items kept so far: truth, radar, rf_attempts, rf_ok, validated_rf,
        validated_radar, updated, coasted."""
        sizes = {
            "truth": len(self._truth),
            "radar": len(self._radar),
            "rf_attempts": len(self._rf) + len(self._rf_failed),
            "rf_ok": len(self._rf),
            "validated_rf": len(self._valid["rf"]),
            "validated_radar": len(self._valid["radar"]),
            "updated": len(self._steps[UPDATED]),
            "coasted": len(self._steps[COASTED]),
        }
        return sizes[what]

    # --- scoring ---------------------------------------------------------------------------
    def evaluate(self) -> Evaluation:
        """Score everything fed so far (can be called any number of times)."""
        tt, tenu, _ = self._truth.arrays()
        if tt.size:  # keep the first sample of equal times (after the value tie-break)
            keep = np.concatenate(([True], np.diff(tt) > 0))
            tt, tenu = tt[keep], tenu[keep]

        rt, rxyz, rex = self._radar.arrays()
        ft, fxyz, _ = self._rf.arrays()
        failed = np.sort(np.asarray(self._rf_failed, dtype=float))
        vr_t, vr_xyz, _ = self._valid["radar"].arrays()
        vf_t, vf_xyz, _ = self._valid["rf"].arrays()
        up_t, up_xyz, _ = self._steps[UPDATED].arrays()
        co_t, co_xyz, _ = self._steps[COASTED].arrays()
        all_t = np.concatenate((up_t, co_t))
        all_xyz = np.concatenate((up_xyz, co_xyz))
        order = np.lexsort((all_xyz[:, 2], all_xyz[:, 1], all_xyz[:, 0], all_t))
        all_t, all_xyz = all_t[order], all_xyz[order]

        n_attempts = int(ft.size + failed.size)
        n_reports = int(rt.size)
        n_steps = int(all_t.size)
        denominators = {"rf_attempts": n_attempts, "radar_reports": n_reports, "steps": n_steps}

        raw = {
            "rf_raw": (ft, fxyz),
            "radar_raw": (rt, rxyz),
            "rf_validated": (vf_t, vf_xyz),
            "radar_validated": (vr_t, vr_xyz),
            "kf_all": (all_t, all_xyz),
            "kf_updated": (up_t, up_xyz),
            "kf_coasted": (co_t, co_xyz),
        }

        window = self.window
        if window is None:
            sensor_t = np.concatenate((rt, ft, failed))
            window = (
                (float(sensor_t.min()), float(sensor_t.max()))
                if sensor_t.size
                else (
                    (float(tt[0]), float(tt[-1])) if tt.size else (math.nan, math.nan)
                )
            )
        in_win = (tt >= window[0]) & (tt <= window[1]) if tt.size else np.zeros(0, bool)
        epochs = tt[in_win]

        rows: list[TableRow] = []
        samples: dict[str, RowSamples] = {}
        for spec in ROWS:
            t, xyz = raw[spec.key]
            if t.size:
                ref = interpolate_truth(tt, tenu, t, max_gap_s=self.max_truth_gap_s)
                err = position_errors(xyz, ref, dims=spec.dims)
            else:
                err = np.zeros(0)
            denom = denominators[spec.denominator]
            stats = error_stats(err, denominator=denom)
            rows.append(
                TableRow(
                    spec=spec,
                    stats=stats,
                    denominator=denom,
                    samples=int(t.size),
                    unscored=int(t.size - stats.count),
                    time_coverage_pct=time_coverage_pct(t, epochs, self.tolerance_s),
                )
            )
            samples[spec.key] = RowSamples(t=t, pos=xyz, err=err)

        radar_range = np.linalg.norm(rxyz - self.radar_enu, axis=1) if rt.size else np.zeros(0)
        vrange = np.linalg.norm(vr_xyz - self.radar_enu, axis=1) if vr_t.size else np.zeros(0)
        return Evaluation(
            rows=tuple(rows),
            samples=samples,
            truth_t=tt,
            truth_enu=tenu,
            radar_range=np.asarray(radar_range, dtype=float),
            radar_rcs_dbsm=rex[:, 0].copy(),
            radar_validated_range=np.asarray(vrange, dtype=float),
            rf_failed_t=failed,
            rf_attempts=n_attempts,
            radar_reports=n_reports,
            steps=n_steps,
            step_status=dict(self.step_status),
            dropped=dict(self.dropped),
            window=window,
            tolerance_s=self.tolerance_s,
            truth_epochs_in_window=int(epochs.size),
            max_truth_gap_s=self.max_truth_gap_s,
            radar_horizontal=self.radar_horizontal,
        )


def time_coverage_pct(sample_t: FloatArray, epochs: FloatArray, tolerance_s: float) -> float:
    """Percentage of ``epochs`` that have a sample at or before them, at most
    ``tolerance_s`` older. ``sample_t`` must be sorted. NaN when there are no epochs."""
    if epochs.size == 0:
        return float("nan")
    if sample_t.size == 0:
        return 0.0
    idx = np.searchsorted(sample_t, epochs, side="right") - 1
    prev = sample_t[np.clip(idx, 0, None)]
    covered = (idx >= 0) & (epochs - prev <= tolerance_s)
    return float(100.0 * np.count_nonzero(covered) / epochs.size)


def format_table(ev: Evaluation, digits: int = 1) -> str:
    """Plain-text table (for terminals and logs)."""
    head = (
        f"{'stage':<62} {'count':>6} {'min m':>8} {'max m':>8} {'mean m':>8} {'std m':>8} "
        f"{'cov %':>6} {'time cov %':>10}"
    )
    lines = [head, "-" * len(head)]
    for r in ev.rows:
        s = r.stats
        lines.append(
            f"{r.spec.label:<62} {s.count:>6d} {_f(s.min, digits):>8} {_f(s.max, digits):>8} "
            f"{_f(s.mean, digits):>8} {_f(s.std, digits):>8} {_f(s.coverage_pct, 1):>6} "
            f"{_f(r.time_coverage_pct, 1):>10}"
        )
    lines.append(
        f"count coverage: over {ev.rf_attempts} RF attempts, {ev.radar_reports} raw radar "
        f"reports, {ev.steps} filter steps; time coverage: truth epochs with a sample "
        f"<= {ev.tolerance_s:g} s old ({ev.truth_epochs_in_window} epochs)"
    )
    return "\n".join(lines)


def _f(v: float, digits: int) -> str:
    return "-" if not math.isfinite(v) else f"{v:.{digits}f}"


def rows_summary(ev: Evaluation, keys: Iterable[str] = ROW_KEYS) -> str:
    """One-line summary (count, mean, count coverage per row) for periodic logging."""
    parts = []
    for k in keys:
        r = ev.row(k)
        if r.stats.count == 0:
            parts.append(f"{k} n=0")
            continue
        parts.append(
            f"{k} n={r.stats.count} mean={_f(r.stats.mean, 1)} m "
            f"cov={_f(r.stats.coverage_pct, 1)}%"
        )
    return "; ".join(parts)


# --- feeding from records (the offline path) -----------------------------------------------
def feed_flight(
    ev: Evaluator,
    flight: Flight,
    radar_tracks: Iterable[RadarTrack] | None = None,
    min_mean_uav_prob: float | None = DEFAULT_MIN_MEAN_UAV_PROB,
) -> None:
    """Feed a flight's truth, raw radar reports and RF attempts.

    ``radar_tracks`` are the reports of the raw radar row; by default the radar's UAV reports
    (:func:`uav_fusion.core.data.uav_class.uav_class_tracks` with ``min_mean_uav_prob``, the
    paper profile's ``evaluation.raw_radar_min_mean_uav_prob`` unless given; None: every
    report).
    """
    for f in flight.truth:
        ev.add_truth(f.t, f.e, f.n, f.u)
    tracks = (
        radar_tracks
        if radar_tracks is not None
        else uav_class_tracks(flight.radar, min_mean_uav_prob)
    )
    for trk in tracks:
        ev.add_radar_report(trk.t, trk.e, trk.n, trk.u, trk.rcs_dbsm)
    for a in flight.rf:
        ev.add_rf_attempt(a.t, a.ok, a.e, a.n)


def step_class(step: Any) -> str:
    """Table II class of an estimator step: "updated" or "coasted" when the step says so
    through its ``updated`` / ``coasted`` properties (an initialisation from an accepted
    measurement is an update there), otherwise its ``status`` string ("discarded", or
    "tentative" for a step of a track not yet confirmed: counted in ``step_status``, never
    scored, like the fusion node that does not publish them)."""
    if getattr(step, "updated", False) is True:
        return UPDATED
    if getattr(step, "coasted", False) is True:
        return COASTED
    return str(step.status)


def step_validated(step: Any) -> bool:
    """Did the step's measurement pass the filter's gates (the "after validation" rows)?

    The step's ``validated`` flag when it has one (an estimator step started from a
    measurement is an update but its measurement was never tested against a prediction, so
    it is not validated); otherwise its Table II class being "updated".
    """
    flag = getattr(step, "validated", None)
    if isinstance(flag, bool):
        return flag
    return step_class(step) == UPDATED


def feed_steps(
    ev: Evaluator, steps: Iterable[Any], measurements: Iterable[Measurement] = ()
) -> None:
    """Feed filter steps; a validated step (:func:`step_validated`) also feeds its measurement.

    A step is any object with ``t``, ``source``, ``status`` and ``x`` (state, at least 3
    values), classed by :func:`step_class`. The accepted measurement is the step's ``z``
    when it has one, otherwise the measurement of ``measurements`` with the step's
    ``source`` and ``seq``.
    """
    by_seq = {(m.source, m.seq): m for m in measurements}
    for s in steps:
        status = step_class(s)
        ev.add_step(s.t, status, np.asarray(s.x, dtype=float).reshape(-1))
        if not step_validated(s):
            continue
        z = getattr(s, "z", None)
        if z is None:
            m = by_seq.get((str(s.source), int(getattr(s, "seq", -1))))
            if m is None:
                ev.dropped["validated: step without its measurement"] += 1
                continue
            z = m.z
        ev.add_validated(s.t, str(s.source), np.asarray(z, dtype=float).reshape(-1))
