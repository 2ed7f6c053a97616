"""
Static equilibrium of a ``Model``.

Newton's method on Q_F(z) = 0 with the exact stiffness dQ_F/dz_F, for one drive input or a sweep of
many.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg

from .data import State
from .model import Model, SolverError
from .snapshot import Snapshot, snapshot


@dataclass(frozen=True)
class StaticResult:
    """Static equilibrium: the snapshot at rest, and Newton's iteration count and residual."""

    snapshot: Snapshot
    iterations: int
    residual: float
    z: np.ndarray


@dataclass(frozen=True)
class StaticSweep:
    """
    Static answers for a list of drive inputs (m).

    Output displacement (m), compression (m; NaN without a compression hinge), drive force (N), and
    total Newton iterations.
    """

    inputs: np.ndarray
    outputs: np.ndarray
    compressions: np.ndarray
    drive_forces: np.ndarray
    iterations: int


def static(model: Model, u: float, t: float = 0.0, tol: float = 1e-13,
           max_iter: int = 50) -> StaticResult:
    """
    Return static equilibrium with the actuator output held at u (and timed constraints at t).

    Newton's method on Q_F(z_F) = 0 from the unstressed pose with the exact tangent
    stiffness dQ_F/dz_F (see ``newton``); converged when the update is below tol
    (relative to the mechanism's size). Without free coordinates (every body fixed or
    driven) the prescribed pose is the equilibrium: 0 iterations, forces as reported.
    """
    zF, iterations = newton(model, u, t, model.z0[model.part.free].copy(), None, tol, max_iter)[:2]
    z = _z_static(model, zF, t, u)
    Q = model.assembly.generalized_forces(z, np.zeros_like(z))[0]
    residual = float(np.max(np.abs(Q[model.part.free]), initial=0.0))
    state = State(t, z, np.zeros_like(z), u, u)
    return StaticResult(snapshot(model, state), iterations, residual, z)


def static_sweep(model: Model, inputs, t: float = 0.0, tol: float = 1e-13) -> StaticSweep:
    """
    Return static equilibria for many drive inputs.

    Each started from the previous one and reusing the factorised stiffness while Newton keeps
    contracting fast.
    """
    inputs = np.asarray(inputs, dtype=float)
    if not np.all(np.isfinite(inputs)):
        raise ValueError("drive inputs must be finite")
    out = np.full(len(inputs), np.nan)
    comp = np.full(len(inputs), np.nan)
    force = np.zeros(len(inputs))
    zF = model.z0[model.part.free].copy()
    lu = None
    total = 0
    for k, u in enumerate(inputs):
        zF, iterations, lu = newton(model, float(u), t, zF, lu, tol, 50)
        total += iterations
        z = _z_static(model, zF, t, float(u))
        if model.output_axis is not None:
            out[k] = model.output_displacement(z)
        if model.compression is not None:
            comp[k] = model.hinge_compression(z)
        if model.drive is not None:
            zero = np.zeros_like(z)
            force[k] = model.drive_force(z, zero, np.zeros(len(model.part.prescribed)))
    return StaticSweep(inputs, out, comp, force, total)


def _z_static(model: Model, zF: np.ndarray, t: float, u: float) -> np.ndarray:
    return model.full(zF, np.zeros(len(zF)), t, u, u)[0]


def newton(model: Model, u, t, zF, lu, tol, max_iter):
    """
    Newton on Q_F(z_F) = 0 with the exact stiffness.

    A factorisation from a nearby solution (``lu``) is reused while its updates shrink at least
    tenfold; an update that does not is discarded and the stiffness re-factorised at the current
    point, so the iteration is never worse than Newton's. Returns (z_F, iterations, factorisation).
    """
    if not np.isfinite(u):
        raise ValueError(f"drive input must be finite, got {u!r}")
    free = model.part.free
    if len(free) == 0:
        return zF, 0, None  # every coordinate prescribed: the equilibrium is the prescription
    lengths = np.where(np.isin(free % 3, (0, 1)), model.length_scale, 1.0)
    previous = np.inf
    for it in range(1, max_iter + 1):
        z = _z_static(model, zF, t, u)
        if lu is None:
            hf = model.assembly.forces(z, np.zeros_like(z), jacobian=True)
            K = hf.dQ_dz[np.ix_(free, free)]
            if not np.all(np.isfinite(K)):
                raise SolverError("non-finite stiffness in the static solve")
            lu = scipy.linalg.lu_factor(K, check_finite=False)
            if np.any(np.diag(lu[0]) == 0.0):
                raise SolverError("singular stiffness: a free body is not held by any hinge")
            Q = hf.Q[free]
            fresh = True
        else:
            Q = model.assembly.generalized_forces(z, np.zeros_like(z))[0][free]
            fresh = False
        dz = scipy.linalg.lu_solve(lu, -Q)
        size = float(np.max(np.abs(dz / lengths)))
        if not fresh and size > 0.1 * previous:
            lu = None  # a stale factorisation that no longer contracts fast: refresh here
            continue
        zF = zF + dz
        if size < tol:
            return zF, it, lu
        previous = size
    raise SolverError(f"static solve did not converge in {max_iter} iterations")
