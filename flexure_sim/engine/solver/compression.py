"""
Where and how a hinge's compression is measured (docs/engine.md, "Conventions").

The compression hinge (e.g. the stage's joint a) is measured at its centre of stiffness,
along the drive axis: the displacement from rest of that point as carried by the hinge's
drive side (its body fewer hinges away from the driven body) minus as carried by its far
side. It depends neither on which body is called A nor on where the coincident hinge
frames are put (they move the centre with them only in coordinates, not physically).
"""
from __future__ import annotations

import math

import numpy as np

from flexure_sim.engine.laws.quadratic import LawBatch
from flexure_sim.engine.kinematics.planar import J, rot
from flexure_sim.engine.mechanism.parts import Mechanism


def compression_of(z, z0, i_drive: int, cdx: float, cdy: float, i_far: int, cfx: float,
                   cfy: float, ax: float, ay: float) -> float:
    """
    Return the compression at coordinates z.

    Along (ax, ay): the displacement from rest of the point (cdx, cdy) of body ``i_drive``
    minus that of the point (cfx, cfy) of body ``i_far`` (body coordinates of
    ``compression_points``). Scalar arithmetic only, so that Numba compiles this very source
    for the tick report (``tick_report``); ``Model.hinge_compression`` calls it as Python.
    """
    i, j = 3 * i_drive, 3 * i_far
    c, s = math.cos(z[i + 2]), math.sin(z[i + 2])
    c0, s0 = math.cos(z0[i + 2]), math.sin(z0[i + 2])
    dx = (z[i] + (c * cdx - s * cdy)) - (z0[i] + (c0 * cdx - s0 * cdy))
    dy = (z[i + 1] + (s * cdx + c * cdy)) - (z0[i + 1] + (s0 * cdx + c0 * cdy))
    c, s = math.cos(z[j + 2]), math.sin(z[j + 2])
    c0, s0 = math.cos(z0[j + 2]), math.sin(z0[j + 2])
    dx -= (z[j] + (c * cfx - s * cfy)) - (z0[j] + (c0 * cfx - s0 * cfy))
    dy -= (z[j + 1] + (s * cfx + c * cfy)) - (z0[j + 1] + (s0 * cfx + c0 * cfy))
    return dx * ax + dy * ay


def stiffness_centre(K: np.ndarray) -> np.ndarray:
    """
    Centre of stiffness of a hinge in its frame's coordinates.

    The point where the stiffness at rest K = [[Ko, Kc^T], [Kc, Kt]] (moment first) decouples.
    Moving the frame by p turns the coupling into Kc + Kt (-J p)
    (``kinematics.transform_stiffness``), which vanishes at p = -J Kt^-1 Kc.
    """
    K = np.asarray(K, dtype=float)
    return -J @ np.linalg.solve(K[1:, 1:], K[1:, 0])


def compression_points(mech: Mechanism):
    """
    Return the points and axis of the mechanism's compression hinge, or None.

    The result is ((drive body, centre in its coordinates), (far body, centre), drive axis).
    The drive side is the hinge's body fewer hinges away from the driven body; when both
    are equally far, the one whose rest centre lies further back along the drive axis.
    The centre of stiffness comes from the law's Hessian at rest (any law).
    """
    drive = mech.drive
    if mech.compression_hinge is None or drive is None:
        return None
    h = mech.hinges[mech.hinge_index(mech.compression_hinge)]
    law = LawBatch([h.law]).evaluate(np.zeros(1), np.zeros((1, 2)), np.zeros((1, 3)))
    centre = stiffness_centre(law.hess[0])
    axis = np.array(drive.axis, dtype=float)
    hops = _hinge_distance(mech, mech.body_index(drive.body))
    sides = []
    for frame in (h.a, h.b):
        i = mech.body_index(frame.body)
        local = np.array(frame.position) + rot(frame.angle) @ centre
        back = float(np.array(mech.bodies[i].pose[:2]) @ axis)
        sides.append(((hops[i], back), (i, local)))
    sides.sort(key=lambda side: side[0])
    return sides[0][1], sides[1][1], axis


def _hinge_distance(mech: Mechanism, start: int) -> list:
    """Count the hinges between each body and body ``start`` (inf where unconnected)."""
    dist = [np.inf] * len(mech.bodies)
    dist[start] = 0
    frontier = [start]
    while frontier:
        nxt = []
        for h in mech.hinges:
            ia, ib = mech.body_index(h.a.body), mech.body_index(h.b.body)
            for i, j in ((ia, ib), (ib, ia)):
                if i in frontier and dist[j] == np.inf:
                    dist[j] = dist[i] + 1
                    nxt.append(j)
        frontier = nxt
    return dist
