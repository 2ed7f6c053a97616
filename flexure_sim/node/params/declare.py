"""
The stage node's parameters declared to ROS.

A ``ParameterDescriptor`` per `ParamSpec` (description with unit, range, read-only, constraints),
and ``-p publish_rate:=500`` accepted for double parameters.
"""
from __future__ import annotations

from typing import Any

from rcl_interfaces.msg import (
    FloatingPointRange,
    IntegerRange,
    ParameterDescriptor,
    ParameterType,
)
from rclpy.parameter import Parameter

from flexure_sim.node.inputs.drive_bank import LIMIT_KEYS
from flexure_sim.node.publish.interface import TIME_MODES
from flexure_sim.node.params.table import (
    COMMAND_RELIABILITIES, RECORD_FORMATS, SPACES, ParamSpec, parameter_specs,
)

_TYPE_CODES = {
    float: ParameterType.PARAMETER_DOUBLE,
    bool: ParameterType.PARAMETER_BOOL,
    str: ParameterType.PARAMETER_STRING,
    int: ParameterType.PARAMETER_INTEGER,
}
_CONSTRAINTS = {
    "time_mode": f"one of {', '.join(TIME_MODES)}",
    "command_reliability": f"one of {', '.join(COMMAND_RELIABILITIES)}",
    "record_format": f"one of {', '.join(RECORD_FORMATS)}",
    "space": f"one of {', '.join(SPACES)}",
    "sim_step": "> 0 and divides 1/publish_rate",
    "slew_rate": "> 0",
    "stroke_min": "stroke_min <= stroke_max; the engine must find a static equilibrium there",
    "stroke_max": "stroke_min <= stroke_max; the engine must find a static equilibrium there",
}


def descriptor(spec: ParamSpec) -> ParameterDescriptor:
    """Return the ROS descriptor of one parameter."""
    d = ParameterDescriptor(
        name=spec.name,
        type=_TYPE_CODES[spec.type],
        description=spec.description + (f" [{spec.unit}]" if spec.unit else ""),
        read_only=spec.read_only,
        additional_constraints=_CONSTRAINTS.get(spec.name.rpartition(".")[2], ""),
    )
    if spec.type is float and spec.low is not None and spec.high is not None:
        d.floating_point_range = [
            FloatingPointRange(from_value=float(spec.low), to_value=float(spec.high), step=0.0)]
    if spec.type is int and spec.low is not None and spec.high is not None:
        d.integer_range = [IntegerRange(from_value=int(spec.low), to_value=int(spec.high), step=1)]
    return d


def declare(node: Any, spec: ParamSpec) -> None:
    """Declare ``spec`` on ``node`` with its default and descriptor."""
    node.declare_parameter(spec.name, spec.default, descriptor(spec))


def coerce_integer_overrides(node: Any) -> None:
    """
    Accept ``-p publish_rate:=500`` for double parameters (ROS would reject the int).

    Must run before the parameters are declared.
    """
    overrides = getattr(node, "_parameter_overrides", None)
    if not isinstance(overrides, dict):
        return
    floats = {s.name for s in parameter_specs() if s.type is float}
    for name, p in list(overrides.items()):
        per_drive = name.startswith("drives.") and name.rpartition(".")[2] in LIMIT_KEYS
        if (name in floats or per_drive) and p.type_ == Parameter.Type.INTEGER:
            overrides[name] = Parameter(name, Parameter.Type.DOUBLE, float(p.value))


def undeclared_drive_overrides(node: Any, drive_names: list[str], single: bool) -> str:
    """
    Why a ``-p drives.<name>.<key>:=...`` override does not apply ("" if every one does).

    ROS ignores overrides of parameters never declared: a typo in a drive's name or key would
    leave the limit at its default without a word, so it is refused naming the drives.
    """
    overrides = getattr(node, "_parameter_overrides", None)
    if not isinstance(overrides, dict):
        return ""
    for name in sorted(overrides):
        if name.startswith("drives.") and not node.has_parameter(name):
            if single:
                return (f"{name}: this mechanism has a single drive, whose limits are "
                        f"{', '.join(LIMIT_KEYS)} (no drives.<name>.*)")
            if not drive_names:
                return f"{name}: this mechanism has no drive"
            return (f"{name}: no such parameter; the drives are {', '.join(drive_names)}, "
                    f"each with drives.<name>.{{{', '.join(LIMIT_KEYS)}}}")
    return ""
