"""
Mechanisms as plain data: bodies, hinges, constraints, drive (the MjModel of flexure_sim).

A mechanism holds constants only; the evolving state lives in ``solver.State``.

Coordinates: every body has a pose (x, y, theta) of its body frame (at its mass centre) in
the root frame ``stage`` (REP-103: x forward/right in the drawing, y up, z out of the
plane, theta counter-clockwise), and velocities (vx, vy, omega) in the root frame.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import ClassVar, Optional, Union

import numpy as np

from flexure_sim.engine.mechanism.damping_models import DampingSpec
from flexure_sim.engine.laws.quadratic import HingeLaw
from flexure_sim.engine.actuators.piezo import PiezoSpec
from flexure_sim.engine.actuators.sensor import SensorSpec
from flexure_sim.engine.hinges.stress import StressGeometry

#: Names of the three generalized coordinates of a planar body.
COORDINATE_NAMES = ("x", "y", "theta")


def coordinate_unit(coordinate: Optional[str], force: bool = False) -> str:
    """
    Return the SI unit of a displacement (or force) along an axis, or about theta.

    m along an axis, rad about theta (and about a spatial body's rx, ry, rz: docs/spatial.md);
    N and N m for a force (the units of drive inputs and outputs, docs/mechanism_file.md,
    "Several drives and outputs; the XY stage").
    """
    if coordinate in ("theta", "rx", "ry", "rz"):
        return "N m" if force else "rad"
    return "N" if force else "m"


@dataclass(frozen=True)
class Body:
    """
    A rigid body.

    Mass (kg), rotational inertia about its mass centre (kg m^2), and the initial (unstressed) pose
    (x, y, theta) of its body frame in the root frame.
    """

    name: str
    mass: float
    inertia: float
    pose: tuple[float, float, float]
    #: Outline for displays: polygon vertices (x, y) in the body frame, m; None: no shape given.
    shape: Optional[tuple[tuple[float, float], ...]] = None


@dataclass(frozen=True)
class Frame:
    """A frame fixed to a body: position (m) and angle (rad) in the body frame."""

    body: str
    position: tuple[float, float]
    angle: float = 0.0


@dataclass(frozen=True)
class Hinge:
    """
    An elastic element joining frame ``a`` on body A and frame ``b`` on body B.

    Which coincide in the unstressed pose. ``law`` evaluates potential and dissipation (see
    hinge_laws; its stiffness and damping are 3x3, moment first, in the hinge frame);
    ``stiffness_source`` says where the stiffness came from (model name, matrix, file); ``stress``:
    the geometry of its stress (engine/hinges/stress.py), None without a notch or cantilever model.
    """

    name: str
    a: Frame
    b: Frame
    law: HingeLaw
    stiffness_source: str = "matrix"
    stress: Optional[StressGeometry] = None


@dataclass(frozen=True)
class Fixed:
    """Body held at its initial pose (all three coordinates prescribed)."""

    body: str


@dataclass(frozen=True)
class DriveFields:
    """What a planar and a spatial drive both are (``Drive``, ``spatial_parts.Drive``)."""

    body: str
    axis: tuple
    response_time: float
    stroke: tuple[float, float]
    slew_rate: float
    name: str = "drive"
    coordinate: Optional[str] = None
    kind: str = "displacement"
    actuator: Optional[PiezoSpec] = None
    #: A body's coordinate names, translations first (``direction``).
    coordinate_names: ClassVar[tuple[str, ...]] = COORDINATE_NAMES

    def direction(self, mech) -> np.ndarray:
        """
        Return the drive's direction e in the body coordinates of ``mech``.

        The input is e . (z - z0) and a force drive's generalized force is e f (virtual work).
        """
        return direction(mech, self.body, self.axis, self.coordinate, self.coordinate_names)


@dataclass(frozen=True)
class Drive(DriveFields):
    """
    The driven input.

    The body's displacement along ``axis`` (unit vector in the root frame) equals the actuator
    output u; its other coordinates are held.

    The actuator output follows the command through a first-order lag,
    du/dt = (command - u) / response_time: the slow pole of the dissertation's second-order
    input constraint (eqs. 6.21-6.23), which with B = t_char K is overdamped with a slow
    time constant t_char. ``response_time`` 0: no lag, the displacement is prescribed exactly
    (a command is reached over one engine step; a program is followed with its rate and
    acceleration: engine/solver/programs.py). ``stroke`` is the actuator's range [min, max] (m) and
    ``slew_rate`` its speed limit (m/s); the node enforces both on commands.

    ``name`` tells drives apart (``drive`` for a mechanism's single unnamed drive).
    ``coordinate`` (x, y or theta): the drive acts on that one coordinate of the body (a
    tangential piezo turning it: theta, input in rad) and the others stay free; None: along
    ``axis`` with the body's other coordinates held. ``kind``: ``displacement`` (the input
    is prescribed) or ``force`` (the input is a force (N, or N m on theta) applied to the
    body along ``axis``/``coordinate``, whose coordinates stay free; ``stroke`` is then
    the force range).

    ``actuator``: the piezo stack model of the ``actuator:`` block (engine/actuators/piezo.py),
    None without one (docs/mechanism_file.md, "Piezo actuator").
    """

    axis: tuple[float, float]


def direction(mech, body: str, axis, coordinate: Optional[str],
              names: tuple = COORDINATE_NAMES) -> np.ndarray:
    """
    Return the direction of a body's axis or coordinate.

    e in the len(names) n_bodies coordinates (``names``: a body's coordinates, translations
    first; the planar (x, y, theta) or the spatial six) of a body's axis (unit vector in the
    root frame, one entry per translation) or of one of its coordinates.
    """
    k = len(names)
    e = np.zeros(k * len(mech.bodies))
    i = mech.body_index(body)
    if coordinate is not None:
        e[k * i + names.index(coordinate)] = 1.0
    else:
        e[k * i:k * i + len(axis)] = axis
    return e


@dataclass(frozen=True)
class SineRate:
    """
    Prescribed rate omega(t) = amplitude * sin(2 pi frequency t + phase) of one coordinate.

    The four-bar driver is omega2 = 0.5 pi^2 sin(10 pi t), eqs. 5.26 and 5.34.
    """

    body: str
    coordinate: str
    amplitude: float
    frequency: float
    phase: float = 0.0

    def offset(self, t: float) -> tuple[float, float, float]:
        """Displacement from the initial value, its rate and acceleration at time t."""
        w = 2.0 * np.pi * self.frequency
        a = self.amplitude
        return (
            a / w * (np.cos(self.phase) - np.cos(w * t + self.phase)),
            a * np.sin(w * t + self.phase),
            a * w * np.cos(w * t + self.phase),
        )


Constraint = Union[Fixed, Drive, SineRate]


@dataclass(frozen=True)
class OutputFields:
    """What a planar and a spatial output both are (``Output``, ``spatial_parts.Output``)."""

    body: str
    axis: tuple
    name: str = "output"
    coordinate: Optional[str] = None
    #: A body's coordinate names, translations first (``direction``).
    coordinate_names: ClassVar[tuple[str, ...]] = COORDINATE_NAMES

    def direction(self, mech) -> np.ndarray:
        """Return the output's direction c in the body coordinates: the output is c . (z - z0)."""
        return direction(mech, self.body, self.axis, self.coordinate, self.coordinate_names)


@dataclass(frozen=True)
class Output(OutputFields):
    """
    The displacement reported as an output.

    The displacement reported as the mechanism's output: body origin along axis, or one coordinate
    of the body (``coordinate``: x, y or theta) from rest.
    """

    axis: tuple[float, float]


class Lookup:
    """Look-ups by name shared by the planar and the spatial ``Mechanism``."""

    name: str
    bodies: tuple
    hinges: tuple
    constraints: tuple
    drive_type: type

    def body_index(self, name: str) -> int:
        """Index of a body by name (ValueError naming it if unknown)."""
        for i, body in enumerate(self.bodies):
            if body.name == name:
                return i
        raise ValueError(f"unknown body {name!r} in mechanism {self.name!r}")

    def hinge_index(self, name: str) -> int:
        """Index of a hinge by name (ValueError naming it if unknown)."""
        for i, hinge in enumerate(self.hinges):
            if hinge.name == name:
                return i
        raise ValueError(f"unknown hinge {name!r} in mechanism {self.name!r}")

    @property
    def drives(self) -> tuple:
        """Every drive constraint, in the order of the constraints."""
        return tuple(c for c in self.constraints if isinstance(c, self.drive_type))


@dataclass(frozen=True)
class Mechanism(Lookup):
    """
    A planar flexure mechanism.

    ``compression_hinge`` names the hinge whose compression (along the drive axis, at its centre of
    stiffness: its drive side's displacement minus its far side's; see
    ``solver.compression_points``) is reported, as joint a of the micropositioning stage (Figure
    6.4).
    """

    name: str
    bodies: tuple[Body, ...]
    hinges: tuple[Hinge, ...]
    constraints: tuple[Constraint, ...]
    output: Optional[Output] = None
    compression_hinge: Optional[str] = None
    description: str = ""
    source: str = ""
    metadata: dict = field(default_factory=dict)
    #: The sensor reading the output (published as ``output/measured``); None: no sensor.
    sensor: Optional[SensorSpec] = None
    #: Named outputs (``outputs:`` in YAML); empty: the single ``output``, if any.
    outputs: tuple[Output, ...] = ()
    #: The mechanism's damping matrix (``damping:`` in YAML: Rayleigh or modal, built at rest
    #: by ``damping_models.damping_matrix``), besides the hinges' own; None: hinges only.
    damping: Optional[DampingSpec] = None

    #: The class of its drive constraints (``Lookup.drives``).
    drive_type = Drive

    @property
    def drive(self) -> Optional[Drive]:
        """Return the drive constraint, if the mechanism has one."""
        drives = self.drives
        return drives[0] if drives else None

    @property
    def all_outputs(self) -> tuple[Output, ...]:
        """
        Return the named outputs, or the single ``output``, or none.

        The named outputs, or the single ``output`` (named ``output``), or none.
        """
        if self.outputs:
            return self.outputs
        return (self.output,) if self.output is not None else ()
