"""One estimator interface: radar frames and RF fixes in, outputs up to a time out.

Three estimators implement :class:`Estimator`, chosen by a profile's ``estimator`` key:

- ``paper``: the paper's gated asynchronous CV Kalman filter
  (:class:`~uav_fusion.core.estimators.paper.FusionEstimator`): the selected radar reports and
  the RF fixes, one filter step each; ``fusion/odom`` carries every step;
- ``tracker``: the single-UAV tracker (:class:`~uav_fusion.core.estimators.tracker.Tracker`):
  every report of every radar frame, one step each, and a fixed-rate output;
- ``multi``: the multi-UAV tracker (:class:`~uav_fusion.core.estimators.multi.MultiTracker`):
  every confirmed track at every epoch of its fixed-rate output.

Every consumer drives them the same way (the live pipeline
:mod:`uav_fusion.core.live.pipeline`, :func:`drive` for offline runs, the benchmark, the sweeps
and the analyses): hand it the radar frames and RF attempts in time order
(:meth:`Estimator.radar_frame`, :meth:`Estimator.rf_attempt`), declare time passed
(:meth:`Estimator.advance`), and collect the :class:`~uav_fusion.core.estimators.grid.Outputs`
each call returns. Empty radar frames and failed RF attempts carry nothing to fuse: consumers
do not hand them over.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Protocol

import numpy as np
import numpy.typing as npt

from uav_fusion.core.errors import ConfigError
from uav_fusion.core.estimators.grid import Outputs
from uav_fusion.core.estimators.steps import Step
from uav_fusion.core.profiles.model import Profile
from uav_fusion.core.records import Flight, RadarFrame, RfAttempt
from uav_fusion.core.site import Site

FloatArray = npt.NDArray[np.float64]

#: The estimators a profile's ``estimator`` key may name.
ESTIMATORS = ("paper", "tracker", "multi")

#: What an estimator reads: ``selected`` (the paper's selected radar reports, each with its
#: covariance, on ``radar/pose``, and RF fixes on ``rf/fix``) or ``frames`` (every report of
#: every radar frame on ``radar/tracks``, every RF attempt with its quality on ``rf/fixes``).
READS = ("selected", "frames")

Input = RadarFrame | RfAttempt


class Estimator(Protocol):
    """What every estimator offers its drivers (see the module text)."""

    #: ``paper``, ``tracker`` or ``multi``
    kind: str
    #: ``fusion/odom`` is the fixed-rate output (True) or every filter step (False)
    fixed_rate: bool
    #: the inputs it reads: one of :data:`READS`
    reads: str
    profile: Profile
    counters: dict[str, int]

    def radar_frame(self, frame: RadarFrame) -> Outputs:
        """One radar frame (all reports share its time; at least one report)."""

    def rf_attempt(self, attempt: RfAttempt) -> Outputs:
        """One RF attempt with a position (``ok``)."""

    def advance(self, t: float) -> Outputs:
        """Everything up to ``t`` has been handed over: the fixed-rate epochs up to ``t``."""

    def finish(self) -> Outputs:
        """The input ended: what is still held back (smoothing windows; the epochs up to the
        output's end time when one was given)."""

    def restart(self, reason: str) -> None:
        """The input's time starts over (a bag loop): forget the track(s) and the time."""

    def measurement(self, step: Step) -> tuple[FloatArray, FloatArray | None] | None:
        """The position a step's measurement gave (``z``; 3 values, or 2 for a horizontal-only
        one) and the covariance it was fused with (None: not known), for views and the
        accepted-measurement topics; None when the step has none."""

    def status(self) -> dict[str, object]:
        """Estimator-specific diagnostics (key -> value)."""

    def flight_input(self, flight: Flight) -> list[Input]:
        """What this estimator reads from a whole flight, in processing order (offline)."""


def make_estimator(
    profile: Profile,
    site: Site,
    grid_hz: float | None = 10.0,
    t0: float | None = None,
    t1: float | None = None,
    *,
    kind: str | None = None,
    live: bool = False,
) -> Estimator:
    """The estimator ``profile`` names (``kind`` overrides it), with a fixed-rate output at
    ``grid_hz`` on ``[t0, t1]`` (None: from the first input, without end). ``grid_hz`` None:
    no fixed-rate output (an offline run that grids its final steps itself; the multi-UAV
    tracker needs one).

    ``live`` (a node): a tracker profile with a finite ``smoother.lag_s`` also gives fixed-lag
    smoothed estimates as they become final (offline runs smooth the whole run instead), and
    the paper's filter keeps no fixed-rate output (its ``fusion/odom`` is every step)."""
    name = kind or profile.estimator
    if name == "paper":
        from uav_fusion.core.estimators.paper import FusionEstimator

        return FusionEstimator(profile, site, None if live else grid_hz, t0, t1)
    if name == "tracker":
        from uav_fusion.core.estimators.tracker import Tracker

        return Tracker(profile, site, grid_hz=grid_hz, t0=t0, t1=t1, smooth=live)
    if name == "multi":
        from uav_fusion.core.estimators.multi import MultiTracker

        if grid_hz is None:
            raise ValueError("the multi-UAV estimator needs a fixed-rate output (grid_hz)")
        return MultiTracker(profile, site, grid_hz=grid_hz, t0=t0, t1=t1)
    raise ConfigError(
        f"{profile.source or profile.name}: estimator {name!r} is not one of "
        f"{', '.join(ESTIMATORS)}"
    )


def feed(est: Estimator, item: Input) -> Outputs:
    """Hand one radar frame or RF attempt to ``est``."""
    if isinstance(item, RadarFrame):
        return est.radar_frame(item)
    return est.rf_attempt(item)


def drive(est: Estimator, items: Iterable[Input], t_end: float | None = None) -> Outputs:
    """Feed ``items`` (time order) through ``est``, then declare time up to ``t_end`` passed
    (None: the last item's time) and finish; every output, in order."""
    out = Outputs()
    last: float | None = None
    for item in items:
        out.add(feed(est, item))
        last = item.t
    end = t_end if t_end is not None else last
    if end is not None:
        out.add(est.advance(end))
    out.add(est.finish())
    return out
