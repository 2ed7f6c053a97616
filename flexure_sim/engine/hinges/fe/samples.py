"""
Wrench samples of a finite-element hinge over its working range, in SI units (Ch. 7 data).

The working range is the set of hinge displacements r = (alpha, p_x, p_y) of frame b relative
to frame a (the hinge frame's convention: the leaf along y, notches along x) whose peak stress
is at most that of the rotation alpha_max alone, by the linear solve's conservative bound
sum_i c_i |K r|_i (model.stress_coefficients): in units of each component's stress-equivalent
size (``working_box``: alpha_max, and each translation that alone raises that stress), the
cross-polytope |a| + |x| + |y| <= 1. Points are drawn uniformly in it with a seeded generator
(uniform in the box, the others rejected). Each point is solved
with large deflection (large.py) on the model's mesh at resolution n; the rows are what
``fitting.wrench_data.write_wrench_csv`` writes and ``flexure-sim fit`` reads, and what
``fitting.least_squares.wrench_errors`` compares a law with (``flexure-sim hinge --samples``
reports the twistor quadratic law of the linear stiffness against them: how far the
quadratic potential is from the hinge over the range, Ch. 7's question).
"""
from __future__ import annotations

from typing import Any, Mapping

import numpy as np

from flexure_sim.engine.hinges.fe.large import LargeDeflection
from flexure_sim.engine.hinges.fe.mesh import mesh_profile
from flexure_sim.engine.hinges.fe.fe_model import _LEAF_ORDER, _LEAF_SIGN, plane_of
from flexure_sim.engine.hinges.fe.shapes import profile, ratios_of, shape
from flexure_sim.engine.hinges.fe.solves import DEFAULT_RESOLUTION, Case, solve


def _to_internal(name: str, r: np.ndarray) -> np.ndarray:
    """Hinge-frame vectors (alpha, x, y) to the solve's axes (the leaf runs along x there)."""
    if name != "leaf":
        return r
    out = np.empty_like(r)
    for i in range(3):
        out[..., _LEAF_ORDER[i]] = _LEAF_SIGN[i] * r[..., i]
    return out


def _to_frame(name: str, w: np.ndarray) -> np.ndarray:
    """Turn the solve's wrench components back to the hinge frame (inverse of _to_internal)."""
    if name != "leaf":
        return w
    return np.stack([_LEAF_SIGN[i] * w[..., _LEAF_ORDER[i]] for i in range(3)], axis=-1)


def working_box(name: str, values: Mapping[str, float], nu: float, alpha_max: float,
                plane: str = "auto", n: int = DEFAULT_RESOLUTION) -> np.ndarray:
    """Return (alpha_max, p_x max, p_y max) of the working range, rad and m (module docstring)."""
    s = shape(name)
    ell = float(values[s.lengths[0]])
    res = solve(Case(name, ratios_of(name, values), nu, plane_of(name, values, plane), n))
    K = np.linalg.inv(res.compliance)
    sigma = res.peak[0] * K[0, 0] * alpha_max
    internal = np.array([alpha_max, sigma / (res.peak[1] * K[1, 1]) * ell,
                         sigma / (res.peak[2] * K[2, 2]) * ell])
    return np.abs(_to_frame(name, internal))


def wrench_samples(name: str, values: Mapping[str, Any], E: float, nu: float,
                   alpha_max: float, count: int, seed: int = 0, plane: str = "auto",
                   n: int = DEFAULT_RESOLUTION) -> tuple[np.ndarray, np.ndarray]:
    """
    Return (r (count, 3), m_b (count, 3)) over the working range, SI units.

    r = (alpha, p_x, p_y) of frame b in frame a; m_b = (m, f_x, f_y), the wrench body B
    exerts on the element in frame b, moment about b's origin.
    """
    s = shape(name)
    ell, t = float(values[s.lengths[0]]), float(values[s.plate])
    plane = plane_of(name, values, plane)
    box = working_box(name, values, nu, alpha_max, plane, n)
    rng = np.random.default_rng(seed)
    unit = np.zeros((0, 3))
    while len(unit) < count:
        draw = rng.uniform(-1.0, 1.0, size=(8 * count, 3))
        unit = np.concatenate([unit, draw[np.abs(draw).sum(axis=1) <= 1.0]])
    r = unit[:count] * box
    prof = profile(name, ratios_of(name, values))
    solver = LargeDeflection(mesh_profile(prof, n), prof.half, nu, plane)
    order = np.argsort(np.abs(r[:, 0]))  # small rotations first: warm starts stay close
    wrench = np.zeros((count, 3))
    for i in order:
        ri = _to_internal(name, r[i])
        w = solver.wrench(ri[0], ri[1:] / ell)
        wrench[i] = _to_frame(name, w) * E * t * np.array([ell * ell, ell, ell])
    return r, wrench
