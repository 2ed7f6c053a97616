"""
Dimensionless finite-element solves of a hinge, cached on disk; meshes moved for derivatives.

A ``Case`` is what a solve depends on once E, the plate thickness and the size are scaled out
(elastic.py solves with E = 1, unit plate thickness, lengths in the shape's reference length):
the shape, its ratios (shapes.py), Poisson's ratio, plane stress or strain, and the mesh
resolution n (elements across a section). ``solve`` returns its compliance and peak stresses,
from the disk cache (cache.py) when it has them.

Derivatives (model.py) need the solve at geometries a small step away. Re-meshing there would
change the mesh's topology and add a discretisation jump of the order of the discretisation
error (~1e-5) to a difference of the order of the step; instead the base case's mesh is
*moved* onto the nearby outline (``morph``): x is stretched piecewise linearly so that the
clamp line and the end of the straight part of the outline stay where they belong, and y
is scaled by the ratio of the two outlines' half-widths at the point, which puts every
boundary node on the new outline exactly. The discrete stiffness is then a smooth function
of the geometry whose derivative is that of the finite-element model. The fibre points
(elastic.py) of a moved mesh are the base case's, moved the same way: the derivatives of a
fibre's coefficients follow one material point rather than jump between surface nodes.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, replace
from typing import Optional

import numpy as np

from flexure_sim.engine.hinges.fe import cache
from flexure_sim.engine.hinges.fe.elastic import PLANES, solve as solve_mesh
from flexure_sim.engine.hinges.fe.mesh import HingeMesh, mesh_profile
from flexure_sim.engine.hinges.fe.shapes import Profile, profile, shape

#: Elements across a section by default: the stiffness is then within 1e-4 of its converged
#: value for the shapes of docs/hinges.md (the convergence study of convergence.py).
DEFAULT_RESOLUTION = 16


@dataclass(frozen=True)
class Case:
    """The dimensionless inputs of one solve (module docstring)."""

    shape: str
    ratios: tuple[float, ...]
    nu: float
    plane: str
    n: int = DEFAULT_RESOLUTION

    def __post_init__(self):
        shape(self.shape)
        if self.plane not in PLANES:
            raise ValueError(f"plane: expected one of {PLANES}, got {self.plane!r}")
        profile(self.shape, self.ratios)  # ShapeError for an impossible outline

    def key(self) -> dict:
        """Return the cache key: ratios and nu to 15 significant digits, as JSON numbers."""
        return {"shape": self.shape, "ratios": [float(f"{r:.15g}") for r in self.ratios],
                "nu": float(f"{self.nu:.15g}"), "plane": self.plane, "n": int(self.n)}


@dataclass(frozen=True)
class Result:
    """
    Compliance (3, 3) and peak von Mises stresses (3,) under unit wrenches, dimensionless.

    ``peak_at`` (3, 2): where each peak is (in the reference length); ``fibres`` (k, 3): the
    signed von Mises stress of the surface's critical points under the unit wrenches, and
    ``fibres_at`` (k, 2) where they are (elastic.py); ``seconds``: the time the solve took (0
    when read from the cache).
    """

    compliance: np.ndarray
    peak: np.ndarray
    peak_at: np.ndarray
    fibres: np.ndarray
    fibres_at: np.ndarray
    seconds: float


def morph(m: HingeMesh, source: Profile, target: Profile) -> HingeMesh:
    """Move the nodes of ``m``, a mesh of ``source``, onto ``target`` (module docstring)."""
    return replace(m, nodes=moved(m.nodes, source, target))


def moved(points: np.ndarray, source: Profile, target: Profile) -> np.ndarray:
    """Return points (k, 2) in ``source`` moved onto ``target`` as ``morph`` moves nodes."""
    x, y = points[:, 0], points[:, 1]
    ax = np.abs(x)
    if source.flat > 0:
        inner = ax * (target.flat / source.flat)
    else:
        inner = ax * 0.0
    arc0, arc1 = source.half - source.flat, target.half - target.flat
    outer = target.flat + (ax - source.flat) * (arc1 / arc0 if arc0 > 0 else 0.0)
    xn = np.sign(x) * np.where(ax <= source.flat, inner, outer)
    yn = y * target.y_top(xn) / source.y_top(x)
    return np.stack([xn, yn], axis=1)


_LAYOUT = {"compliance": (3, 3), "peak": (3,), "peak_at": (3, 2), "fibres": (-1, 3),
           "fibres_at": (-1, 2)}


def _result(values: dict, seconds: float) -> Result:
    return Result(**{k: values[k] for k in _LAYOUT}, seconds=seconds)


def solve(case: Case, target: Optional[tuple[tuple[float, ...], float]] = None) -> Result:
    """
    Return the solve of ``case``, or of its mesh moved to ``target`` = (ratios, nu).

    From the cache when possible (cache.py); otherwise mesh, solve and store.
    """
    key = case.key()
    if target is not None:
        key["target"] = {"ratios": [float(f"{r:.15g}") for r in target[0]],
                         "nu": float(f"{target[1]:.15g}")}
    stored = cache.load(key, _LAYOUT)
    if stored is not None:
        return _result(stored, 0.0)
    at = None if target is None else solve(case).fibres_at  # the base case's fibre points
    start = time.perf_counter()
    base = profile(case.shape, case.ratios)
    m = mesh_profile(base, case.n)
    prof, nu = base, case.nu
    if target is not None:
        prof, nu = profile(case.shape, tuple(target[0])), float(target[1])
        m = morph(m, base, prof)
        assert at is not None  # the base case's, solved above
        at = moved(at, base, prof)
    sol = solve_mesh(m, prof.half, nu, case.plane, at)
    values = {k: getattr(sol, k) for k in _LAYOUT}
    cache.store(key, values)
    return _result({k: np.asarray(v, dtype=float) for k, v in values.items()},
                   time.perf_counter() - start)
