"""
The stroke rule of the analyses: a drive input outside the drive's stroke is refused.

``flexure-sim simulate`` (static and dynamic), ``modes``, ``frf``, ``linearize``,
``sensitivity`` and ``sweep`` take drive inputs (``simulate``'s dynamic run: a command). Each
refuses a value outside its drive's stroke ``[min, max]`` (the mechanism file's ``stroke``, in
the drive's unit: m, rad on theta, N or N m for a force drive; a command to a piezo
``actuator:`` taking volts lies in its voltage range ``[v_min, v_max]``), with one line
naming the drive, the value and the stroke: the actuator cannot get there, and stage_node
clamps such a command to the stroke. To analyse a longer actuator, widen ``stroke`` in the
mechanism file; ``simulate --stroke-limit`` reports the input at which the first hinge yields,
which may lie beyond the stroke.
"""
from __future__ import annotations

from typing import Optional, Sequence

from flexure_sim.errors import FlexureSimError
from flexure_sim.engine.mechanism.parts import coordinate_unit

#: What the refusal adds: why, and what to do instead.
REASON = ("the actuator cannot reach it (stage_node clamps a command there); to analyse a "
          "longer actuator, widen the drive's stroke in the mechanism file")


class StrokeError(FlexureSimError, ValueError):
    """A drive input lies outside its drive's stroke (the message names both)."""


def limits(drive, command: bool = False) -> tuple[float, float, str]:
    """
    Return a drive's range and unit: its stroke, or with ``command`` its command's range.

    The command of a piezo actuator taking volts lies in its voltage range (V).
    """
    spec = drive.actuator
    if command and spec is not None and spec.command == "voltage":
        return spec.v_min, spec.v_max, "V"
    unit = coordinate_unit(drive.coordinate, drive.kind == "force")
    return drive.stroke[0], drive.stroke[1], unit


def outside(drive, value: float, alone: bool, command: bool = False) -> Optional[str]:
    """
    Return why ``value`` is not an input of ``drive`` (None: it lies within the stroke).

    ``alone``: the mechanism's only drive ("the drive's stroke"), else it is named.
    """
    lo, hi, unit = limits(drive, command)
    if lo <= value <= hi:
        return None
    which = "the drive's" if alone else f"drive {drive.name}'s"
    return f"{value} {unit} is outside {which} stroke [{lo}, {hi}] {unit}"


def check(drives: Sequence, values: Sequence[float], option: str,
          command: bool = False) -> None:
    """Raise StrokeError for the first value outside its drive's stroke (module doc)."""
    for drive, value in zip(drives, values):
        reason = outside(drive, float(value), len(drives) == 1, command)
        if reason is not None:
            raise StrokeError(f"{option}: {reason}: {REASON}")
