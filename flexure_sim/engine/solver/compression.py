"""
Where and how a hinge's compression is measured (docs/engine.md, "Conventions").

The compression hinge (e.g. the stage's joint a) is measured at its centre of stiffness,
along the drive axis: the displacement from rest of that point as carried by the hinge's
drive side (its body fewer hinges away from the driven body) minus as carried by its far
side. It depends neither on which body is called A nor on where the coincident hinge
frames are put (they move the centre with them only in coordinates, not physically).
"""
from __future__ import annotations

import numpy as np

from flexure_sim.engine.laws.quadratic import LawBatch
from flexure_sim.engine.kinematics.planar import J, rot
from flexure_sim.engine.mechanism.parts import Mechanism


def point_displacement(i: int, c: np.ndarray, z: np.ndarray, z0: np.ndarray) -> np.ndarray:
    """Displacement from rest (root frame) of the point at c (body coordinates) on body i."""
    def at(zz):
        th = zz[3 * i + 2]
        cs, sn = np.cos(th), np.sin(th)
        return zz[3 * i:3 * i + 2] + np.array([cs * c[0] - sn * c[1], sn * c[0] + cs * c[1]])

    return at(z) - at(z0)


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
