"""Generalized forces of all hinges on all bodies, with exact Jacobians.

Body coordinates z = (x, y, theta) per body, velocities v = dz/dt (root frame), stacked as
vectors of length 3 * n_bodies in body order. For a hinge joining frame a (body A, offset
c_a, angle phi_a) and frame b (body B), its relative displacement r = (alpha, p) is

    alpha = theta_B + phi_b - theta_A - phi_a,
    p     = R(theta_A + phi_a)^T (P_B + R(theta_B) c_b - P_A - R(theta_A) c_a),

(eq. 2.81 with the poses of eq. 6.1). With U(r) and D = 1/2 r_dot^T C_r r_dot from the
hinge law, the generalized force is Q = -dr/dz^T (dU/dr + C_r r_dot): the virtual-work
form of eqs. 4.34-4.39 (dynam.sci applies the same wrench, transformed to the root frame,
to both bodies). Jacobians dQ/dz and dQ/dv are exact (second derivatives of r(z) and of
the law coordinates, no finite differences).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .hinge_laws import evaluate, wrench_on_element
from .kinematics import J, rot
from .mechanism import Mechanism


@dataclass(frozen=True)
class HingeForces:
    """Everything the hinges contribute at one state (n hinges, N = 3 n_bodies).

    Q (N,): generalized forces (forces in N, moments in N m about each body's origin).
    dQ_dz, dQ_dv (N, N): exact Jacobians (None unless asked for).
    r (n, 3): deflection (alpha, p1, p2) of each hinge, frame b relative to frame a, in a.
    r_dot (n, 3): its rate. energy (n,): potential energy (J). dissipation (n,): power
    dissipated by damping (W, = r_dot^T C_r r_dot).
    wrench_b (n, 3): wrench the hinge exerts on body B, in frame b coordinates, moment
    about b's origin (moment N m, force N): -(m_b elastic + viscous), eqs. 4.35, 4.40.
    """

    Q: np.ndarray
    dQ_dz: np.ndarray | None
    dQ_dv: np.ndarray | None
    r: np.ndarray
    r_dot: np.ndarray
    energy: np.ndarray
    dissipation: np.ndarray
    wrench_b: np.ndarray


class Assembly:
    """Precomputed hinge geometry of a mechanism; evaluates hinge forces at a state."""

    def __init__(self, mechanism: Mechanism):
        self.mechanism = mechanism
        hinges = mechanism.hinges
        self.n_bodies = len(mechanism.bodies)
        self.ia = np.array([mechanism.body_index(h.a.body) for h in hinges])
        self.ib = np.array([mechanism.body_index(h.b.body) for h in hinges])
        self.ca = np.array([h.a.position for h in hinges], dtype=float)
        self.cb = np.array([h.b.position for h in hinges], dtype=float)
        self.phia = np.array([h.a.angle for h in hinges], dtype=float)
        self.phib = np.array([h.b.angle for h in hinges], dtype=float)
        # Global coordinate indices of (x_A, y_A, th_A, x_B, y_B, th_B) per hinge.
        self.dofs = np.concatenate([3 * self.ia[:, None] + np.arange(3), 3 * self.ib[:, None] + np.arange(3)], axis=1)
        groups: dict[str, list[int]] = {}
        for i, h in enumerate(hinges):
            groups.setdefault(h.law.coordinates, []).append(i)
        self.groups = [(np.array(idx), [hinges[i].law for i in idx]) for idx in groups.values()]

    # ------------------------------------------------------------------ geometry
    def relative(self, z: np.ndarray, second: bool = True):
        """r (n, 3), dr/dzz (n, 3, 6) and, if asked, d2r/dzz2 (n, 3, 6, 6), where zz are the
        six coordinates (x_A, y_A, theta_A, x_B, y_B, theta_B) of each hinge's bodies."""
        Z = np.asarray(z, dtype=float).reshape(self.n_bodies, 3)
        A, B = Z[self.ia], Z[self.ib]
        RA, RB = rot(A[:, 2]), rot(B[:, 2])
        beta = A[:, 2] + self.phia
        RbT = np.swapaxes(rot(beta), 1, 2)  # R(beta)^T
        wa = np.einsum("nij,nj->ni", RA, self.ca)
        wb = np.einsum("nij,nj->ni", RB, self.cb)
        delta = B[:, :2] + wb - A[:, :2] - wa
        p = np.einsum("nij,nj->ni", RbT, delta)
        alpha = B[:, 2] + self.phib - beta
        n = len(alpha)
        r = np.column_stack([alpha, p])

        Jwa, Jwb, Jp = wa @ J.T, wb @ J.T, p @ J.T
        RbT_Jwa = np.einsum("nij,nj->ni", RbT, Jwa)
        RbT_Jwb = np.einsum("nij,nj->ni", RbT, Jwb)
        dp_dthA = -Jp - RbT_Jwa
        dr = np.zeros((n, 3, 6))
        dr[:, 0, 2], dr[:, 0, 5] = -1.0, 1.0
        dr[:, 1:, 0:2] = -RbT
        dr[:, 1:, 2] = dp_dthA
        dr[:, 1:, 3:5] = RbT
        dr[:, 1:, 5] = RbT_Jwb
        if not second:
            return r, dr, None
        d2 = np.zeros((n, 3, 6, 6))
        J_RbT = np.einsum("ij,njk->nik", J, RbT)
        d2[:, 1:, 2, 2] = -dp_dthA @ J.T + np.einsum("ij,nj->ni", J, RbT_Jwa) + np.einsum("nij,nj->ni", RbT, wa)
        d2[:, 1:, 2, 0:2] = J_RbT
        d2[:, 1:, 0:2, 2] = J_RbT
        d2[:, 1:, 2, 3:5] = -J_RbT
        d2[:, 1:, 3:5, 2] = -J_RbT
        cross = -np.einsum("ij,nj->ni", J, RbT_Jwb)
        d2[:, 1:, 2, 5] = cross
        d2[:, 1:, 5, 2] = cross
        d2[:, 1:, 5, 5] = -np.einsum("nij,nj->ni", RbT, wb)
        return r, dr, d2

    # -------------------------------------------------------------------- forces
    def forces(self, z: np.ndarray, v: np.ndarray, jacobian: bool = False) -> HingeForces:
        """Hinge forces at coordinates z and velocities v (both length 3 n_bodies)."""
        r, dr, d2 = self.relative(z, second=jacobian)
        V = np.asarray(v, dtype=float).reshape(self.n_bodies, 3)
        vv = np.concatenate([V[self.ia], V[self.ib]], axis=1)  # (n, 6)
        rdot = np.einsum("nij,nj->ni", dr, vv)
        n = len(r)
        energy = np.empty(n)
        grad = np.empty((n, 3))
        fdamp = np.empty((n, 3))
        hess = Cr = fdamp_dr = None
        if jacobian:
            hess, Cr, fdamp_dr = np.empty((n, 3, 3)), np.empty((n, 3, 3)), np.empty((n, 3, 3))
        for idx, laws in self.groups:
            ev = evaluate(laws, r[idx, 0], r[idx, 1:], rdot[idx])
            energy[idx], grad[idx], fdamp[idx] = ev.energy, ev.grad, ev.damping_force
            if jacobian:
                hess[idx], Cr[idx], fdamp_dr[idx] = ev.hess, ev.damping, ev.damping_force_dr
        total = grad + fdamp
        q_local = -np.einsum("nki,nk->ni", dr, total)  # (n, 6)
        N = 3 * self.n_bodies
        Q = np.zeros(N)
        np.add.at(Q, self.dofs, q_local)
        dQ_dz = dQ_dv = None
        if jacobian:
            # d/dzz of dr^T (grad + fdamp(r, rdot)) with rdot = dr . vv
            d2_vv = np.einsum("nkij,nj->nki", d2, vv)  # d(rdot)/dzz
            K_local = (
                np.einsum("nki,nkl,nlj->nij", dr, hess + fdamp_dr, dr)
                + np.einsum("nk,nkij->nij", total, d2)
                + np.einsum("nki,nkl,nlj->nij", dr, Cr, d2_vv)
            )
            C_local = np.einsum("nki,nkl,nlj->nij", dr, Cr, dr)
            dQ_dz = np.zeros((N, N))
            dQ_dv = np.zeros((N, N))
            rows = np.repeat(self.dofs[:, :, None], 6, axis=2)
            cols = np.repeat(self.dofs[:, None, :], 6, axis=1)
            np.add.at(dQ_dz, (rows, cols), -K_local)
            np.add.at(dQ_dv, (rows, cols), -C_local)
        dissipation = np.einsum("ni,ni->n", fdamp, rdot)
        wrench_b = -wrench_on_element(r[:, 0], total)
        return HingeForces(Q, dQ_dz, dQ_dv, r, rdot, energy, dissipation, wrench_b)
