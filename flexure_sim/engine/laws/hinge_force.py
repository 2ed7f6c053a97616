"""
One hinge's generalised forces under a quadratic law: the hinge force chain, written once.

From the poses z_A, z_B and velocities v_A, v_B of the hinge's bodies (eq. 6.1) to the forces
on their coordinates, for the quadratic twistor (4.7) or twist (3.4) law with damping (4.40):

    r = (alpha, p1, p2) and dr/dzz               (kinematics/relative.py, eq. 2.81)
    c(r) and dc/dr: (xi, x1, x2) or (tau, t1, t2) (laws/coordinates.py, 2.132-2.135, 2.106-2.108)
    U = 1/2 c^T W c,  D = 1/2 c_dot^T C c_dot,   c_dot = dc/dr dr/dzz v
    total_r = dc/dr^T (W c + C c_dot),  q = -dr/dzz^T total_r,
    wrench on B = -(total_0, R(alpha)^T total_{1,2})   (3.53, 4.35)

with W = 4 K, C = 4 B on the twistor's (xi, x1, x2) and W = K, C = B on the twist
(``QuadraticLaw.metric``, ``dissipation_matrix``). The dissipated power is c_dot^T C c_dot =
r_dot^T C_r r_dot.

``quadratic_hinge`` is written on a generic scalar (kinematics/scalar.py): Numba compiles it
into the per-step force kernel (solver/kernels.py, one hinge at a time), and
analysis/parametric.py evaluates it on HyperDual arrays of all hinges for exact sensitivities
and wrench Jacobians. Sums run left to right in a fixed order, so the compiled stepping path
gives the same bits wherever it runs.
"""
from __future__ import annotations

from flexure_sim.engine.kinematics.relative import element_wrench, relative
from flexure_sim.engine.kinematics.scalar import dot, formula
from flexure_sim.engine.laws.coordinates import twist, twistor


@formula
def quadratic_hinge(twistor_law, moving, zA, zB, vA, vB, ca, cb, phia, phib, W, C):
    """
    Return r, energy U, dissipated power, q (6) and the wrench on body B of one hinge or many.

    twistor_law: the twistor law (True) or the twist law (False); moving: False at rest (v
    not used, no damping terms). zA, zB, vA, vB: (x, y, theta) and their rates; ca, cb, phia,
    phib: the frames (kinematics/relative.py); W, C: 3 rows of 3 (module docstring). q are
    the generalised forces on (x_A, y_A, theta_A, x_B, y_B, theta_B); the wrench is on body B
    in frame b (moment, fx, fy).
    """
    r, dr, _arms = relative(zA, zB, ca, cb, phia, phib)
    alpha, p1, p2 = r
    if twistor_law:
        c4, dc4 = twistor(alpha, p1, p2)
        c, dc = (c4[1], c4[2], c4[3]), (dc4[1], dc4[2], dc4[3])
    else:
        c, dc = twist(alpha, p1, p2)
    e = (dot(W[0], c), dot(W[1], c), dot(W[2], c))
    energy = 0.5 * dot(c, e)
    dissipation = 0.0
    if moving:
        vv = (vA[0], vA[1], vA[2], vB[0], vB[1], vB[2])
        rdot = (dot(dr[0], vv), dot(dr[1], vv), dot(dr[2], vv))
        cdot = (dot(dc[0], rdot), dot(dc[1], rdot), dot(dc[2], rdot))
        g = (dot(C[0], cdot), dot(C[1], cdot), dot(C[2], cdot))
        dissipation = dot(cdot, g)
        e = (e[0] + g[0], e[1] + g[1], e[2] + g[2])
    total = (dot((dc[0][0], dc[1][0], dc[2][0]), e),
             dot((dc[0][1], dc[1][1], dc[2][1]), e),
             dot((dc[0][2], dc[1][2], dc[2][2]), e))
    q = (-dot((dr[0][0], dr[1][0], dr[2][0]), total),
         -dot((dr[0][1], dr[1][1], dr[2][1]), total),
         -dot((dr[0][2], dr[1][2], dr[2][2]), total),
         -dot((dr[0][3], dr[1][3], dr[2][3]), total),
         -dot((dr[0][4], dr[1][4], dr[2][4]), total),
         -dot((dr[0][5], dr[1][5], dr[2][5]), total))
    m0, m1, m2 = element_wrench(alpha, total[0], total[1], total[2])
    return r, energy, dissipation, q, (-m0, -m1, -m2)
