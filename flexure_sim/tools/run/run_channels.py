"""
The drives and outputs of a recorded run, by name, with their topics and units.

A mechanism with one displacement drive records ``drive/displacement`` (command),
``drive/input`` and ``drive/force``; one with several drives (or a force drive) records per
drive ``drive/<name>/displacement`` or, for a force drive, ``drive/<name>/force`` (command),
``drive/<name>/input`` and ``drive/<name>/force`` or ``drive/<name>/position``
(`flexure_sim.topics`). Likewise one output records ``output/displacement``, several one
``output/<name>/displacement`` each. `drive_channels` and `output_channels` find them in a
run's topic names; names are ordered as the ``flexure_sim`` metadata record lists them
(``drives``: ``name:kind,...``; ``outputs``), units come from the recorded mechanism (rad on
a ``theta`` coordinate, N or N m for a force drive), m when it cannot be loaded. A drive
whose piezo actuator takes volts is commanded on ``drive/voltage`` (``drive/<name>/voltage``)
in V.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable, Iterable, Optional

from flexure_sim.engine.mechanism.parts import coordinate_unit as _unit
from flexure_sim.topics import (
    COMMAND, COMMAND_VOLTAGE, DRIVE_FORCE, DRIVE_INPUT, OUTPUT, drive_command, drive_force,
    drive_input, drive_position, output_displacement,
)


@dataclass(frozen=True)
class DriveChannel:
    """
    One drive of a run: its name, kind and topics (relative to the run's namespace).

    ``command``: the command topic; ``input``: the applied input (m, rad, or for a force drive
    N, N m); ``response``: the drive's other signal, the actuator force of a displacement drive
    (``force``) or the body's displacement of a force drive (``position``), None if not
    recorded. ``unit``: the unit of the input (and of the command, but for a drive commanded
    in volts: ``command_unit`` V, topic ``drive/voltage`` or ``drive/<name>/voltage``);
    ``response_unit`` that of ``response``.
    """

    name: str
    kind: str
    command: str
    input: str
    response: Optional[str]
    unit: str
    response_unit: str
    command_unit: str = ""

    def __post_init__(self) -> None:
        if not self.command_unit:
            object.__setattr__(self, "command_unit", self.unit)


@dataclass(frozen=True)
class OutputChannel:
    """One output of a run: name, topic (relative) and unit (m, or rad on theta)."""

    name: str
    topic: str
    unit: str


def _listed(metadata: dict[str, str], key: str) -> list[tuple[str, str]]:
    """(name, kind) of the metadata's ``drives`` / ``outputs`` list (kind '' if not given)."""
    out = []
    for item in metadata.get(key, "").split(","):
        name, _, kind = item.strip().partition(":")
        if name:
            out.append((name, kind))
    return out


def _names_under(topics: Iterable[str], prefix: str, leaf: str) -> set[str]:
    """Names ``n`` of the topics ``<prefix>n/<leaf>``."""
    found = set()
    for name in topics:
        if name.startswith(prefix):
            parts = name[len(prefix):].split("/")
            if len(parts) == 2 and parts[1] == leaf and parts[0]:
                found.add(parts[0])
    return found


def _ordered(found: set[str], listed: list[str]) -> list[str]:
    order = [x for x in listed if x in found]
    return order + sorted(found - set(order))


def drive_channels(topics: Iterable[str], topic: Callable[[str], str],
                   metadata: dict[str, str], mechanism: Any = None) -> list[DriveChannel]:
    """
    Return the drives recorded in a run.

    ``topics``: the run's absolute topic names; ``topic``: relative -> absolute name (the
    run's namespace); ``mechanism``: the recorded mechanism (for units), or None.
    """
    topics = set(topics)
    listed = _listed(metadata, "drives")
    kinds = dict(listed)
    coordinates = {}
    if mechanism is not None:
        for d in getattr(mechanism, "drives", ()):
            coordinates[d.name] = d.coordinate
            kinds.setdefault(d.name, d.kind)
    if topic(DRIVE_INPUT) in topics:
        name = listed[0][0] if len(listed) == 1 else "drive"
        unit = _unit(coordinates.get(name))
        volts = topic(COMMAND_VOLTAGE) in topics and topic(COMMAND) not in topics
        return [DriveChannel(name, "displacement", COMMAND_VOLTAGE if volts else COMMAND,
                             DRIVE_INPUT, DRIVE_FORCE if topic(DRIVE_FORCE) in topics else None,
                             unit, _unit(coordinates.get(name), True), "V" if volts else "")]
    out = []
    for name in _ordered(_names_under(topics, topic("drive/"), "input"),
                         [n for n, _ in listed]):
        kind = kinds.get(name) or ("force" if topic(drive_position(name)) in topics
                                   else "displacement")
        coordinate = coordinates.get(name)
        if kind == "force":
            response = drive_position(name)
            unit, response_unit = _unit(coordinate, True), _unit(coordinate)
        else:
            response = drive_force(name)
            unit, response_unit = _unit(coordinate), _unit(coordinate, True)
        command = drive_command(name, kind)
        volts = kind == "displacement" and topic(drive_command(name, "voltage")) in topics \
            and topic(command) not in topics
        out.append(DriveChannel(name, kind, drive_command(name, "voltage") if volts else command,
                                drive_input(name), response if topic(response) in topics
                                else None, unit, response_unit, "V" if volts else ""))
    return out


def output_channels(topics: Iterable[str], topic: Callable[[str], str],
                    metadata: dict[str, str], mechanism: Any = None) -> list[OutputChannel]:
    """Return the outputs recorded in a run (arguments as `drive_channels`)."""
    topics = set(topics)
    listed = [n for n, _ in _listed(metadata, "outputs")]
    coordinates = {}
    if mechanism is not None:
        for o in getattr(mechanism, "all_outputs", ()):
            coordinates[o.name] = o.coordinate
    if topic(OUTPUT) in topics:
        name = listed[0] if len(listed) == 1 else "output"
        return [OutputChannel(name, OUTPUT, _unit(coordinates.get(name)))]
    names = _ordered(_names_under(topics, topic("output/"), "displacement"), listed)
    return [OutputChannel(n, output_displacement(n), _unit(coordinates.get(n))) for n in names]


def is_single_drive(topics: Iterable[str], topic: Callable[[str], str]) -> bool:
    """Whether a run has today's single-drive, single-output topics (``drive/input`` ...)."""
    topics = set(topics)
    return topic(DRIVE_INPUT) in topics and topic(OUTPUT) in topics


def gain_unit(output_unit: str, input_unit: str) -> str:
    """Return the unit of an output per unit of a drive's input (``m/m``, ``rad/m``...)."""
    return f"{output_unit}/({input_unit})" if " " in input_unit else f"{output_unit}/{input_unit}"


def stroke_keys(drive: Optional[DriveChannel]) -> tuple[str, str]:
    """Return the metadata keys of a drive's stroke (``drives.<name>.stroke_min``...)."""
    if drive is None or drive.command == COMMAND:
        return "stroke_min", "stroke_max"
    return f"drives.{drive.name}.stroke_min", f"drives.{drive.name}.stroke_max"


def recorded_stroke(metadata: dict[str, str], keys: tuple[str, str]
                    ) -> Optional[tuple[float, float]]:
    """Return the stroke (min, max) recorded under ``keys`` at the start, None if absent."""
    try:
        return float(metadata[keys[0]]), float(metadata[keys[1]])
    except (KeyError, ValueError):
        return None
