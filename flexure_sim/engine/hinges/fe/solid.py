"""
The ``model: fe`` hinge in space: its 6x6 stiffness from a three-dimensional elastic solid.

Geometry. The hinge's planar outline (shapes.py, lengths in units of the reference length
ell) is extruded by the plate thickness W (the notch's ``t``, the leaf's ``width``) over
-W/2 <= z <= W/2, and meshed with ten-node tetrahedra by gmsh: in the plane about ``n``
elements across every section (the size rule of mesh.py), across the width layers graded
from 1/n at both free faces (where torsion and anticlastic bending vary fastest) by a factor
1.5 up to the in-plane size at the clamps. The edge nodes lie on the exact arcs.

Elasticity. scikit-fem's isoparametric quadratic tetrahedra (``MeshTet2``,
``ElementVector(ElementTetP2())``, ``skfem.models.elasticity.linear_elasticity``) with E = 1
and the Lamé parameters lambda = nu / ((1 + nu)(1 - 2 nu)), mu = 1 / (2 (1 + nu)): the
three-dimensional Navier equations, no plane assumption. (Linear tetrahedra lock in bending:
``order=1`` is kept for the convergence study of docs/hinges.md, which measured it.)

Rigid ends. Body A's end face x = -l is fixed; the nodes of body B's face x = +l follow B's
small rigid motion q = (omega, v) of the hinge frame's origin (the centre), rotations first,
u = v + omega x r, i.e. u_x = v_x + w_y z - w_z y, u_y = v_y + w_z x - w_x z,
u_z = v_z + w_x y - w_y x. These dofs are eliminated by the six-column map G (u_S = G q), the
multipoint constraint of elastic.py in space. The six unit wrenches on B at the hinge frame
(m_x, m_y, m_z, f_x, f_y, f_z), the work-conjugates of q, are the right-hand sides; their
solutions' q are the columns of the compliance C (6x6, symmetric by construction), K = C^-1.

Scaling. With lengths in ell and E = 1, moments scale as E ell^3, forces as E ell^2,
rotations not at all and displacements as ell, so K = E ell S K^ S, S = diag(ell, ell, ell,
1, 1, 1): the solve depends on the ratios, W / ell and nu only, and is cached (cache.py) by
those. The frame and order are ``spatial_stiffness.notch_stiffness``'s: x along the notch, y
across its neck, z across the plate; the leaf is turned by +90 degrees about z to the
cantilever's convention (length along y, thickness along x), K = T K_int T^T with
T = diag(R, R), R the rotation.
"""
from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any, Mapping

import numpy as np

from flexure_sim.engine.hinges.fe import cache
from flexure_sim.engine.hinges.fe.elastic import tied_end_solve
from flexure_sim.engine.hinges.fe.mesh import MeshError, gmsh_session, size_by_section
from flexure_sim.engine.hinges.fe.shapes import Profile, build_outline, profile, shape

#: Elements across the neck by default, and the element order: the convergence study of
#: docs/hinges.md ("The hinge in space") puts this within 2 % of the converged 6x6 diagonal.
DEFAULT_RESOLUTION = 4
DEFAULT_ORDER = 2
#: Growth of the layer thickness from the plate's free faces towards its middle.
GROWTH = 1.5
#: The leaf's internal frame (along x) to the cantilever's (along y): +90 degrees about z.
_ROT = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])


@dataclass(frozen=True)
class SolidMesh:
    """Tetrahedra of an extruded outline: ``doflocs`` (3, N) of all nodes, ``t`` (4|10, M)."""

    doflocs: np.ndarray
    t: np.ndarray
    order: int


def layers(width: float, first: float, cap: float) -> list[float]:
    """
    Cumulative heights (fractions of ``width``) of layers graded from both faces.

    The layers grow by GROWTH from ``first`` at each face up to ``cap``, then stay; the half
    is scaled to fill width / 2 exactly, and mirrored.
    """
    half = 0.5 * width
    sizes, total, size = [], 0.0, min(first, half)
    while total + 0.5 * size < half:
        sizes.append(size)
        total += size
        size = min(size * GROWTH, cap)
    sizes = sizes or [half]
    sizes = [s * half / sum(sizes) for s in sizes]
    all_sizes = sizes + sizes[::-1]
    return list(np.cumsum(all_sizes) / width)


def mesh_solid(prof: Profile, width: float, n: int, order: int = DEFAULT_ORDER) -> SolidMesh:
    """Mesh the outline ``prof`` extruded by ``width`` (module docstring); MeshError if not."""
    if n < 1 or order not in (1, 2):
        raise ValueError(f"n >= 1 and order 1 or 2, got n={n}, order={order}")
    with gmsh_session("hinge3d", "the hinge in 3-D") as gmsh:
        build_outline(gmsh, prof)
        surface = gmsh.model.getEntities(2)[0]
        geo = gmsh.model.geo
        geo.translate([surface], 0.0, 0.0, -0.5 * width)
        heights = layers(width, 1.0 / n, 2.0 * prof.corner / n)
        geo.extrude([surface], 0.0, 0.0, width, numElements=[1] * len(heights),
                    heights=heights)
        geo.synchronize()
        size_by_section(gmsh, prof, n)
        gmsh.model.mesh.generate(3)
        if order == 2:
            gmsh.model.mesh.setOrder(2)
        tags, coords, _ = gmsh.model.mesh.getNodes()
        types, _, elem_nodes = gmsh.model.mesh.getElements(3)
        want = 4 if order == 1 else 11  # gmsh: 4-node and 10-node tetrahedra
        if list(types) != [want]:
            raise MeshError(f"gmsh returned volume element types {list(types)}, not "
                            f"type {want} tetrahedra")
    index = np.full(int(tags.max()) + 1, -1, dtype=np.int64)
    index[tags.astype(np.int64)] = np.arange(len(tags))
    points = coords.reshape(-1, 3).T
    t = index[elem_nodes[0].astype(np.int64)].reshape(-1, 4 if order == 1 else 10).T
    return _skfem_nodes(points, t, order)


def _skfem_nodes(points: np.ndarray, t: np.ndarray, order: int) -> SolidMesh:
    """
    Return the mesh with vertices first and each edge node where scikit-fem's P2 wants it.

    gmsh's ten-node tetrahedron lists its edge nodes after the vertices (edges 01, 12, 20, 30,
    32, 31); each is matched to scikit-fem's edge by its two end vertices.
    """
    from skfem import MeshTet1, MeshTet2

    verts, inverse = np.unique(t[:4], return_inverse=True)
    tv = inverse.reshape(4, -1)
    linear = MeshTet1(points[:, verts].copy(), tv.copy())
    if order == 1:
        return SolidMesh(linear.p.copy(), linear.t.copy(), 1)
    quad = MeshTet2.from_mesh(linear)
    nv = linear.p.shape[1]
    pairs = ((0, 1), (1, 2), (2, 0), (3, 0), (3, 2), (3, 1))
    # sorted vertex pair -> gmsh's edge node, as one integer key
    a = np.concatenate([linear.t[i] for i, _ in pairs])
    b = np.concatenate([linear.t[j] for _, j in pairs])
    mid = np.concatenate([t[4 + k] for k in range(6)])
    keys = np.minimum(a, b).astype(np.int64) * nv + np.maximum(a, b)
    keys, first = np.unique(keys, return_index=True)
    edges = np.sort(quad.edges, axis=0).astype(np.int64)
    want = edges[0] * nv + edges[1]
    pos = np.searchsorted(keys, want)
    if np.any(pos >= len(keys)) or np.any(keys[np.minimum(pos, len(keys) - 1)] != want):
        raise MeshError("the 3-D mesh's edge nodes do not match its tetrahedra's edges")
    doflocs = quad.doflocs.copy()
    doflocs[:, nv:nv + edges.shape[1]] = points[:, mid[first[pos]]]
    return SolidMesh(doflocs, quad.t.copy(), 2)


def _rigid_map(loc: np.ndarray, comp: np.ndarray) -> np.ndarray:
    """Return G (k, 6): dof values of component ``comp`` at ``loc`` (3, k) for q = (w, v)."""
    x, y, z = loc
    G = np.zeros((len(comp), 6))
    for c, rows in ((0, (0.0 * x, z, -y)), (1, (-z, 0.0 * x, x)), (2, (y, -x, 0.0 * x))):
        sel = comp == c
        for j in range(3):
            G[sel, j] = rows[j][sel]
        G[sel, 3 + c] = 1.0
    return G


def solve_solid(m: SolidMesh, half: float, nu: float) -> tuple[np.ndarray, int]:
    """Return (compliance C^ (6, 6), unknowns) of the meshed solid (module docstring)."""
    from skfem import Basis, ElementTetP1, ElementTetP2, ElementVector, MeshTet1, MeshTet2, asm
    from skfem.models.elasticity import linear_elasticity

    if m.order == 2:
        mesh, element, intorder = MeshTet2(m.doflocs, m.t), ElementTetP2(), 4
    else:
        mesh, element, intorder = MeshTet1(m.doflocs, m.t), ElementTetP1(), 2
    basis = Basis(mesh, ElementVector(element), intorder=intorder)
    lam = nu / ((1.0 + nu) * (1.0 - 2.0 * nu))
    K = asm(linear_elasticity(lam, 0.5 / (1.0 + nu)), basis).tocsr()
    n = K.shape[0]
    comp = np.empty(n, dtype=int)
    for c in range(3):
        comp[basis.nodal_dofs[c]] = c
        if m.order == 2:
            comp[basis.edge_dofs[c]] = c
    loc = basis.doflocs
    tol = 1e-9 * half
    fixed = np.flatnonzero(np.abs(loc[0] + half) < tol)
    tied = np.flatnonzero(np.abs(loc[0] - half) < tol)
    G = _rigid_map(loc[:, tied], comp[tied])
    C, _, unknowns = tied_end_solve(K, fixed, tied, G, permc_spec="MMD_AT_PLUS_A")
    return C, unknowns


def dimensionless(name: str, ratios: tuple[float, ...], width: float, nu: float,
                  n: int = DEFAULT_RESOLUTION,
                  order: int = DEFAULT_ORDER) -> tuple[np.ndarray, float]:
    """
    Return (K^ (6, 6), seconds) of a shape in its internal frame (x along it), E = 1, ell = 1.

    From the cache when it has it (seconds 0), else meshed, solved and stored.
    """
    key = {"model": "solid", "shape": name, "ratios": [float(f"{r:.15g}") for r in ratios],
           "width": float(f"{width:.15g}"), "nu": float(f"{nu:.15g}"), "n": int(n),
           "order": int(order)}
    stored = cache.load(key, {"compliance": (6, 6)})
    if stored is not None:
        return np.linalg.inv(stored["compliance"]), 0.0
    start = time.perf_counter()
    prof = profile(name, tuple(ratios))
    C, _ = solve_solid(mesh_solid(prof, width, n, order), prof.half, nu)
    cache.store(key, {"compliance": C})
    return np.linalg.inv(C), time.perf_counter() - start


def stiffness(name: str, values: Mapping[str, Any], E: float, nu: float,
              n: int = DEFAULT_RESOLUTION, order: int = DEFAULT_ORDER) -> np.ndarray:
    """
    Return a ``model: fe`` hinge's 6x6 K at its frame, SI units, rotations first.

    ``values``: the shape's geometry keys (shapes.SHAPES) in metres; floats only (the 3-D
    engine has no design sensitivities). K = E ell S K^ S (module docstring).
    """
    s = shape(name)
    ell = float(values[s.lengths[0]])
    ratios = tuple(float(values[k]) / ell for k in s.lengths[1:])
    width = float(values[s.plate]) / ell
    K_hat, _ = dimensionless(name, ratios, width, float(nu), n, order)
    S = np.diag([ell, ell, ell, 1.0, 1.0, 1.0])
    K = float(E) * ell * S @ K_hat @ S
    if name == "leaf":
        T = np.zeros((6, 6))
        T[:3, :3] = T[3:, 3:] = _ROT
        K = T @ K @ T.T
    return 0.5 * (K + K.T)
