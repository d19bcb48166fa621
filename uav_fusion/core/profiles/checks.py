"""What a profile key is (:class:`Key`) and what its values may be: the type, bounds and
choice checks the profile loader applies to every key of the schema
(:mod:`~uav_fusion.core.profiles.schema`)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from uav_fusion.core.errors import ConfigError
from uav_fusion.core.records import RADAR, RF

SPEC, PHYSICAL, FITTED, DESIGN = "spec", "physical", "fitted", "design"
BASES = (SPEC, PHYSICAL, FITTED, DESIGN)
# which estimators read a key: every one, the two trackers, the multi-UAV tracker, the paper's
ALL, TRACKER, MULTI, PAPER = "all", "tracker", "multi", "paper"
ESTIMATORS = ("paper", "tracker", "multi")
SOURCES = (RADAR, RF)
# the value kinds (convert and check below)
NUMBER, INTEGER, BOOL, CHOICE, TEXT = "number", "integer", "bool", "choice", "text"
Q3, MATRIX, SOURCE_LIST = "q3", "matrix", "sources"
Q3_LIST, ROWS, PROBS = "q3 list", "rows", "probabilities"


@dataclass(frozen=True)
class Key:
    """One profile key."""

    path: str  # YAML path, dotted: "gating.range_gate_m"
    attr: str  # Profile field, "score.<ScoreConfig field>", "multi.<MultiSettings field>", ""
    kind: str
    basis: str
    meaning: str  # one line
    unit: str = ""
    bounds: str = ""  # "> 0", ">= 0", "[0, 1]", "(0, 1)", "(0, 1]", "[0, inf]": each value's
    choices: tuple[str, ...] = ()
    null: str = ""  # what null means; "" = null is not allowed
    fit: str = ""  # the command that fits a fitted value
    used_by: str = ALL
    size: int = 0  # a matrix's order

    @property
    def name(self) -> str:
        """The key's own name (the last part of its path)."""
        return self.path.rsplit(".", 1)[-1]

    @property
    def section(self) -> str:
        """The section holding the key ("" at the top level)."""
        return self.path.rsplit(".", 1)[0] if "." in self.path else ""

    @property
    def field(self) -> str:
        """The dataclass field the key sets (without its ``score.`` / ``multi.`` prefix)."""
        return self.attr.rsplit(".", 1)[-1]

    def what(self) -> str:
        """What a value must be, for error messages and the README."""
        b = self.bounds
        rng = "" if not b else (f" in {b}" if b[0] in "[(" else f" {b}")
        out = {
            NUMBER: f"a number{rng}",
            INTEGER: f"an integer{rng}",
            BOOL: "true or false",
            CHOICE: "one of " + ", ".join(self.choices),
            TEXT: "text",
            Q3: f"a number{rng} or a list of three ([east, north, up])",
            MATRIX: f"a symmetric positive definite {self.size}x{self.size} matrix",
            SOURCE_LIST: "a list of sources (" + ", ".join(SOURCES) + ")",
            Q3_LIST: f"a list of at least two [east, north, up] densities{rng}",
            ROWS: "a Markov matrix, one row per mode",
            PROBS: "a list of probabilities, one per mode, summing to 1",
        }[self.kind]
        return out + (" or null" if self.null else "")


# --- values -----------------------------------------------------------------------------------
def _short(v: Any) -> str:
    r = repr(v)
    return r if len(r) <= 60 else r[:57] + "..."


def _bad(key: Key, v: Any, where: str) -> ConfigError:
    return ConfigError(f"{where}: {key.path} must be {key.what()}, got {_short(v)}")


def _interval(bounds: str) -> tuple[float, bool, float, bool]:
    """``bounds`` as (low, low included, high, high included)."""
    if bounds[0] in "[(":
        lo, hi = (float(x) for x in bounds[1:-1].split(","))
        return lo, bounds[0] == "[", hi, bounds[-1] == "]"
    op, num = bounds.split()
    x = float(num)
    return {
        ">": (x, False, math.inf, False),
        ">=": (x, True, math.inf, False),
        "<": (-math.inf, False, x, False),
        "<=": (-math.inf, False, x, True),
    }[op]


def in_bounds(x: float, bounds: str) -> bool:
    """``x`` lies in ``bounds`` (no bounds: any finite number)."""
    if not bounds:
        return math.isfinite(x)
    lo, lo_in, hi, hi_in = _interval(bounds)
    return (x > lo or (lo_in and x == lo)) and (x < hi or (hi_in and x == hi))


def _number(v: Any) -> float | None:
    if isinstance(v, bool) or not isinstance(v, int | float):
        return None
    try:
        return float(v)
    except OverflowError:  # an integer beyond the float range
        return None


def _q3(key: Key, v: Any, where: str) -> tuple[float, float, float]:
    x = _number(v)
    vals = [x, x, x] if x is not None else v
    if not isinstance(vals, list | tuple) or len(vals) != 3:
        raise _bad(key, v, where)
    out = [_number(e) for e in vals]
    if any(e is None for e in out):
        raise _bad(key, v, where)
    return (float(out[0] or 0.0), float(out[1] or 0.0), float(out[2] or 0.0))


def convert(key: Key, v: Any, where: str) -> Any:
    """A YAML value of ``key`` as the dataclass holds it (its type checked; :func:`check` checks
    its bounds and choices). A wrong one stops with ``where`` (the file) and the key named."""
    if v is None:
        if key.kind == SOURCE_LIST and key.null:
            return ()
        if key.null or key.kind == TEXT:
            return None
        raise _bad(key, v, where)
    kind = key.kind
    if kind in (NUMBER, INTEGER):
        x = _number(v)
        if x is None or (kind == INTEGER and not (math.isfinite(x) and x.is_integer())):
            raise _bad(key, v, where)
        return int(x) if kind == INTEGER else x
    if kind in (BOOL, CHOICE):
        if not isinstance(v, bool if kind == BOOL else str):
            raise _bad(key, v, where)
        return v
    if kind == TEXT:
        if isinstance(v, bool) or not isinstance(v, str | int | float):
            raise _bad(key, v, where)
        return str(v)
    if kind == Q3:
        return _q3(key, v, where)
    if kind == MATRIX:
        try:
            return np.asarray(v, dtype=float)
        except (TypeError, ValueError, OverflowError):
            raise _bad(key, v, where) from None
    if not isinstance(v, list):
        raise _bad(key, v, where)
    if kind == SOURCE_LIST:
        return tuple(str(s) for s in v)
    if kind == Q3_LIST:
        return tuple(_q3(Key(**{**key.__dict__, "path": f"{key.path}[{i}]", "kind": Q3}), q,
                         where) for i, q in enumerate(v))
    if kind == ROWS:
        return tuple(_numbers(key, row, where) for row in v)
    return _numbers(key, v, where)  # PROBS


def _numbers(key: Key, v: Any, where: str) -> tuple[float, ...]:
    nums = [_number(x) for x in v] if isinstance(v, list) else [None]
    if any(x is None for x in nums):
        raise _bad(key, v, where)
    return tuple(float(x or 0.0) for x in nums)


def check(key: Key, value: Any, where: str) -> None:
    """A dataclass value of ``key`` against its type, bounds and choices (what the loader and
    :meth:`Profile.with_changes` both apply)."""
    if value is None:
        if key.null or key.kind == TEXT:
            return
        raise _bad(key, value, where)
    kind = key.kind
    if kind == NUMBER:
        ok = _number(value) is not None and in_bounds(float(value), key.bounds)
    elif kind == INTEGER:
        ok = isinstance(value, int) and not isinstance(value, bool)
        ok = ok and in_bounds(float(value), key.bounds)
    elif kind == BOOL:
        ok = isinstance(value, bool)
    elif kind == CHOICE:
        ok = value in key.choices
    elif kind == SOURCE_LIST:
        ok = all(s in SOURCES for s in value)
    elif kind == Q3:
        ok = len(value) == 3 and all(in_bounds(float(x), key.bounds) for x in value)
    elif kind == MATRIX:
        _check_matrix(key, value, where)
        return
    elif kind == Q3_LIST:
        for i, q in enumerate(value):
            check(Key(**{**key.__dict__, "path": f"{key.path}[{i}]", "kind": Q3}), q, where)
        return
    else:  # TEXT; ROWS and PROBS depend on the number of modes (profile.py)
        return
    if not ok:
        raise _bad(key, value, where)


def _check_matrix(key: Key, R: Any, where: str) -> None:
    w = f"{where}: {key.path}"
    n = key.size
    a = np.asarray(R, dtype=float)
    if a.shape != (n, n):
        raise ConfigError(f"{w}: must be a {n}x{n} matrix, got shape {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ConfigError(f"{w}: must be finite")
    if not np.allclose(a, a.T, rtol=1e-9, atol=1e-9):
        raise ConfigError(f"{w}: must be symmetric")
    if np.min(np.linalg.eigvalsh(a)) <= 0:
        raise ConfigError(f"{w}: must be positive definite")


def validate_transition(m: object, n_modes: int, where: str) -> tuple[tuple[float, ...], ...]:
    """A Markov transition matrix: ``n_modes`` x ``n_modes``, entries in [0, 1], rows summing
    to 1 (within 1e-9). Raises ValueError naming ``where`` and the fault."""
    try:
        a = np.asarray(m, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"{where}: must be a {n_modes}x{n_modes} matrix of numbers") from None
    if a.shape != (n_modes, n_modes):
        raise ValueError(f"{where}: must be {n_modes}x{n_modes} (one row per mode), got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{where}: entries must be finite")
    if np.any(a < 0) or np.any(a > 1):
        raise ValueError(f"{where}: entries must lie in [0, 1]")
    sums = a.sum(axis=1)
    bad = np.flatnonzero(np.abs(sums - 1.0) > 1e-9)
    if bad.size:
        i = int(bad[0])
        raise ValueError(f"{where}: row {i} sums to {sums[i]:.12g}, not 1")
    return tuple(tuple(float(v) for v in row) for row in a)
