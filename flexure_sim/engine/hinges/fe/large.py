"""
Large deflection of a finite-element hinge: wrench samples for a fitted polynomial law (Ch. 7).

Body A's clamp is fixed; body B's clamp is moved through a finite rigid motion r = (alpha, p):
a point X of it goes to R(alpha) X + p, which is the displacement of hinge frame b relative to
frame a that ``wrench_data`` and ``flexure-sim fit`` use. The elastic element between them is
solved in the total Lagrangian form with the Saint Venant-Kirchhoff material (second
Piola-Kirchhoff stress S = lambda tr(E) I + 2 mu E of the Green-Lagrange strain
E = (F^T F - I) / 2, first Piola-Kirchhoff P = F S; plane strain, or plane stress through
lambda*, which is exact in the small-strain limit these hinges stay in): the residual
int P : grad v dX and its exact tangent int grad v : (grad w S + F dS[w]) dX are assembled by
scikit-fem on the same P2 isoparametric mesh as the linear solve (elastic.py), and Newton's
method converges each sample (from the previous one, B's rigid motion interpolated in
steps of at most 0.1 rad of rotation).

The internal force at B's clamp nodes is the force body B exerts on the element; summed, with
the moment about b's origin (now at p) of the forces at the deformed node positions
R(alpha) X + p, and turned into frame b, it is m_b = (m, f_x, f_y) of eqs. 4.34-4.35 -- the
CSV's wrench. Everything is dimensionless (E = 1, unit plate thickness, lengths in ell) and
model.py's scaling applies unchanged: m = E t ell^2 m^, f = E t ell f^, p = ell p^.
"""
from __future__ import annotations

import numpy as np

from flexure_sim.engine.hinges.fe.elastic import lame
from flexure_sim.engine.hinges.fe.mesh import HingeMesh
from flexure_sim.errors import FlexureSimError

#: Largest rotation applied in one load step (rad).
ROTATION_STEP = 0.1


class ConvergenceError(FlexureSimError, RuntimeError):
    """Newton's method did not converge for a large-deflection sample (names it)."""


def _matmul(A, B):
    return np.einsum("ik...,kj...->ij...", A, B)


def _forms(lam: float, mu: float):
    from skfem import BilinearForm, LinearForm
    from skfem.helpers import ddot, eye, trace, transpose

    def kinematics(grad_u):
        ident = eye(np.ones_like(grad_u[0, 0]), 2)
        F = grad_u + ident
        E = 0.5 * (_matmul(transpose(F), F) - ident)
        S = lam * trace(E) * ident + 2.0 * mu * E
        return F, S, ident

    @LinearForm
    def residual(v, w):
        F, S, _ = kinematics(w["u"].grad)
        return ddot(_matmul(F, S), v.grad)

    @BilinearForm
    def tangent(u, v, w):
        F, S, ident = kinematics(w["u"].grad)
        dE = 0.5 * (_matmul(transpose(F), u.grad) + _matmul(transpose(u.grad), F))
        dS = lam * trace(dE) * ident + 2.0 * mu * dE
        return ddot(_matmul(u.grad, S) + _matmul(F, dS), v.grad)

    return residual, tangent


def _rot(a: float) -> np.ndarray:
    return np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])


def _screw(start: np.ndarray, goal: np.ndarray, s: float) -> np.ndarray:
    """
    Return the rigid motion (alpha, p) a fraction s of the way from ``start`` to ``goal``.

    Along the screw (the rotation about the fixed point c, or the translation) that takes
    start to goal: a bending leaf's end moves nearly so, while straight-line interpolation of
    p would shorten or stretch a slender leaf on the way (even past its buckling load).
    """
    da = goal[0] - start[0]
    d = _rot(-start[0]) @ (goal[1:] - start[1:])  # the relative motion in start's frame
    if abs(da) < 1e-12:
        rel = s * d
    else:
        c = np.linalg.solve(np.eye(2) - _rot(da), d)
        rel = (np.eye(2) - _rot(s * da)) @ c
    return np.concatenate([[start[0] + s * da], start[1:] + _rot(start[0]) @ rel])


class LargeDeflection:
    """A meshed hinge ready for large-deflection solves (module docstring)."""

    def __init__(self, m: HingeMesh, half: float, nu: float, plane: str):
        """Build the basis, forms and clamp dofs of the mesh ``m`` (clamps at x = +-half)."""
        from skfem import Basis, ElementTriP2, ElementVector, MeshTri2

        mesh = MeshTri2(m.nodes.T.copy(), m.triangles.T.copy())
        self.basis = Basis(mesh, ElementVector(ElementTriP2()), intorder=4)
        self.residual, self.tangent = _forms(*lame(nu, plane))
        tol = 1e-9 * half

        def clamp(x0):
            facets = mesh.facets_satisfying(lambda x: np.abs(x[0] - x0) < tol,
                                            boundaries_only=True)
            return self.basis.get_dofs(facets)

        left, right = clamp(-half), clamp(half)
        self.fixed = left.all()
        self.bx = np.concatenate([right.nodal["u^1"], right.facet["u^1"]]).astype(int)
        self.by = np.concatenate([right.nodal["u^2"], right.facet["u^2"]]).astype(int)
        self.dirichlet = np.concatenate([self.fixed, self.bx, self.by])
        self.u = np.zeros(self.basis.N)
        self.state = np.zeros(3)  # B's rigid motion (alpha, p) of the current solution

    def _prescribed(self, alpha: float, p) -> np.ndarray:
        """Return the clamp displacement of B's rigid motion (alpha, p), all Dirichlet dofs."""
        c, s = np.cos(alpha), np.sin(alpha)
        X = self.basis.doflocs
        u = np.zeros(self.basis.N)
        u[self.bx] = c * X[0, self.bx] - s * X[1, self.bx] + p[0] - X[0, self.bx]
        u[self.by] = s * X[0, self.by] + c * X[1, self.by] + p[1] - X[1, self.by]
        return u[self.dirichlet]

    def _newton(self, target: np.ndarray, tol: float, max_iter: int) -> None:
        """
        Newton's method to the prescribed clamp values ``target``.

        The first step carries the clamp's increment into the interior through the tangent
        (a linear predictor), so the elements next to the clamp are not torn by it.
        """
        from skfem import asm, condense, solve

        u = self.u.copy()
        jump = np.zeros(self.basis.N)
        jump[self.dirichlet] = target - u[self.dirichlet]
        scale, size = 1e-30, np.inf
        for _ in range(max_iter):
            field = self.basis.interpolate(u)
            r = asm(self.residual, self.basis, u=field)
            K = asm(self.tangent, self.basis, u=field)
            du = solve(*condense(K, -r, x=jump, D=self.dirichlet))
            jump[:] = 0.0
            u += du
            size = np.max(np.abs(du))
            scale = max(scale, np.max(np.abs(u)))
            if size <= tol * scale:
                self.u = u
                return
        raise ConvergenceError(f"Newton's method did not converge in {max_iter} iterations "
                               f"(last update {size / scale:.2e} of the displacement)")

    def wrench(self, alpha: float, p, tol: float = 1e-10, max_iter: int = 30) -> np.ndarray:
        """
        Return m_b (3,) at B's rigid motion (alpha, p) (dimensionless; module docstring).

        Continues from the previous sample's solution through rigid motions interpolated
        between the two, in rotation steps of at most ROTATION_STEP.
        """
        from skfem import asm

        goal = np.array([alpha, p[0], p[1]], dtype=float)
        start = self.state
        steps = max(1, int(np.ceil(abs(goal[0] - start[0]) / ROTATION_STEP)))
        for k in range(1, steps + 1):
            step = _screw(start, goal, k / steps)
            try:
                self._newton(self._prescribed(step[0], step[1:]), tol, max_iter)
            except ConvergenceError as exc:
                self.u, self.state = np.zeros(self.basis.N), np.zeros(3)  # restart from rest
                raise ConvergenceError(f"sample alpha={alpha:g}, p={list(p)}: {exc}") from None
            self.state = step
        f = asm(self.residual, self.basis, u=self.basis.interpolate(self.u))
        c, s = np.cos(alpha), np.sin(alpha)
        X = self.basis.doflocs
        fx, fy = f[self.bx], f[self.by]
        # Moment about b's origin of the forces at the deformed positions, minus p: R X.
        arm_x = c * X[0, self.by] - s * X[1, self.by]
        arm_y = s * X[0, self.bx] + c * X[1, self.bx]
        m = np.sum(arm_x * fy) - np.sum(arm_y * fx)
        Fx, Fy = np.sum(fx), np.sum(fy)
        return np.array([m, c * Fx + s * Fy, -s * Fx + c * Fy])
