"""
Exact linearisation about a static equilibrium, with any number of drives.

Natural modes, damped poles, frequency response and a named state-space model
(``linear_response``: modes, frf, static_gain, gain_matrix, re-exported here).

About the static equilibrium z* at the drive inputs u* (``Simulation.static``: one per drive),
the engine's first-order system y' = F(y, command), y = (z_F, v_F, u_1 .. u_m) with one
actuator output u_a per displacement drive (``Model.pack``), has the exact Jacobian
A = dF/dy (``Model.jacobian``: analytic, no finite differences) and input matrix
B = dF/dcommand, one column per drive (``Model.drive_names`` order). A displacement drive's
command enters through its actuator lag du_a/dt = (command - u_a)/tau_a and the prescribed
velocities v_P = sum_a D_a (command_a - u_a)/tau_a (D_a = dz_P/du_a, ``Partition.D``); a force
drive's command is a generalised force e f on the free coordinates (virtual work, held as
commanded), so

    B[:, displacement a] = [0; M_F^-1 dQ_F/dv_P D_a / tau_a; e_a / tau_a],
    B[:, force j]        = [0; M_F^-1 e_jF; 0].

Outputs are linear in (x, command) with x = y - y*: each named output c . (z - z0)
(``Model.output_matrix``), the compression of the compression hinge (along the first drive's
axis, ``compression.compression_points``; frame positions P + R(theta) c, differentiated in
theta), each displacement drive's force
f_d = D_d^T (M_P a_P - Q_P) with a_P = sum_a D_a (u_a - command_a)/tau_a^2 (eq. 6.4,
``Model.drive_forces``), each force drive's body position e . (z - z0), and each hinge's wrench
on its body B, whose derivatives in z and v are the derivative parts of one hyper-dual
evaluation of ``parametric.forces``. A single drive keeps the names of the one-drive model
(input ``drive``, state ``drive.u``, output ``drive_force``); with several they are
``<drive>``, ``drive.<drive>.u``, ``drive_force.<drive>`` and ``drive_position.<drive>``.
A drive with a finite-stiffness piezo stack (input: the actuator's free stroke) is refused by
name; a rigid piezo actuator's input is its applied displacement (its amplifier, hysteresis
and creep are not part of the linear model).

Undamped modes solve K phi = omega^2 M phi on the free coordinates with the exact tangent
stiffness K = -dQ_F/dz_F (symmetric at an equilibrium: the Hessian of the potential) and the
diagonal mass matrix (``damping_models.natural_modes``: phi^T M phi = I), the displacement
drives held at their inputs. The damped poles are the eigenvalues of A (including each
actuator's pole -1/tau); with damping scaled to zero they tend to +-i omega. Damping: the
hinges' and the mechanism file's damping matrix C (a ``damping:`` block, ``Model.damping``),
both in dQ/dv (``tangent_at``) and so in A, B, the drive force rows and the modal ratios. The
frequency response is G(i w) = C (i w I - A)^-1 B + D.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Optional, Union

import numpy as np

from flexure_sim.engine.kinematics import hyperdual as hd
from flexure_sim.engine.kinematics.planar import J
from flexure_sim.engine.mechanism.parameters import design_of, hinge_indices, twistor_flags
from flexure_sim.engine.analysis.linear_response import Modes, frf, gain_matrix, modes, static_gain
from flexure_sim.engine.analysis.parametric import forces
from flexure_sim.engine.solver.simulation import Simulation, StaticResult

WRENCH_COMPONENTS = ("moment", "force_x", "force_y")

__all__ = ["LinearModel", "Modes", "frf", "gain_matrix", "layout", "linearize", "modes",
           "static_gain", "tangent_at", "wrench_jacobians"]


# ------------------------------------------------ the engine's internals, in one place


def jacobian_at(sim: Simulation, y: np.ndarray, t: float,
                command: Union[float, np.ndarray]) -> np.ndarray:
    """Exact A = dF/dy of the engine's first-order system at y (`Model.jacobian`)."""
    return sim.model.jacobian(y, t, command)


@dataclass(frozen=True)
class Layout:
    """
    How the engine's state is laid out.

    Free and prescribed coordinate indices, the prescribed coordinates' drive-axis components d_u
    and the actuator time constant of a single displacement drive (zeros and None otherwise:
    ``Partition.D`` and ``Model.tau`` hold every drive's), masses (3 n_bodies), the rest pose z0.
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
    x' = A x + B command, y = C x + D command about the equilibrium at the drive inputs.

    x: deviations of (z_F, v_F, u_1 .. u_m) (m, rad, m/s, rad/s, m); command: one per drive
    (``input_names``, B's columns); outputs are deviations of the named quantities from their
    static values ``y0``. ``u0``: the drive input of the equilibrium (a number with one drive or
    none, else one per drive in ``drive_names`` order); ``lags``: per input, the index of its
    actuator state among the u (-1 for a force drive's input).
    """

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    state_names: list
    input_names: list
    output_names: list
    u0: object
    z: np.ndarray
    y0: np.ndarray
    stiffness: np.ndarray = field(repr=False)
    mass: np.ndarray = field(repr=False)
    free: np.ndarray = field(repr=False)
    damping: np.ndarray = field(repr=False)
    drive_names: tuple = ()
    lags: tuple = ()

    def output_index(self, name: str) -> int:
        if name not in self.output_names:
            raise ValueError(f"unknown output {name!r} (outputs: {', '.join(self.output_names)})")
        return self.output_names.index(name)

    def input_index(self, name: Optional[str] = None) -> int:
        """
        Return the column of B of the input ``name``.

        None: the only input. A single drive's input ``drive`` may also be called by the drive's
        own name. ValueError listing the inputs otherwise.
        """
        names = self.input_names
        if not names:
            raise ValueError("the mechanism has no drive input")
        if name is None:
            if len(names) > 1:
                raise ValueError(f"the model has {len(names)} inputs ({', '.join(names)}): "
                                 "name the drive")
            return 0
        if name in names:
            return names.index(name)
        if len(names) == 1 and tuple(self.drive_names) == (name,):
            return 0
        raise ValueError(f"unknown input {name!r} (inputs: {', '.join(names)})")


def linearize(sim: Simulation, u=None, wrenches: bool = True,
              static: Optional[StaticResult] = None) -> LinearModel:
    """
    Return the exact linear model about the static equilibrium at the drive inputs u (module doc).

    ``u``: a number (a single drive), one value per drive or a {name: value} mapping
    (``Model.drive_inputs``); None: every drive at 0. ``static``: that equilibrium if already
    solved (``sim.static(u)``).
    """
    model = sim.model
    model.require_rigid("the linear model")
    mech = sim.mechanism
    names = model.drive_names
    inputs = model.drive_inputs(np.zeros(len(names)) if u is None else u)
    single = len(names) == 1
    u0 = float(inputs[0]) if single else 0.0 if not names else inputs.copy()
    st = static if static is not None else sim.static(u0 if single or not names else inputs)
    z = st.z
    lay = layout(sim)
    F, P = lay.free, lay.prescribed
    disp, force = model.displacement_index, model.force_index
    nF, N, na, m = len(F), len(z), len(disp), len(names)
    y = np.concatenate([z[F], np.zeros(nF)] + ([inputs[disp]] if na else []))
    n = len(y)
    A = jacobian_at(sim, y, 0.0, u0 if single else model.actuator_command(inputs))
    dQz, dQv = tangent_at(sim, z)
    mF = lay.mass[F]
    B = np.zeros((n, m))
    Zx, Vx, Vc = np.zeros((N, n)), np.zeros((N, n)), np.zeros((N, m))
    Zx[F, np.arange(nF)] = 1.0
    Vx[F, nF + np.arange(nF)] = 1.0
    lags = np.full(m, -1, dtype=int)
    for a, (k, tau) in enumerate(zip(disp, model.tau)):
        du = model.D_rows[a]
        lags[k] = a
        B[nF:2 * nF, k] = dQv[np.ix_(F, P)] @ du / (tau * mF)
        B[2 * nF + a, k] = 1.0 / tau
        Zx[P, 2 * nF + a] = du
        Vx[P, 2 * nF + a] = -du / tau
        Vc[P, k] = du / tau
    for k in force:
        B[nF:2 * nF, k] = model.drive_directions[k][F] / mF
    out_names, Cs, Ds, y0 = [], [], [], []
    snap = st.snapshot

    def add(name, row, d, value):
        out_names.append(name), Cs.append(row), Ds.append(d), y0.append(value)

    for name, out_row in zip(model.output_names, model.output_matrix):
        add(name, out_row @ Zx, np.zeros(m), snap.output if len(model.outputs) == 1 else
            snap.outputs[name])
    if model.compression is not None:
        # The engine's one definition (engine/solver/compression.py): the drive side's centre of
        # stiffness minus the far side's, along the drive axis.
        (i_drive, c_drive), (i_far, c_far), axis = model.compression
        G = _point_jacobian(i_drive, c_drive, z) - _point_jacobian(i_far, c_far, z)
        row = axis @ G
        add("compression", row @ Zx, np.zeros(m), snap.compression)
    dQP = dQz[P] @ Zx + dQv[P] @ Vx
    dQPc = dQv[P] @ Vc
    for a, k in enumerate(disp):
        dk = model.D_rows[a]
        row = -(dk @ dQP)
        d = np.array([-(dk @ dQPc[:, j]) for j in range(m)])
        for b, (j, tau) in enumerate(zip(disp, model.tau)):  # M_P a_P, a_P = D (u - c)/tau^2
            mkj = dk @ (lay.mass[P] * model.D_rows[b])
            row[2 * nF + b] += mkj / tau**2
            d[j] -= mkj / tau**2
        add("drive_force" if single else f"drive_force.{names[k]}", row, d,
            float(snap.drive_forces[k]))
    for k in force:
        add("drive_position" if single else f"drive_position.{names[k]}",
            model.drive_directions[k] @ Zx, np.zeros(m), float(snap.drive_positions[k]))
    if wrenches:
        Jz, Jv = wrench_jacobians(mech, z)
        for k, hinge in enumerate(mech.hinges):
            for c, comp in enumerate(WRENCH_COMPONENTS):
                add(f"hinges.{hinge.name}.{comp}", Jz[k, c] @ Zx + Jv[k, c] @ Vx,
                    np.array([Jv[k, c] @ Vc[:, j] for j in range(m)]),
                    float(snap.wrenches[k, c]))
    state_names = (
        [_coord(mech, k) for k in F]
        + [_coord(mech, k, rate=True) for k in F]
        + (["drive.u"] if single and na else [f"drive.{names[k]}.u" for k in disp])
    )
    K = -dQz[np.ix_(F, F)]
    return LinearModel(
        A,
        B,
        np.array(Cs).reshape(len(Cs), n),
        np.array(Ds, dtype=float).reshape(len(Ds), m),
        state_names,
        ["drive"] if single else list(names),
        out_names,
        u0,
        z,
        np.array(y0, dtype=float),
        0.5 * (K + K.T),
        mF.copy(),
        F.copy(),
        -dQv[np.ix_(F, F)],
        tuple(names),
        tuple(int(a) for a in lags),
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
