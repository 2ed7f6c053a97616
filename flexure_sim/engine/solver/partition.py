"""
Which coordinates of a mechanism are free and which its constraints prescribe.

Every constraint prescribes whole coordinates (a fixed body; a displacement drive's body along
its axis, its other coordinates held; one coordinate at a prescribed rate), so the 3 n_bodies
coordinates split into free ones z_F and prescribed ones z_P(t): ``model.Model`` eliminates
z_P exactly (eqs. 5.25, 6.4).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from flexure_sim.engine.mechanism.parts import COORDINATE_NAMES, Drive, Fixed, Mechanism, SineRate
from flexure_sim.engine.solver.drives import stacked


@dataclass
class Partition:
    """
    Free and prescribed coordinate indices.

    Per prescribed coordinate dz_P/du (the drive axis component) of the single displacement
    drive (zeros with none or several); the sine-rate constraints as (index into prescribed,
    constraint); ``D``: dz_P/du per displacement drive (columns, ``DriveTable.displacement``
    order); ``held``: per drive (``Mechanism.drives`` order) the coordinates it prescribes (its
    body's axis and held coordinates; a stack drive's held ones; none for a force drive).
    """

    free: np.ndarray
    prescribed: np.ndarray
    du: np.ndarray
    timed: list = field(default_factory=list)
    D: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    held: tuple = ()


def partition(mech: Mechanism) -> Partition:
    """Split the 3 n_bodies coordinates of ``mech`` by its constraints."""
    prescribed: set[int] = set()
    timed = []
    columns = []
    held = []
    for c in mech.constraints:
        i = mech.body_index(c.body)
        if isinstance(c, Fixed):
            prescribed.update(3 * i + k for k in range(3))
        elif isinstance(c, Drive):
            held.append(_held(c, i))
            prescribed.update(held[-1])
            if c.kind == "displacement" and not stacked(c):
                columns.append(c.direction(mech))
        elif isinstance(c, SineRate):
            prescribed.add(3 * i + COORDINATE_NAMES.index(c.coordinate))
            timed.append((3 * i + COORDINATE_NAMES.index(c.coordinate), c))
    P = np.array(sorted(prescribed), dtype=int)
    F = np.array([k for k in range(3 * len(mech.bodies)) if k not in prescribed], dtype=int)
    pos = {k: j for j, k in enumerate(P)}
    D = np.array(columns, dtype=float).reshape(len(columns), -1)[:, P].T if columns else (
        np.zeros((len(P), 0)))
    du = D[:, 0].copy() if D.shape[1] == 1 else np.zeros(len(P))
    return Partition(F, P, du, [(pos[k], c) for k, c in timed], D, tuple(held))


def _held(drive: Drive, i: int) -> tuple[int, ...]:
    """
    Return the coordinates of body i that ``drive`` prescribes.

    A displacement drive along an axis: all three (along the axis, the rest held); on one
    coordinate: that one; a stack drive along an axis: all but its axis coordinate (the stack
    pulls along it), on one coordinate: none; a force drive: none (its body stays free).
    """
    if drive.kind == "force" or (stacked(drive) and drive.coordinate is not None):
        return ()
    if stacked(drive):
        return tuple(3 * i + k for k in range(3) if k != _axis_coordinate(drive))
    if drive.coordinate is not None:
        return (3 * i + COORDINATE_NAMES.index(drive.coordinate),)
    return tuple(3 * i + k for k in range(3))


def _axis_coordinate(drive: Drive) -> int:
    """
    Return the coordinate (0: x, 1: y) a stack drive's axis runs along.

    A finite stack frees its body along the axis and holds the other coordinates as the rigid
    drive does, so the axis must be a coordinate axis (else ValueError naming the drive).
    """
    ax = np.abs(np.asarray(drive.axis, dtype=float))
    for k in (0, 1):
        if ax[k] == 1.0 and ax[1 - k] == 0.0:
            return k
    raise ValueError(f"drive {drive.name!r}: an actuator with a finite stack stiffness needs an "
                     f"axis along x or y (or a coordinate), got axis {tuple(drive.axis)}")
