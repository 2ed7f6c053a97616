"""
Static equilibrium of a ``Model``.

Newton's method on Q_F(z) = 0 with the exact stiffness dQ_F/dz_F, for one drive input (one per
drive) or a sweep of many, and the exact static gain of every output against every drive.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg

from flexure_sim.engine.solver.state import State
from flexure_sim.engine.solver.model import Model, SolverError
from flexure_sim.engine.solver.snapshot import Snapshot, snapshot


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


def static(model: Model, u, t: float = 0.0, tol: float = 1e-13,
           max_iter: int = 50) -> StaticResult:
    """
    Return static equilibrium with the actuator output held at u (and timed constraints at t).

    ``u``: a number (a single drive), one value per drive or a {name: value} mapping
    (``Model.drive_inputs``): a displacement drive's input is prescribed, a force drive's
    is a generalized force e f on the free coordinates (Q_F + E_F f = 0).

    Newton's method on Q_F(z_F) = 0 from the unstressed pose with the exact tangent
    stiffness dQ_F/dz_F (see ``newton``); converged when the update is below tol
    (relative to the mechanism's size). Without free coordinates (every body fixed or
    driven) the prescribed pose is the equilibrium: 0 iterations, forces as reported.
    """
    drives = model.drives
    drives.require_rigid("static equilibrium")
    inputs = drives.inputs(u)
    zF, iterations = newton(model, inputs, t, model.z0[model.part.free].copy(), None, tol,
                            max_iter)[:2]
    z = _z_static(model, zF, t, inputs)
    Q = model.assembly.generalized_forces(z, np.zeros_like(z))[0] + _applied(model, inputs)
    residual = float(np.max(np.abs(Q[model.part.free]), initial=0.0))
    state = State(t, z, np.zeros_like(z), inputs[drives.lagged], inputs.copy())
    return StaticResult(snapshot(model, state, inputs), iterations, residual, z)


def static_sweep(model: Model, inputs, t: float = 0.0, tol: float = 1e-13) -> StaticSweep:
    """
    Return static equilibria for many drive inputs.

    Each started from the previous one and reusing the factorised stiffness while Newton keeps
    contracting fast.
    """
    model.drives.require_rigid("static sweep")
    inputs = np.asarray(inputs, dtype=float)
    if not np.all(np.isfinite(inputs)):
        raise ValueError("drive inputs must be finite")
    if len(model.drives) > 1:
        raise ValueError("a static sweep takes one drive's inputs; with several drives "
                         "call static() per point or static_gain()")
    out = np.full(len(inputs), np.nan)
    comp = np.full(len(inputs), np.nan)
    force = np.zeros(len(inputs))
    zF = model.z0[model.part.free].copy()
    lu = None
    total = 0
    for k, u in enumerate(inputs):
        one = model.drives.inputs(float(u)) if model.drives else np.zeros(0)
        zF, iterations, lu = newton(model, one, t, zF, lu, tol, 50)
        total += iterations
        z = _z_static(model, zF, t, one)
        if model.outputs:
            out[k] = model.output_displacement(z)
        if model.compression is not None:
            comp[k] = model.hinge_compression(z)
        if model.drives:
            zero = np.zeros_like(z)
            force[k] = model.drive_forces(z, zero, np.zeros(len(model.part.prescribed)),
                                          inputs=one)[0]
    return StaticSweep(inputs, out, comp, force, total)


def _z_static(model: Model, zF: np.ndarray, t: float, inputs: np.ndarray) -> np.ndarray:
    """
    Return all coordinates of a static state.

    All coordinates: z_F, and z_P = the held and timed values at t plus D u (the displacement
    drives' inputs).
    """
    d = model.drives
    z = model.full(zF, np.zeros(len(zF)), t, np.zeros(d.n_lags), d.kernel_command(
        np.zeros(len(d))))[0]
    if len(d.displacement):
        z[model.part.prescribed] += model.part.D @ inputs[d.displacement]
    return z


def _applied(model: Model, inputs: np.ndarray) -> np.ndarray:
    """Generalized forces of the force drives, sum_d e_d f_d (virtual work)."""
    d = model.drives
    if not len(d.force):
        return np.zeros(len(model.z0))
    return d.directions[d.force].T @ inputs[d.force]


def static_gain(model: Model, t: float = 0.0) -> np.ndarray:
    """
    Return the exact static gain at rest.

    Exact static gain at rest: d(output k)/d(input d) for every output (rows, ``output_names``)
    and drive (columns, ``DriveTable.names``), from the tangent stiffness K = dQ/dz at the
    unstressed pose: a displacement drive moves z_P by D_d and the free coordinates by
    dz_F = -K_FF^-1 K_FP D_d; a force drive applies e_d: dz_F = -K_FF^-1 e_dF (the linearised
    equilibrium Q_F + E_F f = 0).
    Output k moves by c_k . dz.
    """
    d = model.drives
    d.require_rigid("static gain")
    z = _z_static(model, model.z0[model.part.free].copy(), t, np.zeros(len(model.drives)))
    K = model.assembly.forces(z, np.zeros_like(z), jacobian=True).dQ_dz
    F, P = model.part.free, model.part.prescribed
    dz = np.zeros((len(z), len(model.drives)))
    rhs = np.zeros((len(F), len(model.drives)))
    if len(d.displacement):
        dz[np.ix_(P, d.displacement)] = model.part.D
        rhs[:, d.displacement] = K[np.ix_(F, P)] @ model.part.D
    if len(d.force):
        rhs[:, d.force] = d.directions[d.force][:, F].T
    if len(F):
        dz[F] = -np.linalg.solve(K[np.ix_(F, F)], rhs)
    return model.output_matrix @ dz


def newton(model: Model, u, t, zF, lu, tol, max_iter):
    """
    Newton on Q_F(z_F) = 0 with the exact stiffness.

    A factorisation from a nearby solution (``lu``) is reused while its updates shrink at least
    tenfold; an update that does not is discarded and the stiffness re-factorised at the current
    point, so the iteration is never worse than Newton's. Returns (z_F, iterations, factorisation).
    """
    u = np.asarray(u, dtype=float)
    if not np.all(np.isfinite(u)):
        raise ValueError(f"drive input must be finite, got {u!r}")
    applied = _applied(model, u)
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
            Q = (hf.Q + applied)[free]
            fresh = True
        else:
            Q = (model.assembly.generalized_forces(z, np.zeros_like(z))[0] + applied)[free]
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
