"""
The exact derivatives of a ``model.Model``'s first-order system y' = F(y, t).

``jacobian_parts``: A = dF/dy (``Model.jacobian``) with the dQ/dz, dQ/dv it is built from;
``tangent``: A and what the step's energy integrals need (``step_energy``), in one ``Tangent``.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Tangent:
    """
    The exact derivatives of one linearization (``Model.tangent``), for y = (z_F, v_F, u).

    ``A`` = dF/dy; ``G``: rows g_d = dq_d/dy of the displacement drives' loads q_d = D_d^T Q_P;
    ``damping``: -dQ/dv over all coordinates; ``load_rows``: dQ_P/dy; ``free_by_prescribed``:
    dQ_F/dz_P and dQ_F/dv_P, how the prescribed coordinates' motion forces the free ones.
    """

    A: np.ndarray
    G: np.ndarray
    damping: np.ndarray
    load_rows: np.ndarray
    free_by_prescribed: tuple = ()


@dataclass(frozen=True)
class JacobianParts:
    """A and the dQ/dz, dQ/dv (all coordinates, stack springs and damping matrix in) it uses."""

    A: np.ndarray
    Kzz: np.ndarray
    Kvv: np.ndarray


def jacobian_parts(model, y: np.ndarray, t: float, command: np.ndarray) -> JacobianParts:
    """
    Return A = dF/dy and the exact dQ/dz, dQ/dv (all forces, all coordinates) it is built from.

    Rows dz_F/dt = v_F, M_F dv_F/dt = Q_F(z, v), du_d/dt = (command_d - u_d)/tau_d, with z_P,
    v_P depending on each u_d through D_d (the force drives' held forces do not depend on y;
    the stack springs add -k_s e e^T to dQ/dz); dQ/dv includes -C (``Model.velocity_jacobian``),
    also through v_P.
    """
    part = model.part
    nF = len(part.free)
    z, v, _ = model.unpack(y, t, command)
    hf = model.assembly.forces(z, v, jacobian=True)
    mF = model.mass_free
    m = len(y)
    A = np.zeros((m, m))
    A[:nF, nF:2 * nF] = np.eye(nF)
    Kzz, Kvv = hf.dQ_dz, model.velocity_jacobian(hf.dQ_dv)
    if model.drives.stack_K is not None:  # the stack springs: dQ/dz = -k_s e e^T
        Kzz = Kzz - model.drives.stack_K
    FF = np.ix_(part.free, part.free)
    A[nF:2 * nF, :nF] = Kzz[FF] / mF[:, None]
    A[nF:2 * nF, nF:2 * nF] = Kvv[FF] / mF[:, None]
    FP = np.ix_(part.free, part.prescribed)
    for k, (dk, tau) in enumerate(zip(model.drives.lag_rows, model.drives.tau)):
        A[nF:2 * nF, 2 * nF + k] = (Kzz[FP] @ dk - Kvv[FP] @ dk / tau) / mF
        A[2 * nF + k, 2 * nF + k] = -1.0 / tau
    return JacobianParts(A, Kzz, Kvv)


def tangent(model, y: np.ndarray, t: float, command: np.ndarray) -> Tangent:
    """
    Return A (``Model.jacobian``) and the derivatives the step's energy integrals need.

    G: rows g_d = dq_d/dy of the drive loads q_d = D_d^T Q_P; the damping matrix -dQ/dv
    over all coordinates (1/2 the Hessian of the dissipated power in the velocities); and
    dQ_P/dy.
    """
    d = jacobian_parts(model, y, t, command)
    part = model.part
    nF, m = len(part.free), len(y)
    rows_d, tau = model.drives.lag_rows, model.drives.tau
    G = np.zeros((len(rows_d), m))
    PF, PP = np.ix_(part.prescribed, part.free), np.ix_(part.prescribed, part.prescribed)
    Kzz, Kvv = d.Kzz, d.Kvv
    for k, dk in enumerate(rows_d):
        G[k, :nF] = dk @ Kzz[PF]
        G[k, nF:2 * nF] = dk @ Kvv[PF]
        for j, (dj, tau_j) in enumerate(zip(rows_d, tau)):
            G[k, 2 * nF + j] = dk @ (Kzz[PP] @ dj - Kvv[PP] @ dj / tau_j)
    rows = np.zeros((len(part.prescribed), m))  # dQ_P/dy
    rows[:, :nF], rows[:, nF:2 * nF] = Kzz[PF], Kvv[PF]
    for k, (dk, tau_k) in enumerate(zip(rows_d, tau)):
        rows[:, 2 * nF + k] = Kzz[PP] @ dk - Kvv[PP] @ dk / tau_k
    FP = np.ix_(part.free, part.prescribed)
    return Tangent(d.A, G, -Kvv, rows, (Kzz[FP], Kvv[FP]))
