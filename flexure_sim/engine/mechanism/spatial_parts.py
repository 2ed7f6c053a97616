"""
Spatial mechanisms as plain data: bodies, hinges, constraints, drives and outputs in 3-D.

Constants only, as ``engine.mechanism`` (the state lives in ``data.State``). Coordinates per
body (``kinematics.quaternion``, ``solver.spatial_chain``): (x, y, z, rx, ry, rz) = position of
the body frame (its mass
centre) in the root frame ``stage`` (REP-103) and the rotation vector from its rest
orientation, in body coordinates; velocities (vx, vy, vz) in the root frame and the angular
velocity (wx, wy, wz) in body coordinates.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Union


from flexure_sim.engine.laws.spatial import SpatialLaw
from flexure_sim.engine.mechanism.parts import DriveFields, Fixed, Lookup, OutputFields

#: Names of a body's six coordinates; ``theta`` (a planar file's) is ``rz``.
COORDINATE_NAMES = ("x", "y", "z", "rx", "ry", "rz")
#: Planar coordinate names and their spatial ones.
PLANAR_NAMES = {"x": "x", "y": "y", "theta": "rz"}


@dataclass(frozen=True)
class Body:
    """
    A rigid body.

    Mass (kg); inertia tensor about the mass centre in body coordinates (kg m^2, 3x3 as nested
    tuples); rest pose: position (m, root frame) and orientation (unit quaternion w, x, y, z).
    """

    name: str
    mass: float
    inertia: tuple
    position: tuple[float, float, float]
    quaternion: tuple[float, float, float, float]


@dataclass(frozen=True)
class Frame:
    """A frame fixed to a body: position (m) and orientation (quaternion) in body coordinates."""

    body: str
    position: tuple[float, float, float]
    quaternion: tuple[float, float, float, float] = (1.0, 0.0, 0.0, 0.0)


@dataclass(frozen=True)
class Hinge:
    """
    An elastic element joining frame ``a`` on body A and frame ``b`` on body B.

    The frames coincide at rest.

    ``law``: its potential and dissipation (6x6 K and B in the hinge frame, rotation first);
    ``stiffness_source``: the model that gave K (notch, cantilever, matrix, ...).
    """

    name: str
    a: Frame
    b: Frame
    law: SpatialLaw
    stiffness_source: str = "matrix"


@dataclass(frozen=True)
class Drive(DriveFields):
    """
    A drive: a displacement drive prescribes its body's displacement along ``axis``.

    ``axis`` (a unit vector in the root frame) with the body's other coordinates held, or
    along one translation ``coordinate`` (x, y, z) with the others free; the actuator output
    follows the command as a first-order lag (``response_time``), within ``stroke`` and
    ``slew_rate`` (enforced by the node), as the planar ``mechanism.parts.Drive``. A force
    drive (``kind`` force) applies the commanded force along ``axis`` or a translation
    coordinate, or a torque about the root axis of a rotation coordinate (rx, ry, rz).
    """

    axis: tuple[float, float, float]
    #: A piezo actuator block: not supported in 3-D (always None; ``drives.DriveTable`` reads it).
    actuator: None = None
    coordinate_names = COORDINATE_NAMES


@dataclass(frozen=True)
class Output(OutputFields):
    """A body's displacement along a root ``axis``, or one of its coordinates, from rest."""

    axis: tuple[float, float, float]
    coordinate_names = COORDINATE_NAMES


Constraint = Union[Fixed, Drive]


@dataclass(frozen=True)
class Mechanism(Lookup):
    """
    A spatial flexure mechanism (``space: 3d``, or a planar file opened in 3-D).

    ``planar``: the planar mechanism it was opened from (None for a 3-D file): its bodies,
    hinges and drives in the same order, so results compare entry by entry.
    """

    name: str
    bodies: tuple[Body, ...]
    hinges: tuple[Hinge, ...]
    constraints: tuple[Constraint, ...]
    outputs: tuple[Output, ...] = ()
    description: str = ""
    source: str = ""
    metadata: dict = field(default_factory=dict)
    planar: object = None

    #: The class of its drive constraints (``parts.Lookup.drives``).
    drive_type = Drive

    @property
    def all_outputs(self) -> tuple[Output, ...]:
        """Return the outputs (as the planar ``Mechanism.all_outputs``)."""
        return self.outputs
