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


def body_stiffness(model: SpatialModel, body: str, u=None) -> np.ndarray:
    """
    Return the 6x6 stiffness a load on ``body`` sees at the equilibrium at drive inputs u.

    The wrench (force in the root frame, moment in body coordinates, at the body's mass
    centre) per unit displacement (translation, small rotation in body coordinates) with every
    other free coordinate relaxed: the inverse of the body's block of K_FF^-1, K the tangent
    stiffness -dQ_F/dz_F dz_F/dtheta (symmetrised; at rest dz_F/dtheta = I). The body's six
    coordinates must be free.
    """
    i = model.mechanism.body_index(body)
    part = model.part
    F = list(part.free)
    missing = [k for k in range(6 * i, 6 * i + 6) if k not in F]
    if missing:
        raise ValueError(f"body {body!r}: its coordinates are not all free (held by a "
                         "constraint), so no load on it moves it")
    st = static(model, np.zeros(len(model.drives)) if u is None else u)
    command = model.actuator_command(st.inputs) if model.drives else np.zeros(0)
    nF = len(F)
    Zx = np.zeros((model.n_coordinates, 2 * nF))
    Wx = np.zeros_like(Zx)
    Zx[F, np.arange(nF)] = 1.0
    Wx[F, nF + np.arange(nF)] = 1.0
    dQ, dzdot, _ = model.derivatives(st.z, np.zeros(model.n_coordinates), command, Zx, Wx)
    K = -dQ[F, :nF] @ dzdot[F, nF:]
    K = 0.5 * (K + K.T)
    rows = [F.index(k) for k in range(6 * i, 6 * i + 6)]
    return np.linalg.inv(np.linalg.inv(K)[np.ix_(rows, rows)])
