"""
Generalized forces of all hinges on all bodies, with exact Jacobians.

Body coordinates z = (x, y, theta) per body, velocities v = dz/dt (root frame), stacked as
vectors of length 3 * n_bodies in body order. Each hinge's relative displacement r = (alpha, p)
of frame b in frame a and its derivatives in z are ``kinematics.relative`` (eq. 2.81 with the
poses of eq. 6.1), evaluated here on the arrays of all hinges. With U(r) and
D = 1/2 r_dot^T C_r r_dot from the hinge law, the generalized force is
Q = -dr/dz^T (dU/dr + C_r r_dot): the virtual-work form of eqs. 4.34-4.39 (dynam.sci applies
the same wrench, transformed to the root frame, to both bodies). Jacobians dQ/dz and dQ/dv are
exact (second derivatives of r(z) and of the law coordinates, no finite differences).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Literal, overload

import numpy as np

from flexure_sim.engine.solver import kernels
from flexure_sim.engine.laws.quadratic import LawBatch, QuadraticLaw, wrench_on_element
from flexure_sim.engine.kinematics.relative import relative, relative_second
from flexure_sim.engine.kinematics.scalar import stacked
from flexure_sim.engine.mechanism.parts import Mechanism


@dataclass(frozen=True)
class HingeForces:
    """
    Everything the hinges contribute at one state (n hinges, N = 3 n_bodies).

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


#: Stands for the per-hinge Jacobian blocks when they are not asked for (never written).
_NO_JACOBIAN = np.empty((0, 3, 3))


@dataclass(frozen=True)
class HingeJacobians(HingeForces):
    """`HingeForces` with the exact Jacobians (``Assembly.forces(..., jacobian=True)``)."""

    dQ_dz: np.ndarray
    dQ_dv: np.ndarray


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
        self.dofs = np.concatenate(
            [3 * self.ia[:, None] + np.arange(3), 3 * self.ib[:, None] + np.arange(3)], axis=1
        )
        # Batches share a coordinate type and a law kind, so quadratic laws stay vectorised.
        groups: dict[tuple[str, bool], list[int]] = {}
        for i, h in enumerate(hinges):
            groups.setdefault((h.law.coordinates, isinstance(h.law, QuadraticLaw)), []).append(i)
        self.groups = [
            (np.array(idx), LawBatch([hinges[i].law for i in idx])) for idx in groups.values()
        ]
        # Scatter of each hinge's six local coordinates into the global vector:
        # S[a, h, j] = 1 where global coordinate a is local coordinate j of hinge h.
        n, N = len(hinges), 3 * self.n_bodies
        self.scatter = np.zeros((N, n, 6))
        for k in range(n):
            for j in range(6):
                self.scatter[self.dofs[k, j], k, j] += 1.0
        self._scatter_flat = self.scatter.reshape(N, 6 * n)
        # Compiled path (kernels.quadratic_forces) when every law is quadratic.
        self.compiled = all(isinstance(h.law, QuadraticLaw) for h in hinges)
        if self.compiled:
            offset = [1 if h.law.coordinates == "twistor" else 0 for h in hinges]
            self._kind = np.array(
                [kernels.TWISTOR if o else kernels.TWIST for o in offset], dtype=np.int64
            )
            self._W = np.ascontiguousarray(
                [h.law.metric()[o:, o:] for h, o in zip(hinges, offset)
                 if isinstance(h.law, QuadraticLaw)]
            )
            self._C = np.ascontiguousarray(
                [h.law.dissipation_matrix()[o:, o:] for h, o in zip(hinges, offset)]
            )
            self._ia, self._ib = self.ia.astype(np.int64), self.ib.astype(np.int64)
            self._ca, self._cb = np.ascontiguousarray(self.ca), np.ascontiguousarray(self.cb)

    def kernel_arrays(self) -> tuple:
        """
        Return the compiled kernel's hinge arguments (``kernels.quadratic_forces``).

        (ia, ib, ca, cb, phia, phib, kind, W, C); only for a ``compiled`` assembly
        (ValueError otherwise).
        """
        if not self.compiled:
            raise ValueError("kernel_arrays: not every hinge law is quadratic (no compiled path)")
        return (self._ia, self._ib, self._ca, self._cb, self.phia, self.phib, self._kind,
                self._W, self._C)

    # ------------------------------------------------------------------ geometry
    def relative(self, z: np.ndarray, second: bool = True):
        """
        Return r (n, 3), dr/dzz (n, 3, 6) and, if asked, d2r/dzz2 (n, 3, 6, 6).

        zz are the six coordinates (x_A, y_A, theta_A, x_B, y_B, theta_B) of each hinge's bodies:
        ``kinematics.relative`` on the arrays of all hinges.
        """
        Z = np.asarray(z, dtype=float).reshape(self.n_bodies, 3)
        A, B = Z[self.ia], Z[self.ib]
        (alpha, p1, p2), rows, arms = relative(
            (A[:, 0], A[:, 1], A[:, 2]), (B[:, 0], B[:, 1], B[:, 2]),
            (self.ca[:, 0], self.ca[:, 1]), (self.cb[:, 0], self.cb[:, 1]), self.phia, self.phib)
        n = len(alpha)
        r = np.empty((n, 3))
        r[:, 0], r[:, 1], r[:, 2] = alpha, p1, p2
        dr = stacked(rows, n, (3, 6))
        return r, dr, relative_second(dr, arms) if second else None

    # -------------------------------------------------------------------- forces
    def _assemble(self, local: np.ndarray) -> np.ndarray:
        """Global matrix sum_h S_h local_h S_h^T from per-hinge 6x6 blocks."""
        n = local.shape[0]
        block = np.zeros((n, 6, n, 6))
        block[np.arange(n), :, np.arange(n), :] = local
        S = self._scatter_flat
        return S @ block.reshape(6 * n, 6 * n) @ S.T

    def generalized_forces(self, z: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, float, float]:
        """
        Q, total potential energy and total dissipated power: the per-step hot path.

        Uses the compiled kernel when every law is quadratic, else ``forces``.
        """
        Q, _, _, energy, dissipation = self.report(z, v)
        return Q, energy, dissipation

    def report(self, z: np.ndarray, v: np.ndarray):
        """
        Q.

        Deflections r (n, 3), wrenches on body B (n, 3), total energy and dissipated power (as in
        ``forces``), by the compiled kernel when every law is quadratic.
        """
        if self.compiled:
            n = len(self.ia)
            Q, r, wrench = np.empty(3 * self.n_bodies), np.empty((n, 3)), np.empty((n, 3))
            energy, dissipation = kernels.quadratic_forces(
                np.asarray(z, dtype=float),
                np.asarray(v, dtype=float),
                self._ia,
                self._ib,
                self._ca,
                self._cb,
                self.phia,
                self.phib,
                self._kind,
                self._W,
                self._C,
                Q,
                r,
                wrench,
            )
            return Q, r, wrench, float(energy), float(dissipation)
        hf = self.forces(z, v)
        return hf.Q, hf.r, hf.wrench_b, float(hf.energy.sum()), float(hf.dissipation.sum())

    @overload
    def forces(self, z: np.ndarray, v: np.ndarray, jacobian: Literal[True]) -> HingeJacobians: ...

    @overload
    def forces(self, z: np.ndarray, v: np.ndarray, jacobian: bool = False) -> HingeForces: ...

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
        # d2U/dr2, C_r and d(C_r r_dot)/dr: allocated and filled when the Jacobian is asked for
        hess = Cr = fdamp_dr = _NO_JACOBIAN
        if jacobian:
            hess, Cr, fdamp_dr = np.empty((n, 3, 3)), np.empty((n, 3, 3)), np.empty((n, 3, 3))
        for idx, batch in self.groups:
            ev = batch.evaluate(r[idx, 0], r[idx, 1:], rdot[idx], jacobian=jacobian)
            energy[idx], grad[idx], fdamp[idx] = ev.energy, ev.grad, ev.damping_force
            if jacobian:
                hess[idx], Cr[idx], fdamp_dr[idx] = ev.hess, ev.damping, ev.damping_force_dr
        total = grad + fdamp
        q_local = -np.einsum("nki,nk->ni", dr, total)  # (n, 6)
        Q = self._scatter_flat @ q_local.ravel()
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
            dQ_dz = -self._assemble(K_local)
            dQ_dv = -self._assemble(C_local)
        dissipation = np.einsum("ni,ni->n", fdamp, rdot)
        wrench_b = -wrench_on_element(r[:, 0], total)
        if dQ_dz is not None and dQ_dv is not None:
            return HingeJacobians(Q, dQ_dz, dQ_dv, r, rdot, energy, dissipation, wrench_b)
        return HingeForces(Q, None, None, r, rdot, energy, dissipation, wrench_b)
