"""
Static equilibrium of a ``SpatialModel``: Newton's method with the exact tangent stiffness.

Q_F(z) = 0 (the generalized forces on the free coordinates, force drives included) is solved
from the rest pose with dQ_F/dz_F from one hyper-dual evaluation per iteration
(``SpatialModel.derivatives``); Q_F = -Jr^-T dU/dz_F on the rotations, so its zeros are the
potential's stationary points. Converged when the update is below ``tol`` (relative to the
mechanism's size; rad on the rotations).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from flexure_sim.engine.solver.model import SolverError
from flexure_sim.engine.solver.spatial_model import SpatialModel


@dataclass(frozen=True)
class SpatialStatic:
    """Static equilibrium: coordinates z, drive inputs, Newton's iterations and residual."""

    z: np.ndarray
    inputs: np.ndarray
    iterations: int
    residual: float


def static_z(model: SpatialModel, zF: np.ndarray, inputs: np.ndarray) -> np.ndarray:
    """Return all coordinates of a static state: z_F and z_P = z_P0 + D u."""
    part = model.part
    z = model.z0.copy()
    z[part.free] = zF
    if len(model.displacement_index):
        z[part.prescribed] += part.D @ inputs[model.displacement_index]
    return z


def static(model: SpatialModel, u, tol: float = 1e-13, max_iter: int = 50) -> SpatialStatic:
    """Return the static equilibrium with every drive at its input u (``drive_inputs``)."""
    inputs = model.drive_inputs(u) if model.drives else np.zeros(0)
    part = model.part
    command = model.actuator_command(inputs) if model.drives else np.zeros(0)
    zF = model.z0[part.free].copy()
    nF = len(part.free)
    lengths = np.where(part.free % 6 < 3, model.length_scale, 1.0)
    w = np.zeros(model.n_coordinates)
    Zx = np.zeros((model.n_coordinates, nF))
    Zx[part.free, np.arange(nF)] = 1.0
    for it in range(1, max_iter + 1):
        z = static_z(model, zF, inputs)
        Q = model.terms(z, w, command)[0][part.free]
        if nF == 0:
            return SpatialStatic(z, inputs, 0, 0.0)
        K = model.derivatives(z, w, command, Zx, np.zeros_like(Zx))[0][part.free]
        if not np.all(np.isfinite(K)):
            raise SolverError("non-finite stiffness in the static solve")
        try:
            dz = np.linalg.solve(K, -Q)
        except np.linalg.LinAlgError:
            raise SolverError("singular stiffness: a free body is not held by any hinge") from None
        zF = zF + dz
        if float(np.max(np.abs(dz / lengths))) < tol:
            z = static_z(model, zF, inputs)
            model.check_range(z)
            residual = float(np.max(np.abs(model.terms(z, w, command)[0][part.free])))
            return SpatialStatic(z, inputs, it, residual)
    raise SolverError(f"static solve did not converge in {max_iter} iterations")


def static_gain(model: SpatialModel) -> np.ndarray:
    """
    Return the exact static gain at rest: d(output k)/d(input d), outputs by drives.

    From the tangent stiffness K = dQ_F/dz_F at the rest pose: a displacement drive moves z_P
    by D_d and the free coordinates by -K^-1 dQ_F/dz_P D_d; a force drive's command adds
    dQ_F/df (its direction, a torque's turned into the body: exact through the same
    hyper-dual evaluation), moving them by -K^-1 dQ_F/df. Output k moves by c_k . dz.
    """
    part = model.part
    F, P = part.free, part.prescribed
    nF, nd = len(F), len(model.drives)
    N = model.n_coordinates
    Zx = np.zeros((N, nF + nd))
    Zx[F, np.arange(nF)] = 1.0
    command = model.actuator_command(np.zeros(nd)) if nd else np.zeros(0)
    Cx = np.zeros((len(command), nF + nd))
    for a, k in enumerate(model.displacement_index):
        Zx[P, nF + k] = part.D[:, a]
    for j, k in enumerate(model.force_index):
        Cx[model.first_force + j, nF + k] = 1.0
    w = np.zeros(N)
    dQ = model.derivatives(model.z0, w, command, Zx, np.zeros_like(Zx), Cx)[0][F]
    dz = Zx[:, nF:].copy()
    if nF:
        dz[F] = -np.linalg.solve(dQ[:, :nF], dQ[:, nF:])
    return model.output_matrix @ dz
