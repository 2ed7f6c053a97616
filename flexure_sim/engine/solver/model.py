"""
A mechanism prepared for stepping: the constants (as MuJoCo's mjModel), no state.

Constraints are handled by **exact elimination of prescribed coordinates**: every
constraint of a mechanism prescribes whole coordinates (a fixed body; the driven body's
displacement along its axis with its other coordinates held; a prescribed rate of one
coordinate), so the coordinates split into free ones z_F and prescribed ones z_P(t).
With the diagonal mass matrix of body frames at mass centres (eqs. 6.4-6.13) the equations
of motion (5.25, 6.4) reduce exactly to

    M_F dv_F/dt = Q_F(z, v),        lambda_P = M_P a_P - Q_P(z, v),

where lambda_P are the constraint forces (the Lagrange multipliers of eq. 6.4, so the
force the drive must supply is the drive-axis component of lambda). Unlike the
dissertation's Baumgarte-stabilised multipliers (6.21-6.23), nothing drifts.

The driven coordinates follow the actuator outputs u, one per displacement drive, each a
first-order lag of its command (``Drive``); u is part of the integrated state
y = (z_F, v_F, u). A force drive's held force enters Q on its free coordinates (``drives``).
A ``Model`` holds the partition, masses, the hinge assembly, the mechanism's damping matrix C
(a ``damping:`` block: Rayleigh or modal, built once at rest by
``damping_models.damping_matrix``; Q -= C v on all coordinates, dissipating v^T C v) and the
compiled kernel's arguments, and evaluates F(y, t), its exact Jacobian and the reported
measures (output, drive force, compression).
It never changes after construction, so any number of ``Data`` may share it.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Optional

import numpy as np

from flexure_sim.errors import FlexureSimError
from flexure_sim.engine.solver import step_loop as stepping
from flexure_sim.engine.solver.assembly import Assembly
from flexure_sim.engine.solver.compression import compression_of, compression_points
from flexure_sim.engine.mechanism.damping_models import damping_matrix
from flexure_sim.engine.solver.drives import DriveMixin, stacked
from flexure_sim.engine.mechanism.parts import COORDINATE_NAMES, Drive, Fixed, Mechanism, SineRate

#: Default fixed step (s): 10 steps per millisecond.
DEFAULT_STEP = 1e-4


class SolverError(FlexureSimError, RuntimeError):
    """The solver could not produce a finite answer (names the cause)."""


@dataclass
class Partition:
    """
    Free and prescribed coordinate indices.

    Per prescribed coordinate dz_P/du (the drive axis component) of the single displacement
    drive (zeros with none or several); the sine-rate constraints as (index into prescribed,
    constraint); ``D``: dz_P/du per displacement drive (columns, ``Model.displacement_index``
    order).
    """

    free: np.ndarray
    prescribed: np.ndarray
    du: np.ndarray
    timed: list = field(default_factory=list)
    D: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))


def partition(mech: Mechanism) -> Partition:
    """Split the 3 n_bodies coordinates of ``mech`` by its constraints."""
    prescribed: set[int] = set()
    timed = []
    columns = []
    for c in mech.constraints:
        i = mech.body_index(c.body)
        if isinstance(c, Fixed):
            prescribed.update(3 * i + k for k in range(3))
        elif isinstance(c, Drive) and c.kind == "displacement" and stacked(c):
            if c.coordinate is None:  # the axis coordinate free (the stack pulls), rest held
                prescribed.update(3 * i + k for k in range(3) if k != _axis_coordinate(c))
        elif isinstance(c, Drive) and c.kind == "displacement":
            if c.coordinate is None:
                prescribed.update(3 * i + k for k in range(3))  # along the axis, rest held
            else:
                prescribed.add(3 * i + COORDINATE_NAMES.index(c.coordinate))
            columns.append(c.direction(mech))
        elif isinstance(c, SineRate):
            prescribed.add(3 * i + COORDINATE_NAMES.index(c.coordinate))
            timed.append((3 * i + COORDINATE_NAMES.index(c.coordinate), c))
    P = np.array(sorted(prescribed), dtype=int)
    F = np.array([k for k in range(3 * len(mech.bodies)) if k not in prescribed], dtype=int)
    pos = {k: j for j, k in enumerate(P)}
    D = np.array(columns, dtype=float).reshape(len(columns), -1)[:, P].T if columns else (
        np.zeros((len(P), 0)))
    du = D[:, 0].copy() if D.shape[1] == 1 else np.zeros(len(P))
    return Partition(F, P, du, [(pos[k], c) for k, c in timed], D)


def _axis_coordinate(drive: Drive) -> int:
    """
    Return the coordinate (0: x, 1: y) a stack drive's axis runs along.

    A finite stack frees its body along the axis and holds the other coordinates as the rigid
    drive does, so the axis must be a coordinate axis (else ValueError naming the drive).
    """
    ax = np.abs(np.asarray(drive.axis, dtype=float))
    for k in (0, 1):
        if ax[k] == 1.0 and ax[1 - k] == 0.0:
            return k
    raise ValueError(f"drive {drive.name!r}: an actuator with a finite stack stiffness needs an "
                     f"axis along x or y (or a coordinate), got axis {tuple(drive.axis)}")


class Model(DriveMixin):
    """
    The constants of a mechanism prepared for stepping with fixed step ``dt`` (s).

    ``relinearize_tol``: recompute the Jacobian when the configuration has moved by more
    than that (rad for angles, metres / ``length_scale`` for positions) since the last
    linearization (0: every step; None: only when the remainder iteration stops
    contracting). The answer does not depend on where the Jacobian was taken.

    ``energy``: integrate the dissipated energy and the drives' work over each step
    (``step_energy``; True by default). Off (as MuJoCo's energy flag, which is off by default),
    the motion is the same to the bit and ``dissipated`` and ``drive_work`` are NaN; each
    linearization then skips the energy integrals' matrices (~5 ms of the ~7 ms a
    linearization of the stage costs, measured with ``flexure-sim bench``) and each step the
    quadratic forms (~2 µs of ~5 µs). ``stage_node`` runs without: it publishes no energies.
    """

    #: The remainder iteration has converged when its last change is below
    #: iteration_rtol |y| + atol in every component (atol: 1e-12 of the mechanism's size in
    #: positions, 1e-12 rad in angles, those per step in rates, 1e-12 of the stroke in u).
    iteration_rtol = 1e-10
    #: Largest number of remainder iterations before re-linearizing within the step.
    max_iterations = 8
    #: A step that needed more iterations than this re-linearizes before the next one.
    relinearize_after = 3

    def __init__(self, mechanism: Mechanism, dt: float = DEFAULT_STEP,
                 relinearize_tol: Optional[float] = None, energy: bool = True):
        if not (dt > 0 and np.isfinite(dt)):
            raise ValueError(f"dt must be a positive number of seconds, got {dt!r}")
        if relinearize_tol is not None and not relinearize_tol >= 0:
            raise ValueError(f"relinearize_tol must be None or >= 0, got {relinearize_tol!r}")
        self.mechanism = mechanism
        self.assembly = Assembly(mechanism)
        self.dt = float(dt)
        self.relinearize_tol = relinearize_tol
        self.energy = bool(energy)
        #: Every drive (constraint order), their names and directions e (rows; the input
        #: of drive d is e_d . (z - z0)), the displacement and force drives' indices.
        self.drives: tuple[Drive, ...] = mechanism.drives
        self.drive_names = tuple(d.name for d in self.drives)
        self.drive_directions = np.array([d.direction(mechanism) for d in self.drives]
                                         ).reshape(len(self.drives), 3 * len(mechanism.bodies))
        self.displacement_index = np.array(
            [k for k, d in enumerate(self.drives) if d.kind == "displacement" and not stacked(d)],
            dtype=int)
        #: The stack drives (a piezo actuator of finite stiffness k_s: ``drives.stacked``).
        self.stack_index = np.array([k for k, d in enumerate(self.drives) if stacked(d)],
                                    dtype=int)
        self.force_index = np.array(
            [k for k, d in enumerate(self.drives) if d.kind == "force"], dtype=int)
        #: The single drive of a mechanism with one displacement drive and no other (the
        #: scalar interfaces: linear model, stroke limit), else None.
        self.drive: Optional[Drive] = (
            self.drives[0] if len(self.drives) == 1 and len(self.displacement_index) == 1
            else None)
        nb = len(mechanism.bodies)
        self.mass = np.array([[b.mass, b.mass, b.inertia]
                             for b in mechanism.bodies], dtype=float).ravel()
        self.z0 = np.array([b.pose for b in mechanism.bodies], dtype=float).ravel()
        self.part = partition(mechanism)
        self.mass_free = self.mass[self.part.free]
        #: The damping matrix C of the mechanism's ``damping:`` block on all coordinates
        #: (None without the block): generalised force -C v, dissipated power v^T C v.
        self.damping: Optional[np.ndarray] = None
        if mechanism.damping is not None:
            rest = self.assembly.forces(self.z0, np.zeros_like(self.z0), jacobian=True)
            self.damping = damping_matrix(mechanism.damping, self.mass, -rest.dQ_dz,
                                          self.part.free)
        self._drive_constants()
        self.motion = self._motion_arrays()
        self.compression = compression_points(mechanism)
        self.length_scale = max(
            1e-3, float(np.ptp(self.z0.reshape(nb, 3)[:, :2]))) if nb > 1 else 1.0
        self.atol = self._iteration_atol()
        self.kernel_args = self._kernel_args() if self.assembly.compiled else None
        #: The outputs (named; the single ``output:`` is named ``output``) and their
        #: directions c (rows; output k is c_k . (z - z0)).
        self.outputs = mechanism.all_outputs
        self.output_names = tuple(o.name for o in self.outputs)
        self.output_matrix = np.array([o.direction(mechanism) for o in self.outputs]
                                      ).reshape(len(self.outputs), 3 * nb)

    @property
    def compiled(self) -> bool:
        """Whether stepping runs the compiled kernel (every law quadratic)."""
        return self.assembly.compiled

    def _motion_arrays(self) -> tuple:
        """Arguments of stepping.prescribed_motion after (t, u, command)."""
        part = self.part
        sines = [c for _, c in part.timed]
        return (
            self.tau,
            self.z0[part.prescribed].copy(),
            np.ascontiguousarray(part.D, dtype=float).reshape(len(part.prescribed),
                                                              self.n_actuators),
            np.array([j for j, _ in part.timed], dtype=np.int64),
            np.array([c.amplitude for c in sines], dtype=float),
            np.array([2.0 * np.pi * c.frequency for c in sines], dtype=float),
            np.array([c.phase for c in sines], dtype=float),
        )

    def _iteration_atol(self) -> np.ndarray:
        free = self.part.free
        per_coord = np.where(free % 3 == 2, 1e-12, 1e-12 * self.length_scale)
        return np.concatenate([per_coord, per_coord / self.dt, 1e-12 * self.stroke_span])

    def _kernel_args(self) -> tuple:
        a = self.assembly
        part = self.part
        tau, zP0, D, sine_index, sine_amp, sine_w, sine_phase = self.motion
        damping = self.damping if self.damping is not None else np.zeros((0, 0))
        return (part.free.astype(np.int64), part.prescribed.astype(np.int64), self.mass, zP0, D,
                tau, sine_index, sine_amp, sine_w, sine_phase, self.force_dir, self.force_z0,
                self.stack_dir, self.stack_z0, self.stack_k, a._ia, a._ib, a._ca, a._cb,
                a.phia, a.phib, a._kind, a._W, a._C,
                np.ascontiguousarray(damping))

    # ------------------------------------------------------------- coordinates
    def prescribed(self, t: float, u, command):
        """
        Return z_P, v_P, a_P: prescribed coordinates, their rates and accelerations.

        ``u``: a state's u (``actuator_u``); ``command``: a number or the actuator-order vector
        (``kernel_command``).
        """
        return stepping.prescribed_motion(t, self.actuator_u(u), self.kernel_command(command),
                                          *self.motion)

    def full(self, zF, vF, t, u, command):
        """All coordinates z, velocities v (root frame) and a_P from the free ones."""
        part = self.part
        zP, vP, aP = self.prescribed(t, u, command)
        z = np.empty(len(self.z0))
        v = np.empty(len(self.z0))
        z[part.free], z[part.prescribed] = zF, zP
        v[part.free], v[part.prescribed] = vF, vP
        return z, v, aP

    def pack(self, state) -> np.ndarray:
        """Return y = (z_F, v_F, u) of a state (one u per displacement drive)."""
        part = self.part
        return np.concatenate([state.z[part.free], state.v[part.free],
                               self.actuator_u(state.u)])

    def unpack(self, y: np.ndarray, t: float, command):
        """(z, v, u) of y at time t under ``command`` (u: the actuator outputs, a vector)."""
        nF = len(self.part.free)
        u = y[2 * nF:2 * nF + self.n_actuators].copy()
        z, v, _ = self.full(y[:nF], y[nF:2 * nF], t, u, command)
        return z, v, u

    # --------------------------------------------------------------- dynamics
    def generalized_forces(self, z: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, float, float]:
        """
        Q, potential energy and dissipated power: the hinges' and the damping matrix's.

        Q = Q_hinges - C v and dissipation + v^T C v (``Assembly.generalized_forces``; C:
        ``damping``, nothing added without it).
        """
        Q, potential, dissipation = self.assembly.generalized_forces(z, v)
        Q, extra = self.add_damping(Q, v)
        return Q, potential, dissipation + extra

    def add_damping(self, Q: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, float]:
        """Return (Q - C v, v^T C v) for the hinges' Q (Q itself and 0 without C)."""
        if self.damping is None:
            return Q, 0.0
        cv = self.damping @ v
        return Q - cv, float(v @ cv)

    def velocity_jacobian(self, dQ_dv: np.ndarray) -> np.ndarray:
        """Return dQ/dv of all forces from the hinges' dQ/dv: minus C (``damping``) if given."""
        return dQ_dv if self.damping is None else dQ_dv - self.damping

    def rhs(self, y: np.ndarray, t: float, command):
        """
        Return F(y, t) and the energy rates (``stepping.energy_rates``).

        ``command``: a number or the actuator-order vector (``kernel_command``).
        """
        command = self.kernel_command(command)
        if self.compiled:
            return stepping.kernel_rhs(y, t, command, self.kernel_args)
        return self.rhs_python(y, t, command)

    def rhs_python(self, y: np.ndarray, t: float, command, _args=None):
        """F(y, t) and the energy rates through Assembly (any hinge law)."""
        part = self.part
        command = self.kernel_command(command)
        nF, nd = len(part.free), self.n_actuators
        u = y[2 * nF:2 * nF + nd]
        z, v, aP = self.full(y[:nF], y[nF:2 * nF], t, u, command)
        Q, potential, dissipation = self.generalized_forces(z, v)
        applied, springs = stepping.applied_forces(Q, z, command, nd, self.force_dir,
                                                   self.force_z0, self.stack_dir, self.stack_z0,
                                                   self.stack_k)
        potential += springs
        F = np.empty_like(y)
        F[:nF] = y[nF:2 * nF]
        F[nF:2 * nF] = Q[part.free] / self.mass_free
        F[2 * nF:] = (command[:nd] - u) / self.tau
        aux = np.empty(stepping.AUX_LOAD + nd)
        return F, stepping.energy_rates(aux, Q, v, potential, dissipation, applied,
                                        part.prescribed, self.mass, self.motion[2],
                                        self.motion[3], aP)

    def jacobian(self, y: np.ndarray, t: float, command, load_gradient: bool = False,
                 damping: bool = False):
        """
        Exact A = dF/dy for y = (z_F, v_F, u).

        Rows dz_F/dt = v_F, M_F dv_F/dt = Q_F(z, v), du_d/dt = (command_d - u_d)/tau_d, with z_P,
        v_P depending on each u_d through D_d (the force drives' held forces do not depend on y;
        the stack springs add -k_s e e^T to dQ/dz);
        dQ/dv includes -C (``velocity_jacobian``), also through v_P. With ``load_gradient`` also
        G (rows g_d = dq_d/dy) of the drive loads q_d = D_d^T Q_P: (A, G); with ``damping`` also
        the damping matrix -dQ/dv over all coordinates (1/2 the Hessian of the dissipated power
        in the velocities) and dQ_P/dy: (A, G, C, dQ_P/dy).
        """
        part = self.part
        nF = len(part.free)
        z, v, _ = self.unpack(y, t, command)
        hf = self.assembly.forces(z, v, jacobian=True)
        mF = self.mass_free
        m = len(y)
        A = np.zeros((m, m))
        A[:nF, nF:2 * nF] = np.eye(nF)
        Kzz, Kvv = hf.dQ_dz, self.velocity_jacobian(hf.dQ_dv)
        if self.stack_K is not None:  # the stack springs: dQ/dz = -k_s e e^T
            Kzz = Kzz - self.stack_K
        FF = np.ix_(part.free, part.free)
        A[nF:2 * nF, :nF] = Kzz[FF] / mF[:, None]
        A[nF:2 * nF, nF:2 * nF] = Kvv[FF] / mF[:, None]
        G = np.zeros((self.n_actuators, m))
        FP = np.ix_(part.free, part.prescribed)
        PF, PP = np.ix_(part.prescribed, part.free), np.ix_(part.prescribed, part.prescribed)
        for k, (dk, tau) in enumerate(zip(self.D_rows, self.tau)):
            A[nF:2 * nF, 2 * nF + k] = (Kzz[FP] @ dk - Kvv[FP] @ dk / tau) / mF
            A[2 * nF + k, 2 * nF + k] = -1.0 / tau
            G[k, :nF] = dk @ Kzz[PF]
            G[k, nF:2 * nF] = dk @ Kvv[PF]
            for j, (dj, tau_j) in enumerate(zip(self.D_rows, self.tau)):
                G[k, 2 * nF + j] = dk @ (Kzz[PP] @ dj - Kvv[PP] @ dj / tau_j)
        if damping:
            rows = np.zeros((len(part.prescribed), m))  # dQ_P/dy
            rows[:, :nF], rows[:, nF:2 * nF] = Kzz[PF], Kvv[PF]
            for k, (dk, tau) in enumerate(zip(self.D_rows, self.tau)):
                rows[:, 2 * nF + k] = Kzz[PP] @ dk - Kvv[PP] @ dk / tau
            return A, G, -Kvv, rows
        return (A, G) if load_gradient else A

    # --------------------------------------------------------------- measures
    def output_displacement(self, z: np.ndarray) -> Optional[float]:
        """Return the (first) output's displacement from rest (m, or rad on theta), or None."""
        if not self.outputs:
            return None
        return float(self.output_matrix[0] @ (z - self.z0))

    def output_values(self, z: np.ndarray) -> np.ndarray:
        """Every output's displacement from rest, c_k . (z - z0) (``output_names`` order)."""
        return self.output_matrix @ (z - self.z0)

    def hinge_compression(self, z: np.ndarray) -> Optional[float]:
        """
        Compression of the compression hinge at z (m, ``compression.compression_points``).

        Along the drive axis, at its centre of stiffness, its drive side's displacement from rest
        minus its far side's; None without a compression hinge.
        """
        if self.compression is None:
            return None
        (i_drive, c_drive), (i_far, c_far), axis = self.compression
        return float(compression_of(z, self.z0, i_drive, *c_drive, i_far, *c_far, *axis))
