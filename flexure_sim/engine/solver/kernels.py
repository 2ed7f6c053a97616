"""
Compiled hot path: generalized hinge forces of quadratic laws, without Jacobians.

This is the force evaluation the stepping loop performs once per step. It computes the
same quantities as ``Assembly.forces`` (solver/assembly.py, which remains the reference and the
only source of Jacobians and reports) for hinges with the quadratic twistor (4.7) or twist
(3.4) law, written as scalar loops so that Numba compiles it to machine code: about
30x faster than the vectorised NumPy path for the stage (see BENCHMARKS.md). A test checks
that both paths agree to rounding. Without Numba the same function runs as plain Python.

Per hinge (see solver/assembly.py for the derivation): r = (alpha, p) and dr/dzz; law
coordinates v (twistor vector part (xi, x1, x2) or twist (tau, t1, t2)) and dv/dr;
U = 1/2 v^T W v with W = 4K (twistor) or K (twist); D = 1/2 v_dot^T C v_dot;
Q = -dr^T dv^T (W v + C dv r_dot).
"""
from __future__ import annotations

import math

import numpy as np

from flexure_sim.engine.jit import njit
from flexure_sim.engine.kinematics.planar import half_cot_scalar

TWISTOR, TWIST = 0, 1

#: (a/2) cot(a/2) and its derivatives: kinematics.half_cot_scalar, compiled (one source).
_half_cot = njit(cache=True)(half_cot_scalar)


@njit(cache=True, inline="always")
def hinge_relative(xA, yA, thA, xB, yB, thB, ca1, ca2, cb1, cb2, phia, phib, dr):
    """
    Return r = (alpha, p1, p2) of one hinge; write dr/dzz into dr (3, 6).

    Here zz = (x_A, y_A, theta_A, x_B, y_B, theta_B): the compiled twin of ``Assembly.relative``
    (eq. 2.81 with the poses of eq. 6.1; a test pins the two together at random inputs).
    """
    cA, sA = math.cos(thA), math.sin(thA)
    cB, sB = math.cos(thB), math.sin(thB)
    beta = thA + phia
    cb_, sb_ = math.cos(beta), math.sin(beta)
    wa1 = cA * ca1 - sA * ca2
    wa2 = sA * ca1 + cA * ca2
    wb1 = cB * cb1 - sB * cb2
    wb2 = sB * cb1 + cB * cb2
    d1 = xB + wb1 - xA - wa1
    d2 = yB + wb2 - yA - wa2
    p1 = cb_ * d1 + sb_ * d2
    p2 = -sb_ * d1 + cb_ * d2
    alpha = thB + phib - beta
    ta1 = -cb_ * wa2 + sb_ * wa1
    ta2 = sb_ * wa2 + cb_ * wa1
    tb1 = -cb_ * wb2 + sb_ * wb1
    tb2 = sb_ * wb2 + cb_ * wb1
    dr[:, :] = 0.0
    dr[0, 2] = -1.0
    dr[0, 5] = 1.0
    dr[1, 0] = -cb_
    dr[1, 1] = -sb_
    dr[2, 0] = sb_
    dr[2, 1] = -cb_
    dr[1, 3] = cb_
    dr[1, 4] = sb_
    dr[2, 3] = -sb_
    dr[2, 4] = cb_
    dr[1, 2] = p2 - ta1
    dr[2, 2] = -p1 - ta2
    dr[1, 5] = tb1
    dr[2, 5] = tb2
    return alpha, p1, p2


@njit(cache=True, inline="always")
def law_coordinates(kind, alpha, p1, p2, dv):
    """
    Return the law coordinates of r = (alpha, p1, p2); write their derivative dv/dr into dv (3, 3).

    The law coordinates are the twistor vector part (xi, x1, x2), or twist (tau, t1, t2): the
    compiled twin of ``hinge_laws.twistor_coordinates`` / ``twist_coordinates`` (pinned by a
    test).
    """
    if kind == TWISTOR:
        sg, xi = math.cos(0.5 * alpha), math.sin(0.5 * alpha)
        x1 = 0.5 * (sg * p1 + xi * p2)
        x2 = 0.5 * (-xi * p1 + sg * p2)
        dv[0, 0], dv[0, 1], dv[0, 2] = 0.5 * sg, 0.0, 0.0
        dv[1, 0], dv[1, 1], dv[1, 2] = 0.5 * x2, 0.5 * sg, 0.5 * xi
        dv[2, 0], dv[2, 1], dv[2, 2] = -0.5 * x1, -0.5 * xi, 0.5 * sg
        return xi, x1, x2
    f, f1, _ = _half_cot(alpha)
    dv[0, 0], dv[0, 1], dv[0, 2] = 1.0, 0.0, 0.0
    dv[1, 0], dv[1, 1], dv[1, 2] = f1 * p1 + 0.5 * p2, f, 0.5 * alpha
    dv[2, 0], dv[2, 1], dv[2, 2] = f1 * p2 - 0.5 * p1, -0.5 * alpha, f
    # t = f p - (alpha/2) J p, J p = (-p2, p1)
    return alpha, f * p1 + 0.5 * alpha * p2, f * p2 - 0.5 * alpha * p1


@njit(cache=True)
def quadratic_forces(z, v, ia, ib, ca, cb, phia, phib, kind, W, C, Q, r_out, wrench_out):
    """
    Fill Q (3 n_bodies) with the hinge forces at (z, v); return (energy, dissipation).

    Also fills r_out (n, 3) with each hinge's deflection (alpha, p1, p2) and wrench_out (n, 3)
    with the wrench it exerts on body B in frame b (-m_b, eqs. 3.53/4.35), as in
    Assembly.forces.
    """
    Q[:] = 0.0
    energy = 0.0
    dissipation = 0.0
    dr = np.zeros((3, 6))
    dv = np.zeros((3, 3))
    vv = np.zeros(6)
    for h in range(ia.shape[0]):
        A, B = 3 * ia[h], 3 * ib[h]
        alpha, p1, p2 = hinge_relative(
            z[A],
            z[A + 1],
            z[A + 2],
            z[B],
            z[B + 1],
            z[B + 2],
            ca[h, 0],
            ca[h, 1],
            cb[h, 0],
            cb[h, 1],
            phia[h],
            phib[h],
            dr,
        )
        for j in range(3):
            vv[j] = v[A + j]
            vv[3 + j] = v[B + j]
        rdot0 = 0.0
        rdot1 = 0.0
        rdot2 = 0.0
        for j in range(6):
            rdot0 += dr[0, j] * vv[j]
            rdot1 += dr[1, j] * vv[j]
            rdot2 += dr[2, j] * vv[j]
        c0, c1, c2 = law_coordinates(kind[h], alpha, p1, p2, dv)
        # Law forces in law coordinates: W v + C v_dot.
        vd0 = dv[0, 0] * rdot0 + dv[0, 1] * rdot1 + dv[0, 2] * rdot2
        vd1 = dv[1, 0] * rdot0 + dv[1, 1] * rdot1 + dv[1, 2] * rdot2
        vd2 = dv[2, 0] * rdot0 + dv[2, 1] * rdot1 + dv[2, 2] * rdot2
        e0 = W[h, 0, 0] * c0 + W[h, 0, 1] * c1 + W[h, 0, 2] * c2
        e1 = W[h, 1, 0] * c0 + W[h, 1, 1] * c1 + W[h, 1, 2] * c2
        e2 = W[h, 2, 0] * c0 + W[h, 2, 1] * c1 + W[h, 2, 2] * c2
        g0 = C[h, 0, 0] * vd0 + C[h, 0, 1] * vd1 + C[h, 0, 2] * vd2
        g1 = C[h, 1, 0] * vd0 + C[h, 1, 1] * vd1 + C[h, 1, 2] * vd2
        g2 = C[h, 2, 0] * vd0 + C[h, 2, 1] * vd1 + C[h, 2, 2] * vd2
        energy += 0.5 * (c0 * e0 + c1 * e1 + c2 * e2)
        dissipation += vd0 * g0 + vd1 * g1 + vd2 * g2
        t0 = e0 + g0
        t1 = e1 + g1
        t2 = e2 + g2
        # total_r = dv^T (W v + C v_dot); Q_local = -dr^T total_r
        r0 = dv[0, 0] * t0 + dv[1, 0] * t1 + dv[2, 0] * t2
        r1 = dv[0, 1] * t0 + dv[1, 1] * t1 + dv[2, 1] * t2
        r2 = dv[0, 2] * t0 + dv[1, 2] * t1 + dv[2, 2] * t2
        r_out[h, 0], r_out[h, 1], r_out[h, 2] = alpha, p1, p2
        ca_, sa_ = math.cos(alpha), math.sin(alpha)
        wrench_out[h, 0] = -r0
        wrench_out[h, 1] = -(ca_ * r1 + sa_ * r2)
        wrench_out[h, 2] = -(-sa_ * r1 + ca_ * r2)
        for j in range(3):
            Q[A + j] -= dr[0, j] * r0 + dr[1, j] * r1 + dr[2, j] * r2
            Q[B + j] -= dr[0, 3 + j] * r0 + dr[1, 3 + j] * r1 + dr[2, 3 + j] * r2
    return energy, dissipation
