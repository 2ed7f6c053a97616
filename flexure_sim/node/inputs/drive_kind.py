"""
What a drive's command is, and its unit and limits in that unit (pure Python, no ROS).

A displacement drive takes metres (radians on theta), a force drive newtons (N m), and a
displacement drive whose ``actuator:`` block says ``command: voltage`` (engine/actuators/piezo.py)
volts.
"""
from __future__ import annotations

from typing import Any

from flexure_sim.engine.mechanism.parts import coordinate_unit
from flexure_sim.engine.actuators.piezo import command_limits as command_limits_of


def command_kind(drive: Any) -> str:
    """
    Return what a drive's command is: ``displacement``, ``force``, or ``voltage``.

    ``voltage``: a displacement drive whose ``actuator:`` block takes volts
    (engine/actuators/piezo.py).
    """
    if drive.kind == "force":
        return "force"
    actuator = getattr(drive, "actuator", None)
    return "voltage" if actuator is not None and actuator.command == "voltage" else "displacement"


def command_limits(drive: Any) -> tuple[float, float, float]:
    """
    Return a drive's (stroke_min, stroke_max, slew_rate) in its command's unit.

    The mechanism file's stroke and slew rate; with an ``actuator:`` block, in its command's
    unit (`piezo.command_limits`: a voltage command's [v_min, v_max] V and slew_rate / d V/s).
    """
    if getattr(drive, "actuator", None) is None:
        return float(drive.stroke[0]), float(drive.stroke[1]), float(drive.slew_rate)
    return tuple(float(v) for v in command_limits_of(drive.actuator, drive.stroke,
                                                     drive.slew_rate))


def units(drive: Any) -> tuple[str, str]:
    """(command unit, slew-rate unit) of a drive: m, rad, N, N m or V."""
    if command_kind(drive) == "voltage":
        return "V", "V/s"
    unit = coordinate_unit(drive.coordinate, drive.kind == "force")
    return unit, f"{unit}/s"
