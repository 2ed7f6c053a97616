"""
Exact linearisation of a spatial mechanism about a static equilibrium: modes, FRF, gains.

The planar engine's linear model (``analysis.linear``) in 3-D: x = deviations of (z_F, w_F, u)
with A = dF/dy and B = dF/dcommand from one hyper-dual evaluation of ``spatial_chain.terms`` seeded
along the state and the commands (``SpatialModel.derivatives``), outputs: the named outputs,
each displacement drive's force f_d = D_d^T (M_P a_P - Q_P) (eq. 6.4), each force drive's body
position, and the six components of every hinge's wrench on its body B. The result is a
``analysis.linear.LinearModel``, so ``linear_response.frf`` and ``gain_matrix`` apply as they are.

Undamped modes solve K phi = omega^2 M phi on the free coordinates in quasi-displacements
(translations and small body rotations): K = -dQ_F/dz_F dz_F/dtheta (dz_F/dtheta = Jr^-1 on the
rotations, the identity at rest), symmetrised (it is the potential's Hessian at an
equilibrium), and M the full mass matrix (inertia tensors included).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Optional

import numpy as np

from flexure_sim.engine.analysis.linear import LinearModel
from flexure_sim.engine.analysis import linear_response
from flexure_sim.engine.analysis.linear_response import Modes
from flexure_sim.engine.mechanism.spatial_parts import COORDINATE_NAMES
from flexure_sim.engine.solver.spatial_model import SpatialModel
from flexure_sim.engine.solver.spatial_statics import SpatialStatic, static

WRENCH_COMPONENTS = ("moment_x", "moment_y", "moment_z", "force_x", "force_y", "force_z")
_RATE = {"x": "vx", "y": "vy", "z": "vz", "rx": "wx", "ry": "wy", "rz": "wz"}


@dataclass
class SpatialLinearModel(LinearModel):
    """``LinearModel`` with the full free mass matrix (``mass`` holds its diagonal)."""

    mass_matrix: Optional[np.ndarray] = None


def mass_matrix(model: SpatialModel) -> np.ndarray:
    """Return M on the free coordinates (m on translations, the inertia tensors' blocks)."""
    N = model.n_coordinates
    M = np.zeros((N, N))
    for i, body in enumerate(model.mechanism.bodies):
        M[6 * i:6 * i + 3, 6 * i:6 * i + 3] = body.mass * np.eye(3)
        M[6 * i + 3:6 * i + 6, 6 * i + 3:6 * i + 6] = model.inertia[i]
    F = model.part.free
    return M[np.ix_(F, F)]


def linearize(model: SpatialModel, u=None, wrenches: bool = True,
              equilibrium: Optional[SpatialStatic] = None) -> SpatialLinearModel:
    """Return the exact linear model about the equilibrium at drive inputs u (module doc)."""
    names = model.drive_names
    st = equilibrium or static(model, np.zeros(len(names)) if u is None else u)
    inputs = st.inputs
    part = model.part
    F, P = part.free, part.prescribed
    nF, na, nd = len(F), model.n_actuators, len(names)
    command = model.actuator_command(inputs) if nd else np.zeros(0)
    m = 2 * nF + na
    Zx, Wx = model.seeds(n_extra=nd)
    Cx = np.zeros((len(command), m + nd))
    for a, k in enumerate(model.displacement_index):
        Wx[P, m + k] = part.D[:, a] / model.tau[a]
    for j, k in enumerate(model.force_index):
        Cx[model.first_force + j, m + k] = 1.0
    w0 = np.zeros(model.n_coordinates)
    dQ, dzdot, dW = model.derivatives(st.z, w0, command, Zx, Wx, Cx)
    acc = model.accelerations(dQ)
    A = np.zeros((m, m))
    B = np.zeros((m, nd))
    A[:nF], B[:nF] = dzdot[F, :m], dzdot[F, m:]
    A[nF:2 * nF], B[nF:2 * nF] = acc[F, :m], acc[F, m:]
    for a, (k, tau) in enumerate(zip(model.displacement_index, model.tau)):
        A[2 * nF + a, 2 * nF + a] = -1.0 / tau
        B[2 * nF + a, k] = 1.0 / tau
    single = nd == 1
    rows, ds, out_names, y0 = [], [], [], []

    def add(name, row, d, value):
        out_names.append(name), rows.append(row), ds.append(d), y0.append(value)

    Q0, *_, wrench0, _, _, _ = model.terms(st.z, w0, command)
    for name, out_row in zip(model.output_names, model.output_matrix):
        add(name, out_row @ Zx[:, :m], np.zeros(nd), float(out_row @ (st.z - model.z0)))
    for a, k in enumerate(model.displacement_index):
        dk = model.D_rows[a]
        row = -(dk @ dQ[P, :m])
        d = -(dk @ dQ[P, m:])
        for b, (j, tau) in enumerate(zip(model.displacement_index, model.tau)):
            mkj = dk @ (model.mass[P] * model.D_rows[b])
            row[2 * nF + b] += mkj / tau**2
            d[j] -= mkj / tau**2
        add("drive_force" if single else f"drive_force.{names[k]}", row, d,
            float(-(dk @ Q0[P])))
    for k in model.force_index:
        e = model.drive_directions[k]
        add("drive_position" if single else f"drive_position.{names[k]}", e @ Zx[:, :m],
            np.zeros(nd), float(e @ (st.z - model.z0)))
    if wrenches:
        for h, hinge in enumerate(model.mechanism.hinges):
            for c, comp in enumerate(WRENCH_COMPONENTS):
                add(f"hinges.{hinge.name}.{comp}", dW[h, c, :m], dW[h, c, m:],
                    float(wrench0[h, c]))
    bodies = model.mechanism.bodies
    state_names = ([f"{bodies[k // 6].name}.{COORDINATE_NAMES[k % 6]}" for k in F]
                   + [f"{bodies[k // 6].name}.{_RATE[COORDINATE_NAMES[k % 6]]}" for k in F]
                   + (["drive.u"] if single and na else
                      [f"drive.{names[k]}.u" for k in model.displacement_index]))
    K = -dQ[F, :nF] @ A[:nF, nF:2 * nF]
    M = mass_matrix(model)
    lags = np.full(nd, -1, dtype=int)
    lags[model.displacement_index] = np.arange(na)
    return SpatialLinearModel(
        A, B, np.array(rows, dtype=float).reshape(len(rows), m),
        np.array(ds, dtype=float).reshape(len(ds), nd), state_names,
        ["drive"] if single else list(names), out_names,
        float(inputs[0]) if single else inputs.copy(), st.z, np.array(y0, dtype=float),
        0.5 * (K + K.T), np.diag(M).copy(), F.copy(), -dQ[F, nF:2 * nF], tuple(names),
        tuple(int(a) for a in lags), mass_matrix=M)


def modes(lin: SpatialLinearModel) -> Modes:
    """Return the undamped modes, with the full mass matrix, and the damped poles."""
    return linear_response.modes(lin, lin.mass_matrix)


def out_of_plane_shares(lin: SpatialLinearModel, md: Modes) -> np.ndarray:
    """
    Return each mode's share of kinetic energy in the out-of-plane coordinates (z, rx, ry).

    phi_O^T (M phi)_O for the M-orthonormal shape phi (the shares of all coordinates sum to 1):
    1 for a mode of a planar stage that moves only out of its plane, 0 for an in-plane one.
    """
    out = np.array([k % 6 in (2, 3, 4) for k in lin.free])
    weighted = lin.mass_matrix @ md.shapes
    return np.einsum("ik,ik->k", md.shapes[out], weighted[out])
