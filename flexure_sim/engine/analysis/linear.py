"""
Exact linearisation about a static equilibrium, with any number of drives.

Natural modes, damped poles, frequency response and a named state-space model
(``linear_response``: modes, frf, static_gain, gain_matrix, re-exported here).

About the static equilibrium z* at the drive inputs u* (``Simulation.static``: one per drive),
the engine's first-order system y' = F(y, command), y = (z_F, v_F, u_1 .. u_m) with one
actuator output u_a per displacement drive (``Model.pack``), has the exact Jacobian
A = dF/dy (``Model.jacobian``: analytic, no finite differences) and input matrix
B = dF/dcommand, one column per drive (``DriveTable.names`` order). A displacement drive's
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
from typing import Any, Optional, Sequence

import numpy as np

from flexure_sim.engine.kinematics import hyperdual as hd
from flexure_sim.engine.kinematics.planar import J
from flexure_sim.engine.mechanism.parameters import design_of, hinge_indices, twistor_flags
from flexure_sim.engine.analysis.linear_response import Modes, frf, gain_matrix, modes, static_gain
from flexure_sim.engine.analysis.parametric import forces
from flexure_sim.engine.solver.simulation import Simulation, StaticResult

WRENCH_COMPONENTS = ("moment", "force_x", "force_y")
#: What a displacement drive's input is (``linearize``): its command, through its lag, or the
#: displacement itself.
INPUT_KINDS = ("command", "displacement")

__all__ = ["LinearModel", "Modes", "frf", "gain_matrix", "layout", "linearize", "modes",
           "static_gain", "tangent_at", "wrench_jacobians"]


# ------------------------------------------------ the engine's internals, in one place


def jacobian_at(sim: Simulation, y: np.ndarray, t: float, command: np.ndarray) -> np.ndarray:
    """Exact A = dF/dy of the engine's first-order system at y (`Model.jacobian`)."""
    return sim.model.jacobian(y, t, command)


@dataclass(frozen=True)
class Layout:
    """
    How the engine's state is laid out.

    Free and prescribed coordinate indices, the prescribed coordinates' drive-axis components d_u
    and the actuator time constant of a single displacement drive (zeros and None otherwise:
    ``Partition.D`` and ``DriveTable.tau`` hold every drive's), masses (3 n_bodies), the rest
    pose z0.
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
    x' = A x + B u + B1 u', y = C x + D u + D1 u' + D2 u'' about the equilibrium.

    x: deviations of (z_F, v_F, u_1 .. u_a) (m, rad, m/s, rad/s, m; one actuator output per
    lagged drive whose input is its command); u: one input per drive (``input_names``, B's
    columns): per ``input_kinds`` a lagged drive's command, a drive's displacement itself, or a
    force drive's force. A displacement input's rate and acceleration enter too (the prescribed
    body's velocity through the damping, its inertia in its drive force): ``B1``, ``D1``, ``D2``
    (zero for the other inputs; ``frf`` and ``gain_matrix`` include them). Outputs are deviations
    of the named quantities from their static values ``y0``. ``u0``: the drive input of the
    equilibrium (a number with one drive or none, else one per drive in ``drive_names`` order);
    ``lags``: per input, the index of its actuator state among the u (-1 for any other input).
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
    B1: Optional[np.ndarray] = None
    D1: Optional[np.ndarray] = None
    D2: Optional[np.ndarray] = None
    input_kinds: tuple = ()

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
              static: Optional[StaticResult] = None,
              input_kind: str = "command") -> LinearModel:
    """
    Return the exact linear model about the static equilibrium at the drive inputs u (module doc).

    ``u``: a number (a single drive), one value per drive or a {name: value} mapping
    (``DriveTable.inputs``); None: every drive at 0. ``static``: that equilibrium if already
    solved (``sim.static(u)``). ``input_kind``: ``command`` (a lagged drive's input is its
    command, through its lag) or ``displacement`` (every displacement drive's input is its
    displacement itself: no lag state; the input's rate and acceleration enter through ``B1``,
    ``D1``, ``D2``). A prescribed drive's (``response_time: 0``) input is its displacement
    either way.
    """
    if input_kind not in INPUT_KINDS:
        raise ValueError(f"input_kind {input_kind!r}: expected one of {', '.join(INPUT_KINDS)}")
    model = sim.model
    drives = model.drives
    drives.require_rigid("the linear model")
    mech = sim.mechanism
    names = drives.names
    inputs = drives.inputs(np.zeros(len(names)) if u is None else u)
    single = len(names) == 1
    u0 = float(inputs[0]) if single else 0.0 if not names else inputs.copy()
    st = static if static is not None else sim.static(u0 if single or not names else inputs)
    z = st.z
    lay = layout(sim)
    F, P = lay.free, lay.prescribed
    force = drives.force
    nF, N, m = len(F), len(z), len(names)
    # The lagged drives whose command is the input keep their lag state; the others' input is
    # the displacement (column of Partition.D, ``drives.displacement`` order).
    lagged = list(drives.lagged) if input_kind == "command" else []
    shifted = [k for k in drives.displacement if k not in lagged]
    column = {int(k): j for j, k in enumerate(drives.displacement)}
    na = len(lagged)
    y_full = np.concatenate([z[F], np.zeros(nF), inputs[drives.lagged]])
    A_full = jacobian_at(sim, y_full, 0.0, drives.kernel_command(inputs))
    keep = np.r_[0:2 * nF, [2 * nF + list(drives.lagged).index(k) for k in lagged]].astype(int)
    A = A_full[np.ix_(keep, keep)]
    n = len(keep)
    dQz, dQv = tangent_at(sim, z)
    mF = lay.mass[F]
    B, B1 = np.zeros((n, m)), np.zeros((n, m))
    Zx, Vx, Vc = np.zeros((N, n)), np.zeros((N, n)), np.zeros((N, m))
    Zu, Vu = np.zeros((N, m)), np.zeros((N, m))   # z and v on the inputs and their rates
    Zx[F, np.arange(nF)] = 1.0
    Vx[F, nF + np.arange(nF)] = 1.0
    lags = np.full(m, -1, dtype=int)
    for a, k in enumerate(lagged):
        du = model.part.D[:, column[k]]
        tau = drives[k].response_time
        lags[k] = a
        B[nF:2 * nF, k] = dQv[np.ix_(F, P)] @ du / (tau * mF)
        B[2 * nF + a, k] = 1.0 / tau
        Zx[P, 2 * nF + a] = du
        Vx[P, 2 * nF + a] = -du / tau
        Vc[P, k] = du / tau
    for k in shifted:
        du = model.part.D[:, column[k]]
        B[nF:2 * nF, k] = dQz[np.ix_(F, P)] @ du / mF
        B1[nF:2 * nF, k] = dQv[np.ix_(F, P)] @ du / mF
        Zu[P, k] = du
        Vu[P, k] = du
    for k in force:
        B[nF:2 * nF, k] = drives.directions[k][F] / mF
    rows = _Outputs(m)
    snap = st.snapshot

    def position(name, r, value):        # an output of the coordinates alone
        rows.add(name, r @ Zx, r @ Zu, np.zeros(m), np.zeros(m), value)

    for name, c in zip(model.output_names, model.output_matrix):
        position(name, c, snap.output if len(model.outputs) == 1 else snap.outputs[name])
    if model.compression is not None:
        # The engine's one definition (engine/solver/compression.py): the drive side's centre of
        # stiffness minus the far side's, along the drive axis.
        (i_drive, c_drive), (i_far, c_far), axis = model.compression
        G = _point_jacobian(i_drive, c_drive, z) - _point_jacobian(i_far, c_far, z)
        position("compression", axis @ G, snap.compression)
    # Drive forces D_d^T (M_P a_P - Q_P): a lag's a_P = D (u - c)/tau^2, a displacement input's
    # a_P = D u''.
    dQP, dQPc = dQz[P] @ Zx + dQv[P] @ Vx, dQv[P] @ Vc
    dQPu, dQPr = dQz[P] @ Zu, dQv[P] @ Vu
    for k in drives.displacement:
        dk = model.part.D[:, column[k]]
        row, d = -(dk @ dQP), -(dk @ (dQPc + dQPu))
        d2 = np.zeros(m)
        for j in drives.displacement:
            mkj = dk @ (lay.mass[P] * model.part.D[:, column[j]])
            if j in lagged:
                tau = drives[j].response_time
                row[2 * nF + lagged.index(j)] += mkj / tau**2
                d[j] -= mkj / tau**2
            else:
                d2[j] = mkj
        rows.add("drive_force" if single else f"drive_force.{names[k]}", row, d, -(dk @ dQPr),
                 d2, float(snap.drive_forces[k]))
    for k in force:
        position("drive_position" if single else f"drive_position.{names[k]}",
                 drives.directions[k], float(snap.drive_positions[k]))
    if wrenches:
        Jz, Jv = wrench_jacobians(mech, z)
        for k, hinge in enumerate(mech.hinges):
            for w, comp in enumerate(WRENCH_COMPONENTS):
                rows.add(f"hinges.{hinge.name}.{comp}", Jz[k, w] @ Zx + Jv[k, w] @ Vx,
                         Jv[k, w] @ Vc + Jz[k, w] @ Zu, Jv[k, w] @ Vu, np.zeros(m),
                         float(snap.wrenches[k, w]))
    state_names = (
        [_coord(mech, k) for k in F]
        + [_coord(mech, k, rate=True) for k in F]
        + (["drive.u"] if single and na else [f"drive.{names[k]}.u" for k in lagged])
    )
    K = -dQz[np.ix_(F, F)]
    C, D, D1, D2, y0 = rows.arrays(n)
    return LinearModel(
        A, B, C, D, state_names, ["drive"] if single else list(names), rows.names, u0, z, y0,
        0.5 * (K + K.T), mF.copy(), F.copy(), -dQv[np.ix_(F, F)], tuple(names),
        tuple(int(a) for a in lags), B1, D1, D2,
        tuple("force" if k in force else "command" if k in lagged else "displacement"
              for k in range(m)))


class _Outputs:
    """The output rows of a linear model as they are added: y = C x + D u + D1 u' + D2 u''."""

    def __init__(self, m: int) -> None:
        self.m = m
        self.names: list = []
        self._rows: list = []

    def add(self, name, c, d, d1, d2, value) -> None:
        self.names.append(name)
        self._rows.append((c, d, d1, d2, value))

    def arrays(self, n: int) -> tuple:
        """Return C, D, D1, D2 and y0 as arrays."""
        k, m = len(self._rows), self.m
        parts: list[Sequence[Any]] = (list(zip(*self._rows)) if self._rows
                                      else [[], [], [], [], []])
        return (np.array(parts[0], dtype=float).reshape(k, n),
                *(np.array(p, dtype=float).reshape(k, m) for p in parts[1:4]),
                np.array(parts[4], dtype=float))


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
