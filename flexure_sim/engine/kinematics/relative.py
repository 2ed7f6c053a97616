"""
A hinge's relative displacement r(z) from the poses of its two bodies, and its derivatives.

For a hinge joining frame a (body A, offset c_a, angle phi_a) and frame b (body B, offset c_b,
angle phi_b), with body coordinates z_A = (x_A, y_A, theta_A), z_B likewise (eq. 6.1), the
relative displacement of b in a is r = (alpha, p1, p2) (eq. 2.81):

    alpha = theta_B + phi_b - theta_A - phi_a,
    p     = R(beta)^T Delta,   beta = theta_A + phi_a,
    Delta = P_B + w_b - P_A - w_a,   w_a = R(theta_A) c_a,   w_b = R(theta_B) c_b.

Its derivative in zz = (x_A, y_A, theta_A, x_B, y_B, theta_B): dp/dP_B = -dp/dP_A = R(beta)^T,
dp/dtheta_A = -J p - R(beta)^T J w_a, dp/dtheta_B = R(beta)^T J w_b.

``relative`` is the one definition of r and dr/dzz, on a generic scalar (kinematics/scalar.py):
compiled per hinge in the force kernel (solver/kernels.py), on arrays of hinges in
solver/assembly.py, on HyperDual arrays for sensitivities (analysis/parametric.py).
``relative_second`` adds d2r/dzz2 on float arrays (the assembly's exact Jacobians) from the
quantities ``relative`` returns; ``element_wrench`` is the wrench dual to r.
"""
from __future__ import annotations

import numpy as np

from flexure_sim.engine.kinematics.planar import J
from flexure_sim.engine.kinematics.scalar import formula


@formula
def relative(zA, zB, ca, cb, phia, phib):
    """
    Return r = (alpha, p1, p2), dr/dzz (3 rows of 6) and the lever arms of one hinge or many.

    zA, zB: (x, y, theta) of bodies A and B; ca, cb: (x, y) of the frames on them; phia, phib:
    the frames' angles (module docstring). The lever arms are (w_a1, w_a2, w_b1, w_b2) and
    R(beta)^T J w_a = (ta1, ta2), for ``relative_second``. Entries are scalars or arrays alike.
    """
    xA, yA, thA = zA
    xB, yB, thB = zB
    cA, sA = np.cos(thA), np.sin(thA)
    cB, sB = np.cos(thB), np.sin(thB)
    beta = thA + phia
    ce, se = np.cos(beta), np.sin(beta)
    wa1 = cA * ca[0] - sA * ca[1]
    wa2 = sA * ca[0] + cA * ca[1]
    wb1 = cB * cb[0] - sB * cb[1]
    wb2 = sB * cb[0] + cB * cb[1]
    d1 = xB + wb1 - xA - wa1
    d2 = yB + wb2 - yA - wa2
    p1 = ce * d1 + se * d2          # p = R(beta)^T Delta; R(beta)^T = [[c, s], [-s, c]]
    p2 = -se * d1 + ce * d2
    alpha = thB + phib - beta
    ta1 = -ce * wa2 + se * wa1      # R(beta)^T J w = R(beta)^T (-w2, w1)
    ta2 = se * wa2 + ce * wa1
    tb1 = -ce * wb2 + se * wb1
    tb2 = se * wb2 + ce * wb1
    dr = ((0.0, 0.0, -1.0, 0.0, 0.0, 1.0),
          (-ce, -se, p2 - ta1, ce, se, tb1),          # -J p = (p2, -p1)
          (se, -ce, -p1 - ta2, -se, ce, tb2))
    return (alpha, p1, p2), dr, (wa1, wa2, wb1, wb2, ta1, ta2)


def relative_second(dr: np.ndarray, arms) -> np.ndarray:
    """
    Return d2r/dzz2 (n, 3, 6, 6) of n hinges from ``relative``'s dr/dzz (n, 3, 6) and arms.

    Differentiating the module docstring's dp/dzz once more: the dp/dP rows R(beta)^T depend
    on theta_A only (d/dtheta_A R(beta)^T = -J R(beta)^T); d2p/dtheta_A2 = -J dp/dtheta_A
    + J R(beta)^T J w_a + R(beta)^T w_a, d2p/dtheta_A dtheta_B = -J R(beta)^T J w_b,
    d2p/dtheta_B2 = -R(beta)^T w_b; alpha is linear in zz.
    """
    wa1, wa2, wb1, wb2, ta1, ta2 = arms
    n = dr.shape[0]
    cbe, sbe = dr[:, 1, 3], dr[:, 1, 4]
    RbT = np.empty((n, 2, 2))
    RbT[:, 0, 0], RbT[:, 0, 1], RbT[:, 1, 0], RbT[:, 1, 1] = cbe, sbe, -sbe, cbe
    wa = np.column_stack([wa1, wa2])
    wb = np.column_stack([wb1, wb2])
    RbT_Jwa = np.column_stack([ta1, ta2])
    RbT_Jwb = np.column_stack([dr[:, 1, 5], dr[:, 2, 5]])
    dp_dthA = dr[:, 1:, 2]
    d2 = np.zeros((n, 3, 6, 6))
    J_RbT = np.einsum("ij,njk->nik", J, RbT)
    d2[:, 1:, 2, 2] = (
        -dp_dthA @ J.T + np.einsum("ij,nj->ni", J, RbT_Jwa) + np.einsum("nij,nj->ni", RbT, wa)
    )
    d2[:, 1:, 2, 0:2] = J_RbT
    d2[:, 1:, 0:2, 2] = J_RbT
    d2[:, 1:, 2, 3:5] = -J_RbT
    d2[:, 1:, 3:5, 2] = -J_RbT
    cross = -np.einsum("ij,nj->ni", J, RbT_Jwb)
    d2[:, 1:, 2, 5] = cross
    d2[:, 1:, 5, 2] = cross
    d2[:, 1:, 5, 5] = -np.einsum("nij,nj->ni", RbT, wb)
    return d2


@formula
def element_wrench(alpha, g0, g1, g2):
    """
    Return m_b = (g0, R(alpha)^T (g1, g2)): the wrench dual to r of an r-gradient g.

    The wrench by body B on the element, in frame b coordinates, about b's origin, of a
    generalised force g = dU/dr (or C_r r_dot): from dW = g . delta r and delta r = (delta tau,
    R(alpha) delta t_b) -- eqs. 3.53 and 4.35.
    """
    c, s = np.cos(alpha), np.sin(alpha)
    return g0, c * g1 + s * g2, -s * g1 + c * g2
