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
from typing import Optional, Union

import numpy as np

from flexure_sim.engine.laws.spatial import SpatialLaw
from flexure_sim.engine.mechanism import parts
from flexure_sim.engine.mechanism.parts import Fixed, Lookup

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
class Drive:
    """
    A drive: a displacement drive prescribes its body's displacement along ``axis``.

    ``axis`` (a unit vector in the root frame) with the body's other coordinates held, or
    along one translation ``coordinate`` (x, y, z) with the others free; the actuator output
    follows the command as a first-order lag (``response_time``), within ``stroke`` and
    ``slew_rate`` (enforced by the node), as the planar ``mechanism.parts.Drive``. A force
    drive (``kind`` force) applies the commanded force along ``axis`` or a translation
    coordinate, or a torque about the root axis of a rotation coordinate (rx, ry, rz).
    """

    body: str
    axis: tuple[float, float, float]
    response_time: float
    stroke: tuple[float, float]
    slew_rate: float
    name: str = "drive"
    coordinate: Optional[str] = None
    kind: str = "displacement"
    #: A piezo actuator block: not supported in 3-D (always None; ``drives.DriveTable`` reads it).
    actuator: None = None

    def direction(self, mech: "Mechanism") -> np.ndarray:
        """Return e in the 6 n_bodies coordinates: the input is e . (z - z0)."""
        return direction(mech, self.body, self.axis, self.coordinate)


@dataclass(frozen=True)
class Output:
    """A body's displacement along a root ``axis``, or one of its coordinates, from rest."""

    body: str
    axis: tuple[float, float, float]
    name: str = "output"
    coordinate: Optional[str] = None

    def direction(self, mech: "Mechanism") -> np.ndarray:
        """Return c in the 6 n_bodies coordinates: the output is c . (z - z0)."""
        return direction(mech, self.body, self.axis, self.coordinate)


def direction(mech: "Mechanism", body: str, axis, coordinate: Optional[str]) -> np.ndarray:
    """Return the direction of a body's root axis or of one of its six coordinates."""
    return parts.direction(mech, body, axis, coordinate, COORDINATE_NAMES)


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
