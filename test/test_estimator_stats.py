"""Statistical tests on simulated clean data (the filter's own models, seeded).

* Consistency: with every measurement used (gate probability 1 - 1e-12), the NIS of each
  measurement against the prediction is chi-square with ``dim`` degrees of freedom, so the
  sum over N measurements is chi-square with sum(dim) dof; its 99 % two-sided band is the test.
* The 95 % gate rejects a fraction of clean measurements inside the 99.9 % binomial band
  around 5 %.
* Injected outliers (2 km) are all rejected, and clean measurements still pass.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import binom, chi2

from uav_fusion.core.estimators import FusionEstimator, Step, load_profile
from uav_fusion.core.estimators.synthetic import SyntheticStream, simulate_stream
from uav_fusion.core.records import RADAR
from uav_fusion.core.site import load_site

R_RADAR = np.array([[100.0, 10.0, 0.0], [10.0, 150.0, -5.0], [0.0, -5.0, 200.0]])
R_RF = np.array([[900.0, 200.0], [200.0, 1200.0]])
Q = (2.0, 2.0, 0.5)


def _run(
    seed: int,
    prob: float,
    duration: float = 600.0,
    outlier_rate: dict[str, float] | None = None,
    outlier_scale_m: float = 2000.0,
) -> tuple[list[Step], SyntheticStream]:
    profile = load_profile("paper").with_changes(
        q=Q,
        r_radar=R_RADAR,
        r_rf=R_RF,
        nis_probability=prob,
        range_gate_m=1e7,
        init_sources=(RADAR,),
        max_speed_mps=30.0,  # a new track's velocity sigma: 15 m/s
    )
    s = simulate_stream(
        seed, duration, Q, R_RADAR, R_RF, velocity_std=15.0,
        outlier_rate=outlier_rate, outlier_scale_m=outlier_scale_m,
    )  # fmt: skip
    first = next(i for i, m in enumerate(s.measurements) if m.source == RADAR)
    est = FusionEstimator(profile, load_site())
    steps: list[Step] = []
    for m in s.measurements[first:]:
        steps.extend(est.process(m))
    s.outlier = s.outlier[first:]
    return steps, s


@pytest.mark.parametrize("seed", [1, 2])
def test_nis_is_chi_square(seed: int) -> None:
    steps, _ = _run(seed, 1.0 - 1e-12)
    scored = [s for s in steps if s.nis is not None]
    assert all(s.updated for s in steps)
    for dim in (2, 3):
        nis = np.array([s.nis for s in scored if s.dim == dim], dtype=float)
        n = nis.size
        assert n > (100 if dim == 2 else 2000)
        lo, hi = chi2.ppf([0.005, 0.995], n * dim) / n
        assert lo <= nis.mean() <= hi, (
            f"dim {dim}: mean NIS {nis.mean():.3f} not in [{lo:.3f}, {hi:.3f}]"
        )


def test_mean_nis_band_catches_a_mistuned_filter() -> None:
    """The same band fails when the filter's R is 30 % too small (so the test can fail)."""
    profile = load_profile("paper").with_changes(
        q=Q,
        r_radar=R_RADAR * 0.7,
        r_rf=R_RF,
        nis_probability=1 - 1e-12,
        range_gate_m=1e7,
        init_sources=(RADAR,),
    )
    s = simulate_stream(1, 600.0, Q, R_RADAR, R_RF)
    est = FusionEstimator(profile, load_site())
    first = next(i for i, m in enumerate(s.measurements) if m.source == RADAR)
    nis = np.array(
        [
            st.nis
            for m in s.measurements[first:]
            for st in est.process(m)
            if st.nis is not None and st.dim == 3
        ]
    )
    hi = chi2.ppf(0.995, nis.size * 3) / nis.size
    assert nis.mean() > hi


@pytest.mark.parametrize("seed", [4, 5])
def test_gate_rejects_five_percent(seed: int) -> None:
    steps, _ = _run(seed, 0.95, duration=900.0)
    scored = [s for s in steps if s.nis is not None]
    n = len(scored)
    k = sum(s.coasted for s in scored)
    # 99.9 % binomial band of the rejection count around p = 0.05
    lo, hi = binom.ppf([0.0005, 0.9995], n, 0.05)
    assert lo <= k <= hi, f"{k} of {n} rejected ({100 * k / n:.2f} %), band [{lo}, {hi}]"
    for dim, thr in ((2, 5.991), (3, 7.815)):
        d = [s for s in scored if s.dim == dim]
        assert all((s.nis > thr) == s.coasted for s in d if s.nis is not None)


def test_injected_outliers_are_rejected() -> None:
    steps, s = _run(7, 0.95, outlier_rate={"radar": 0.02, "rf": 0.2}, outlier_scale_m=2000.0)
    out = s.outlier
    assert out.sum() >= 30
    assert not any(st.updated for st, o in zip(steps, out, strict=True) if o)
    clean = [st for st, o in zip(steps, out, strict=True) if not o and st.nis is not None]
    rate = sum(st.coasted for st in clean) / len(clean)
    assert rate < 0.08  # the clean measurements keep their ~5 % rejection rate
