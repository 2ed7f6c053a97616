"""
Linear elasticity of a hinge between two rigid bodies: compliance, stiffness and peak stress.

The hinge outline (shapes.py, lengths in units of the reference length ell) is meshed with
six-node triangles (mesh.py) and solved with scikit-fem's isoparametric P2 elements
(``MeshTri2``, ``ElementVector(ElementTriP2())``, ``skfem.models.elasticity``) in plane stress
or plane strain, with E = 1 and a unit plate thickness; model.py scales the results to SI.

Boundary conditions (the hinge's ends clamped to rigid bodies):

* body A: every node on the clamp line x = -l is fixed, u = 0;
* body B: the nodes on x = +l move with B's small rigid motion q = (theta, u, v) of the hinge
  frame's origin (the centre), u_x = u - theta y, u_y = v + theta x. These dofs are eliminated
  by the 3-column map G (u_S = G q): the system is T^T K T for T = [[1, 0], [0, G]] on
  (interior dofs, q), a multipoint constraint by elimination, so no penalty or multiplier.

The load on q is the work-conjugate of B's motion at the centre, the wrench (m, f_x, f_y) on
body B at the hinge frame: solving with the three unit wrenches as right-hand sides gives the
columns of the compliance C (3x3, moment first, forces second, as ``stiffness.py``), symmetric
by construction; the stiffness is K = C^-1.

Stress: each unit-wrench solution's von Mises stress at the vertices of every element (where
the linear P2 stress takes its extremes in an element), unaveraged; the peak over the mesh and
where it is. Plane strain adds sigma_zz = nu (sigma_xx + sigma_yy).

Fibres (the points fatigue cycles, engine/hinges/fatigue.py). At a traction-free surface the
in-plane stress is uniaxial along the surface, sigma_nn = sigma_nt = 0, so the tangential
stress is the in-plane trace, sigma_t = sigma_xx + sigma_yy (an invariant: no tangent needed),
and it is linear in the wrench: sigma_t = a . (m, f_x, f_y) with a the unit wrenches' traces.
Von Mises there is |sigma_t| in plane stress and |sigma_t| sqrt(1 - nu + nu^2) in plane strain
(sigma_zz = nu sigma_t); a fibre's coefficients are a times that factor, the von Mises stress
with the sign of sigma_t (tension positive). The trace at a surface vertex is averaged over
the elements sharing it. The points: for each unit wrench the free-surface vertex (not on a
clamp line) where |sigma_t| is largest, and the vertices nearest its mirror images in both
axes of the symmetric hinge (both notch roots, the four fillet roots of a leaf), each vertex
once; or, for a moved mesh (solves.morph), the vertices nearest given points, so that the
derivatives follow the same material points.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from flexure_sim.engine.hinges.fe.mesh import HingeMesh

PLANES = ("stress", "strain")


@dataclass(frozen=True)
class Solution:
    """
    One linear solve, dimensionless (E = 1, unit plate thickness, lengths in ell).

    ``compliance`` (3, 3); ``peak`` (3,): the largest von Mises stress under each unit wrench
    (m, f_x, f_y); ``peak_at`` (3, 2): where; ``dofs``: the number of unknowns;
    ``displacements`` (3, N, 2): the nodal displacement of each unit-wrench solution (kept for
    pictures; N nodes of the mesh); ``von_mises`` (3, M, 3) at each element's vertices;
    ``fibres`` (k, 3): the signed von Mises stress of each fibre point under the unit wrenches,
    ``fibres_at`` (k, 2): where (module docstring).
    """

    compliance: np.ndarray
    peak: np.ndarray
    peak_at: np.ndarray
    dofs: int
    displacements: np.ndarray
    von_mises: np.ndarray
    fibres: np.ndarray
    fibres_at: np.ndarray


def lame(nu: float, plane: str) -> tuple[float, float]:
    """
    Lamé parameters (lambda, mu) for E = 1 in plane strain, or the plane-stress lambda*.

    lambda* = 2 lambda mu / (lambda + 2 mu) (sigma_zz = 0 eliminated).
    """
    if plane not in PLANES:
        raise ValueError(f"plane: expected one of {PLANES}, got {plane!r}")
    lam = nu / ((1.0 + nu) * (1.0 - 2.0 * nu))
    mu = 0.5 / (1.0 + nu)
    if plane == "stress":
        lam = 2.0 * lam * mu / (lam + 2.0 * mu)
    return lam, mu


def _skfem_mesh(m: HingeMesh):
    from skfem import MeshTri2

    return MeshTri2(m.nodes.T.copy(), m.triangles.T.copy())


def _clamp_dofs(basis, nodes_x: float, half: float, tol: float):
    """Return the (x-component, y-component) dof indices of the clamp line x = nodes_x."""
    facets = basis.mesh.facets_satisfying(lambda x: np.abs(x[0] - nodes_x) < tol * half,
                                          boundaries_only=True)
    dofs = basis.get_dofs(facets)
    ux = np.concatenate([dofs.nodal.get("u^1", []), dofs.facet.get("u^1", [])]).astype(int)
    uy = np.concatenate([dofs.nodal.get("u^2", []), dofs.facet.get("u^2", [])]).astype(int)
    return np.unique(ux), np.unique(uy)


def tied_end_solve(K, fixed: np.ndarray, tied: np.ndarray, G: np.ndarray,
                   **splu_options) -> tuple[np.ndarray, np.ndarray, int]:
    """
    Compliance of a clamped body whose other end moves rigidly: u_fixed = 0, u_tied = G q.

    The degrees of freedom are reduced to u = T (u_interior, q) and K_r = T^T K T solved for a
    unit generalized load on each of q's k = G.shape[1] components (sparse LU, ``splu_options``
    to scipy's splu). Return (C, u, unknowns): the symmetrised k x k compliance (dq per unit
    load), the full displacement of each load case (n, k) and the reduced system's size.
    """
    n, k = K.shape[0], G.shape[1]
    interior = np.setdiff1d(np.arange(n), np.concatenate([fixed, tied]))
    ni = len(interior)
    rows = np.concatenate([interior, np.repeat(tied, k)])
    cols = np.concatenate([np.arange(ni), ni + np.tile(np.arange(k), len(tied))])
    vals = np.concatenate([np.ones(ni), G.ravel()])
    T = sp.csr_matrix((vals, (rows, cols)), shape=(n, ni + k))
    A = (T.T @ K @ T).tocsc()
    rhs = np.zeros((ni + k, k))
    rhs[ni:, :] = np.eye(k)
    x = spla.splu(A, **splu_options).solve(rhs)
    C = x[ni:, :]
    return 0.5 * (C + C.T), T @ x, ni + k


def solve(m: HingeMesh, half: float, nu: float, plane: str, at=None) -> Solution:
    """
    Compliance and peak stresses of the meshed hinge ``m`` (clamps at x = -half, +half).

    ``at`` (k, 2): the fibre points to take (module docstring), or None to find them.
    """
    from skfem import Basis, ElementTriP2, ElementVector, asm
    from skfem.models.elasticity import linear_elasticity

    mesh = _skfem_mesh(m)
    element = ElementVector(ElementTriP2())
    basis = Basis(mesh, element, intorder=4)
    lam, mu = lame(nu, plane)
    K = asm(linear_elasticity(lam, mu), basis).tocsr()
    fixed = np.concatenate(_clamp_dofs(basis, -half, half, 1e-9))
    sx, sy = _clamp_dofs(basis, half, half, 1e-9)
    tied = np.concatenate([sx, sy])
    loc = basis.doflocs
    # G: u_S = G q, q = (theta, u, v) at the centre.
    G = np.zeros((len(tied), 3))
    G[:len(sx), 0] = -loc[1, sx]
    G[:len(sx), 1] = 1.0
    G[len(sx):, 0] = loc[0, sy]
    G[len(sx):, 2] = 1.0
    C, u, unknowns = tied_end_solve(K, fixed, tied, G)
    peak, peak_at, vm, trace = _von_mises(mesh, element, u, lam, mu, nu, plane)
    fibres, fibres_at = _fibres(mesh, trace, half, nu, plane, at)
    return Solution(C, peak, peak_at, unknowns, _to_mesh_nodes(m, basis, u), vm, fibres,
                    fibres_at)


def _to_mesh_nodes(m: HingeMesh, basis, u: np.ndarray) -> np.ndarray:
    """Return the displacement (3, N, 2) at the mesh's own nodes (matched by position)."""
    from scipy.spatial import cKDTree

    loc = basis.doflocs
    xdofs = np.concatenate([basis.nodal_dofs[0], basis.facet_dofs[0]])
    ydofs = np.concatenate([basis.nodal_dofs[1], basis.facet_dofs[1]])
    _, idx = cKDTree(loc[:, xdofs].T).query(m.nodes)
    return np.stack([u[xdofs[idx], :].T, u[ydofs[idx], :].T], axis=-1)


def _von_mises(mesh, element, u, lam, mu, nu, plane):
    """
    Peak von Mises stress of each load case and where; von Mises and the in-plane trace.

    The last two at each element's vertices, (cases, M, 3).
    """
    from skfem import Basis

    vertices = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    vb = Basis(mesh, element, quadrature=(vertices, np.full(3, 1.0 / 6.0)))
    xy = vb.mapping.F(vertices)  # (2, elements, 3)
    peaks, where, fields, traces = [], [], [], []
    for k in range(u.shape[1]):
        grad = vb.interpolate(u[:, k]).grad  # (2, 2, elements, 3)
        exx, eyy = grad[0, 0], grad[1, 1]
        exy = 0.5 * (grad[0, 1] + grad[1, 0])
        tr = exx + eyy
        sxx = 2 * mu * exx + lam * tr
        syy = 2 * mu * eyy + lam * tr
        sxy = 2 * mu * exy
        szz = nu * (sxx + syy) if plane == "strain" else 0.0 * sxx
        vm = np.sqrt(0.5 * ((sxx - syy) ** 2 + (syy - szz) ** 2 + (szz - sxx) ** 2)
                     + 3.0 * sxy ** 2)
        i = np.unravel_index(np.argmax(vm), vm.shape)
        peaks.append(vm[i])
        where.append(xy[:, i[0], i[1]])
        fields.append(vm)
        traces.append(sxx + syy)
    return np.array(peaks), np.array(where), np.array(fields), np.array(traces)


def _fibres(mesh, trace, half: float, nu: float, plane: str, at=None):
    """
    Return the fibres' signed von Mises coefficients (k, 3) and their points (k, 2).

    ``trace`` (3, M, 3): sigma_xx + sigma_yy of each unit wrench at the element vertices;
    ``at``: the points to take, or None to find them (module docstring).
    """
    t = mesh.t  # (3, M): the vertex of each element's quadrature point (the vertices)
    count = np.bincount(t.ravel(), minlength=mesh.p.shape[1])
    nodal = np.array([np.bincount(t.ravel(), weights=tr.T.ravel(), minlength=len(count))
                      for tr in trace]) / np.maximum(count, 1)  # (3, vertices)
    free = mesh.boundary_nodes()
    free = free[np.abs(mesh.p[0, free]) < half * (1.0 - 1e-9)]  # not on a clamp line
    xy = mesh.p[:, free].T

    def nearest(points) -> list:
        d = ((xy[None, :, :] - np.asarray(points, dtype=float)[:, None, :]) ** 2).sum(-1)
        return [int(free[i]) for i in np.argmin(d, axis=1)]

    if at is None:
        points = []
        for case in nodal:
            x, y = mesh.p[:, free[np.argmax(np.abs(case[free]))]]
            points += [(x, y), (-x, y), (x, -y), (-x, -y)]
        nodes = list(dict.fromkeys(nearest(points)))
    else:  # one node per given point, in their order (a moved mesh's derivatives)
        nodes = nearest(at)
    factor = np.sqrt(1.0 - nu + nu * nu) if plane == "strain" else 1.0
    return factor * nodal[:, nodes].T, mesh.p[:, nodes].T.copy()
