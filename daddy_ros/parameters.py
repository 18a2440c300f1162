"""The node's ROS parameters, declared from the one parameter table (``config``), and the
validation of run-time updates (a pre-set callback in the way of ``demo_nodes_py``'s: a
rejected update changes nothing)."""
from __future__ import annotations

import math

from rcl_interfaces.msg import (FloatingPointRange, IntegerRange, ParameterDescriptor,
                                SetParametersResult)
from rclpy.exceptions import InvalidParameterTypeException, InvalidParameterValueException

from daddy_core.catalogue import list_cases, load_thrust_case
from daddy_core.errors import DaddyError
from daddy_core.solver import METHODS

from .config import Parameter, parameters

NAMES = {p.name for p in parameters()}
RUNTIME = {p.name for p in parameters() if p.runtime}   # settable while configured
DEFAULTS = {p.name: p.default for p in parameters()}


def descriptor(p: Parameter) -> ParameterDescriptor:
    """The ROS descriptor of a ``config`` parameter: its description, read_only for the
    ``static`` ones, its range where it has bounds, and when it may change."""
    when = ("settable in every state" if p.runtime else "fixed at construction" if p.static
            else "settable while unconfigured")
    d = ParameterDescriptor(description=p.description, read_only=p.static,
                            additional_constraints=when)
    if p.bounds is not None:
        lo, hi = p.bounds
        if isinstance(p.default, float):
            d.floating_point_range = [FloatingPointRange(from_value=float(lo), to_value=float(hi),
                                                         step=0.0)]
        else:
            d.integer_range = [IntegerRange(from_value=int(lo), to_value=int(hi), step=1)]
    return d


def declare(node, overrides: dict) -> None:
    """Declare every parameter of ``config`` on ``node`` (``overrides``: other defaults); a
    value of the wrong type or out of range is a DaddyError naming the parameter."""
    for p in parameters():
        try:
            node.declare_parameter(p.name, overrides.get(p.name, p.default), descriptor(p))
        except (InvalidParameterValueException, InvalidParameterTypeException) as exc:
            raise DaddyError(f"parameter {p.name}: {exc}") from exc


def problem(p, has_parameter, configured: bool) -> str:
    """Why the update of parameter ``p`` is refused ('' when it is not): the ``runtime`` ones
    in every state (a value of their type, finite; their ranges rclpy checks), every other
    declared one only while unconfigured (configure reads them: they shape the problem or the
    node's interface); an unknown scenario or method always."""
    if p.name in RUNTIME:
        kind = type(DEFAULTS[p.name])
        if type(p.value) is not kind:
            return f"{p.name} must be a {kind.__name__}, got {p.value!r}"
        if kind is float and not math.isfinite(p.value):
            return f"{p.name} must be finite, got {p.value!r}"
        if p.name == "method" and p.value not in METHODS:
            return f"method {p.value!r} is unknown (known: {', '.join(METHODS)})"
        return ""
    if p.name == "scenario" and isinstance(p.value, str):
        try:
            load_thrust_case(p.value)
        except DaddyError as exc:
            if p.value in list_cases():
                return f"scenario: {exc}"
            return (f"scenario {p.value!r} is unknown (known: {', '.join(list_cases())}); "
                    "scenario is also read-only once configured")
    if p.name in NAMES and has_parameter(p.name) and configured:
        return (f"{p.name} is read-only once configured: it shapes the problem or the node's "
                "interface (clean the node up to change it)")
    return ""


def verdict(params, has_parameter, configured: bool) -> SetParametersResult:
    """The result of a set-parameters request: the first problem, or success."""
    why = next((r for r in (problem(p, has_parameter, configured) for p in params) if r), None)
    return SetParametersResult(successful=why is None, reason=why or "")
