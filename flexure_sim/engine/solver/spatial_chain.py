"""
Generalized forces of a spatial mechanism: hinges, gyroscopic terms, applied forces.

Coordinates, six per body in body order (``kinematics.quaternion``): z = (p, phi), p the body
frame's origin (its mass centre) in the root frame, phi its rotation vector from the rest
orientation R0 (R = R0 Exp(phi)); velocities w = (v, omega), v = dp/dt in the root frame and
omega the angular velocity in body coordinates (quasi-velocities: the mass matrix is constant,
M = diag(m I, I_b) with I_b the inertia tensor in body coordinates), and dz/dt = (v,
Jr^-1(phi) omega).

A hinge joins frame a (position c_a, orientation q_a in body A) and frame b on body B, which
coincide at rest. Its deflection D = (R_a^T R_b, R_a^T (P_b - P_a)) and the relative twist rate
of b in b's coordinates, (dw, dv) = (R_b^T (Omega_B - Omega_A), R_b^T (dP_b/dt - dP_a/dt -
Omega_A x (P_b - P_a))) (Omega: angular velocities in the root frame), give the law's
coordinates and wrench m_b (``laws.spatial``): the wrench body B exerts on the element, in b's
coordinates about b's origin. In the root frame, F = R_b f_b and M = R_b m_b (couple at P_b):
the hinge exerts (-F, -M) on B and (F, M) on A at P_b, which as generalized forces (virtual
work with omega in body coordinates) are

    Q_B = (-F, -R_B^T (M + (P_b - p_B) x F)),    Q_A = (F, R_A^T (M + (P_b - p_A) x F)),

the spatial form of eqs. 4.34-4.39. Rigid bodies add -omega x (I_b omega) (Euler's equations),
force drives f e on a translation (root axis e) or f R^T e on the rotation (a torque about
the root axis e). Everything here is a formula on a generic scalar
(``kinematics.scalar``): the stepping kernel compiles it, and the Jacobians are the complex-step
and hyper-dual evaluations of this same code.
"""
from __future__ import annotations

from flexure_sim.engine.kinematics.scalar import buffer, formula, real
from flexure_sim.engine.kinematics.quaternion import cross, matrix_of, phi_rate, qconj_mul, qmul
from flexure_sim.engine.kinematics.quaternion import quaternion_exp, rotate, rotate_back
from flexure_sim.engine.kinematics.quaternion import rotation_vector
from flexure_sim.engine.laws.spatial import law_terms


@formula(inline=False)
def bodies(z, q0, quat, rot):
    """Fill quat (nb, 4) and rot (nb, 9) with each body's orientation R0 Exp(phi)."""
    for i in range(q0.shape[0]):
        e = quaternion_exp(z[6 * i + 3], z[6 * i + 4], z[6 * i + 5])
        q = qmul((q0[i, 0], q0[i, 1], q0[i, 2], q0[i, 3]), e)
        R = matrix_of(q)
        for k in range(4):
            quat[i, k] = q[k]
        for k in range(9):
            rot[i, k] = R[k]


@formula(inline=False)
def _row9(a, i):
    return (a[i, 0], a[i, 1], a[i, 2], a[i, 3], a[i, 4], a[i, 5], a[i, 6], a[i, 7], a[i, 8])


@formula(inline=False)
def _row4(a, i):
    return a[i, 0], a[i, 1], a[i, 2], a[i, 3]


@formula(inline=False)
def _row3(a, i):
    return a[i, 0], a[i, 1], a[i, 2]


@formula(inline=False)
def hinge(h, z, w, quat, rot, geometry, Q, deflection, wrench, power, report):
    """
    Add hinge h's generalized forces to Q; with ``report`` fill its deflection, wrench, power.

    ``geometry`` = (ia, ib, ca, cb, qa, qb, Ra, Rb, kind, W, C) (``spatial_model.SpatialModel``).
    deflection[h] = (rotation vector of R, p) of D; wrench[h] = -m_b (the wrench the hinge
    exerts on body B, in frame b, moment about b's origin, moment first); power[h] = (U,
    P_c, P_d): potential energy, the power the elastic wrenches deliver to the bodies
    -m_elastic . (dw, dv), and the dissipated power c_dot^T C c_dot.
    """
    ia, ib, ca, cb, qa, qb, Ra, Rb, kind, W, C = geometry
    A, B = ia[h], ib[h]
    RA, RB = _row9(rot, A), _row9(rot, B)
    pA = (z[6 * A], z[6 * A + 1], z[6 * A + 2])
    pB = (z[6 * B], z[6 * B + 1], z[6 * B + 2])
    wa = rotate(RA, _row3(ca, h))
    wb = rotate(RB, _row3(cb, h))
    d = (pB[0] + wb[0] - pA[0] - wa[0], pB[1] + wb[1] - pA[1] - wa[1],
         pB[2] + wb[2] - pA[2] - wa[2])
    Rlb = _row9(Rb, h)
    qr = qconj_mul(qmul(_row4(quat, A), _row4(qa, h)), qmul(_row4(quat, B), _row4(qb, h)))
    p = rotate_back(_row9(Ra, h), rotate_back(RA, d))
    OA = rotate(RA, (w[6 * A + 3], w[6 * A + 4], w[6 * A + 5]))
    OB = rotate(RB, (w[6 * B + 3], w[6 * B + 4], w[6 * B + 5]))
    va, vb, vd = cross(OA, wa), cross(OB, wb), cross(OA, d)
    rel = (w[6 * B] + vb[0] - w[6 * A] - va[0] - vd[0],
           w[6 * B + 1] + vb[1] - w[6 * A + 1] - va[1] - vd[1],
           w[6 * B + 2] + vb[2] - w[6 * A + 2] - va[2] - vd[2])
    dw = rotate_back(Rlb, rotate_back(RB, (OB[0] - OA[0], OB[1] - OA[1], OB[2] - OA[2])))
    dv = rotate_back(Rlb, rotate_back(RB, rel))
    c, cdot, m, me = law_terms(kind[h], qr, p, dw, dv, W, C, h)
    # m_b in body B's coordinates, then F and the couple in the root frame
    fb = rotate(Rlb, (m[3], m[4], m[5]))
    mb = rotate(Rlb, (m[0], m[1], m[2]))
    lb = cross(_row3(cb, h), fb)
    F = rotate(RB, fb)
    M = rotate(RB, mb)
    la = cross((wa[0] + d[0], wa[1] + d[1], wa[2] + d[2]), F)
    ta = rotate_back(RA, (M[0] + la[0], M[1] + la[1], M[2] + la[2]))
    for k in range(3):
        Q[6 * A + k] += F[k]
        Q[6 * B + k] -= F[k]
        Q[6 * A + 3 + k] += ta[k]
        Q[6 * B + 3 + k] -= mb[k] + lb[k]
    if not report:
        return
    e = _energy(W, h, c)
    pc = -(me[0] * dw[0] + me[1] * dw[1] + me[2] * dw[2]
           + me[3] * dv[0] + me[4] * dv[1] + me[5] * dv[2])
    pd = _energy(C, h, cdot) * 2.0
    phi = _rotation_vector_of(qr)
    for k in range(3):
        deflection[h, k] = phi[k]
        deflection[h, 3 + k] = p[k]
    for k in range(6):
        wrench[h, k] = -m[k]
    power[h, 0] = e
    power[h, 1] = pc
    power[h, 2] = pd


@formula(inline=False)
def _rotation_vector_of(qr):
    """Return the rotation vector of qr with the sign of the shorter rotation (|phi| <= pi)."""
    if real(qr[0]) < 0.0:
        return rotation_vector((-qr[0], -qr[1], -qr[2], -qr[3]))
    return rotation_vector(qr)


@formula(inline=False)
def _energy(M, h, c):
    """Return 1/2 c^T M[h] c."""
    s = 0.0 * c[0]
    for i in range(6):
        for j in range(6):
            s = s + 0.5 * c[i] * M[h, i, j] * c[j]
    return s


@formula(inline=False)
def terms(z, w, command, first_force, constants, Q, zdot, deflection, wrench, power, report):
    """
    Fill Q (6 nb) with every generalized force at (z, w) and zdot with dz/dt.

    With ``report`` also each hinge's rows of deflection, wrench and power (``hinge``), and
    return the hinges' total potential energy and dissipated power (else 0, 0: what stepping
    needs is Q and zdot only). ``constants`` =
    (q0, inertia, geometry, force_body, force_axis, force_torque): rest quaternions (nb, 4),
    inertia tensors (nb, 9), the hinge geometry (``hinge``), and per force drive j its body,
    root axis e_j and whether it is a torque; its force is command[first_force + j].
    """
    q0, inertia, geometry, force_body, force_axis, force_torque = constants
    nb = q0.shape[0]
    quat = buffer((nb, 4), z)
    rot = buffer((nb, 9), z)
    bodies(z, q0, quat, rot)
    for k in range(6 * nb):
        Q[k] = 0.0 * z[k]
    for h in range(geometry[0].shape[0]):
        hinge(h, z, w, quat, rot, geometry, Q, deflection, wrench, power, report)
    energy = 0.0 * z[0]
    dissipation = 0.0 * z[0]
    if report:
        for h in range(geometry[0].shape[0]):
            energy = energy + power[h, 0]
            dissipation = dissipation + power[h, 2]
    for i in range(nb):
        om = (w[6 * i + 3], w[6 * i + 4], w[6 * i + 5])
        J = _row9(inertia, i)
        gy = cross(om, rotate(J, om))
        rate = phi_rate((z[6 * i + 3], z[6 * i + 4], z[6 * i + 5]), om)
        for k in range(3):
            Q[6 * i + 3 + k] -= gy[k]
            zdot[6 * i + k] = w[6 * i + k]
            zdot[6 * i + 3 + k] = rate[k]
    for j in range(force_body.shape[0]):
        i = force_body[j]
        f = command[first_force + j]
        e = _row3(force_axis, j)
        if force_torque[j]:
            e = rotate_back(_row9(rot, i), e)
            for k in range(3):
                Q[6 * i + 3 + k] += e[k] * f
        else:
            for k in range(3):
                Q[6 * i + k] += e[k] * f
    return energy, dissipation
