"""What an estimator did with one measurement: :class:`Step` and its statuses.

Every measurement an estimator is given yields exactly one :class:`Step`. Statuses:

* ``initialised`` / ``reset``: a confirmed track (re)started from this measurement
  (``reset`` when a previous track was dropped; ``reason`` says why);
* ``updated``: accepted and fused;
* ``coasted``: rejected by the NIS gate; the estimate is the prediction;
* ``tentative``: the measurement started a tentative track (``reason`` ``start``) or was
  tested against one (``hit``, or the miss's ``nis`` / ``speed``); not a filter estimate;
* ``discarded``: not a filter step at all (``range_gate``, ``class_prob``, ``not_selected``,
  ``out_of_order``, ``no_track``, ``invalid``; the trackers' ``coast``, ``large_rcs``,
  ``score``, ``unreachable``, ``ground``); the track is not changed.

The paper's "KF all steps" are the steps that are neither discarded nor tentative; its
"updated estimates" the steps that used their measurement (updated, initialised, reset) and its
"coasted estimates" the coasted steps. The step that confirms a tentative track is ``updated``.
"""

from __future__ import annotations

import functools
import math
import struct

import numpy as np
import numpy.typing as npt
from scipy.stats import chi2

from uav_fusion.core.estimators.kalman import expand_upper

FloatArray = npt.NDArray[np.float64]

UPDATED = "updated"
COASTED = "coasted"
INITIALISED = "initialised"
RESET = "reset"
DISCARDED = "discarded"
TENTATIVE = "tentative"
STATUSES = (UPDATED, COASTED, INITIALISED, RESET, TENTATIVE, DISCARDED)
NOT_COUNTED = frozenset((DISCARDED, TENTATIVE))
USED = frozenset((UPDATED, INITIALISED, RESET))

# a step's state: x (6 values) then the upper triangle of P (21 values), as packed doubles
_STATE = struct.Struct("27d")
pack_state = _STATE.pack
_UNPACK = _STATE.unpack
NAN_STATE = pack_state(*(math.nan,) * 27)


@functools.lru_cache(maxsize=64)
def nis_gate(probability: float, dim: int) -> float:
    """NIS gate: the chi-square quantile at ``probability`` for ``dim`` degrees of freedom
    (computed once per pair: estimators are built often, by nodes, tests and sweeps)."""
    return float(chi2.ppf(probability, dim))


class Step:
    """What the estimator did with one measurement, and the estimate at its time.

    ``x`` (6,) and ``P`` (6, 6) are the state after this measurement (NaN when no track
    exists); they are built on first access from ``state``, the 27 packed doubles of ``x``
    and of the upper triangle of ``P`` (row by row). Packed bytes rather than Python floats
    keep a long run's steps small: fewer objects to allocate, hold and scan for the garbage
    collector.
    """

    __slots__ = (
        "_P",
        "_state",
        "_x",
        "dim",
        "nis",
        "reason",
        "seq",
        "source",
        "status",
        "t",
        "track_id",
    )

    def __init__(
        self,
        t: float,
        source: str,
        status: str,
        reason: str | None,
        nis: float | None,
        state: bytes,
        dim: int,
        track_id: int | None,
        seq: int,
    ) -> None:
        self.t = t
        self.source = source
        self.status = status
        self.reason = reason
        self.nis = nis
        self._state = state
        self._x: FloatArray | None = None
        self._P: FloatArray | None = None
        self.dim = dim
        self.track_id = track_id
        self.seq = seq

    @property
    def x(self) -> FloatArray:
        if self._x is None:
            self._x = np.frombuffer(self._state, dtype=float, count=6).copy()
        return self._x

    @property
    def P(self) -> FloatArray:
        if self._P is None:
            self._P = expand_upper(np.frombuffer(self._state, dtype=float, count=21, offset=48))
        return self._P

    @property
    def values(self) -> tuple[float, ...]:
        """The 27 packed doubles as Python floats: x (6), then P's upper triangle (21, row by
        row, :data:`~uav_fusion.core.estimators.kalman.UPPER_INDEX`); no arrays built."""
        return _UNPACK(self._state)

    @property
    def updated(self) -> bool:
        """The estimate used this measurement (updated, initialised or reset)."""
        return self.status in USED

    @property
    def validated(self) -> bool:
        """The measurement passed every gate (NIS included) and updated the track.

        Unlike :attr:`updated` this excludes track starts, whose measurement was not tested
        against a prediction: the paper's "after validation" rows count these.
        """
        return self.status == UPDATED

    @property
    def coasted(self) -> bool:
        """The measurement failed the NIS gate; the estimate is the prediction."""
        return self.status == COASTED

    @property
    def counted(self) -> bool:
        """A filter step in the paper's sense: an estimate of a confirmed track (every status
        except ``discarded`` and ``tentative``)."""
        return self.status not in NOT_COUNTED

    def __repr__(self) -> str:
        nis = "None" if self.nis is None else f"{self.nis:.3f}"
        return (
            f"Step(t={self.t:.3f}, source={self.source!r}, status={self.status!r}, "
            f"reason={self.reason!r}, nis={nis}, dim={self.dim}, track_id={self.track_id}, "
            f"seq={self.seq}, x={np.array2string(self.x, precision=2)})"
        )


class TrackerStep(Step):
    """A :class:`Step` with the measurement, its object's UAV score, the robust weight, the
    IMM mode probabilities and the track segment (a new one starts at every track start)."""

    __slots__ = ("mode_probs", "q_eff", "score", "segment", "weight", "z")

    def __init__(
        self, t: float, source: str, status: str, reason: str | None, nis: float | None,
        state: bytes, dim: int, track_id: int | None, seq: int, z: tuple[float, ...],
        score: float | None, weight: float | None, mode_probs: tuple[float, ...], segment: int,
        q_eff: tuple[float, float, float],
    ) -> None:  # fmt: skip
        self.t = t
        self.source = source
        self.status = status
        self.reason = reason
        self.nis = nis
        self._state = state
        self._x = None
        self._P = None
        self.dim = dim
        self.track_id = track_id
        self.seq = seq
        self.z = z
        self.score = score
        self.weight = weight
        self.mode_probs = mode_probs
        self.segment = segment
        self.q_eff = q_eff

    def with_state(self, state: bytes) -> TrackerStep:
        """A copy with another packed state (x then the upper triangle of P)."""
        return TrackerStep(
            self.t, self.source, self.status, self.reason, self.nis, state, self.dim,
            self.track_id, self.seq, self.z, self.score, self.weight, self.mode_probs,
            self.segment, self.q_eff,
        )  # fmt: skip
