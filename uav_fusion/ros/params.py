"""Parameter declaration for the nodes: descriptors, ranges, choices, clear rejections.

Each node lists its parameters as :class:`Param` specs and calls :func:`declare_all`. Ranges
go into the ROS descriptor (``FloatingPointRange`` / ``IntegerRange``, visible to
``ros2 param describe``) and are enforced by rclpy both at start-up (overrides from
``--ros-args -p`` or a ``--params-file``) and at run time (``set_parameters`` returns
``successful=False`` with the reason). Choices and other checks that a range cannot express
are enforced by an on-set callback installed here. A bad value at start-up raises
:class:`ParamError` naming the parameter, the value and what is allowed; the node runtime
(:mod:`uav_fusion.ros.app`) logs it and exits with status 2.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

from rcl_interfaces.msg import (
    FloatingPointRange,
    IntegerRange,
    ParameterDescriptor,
    SetParametersResult,
)
from rclpy.exceptions import ParameterException
from rclpy.node import Node
from rclpy.parameter import Parameter

from uav_fusion.core.errors import ConfigError

Check = Callable[[Any], str | None]  # returns an error text, or None if the value is fine


class ParamError(ConfigError):
    """A parameter value is not acceptable."""


@dataclass(frozen=True)
class Param:
    """One parameter: name, default (its type is the parameter's type), description, limits.

    ``lo``/``hi`` are inclusive bounds (numbers only); ``choices`` restricts a string;
    ``check`` is any further test; ``read_only`` parameters cannot change after start-up.
    """

    name: str
    default: Any
    description: str
    lo: float | None = None
    hi: float | None = None
    choices: tuple[str, ...] | None = None
    check: Check | None = None
    read_only: bool = True

    def descriptor(self) -> ParameterDescriptor:
        d = ParameterDescriptor(description=self.description, read_only=self.read_only)
        if isinstance(self.default, bool):
            return d
        if isinstance(self.default, int) and (self.lo is not None or self.hi is not None):
            lo = int(self.lo) if self.lo is not None else -(2**63)
            hi = int(self.hi) if self.hi is not None else 2**63 - 1
            d.integer_range = [IntegerRange(from_value=lo, to_value=hi, step=0)]
        elif isinstance(self.default, float) and (self.lo is not None or self.hi is not None):
            lo_f = float(self.lo) if self.lo is not None else -math.inf
            hi_f = float(self.hi) if self.hi is not None else math.inf
            d.floating_point_range = [FloatingPointRange(from_value=lo_f, to_value=hi_f, step=0.0)]
        if self.choices:
            d.additional_constraints = "one of: " + ", ".join(self.choices)
        return d

    def problem(self, value: Any) -> str | None:
        """Why ``value`` is not acceptable beyond type and range, or None."""
        if self.choices is not None and value not in self.choices:
            return (
                f"parameter '{self.name}' = {value!r} is not allowed; "
                f"choose one of: {', '.join(self.choices)}"
            )
        if isinstance(value, float) and not math.isfinite(value) and self.lo is not None:
            return f"parameter '{self.name}' must be finite, got {value!r}"
        if self.check is not None:
            why = self.check(value)
            if why:
                return f"parameter '{self.name}' = {value!r}: {why}"
        return None

    def allowed(self) -> str:
        kind = type(self.default).__name__
        if self.choices:
            return f"a {kind}, one of {', '.join(self.choices)}"
        if self.lo is not None or self.hi is not None:
            return f"a {kind} in [{self.lo}, {self.hi}]"
        return f"a {kind}"


def declare_all(node: Node, specs: Sequence[Param]) -> dict[str, Any]:
    """Declare ``specs`` on ``node``; return their values by name.

    Raises :class:`ParamError` for the first value that is not acceptable, and installs a
    callback that rejects bad values set at run time.
    """
    by_name = {p.name: p for p in specs}
    values: dict[str, Any] = {}
    for spec in specs:
        try:
            par = node.declare_parameter(spec.name, spec.default, spec.descriptor())
        except ParameterException as exc:
            raise ParamError(
                f"{node.get_name()}: bad parameter '{spec.name}' (must be {spec.allowed()}): {exc}"
            ) from None
        why = spec.problem(par.value)
        if why:
            raise ParamError(f"{node.get_name()}: {why}")
        values[spec.name] = par.value

    def on_set(params: list[Parameter]) -> SetParametersResult:
        for par in params:
            spec = by_name.get(par.name)
            if spec is None:
                continue
            why = spec.problem(par.value)
            if why:
                return SetParametersResult(successful=False, reason=why)
        return SetParametersResult(successful=True)

    node.add_on_set_parameters_callback(on_set)
    return values


def positive(value: Any) -> str | None:
    """A check: the number must be > 0."""
    return None if value > 0 else "must be > 0"


def not_empty(value: Any) -> str | None:
    """A check: the string must not be empty (topic names, frames)."""
    return None if str(value).strip() else "must not be empty"


def topic_param(name: str, default: str, what: str) -> Param:
    """A topic name (or frame id) parameter: a string that must not be empty."""
    return Param(name, default, what, check=not_empty)


def rf_output_params() -> list[Param]:
    """The RF topics rf_replay and rf_stream publish alike."""
    return [
        topic_param("rf_topic", "rf/fix", "PointStamped topic of the RF attempts"),
        topic_param("rf_fixes_topic", "rf/fixes", "every attempt with its quality"),
        Param("publish_fixes", True, "publish the attempts as PointCloud2 too"),
    ]
