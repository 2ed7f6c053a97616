"""
Exact linearisation about a static equilibrium.

Natural modes, damped poles, frequency response and a named state-space model.

About the static equilibrium z* at drive input u* (``Simulation.static``), the engine's
first-order system y' = F(y, command), y = (z_F, v_F, u) (solver.py), has the exact Jacobian
A = dF/dy (``Simulation._jacobian``: analytic, no finite differences) and input matrix
B = dF/dcommand. The command enters through the actuator lag du/dt = (command - u)/tau and
the driven body's velocity v_P = d_u (command - u)/tau, so

    B = [0; M_F^-1 dQ_F/dv_P d_u / tau; 1/tau].

Outputs are linear in (x, command) with x = y - y*: the output displacement and the
compression of the compression hinge (frame positions P + R(theta) c, differentiated in
theta), the drive force f = m_d (u - command)/tau^2 - d_u . Q_P (the constraint force of
``Simulation.snapshot``), and each hinge's wrench on its body B, whose derivatives in z and
v are the derivative parts of one hyper-dual evaluation of ``parametric.forces``.

Undamped modes solve K phi = omega^2 M phi on the free coordinates with the exact tangent
stiffness K = -dQ_F/dz_F (symmetric at an equilibrium: the Hessian of the potential) and the
diagonal mass matrix (``damping_models.natural_modes``: phi^T M phi = I). The damped poles are
the eigenvalues of A (including the actuator pole -1/tau); with damping scaled to zero they
tend to +-i omega. Damping: the hinges' and the mechanism file's damping matrix C (a
``damping:`` block, ``Model.damping``), both in dQ/dv (``tangent_at``) and so in A, B, the
drive force row and the modal ratios. The frequency response is G(i w) = C (i w I - A)^-1 B + D.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Optional, Sequence

import numpy as np

from . import hyperdual as hd
from .kinematics import J
from .damping_models import natural_modes
from .design import design_of, hinge_indices, twistor_flags
from .parametric import forces
from .solver import Simulation, StaticResult

WRENCH_COMPONENTS = ("moment", "force_x", "force_y")


# ------------------------------------------------ the engine's internals, in one place


def jacobian_at(sim: Simulation, y: np.ndarray, t: float, command: float) -> np.ndarray:
    """Exact A = dF/dy of the engine's first-order system at y (`Model.jacobian`)."""
    return sim.model.jacobian(y, t, command)


@dataclass(frozen=True)
class Layout:
    """
    How the engine's state is laid out.

    Free and prescribed coordinate indices, the prescribed coordinates' drive-axis components d_u,
    masses (3 n_bodies), the rest pose z0 and the actuator time constant (None without a drive).
    """

    free: np.ndarray
    prescribed: np.ndarray
    du: np.ndarray
    mass: np.ndarray
    z0: np.ndarray
    tau: Optional[float]


def layout(sim: Simulation) -> Layout:
    """Return the state layout of a Simulation (see Layout)."""
    part = sim.part
    return Layout(
        part.free,
        part.prescribed,
        np.asarray(part.du, dtype=float),
        sim.mass,
        sim.z0,
        sim.drive.response_time if sim.drive else None,
    )


def tangent_at(sim: Simulation, z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """
    Exact dQ/dz and dQ/dv (all coordinates) at rest at z.

    dQ/dv holds the hinges' damping and the mechanism's damping matrix (-C, ``Model``).
    """
    hf = sim.assembly.forces(z, np.zeros_like(z), jacobian=True)
    return hf.dQ_dz, sim.model.velocity_jacobian(hf.dQ_dv)


# --------------------------------------------------------------------- the model


@dataclass
class LinearModel:
    """
    x' = A x + B command, y = C x + D command about the equilibrium at drive input u0.

    x: deviations of (z_F, v_F, u) (m, rad, m/s, rad/s, m); outputs are deviations of the named
    quantities from their static values ``y0``.
    """

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    state_names: list
    input_names: list
    output_names: list
    u0: float
    z: np.ndarray
    y0: np.ndarray
    stiffness: np.ndarray = field(repr=False)
    mass: np.ndarray = field(repr=False)
    free: np.ndarray = field(repr=False)
    damping: np.ndarray = field(repr=False, default=None)

    def output_index(self, name: str) -> int:
        if name not in self.output_names:
            raise ValueError(f"unknown output {name!r} (outputs: {', '.join(self.output_names)})")
        return self.output_names.index(name)


def linearize(sim: Simulation, u: float = 0.0, wrenches: bool = True,
              static: Optional[StaticResult] = None) -> LinearModel:
    """
    Return the exact linear model about the static equilibrium at drive input u (module doc).

    ``static``: that equilibrium if already solved (``sim.static(u)``).
    """
    mech = sim.mechanism
    if sim.model.drives and sim.drive is None:
        kinds = ", ".join(f"{d.name} ({d.kind})" for d in sim.model.drives)
        raise ValueError(f"mechanism {mech.name!r} has drives {kinds}: the linear model "
                         f"handles a single displacement drive (its static gain matrix: "
                         f"simulate --static)")
    st = static if static is not None else sim.static(u)
    z = st.z
    lay = layout(sim)
    F, P, du = lay.free, lay.prescribed, lay.du
    nF, N = len(F), len(z)
    drive = lay.tau is not None
    y = np.concatenate([z[F], np.zeros(nF)] + ([[u]] if drive else []))
    n = len(y)
    A = jacobian_at(sim, y, 0.0, u)
    dQz, dQv = tangent_at(sim, z)
    mF = lay.mass[F]
    B = np.zeros((n, 1 if drive else 0))
    Zx, Vx, Vc = np.zeros((N, n)), np.zeros((N, n)), np.zeros((N, 1))
    Zx[F, np.arange(nF)] = 1.0
    Vx[F, nF + np.arange(nF)] = 1.0
    if drive:
        tau = lay.tau
        B[nF:2 * nF, 0] = dQv[np.ix_(F, P)] @ du / (tau * mF)
        B[2 * nF, 0] = 1.0 / tau
        Zx[P, 2 * nF] = du
        Vx[P, 2 * nF] = -du / tau
        Vc[P, 0] = du / tau
    names, Cs, Ds, y0 = [], [], [], []
    snap = st.snapshot
    if mech.output is not None:
        e = np.zeros(N)
        i = mech.body_index(mech.output.body)
        e[3 * i:3 * i + 2] = mech.output.axis
        names.append("output"), Cs.append(e @ Zx), Ds.append(0.0), y0.append(snap.output)
    if drive and sim.model.compression is not None:
        # The engine's one definition (engine/compression.py): the drive side's centre of
        # stiffness minus the far side's, along the drive axis.
        (i_drive, c_drive), (i_far, c_far), axis = sim.model.compression
        G = _point_jacobian(i_drive, c_drive, z) - _point_jacobian(i_far, c_far, z)
        row = axis @ G
        names.append("compression"), Cs.append(row @ Zx), Ds.append(0.0), y0.append(
            snap.compression
        )
    if drive:
        md = du @ (lay.mass[P] * du)
        tau = lay.tau
        e_u = np.zeros(n)
        e_u[2 * nF] = 1.0
        row = md * e_u / tau**2 - du @ (dQz[P] @ Zx + dQv[P] @ Vx)
        d = -md / tau**2 - du @ (dQv[P] @ Vc)[:, 0]
        names.append("drive_force"), Cs.append(row), Ds.append(float(d)), y0.append(
            snap.drive_force
        )
    if wrenches:
        Jz, Jv = wrench_jacobians(mech, z)
        for k, hinge in enumerate(mech.hinges):
            for c, comp in enumerate(WRENCH_COMPONENTS):
                names.append(f"hinges.{hinge.name}.{comp}")
                Cs.append(Jz[k, c] @ Zx + Jv[k, c] @ Vx)
                Ds.append(float(Jv[k, c] @ Vc[:, 0]))
                y0.append(float(snap.wrenches[k, c]))
    state_names = (
        [_coord(mech, k) for k in F]
        + [_coord(mech, k, rate=True) for k in F]
        + (["drive.u"] if drive else [])
    )
    K = -dQz[np.ix_(F, F)]
    return LinearModel(
        A,
        B,
        np.array(Cs).reshape(len(Cs), n),
        np.array(Ds).reshape(len(Ds), 1)[:, : B.shape[1]],
        state_names,
        ["drive"] if drive else [],
        names,
        float(u),
        z,
        np.array(y0, dtype=float),
        0.5 * (K + K.T),
        mF.copy(),
        F.copy(),
        -dQv[np.ix_(F, F)],
    )


def _coord(mech, k: int, rate: bool = False) -> str:
    names = ("vx", "vy", "omega") if rate else ("x", "y", "theta")
    return f"{mech.bodies[k // 3].name}.{names[k % 3]}"


def _frame_jacobian(mech, frame, z: np.ndarray) -> np.ndarray:
    """Return d(P + R(theta) c)/dz (2 x N) of a frame's origin in the root frame."""
    return _point_jacobian(mech.body_index(frame.body), frame.position, z)


def _point_jacobian(i: int, c, z: np.ndarray) -> np.ndarray:
    """Return d(P + R(theta) c)/dz (2 x N) of the point c (body coordinates) on body i."""
    th = z[3 * i + 2]
    cs, sn = np.cos(th), np.sin(th)
    w = np.array([cs * c[0] - sn * c[1], sn * c[0] + cs * c[1]])
    G = np.zeros((2, len(z)))
    G[:, 3 * i:3 * i + 2] = np.eye(2)
    G[:, 3 * i + 2] = J @ w
    return G


def wrench_jacobians(mech, z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """
    Return d wrench / dz and d wrench / dv at rest at z, (n_hinges, 3, N) each.

    The e1 and e2 parts of one hyper-dual evaluation with z + e1 I and v = 0 + e2 I (N directions).
    """
    N = len(z)
    ia, ib = hinge_indices(mech)
    eye = np.eye(N)
    f = forces(
        design_of(mech),
        twistor_flags(mech),
        ia,
        ib,
        hd.HyperDual(z, eye, 0.0, 0.0),
        hd.HyperDual(np.zeros(N), 0.0, eye, 0.0),
    )
    _, b, c, _ = hd.parts_of(f.wrench)
    return np.moveaxis(b, 0, -1), np.moveaxis(c, 0, -1)


# ------------------------------------------------------------------------- modes


@dataclass(frozen=True)
class Modes:
    """
    Undamped modes.

    Frequencies (Hz, ascending), shapes (nF, n) M-orthonormal columns on the free coordinates
    ``free``; damped poles (complex, 1/s, by |pole|), their natural frequencies |pole| / 2 pi (Hz)
    and damping ratios -Re/|pole| (1 for a real pole); modal damping ratios phi^T C phi / (2 omega)
    of the undamped modes (exact for the proportional damping B = t_char K, where they are omega
    t_char / 2: a mode above zeta = 1 splits into two real poles, one near -1/t_char).
    """

    frequencies: np.ndarray
    shapes: np.ndarray
    free: np.ndarray
    poles: np.ndarray
    pole_frequencies: np.ndarray
    damping_ratios: np.ndarray
    modal_damping: np.ndarray


def modes(model: LinearModel) -> Modes:
    """
    Return undamped modes and damped poles.

    Undamped modes: the generalised eigenproblem K phi = w^2 M phi; damped poles: eig A.
    """
    w2, shapes = natural_modes(model.stiffness, model.mass)
    poles = np.linalg.eigvals(model.A)
    poles = poles[np.lexsort((poles.imag, np.abs(poles)))]
    mag = np.abs(poles)
    zeta = np.where(mag > 0, -poles.real / np.where(mag > 0, mag, 1.0), 1.0)
    omega = np.sqrt(w2)
    modal = np.einsum("ik,ij,jk->k", shapes, model.damping, shapes) / (2.0 * omega)
    return Modes(omega / (2 * np.pi), shapes, model.free, poles, mag / (2 * np.pi), zeta, modal)


# ------------------------------------------------------------ frequency response


def frf(
    model: LinearModel, frequencies: Sequence[float], outputs: Optional[Sequence[str]] = None
) -> np.ndarray:
    """
    G(i 2 pi f) = C (i w I - A)^-1 B + D for the drive input: (n_outputs, n_frequencies).

    The first-order system has the engine's block structure x = (z, v, u) with z' = v, so
    the solve is done in second-order form: with s = i w, u = command / (1 + tau s) and
    v = s z, (s^2 I - s A_vv - A_vz) z = A_vu u + B_v command -- an (n_F x n_F) system per
    frequency instead of (2 n_F + 1), with the same exact result.
    """
    if not model.input_names:
        raise ValueError("the mechanism has no drive input")
    rows = (
        [model.output_index(o) for o in outputs]
        if outputs is not None
        else list(range(len(model.output_names)))
    )
    s = 2j * np.pi * np.asarray(frequencies, dtype=float)
    A, nF = model.A, len(model.free)
    Avz, Avv, Avu = A[nF:2 * nF, :nF], A[nF:2 * nF, nF:2 * nF], A[nF:2 * nF, 2 * nF]
    tau = -1.0 / A[2 * nF, 2 * nF]
    u = 1.0 / (1.0 + tau * s)
    M = (s * s)[:, None, None] * np.eye(nF) - s[:, None, None] * Avv - Avz
    rhs = u[:, None] * Avu + model.B[nF:2 * nF, 0]
    z = np.linalg.solve(M, rhs[..., None])[..., 0]
    x = np.concatenate([z, s[:, None] * z, u[:, None]], axis=1)
    return model.C[rows] @ x.T + model.D[rows]


def static_gain(model: LinearModel, outputs: Optional[Sequence[str]] = None) -> np.ndarray:
    """G(0) = D - C A^-1 B (the derivative of the static outputs in the drive input)."""
    rows = (
        [model.output_index(o) for o in outputs]
        if outputs is not None
        else list(range(len(model.output_names)))
    )
    return (model.D[rows] - model.C[rows] @ np.linalg.solve(model.A, model.B))[:, 0]
