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

The driven coordinates follow the actuator outputs u, one per lagged displacement drive, each a
first-order lag of its command (``Drive``); u is part of the integrated state
y = (z_F, v_F, u). A prescribed drive's (``response_time: 0``) coordinates follow its program,
a function of time (``programs``). A force drive's held force enters Q on its free coordinates
(``drives``).
A ``Model`` holds the partition, masses, the hinge assembly, the mechanism's damping matrix C
(a ``damping:`` block: Rayleigh or modal, built once at rest by
``damping_models.damping_matrix``; Q -= C v on all coordinates, dissipating v^T C v) and the
compiled kernel's arguments, and evaluates F(y, t), its exact Jacobian and the reported
measures (output, drive force, compression).
It never changes after construction, so any number of ``Data`` may share it.
"""
from __future__ import annotations

from typing import Optional

import numpy as np

from flexure_sim.errors import FlexureSimError
from flexure_sim.engine.solver import derivatives, step_loop as stepping
from flexure_sim.engine.solver.assembly import Assembly
from flexure_sim.engine.solver.compression import compression_of, compression_points
from flexure_sim.engine.mechanism.damping_models import damping_matrix
from flexure_sim.engine.solver.derivatives import Tangent
from flexure_sim.engine.solver.drives import DriveTable
from flexure_sim.engine.mechanism.parts import Drive, Mechanism
from flexure_sim.engine.solver.partition import partition

#: Default fixed step (s): 10 steps per millisecond.
DEFAULT_STEP = 1e-4


class SolverError(FlexureSimError, RuntimeError):
    """The solver could not produce a finite answer (names the cause)."""


class Model:
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
        #: Every drive, by kind, and the kernel's drive constants (``drives.DriveTable``).
        self.drives = DriveTable(mechanism, self.part, self.z0)
        self._check_lags()
        #: The single drive of a mechanism with one displacement drive and no other (the
        #: scalar interfaces: linear model, stroke limit), else None.
        self.drive: Optional[Drive] = (
            mechanism.drives[0] if len(self.drives) == 1 and len(self.drives.displacement) == 1
            else None)
        self.motion = self._motion_arrays()
        #: The prescribed coordinates (indices into ``part.prescribed``) that the prescribed
        #: drives' programs move: timed like the sine rates in the energy bookkeeping.
        self.program_index = np.flatnonzero(np.any(self.drives.D_prescribed != 0.0, axis=1)
                                            ).astype(np.int64)
        self.compression = compression_points(mechanism)
        self.length_scale = max(
            1e-3, float(np.ptp(self.z0.reshape(nb, 3)[:, :2]))) if nb > 1 else 1.0
        self.atol = self._iteration_atol()
        #: Where y = (z_F, v_F, u) holds u (the lagged drives' outputs).
        nF = len(self.part.free)
        self.u_slice = slice(2 * nF, 2 * nF + self.drives.n_lags)
        self.kernel_args = self._kernel_args() if self.assembly.compiled else None
        #: The outputs (named; the single ``output:`` is named ``output``) and their
        #: directions c (rows; output k is c_k . (z - z0)).
        self.outputs = mechanism.all_outputs
        self.output_names = tuple(o.name for o in self.outputs)
        self.output_matrix = np.array([o.direction(mechanism) for o in self.outputs]
                                      ).reshape(len(self.outputs), 3 * nb)

    #: A lag shorter than this fraction of the step is refused (``_check_lags``).
    shortest_lag = 1e-5

    def _check_lags(self) -> None:
        """
        Refuse a lag far shorter than the step, naming the drive and what to give instead.

        Below ``shortest_lag`` dt the lag ends within the step to e^-100000 and the step's
        matrices (e^{-h/tau}, (A - I/tau)^-1) no longer hold it in floating point; its limit is
        a prescribed displacement (``response_time: 0``). Longer lags, down to that bound, step
        at any dt (``integrator.step`` re-linearizes where the lag has settled).
        """
        for k, tau in zip(self.drives.lagged, self.drives.tau):
            if tau < self.shortest_lag * self.dt:
                raise ValueError(
                    f"drive {self.drives.names[k]!r}: response_time {tau:g} s is below "
                    f"{self.shortest_lag:g} of the step ({self.dt:g} s), too short a lag to "
                    "step; give response_time: 0 (the displacement then follows its command "
                    "exactly, a step rising over one engine step) or a smaller step")

    @property
    def compiled(self) -> bool:
        """Whether stepping runs the compiled kernel (every law quadratic)."""
        return self.assembly.compiled

    def _motion_arrays(self) -> tuple:
        """Arguments of stepping.prescribed_motion after (t, u, command)."""
        part = self.part
        sines = [c for _, c in part.timed]
        d = self.drives
        return (
            d.tau,
            self.z0[part.prescribed].copy(),
            np.ascontiguousarray(d.lag_rows.T, dtype=float).reshape(len(part.prescribed),
                                                                    d.n_lags),
            np.array([j for j, _ in part.timed], dtype=np.int64),
            np.array([c.amplitude for c in sines], dtype=float),
            np.array([2.0 * np.pi * c.frequency for c in sines], dtype=float),
            np.array([c.phase for c in sines], dtype=float),
            d.D_prescribed,
            d.first_program,
        )

    def _iteration_atol(self) -> np.ndarray:
        free = self.part.free
        per_coord = np.where(free % 3 == 2, 1e-12, 1e-12 * self.length_scale)
        return np.concatenate([per_coord, per_coord / self.dt, 1e-12 * self.drives.stroke_span])

    def _kernel_args(self) -> tuple:
        d = self.drives
        part = self.part
        tau, zP0, D, sine_index, sine_amp, sine_w, sine_phase, Dp, first_program = self.motion
        damping = self.damping if self.damping is not None else np.zeros((0, 0))
        return (part.free.astype(np.int64), part.prescribed.astype(np.int64), self.mass, zP0, D,
                tau, sine_index, sine_amp, sine_w, sine_phase, Dp, first_program,
                self.program_index, d.force_dir, d.force_z0, d.stack_dir, d.stack_z0, d.stack_k,
                *self.assembly.kernel_arrays(), np.ascontiguousarray(damping))

    # ------------------------------------------------------------- coordinates
    def prescribed(self, t: float, u: np.ndarray, command: np.ndarray):
        """
        Return z_P, v_P, a_P: prescribed coordinates, their rates and accelerations.

        ``u``: the actuator outputs (a state's u); ``command``: the kernel's command vector
        (``DriveTable.kernel_command``).
        """
        return stepping.prescribed_motion(t, u, self._checked(command), *self.motion)

    def _checked(self, command) -> np.ndarray:
        """Return ``command`` if it is a kernel command vector; TypeError naming it otherwise."""
        width = self.drives.kernel_width
        if not (isinstance(command, np.ndarray) and command.shape == (width,)
                and command.dtype == np.float64):
            raise TypeError(f"command: expected the kernel's command vector, a float array of "
                            f"{width} (DriveTable.kernel_command), got {command!r}")
        return command

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
        self.drives.check_state(state.u, state.command)
        return np.concatenate([state.z[part.free], state.v[part.free], state.u])

    def unpack(self, y: np.ndarray, t: float, command: np.ndarray):
        """(z, v, u) of y at time t under the kernel ``command`` (u: the actuator outputs)."""
        nF = len(self.part.free)
        u = y[2 * nF:2 * nF + self.drives.n_lags].copy()
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

    def rhs(self, y: np.ndarray, t: float, command: np.ndarray):
        """
        Return F(y, t) and the energy rates (``stepping.energy_rates``).

        ``command``: the kernel's command vector (``DriveTable.kernel_command``).
        """
        if self.compiled:
            return stepping.kernel_rhs(y, t, self._checked(command), self.kernel_args)
        return self.rhs_python(y, t, command)

    def rhs_python(self, y: np.ndarray, t: float, command, _args=None):
        """F(y, t) and the energy rates through Assembly (any hinge law)."""
        part = self.part
        d = self.drives
        nF, nd = len(part.free), d.n_lags
        u = y[2 * nF:2 * nF + nd]
        z, v, aP = self.full(y[:nF], y[nF:2 * nF], t, u, command)
        Q, potential, dissipation = self.generalized_forces(z, v)
        applied, springs = stepping.applied_forces(Q, z, command, nd, d.force_dir, d.force_z0,
                                                   d.stack_dir, d.stack_z0, d.stack_k)
        potential += springs
        F = np.empty_like(y)
        F[:nF] = y[nF:2 * nF]
        F[nF:2 * nF] = Q[part.free] / self.mass_free
        F[2 * nF:] = (command[:nd] - u) / d.tau
        aux = np.empty(stepping.AUX_LOAD + nd + 2 * len(self.program_index))
        return F, stepping.energy_rates(aux, Q, v, potential, dissipation, applied,
                                        part.prescribed, self.mass, self.motion[2],
                                        self.motion[3], self.program_index, aP)

    def jacobian(self, y: np.ndarray, t: float, command) -> np.ndarray:
        """
        Return the exact A = dF/dy for y = (z_F, v_F, u) (``derivatives.jacobian_parts``).

        Rows dz_F/dt = v_F, M_F dv_F/dt = Q_F(z, v), du_d/dt = (command_d - u_d)/tau_d.
        """
        return derivatives.jacobian_parts(self, y, t, command).A

    def tangent(self, y: np.ndarray, t: float, command) -> Tangent:
        """
        Return A (``jacobian``) and the derivatives the step's energy integrals need.

        ``derivatives.Tangent``: the drive loads' gradient, the damping matrix, dQ_P/dy.
        """
        return derivatives.tangent(self, y, t, command)

    # --------------------------------------------------------------- measures
    def constraint_forces(self, z: np.ndarray, v: np.ndarray, aP: np.ndarray,
                          Q: Optional[np.ndarray] = None) -> np.ndarray:
        """
        Return the constraint forces lambda_P = M_P a_P - Q_P on the prescribed coordinates.

        The Lagrange multipliers of eq. 6.4: what the constraints apply to the bodies (N, N m).
        ``Q``: the generalized forces at (z, v) (``generalized_forces``; evaluated if None).
        """
        if Q is None:
            Q = self.generalized_forces(z, v)[0]
        P = self.part.prescribed
        return self.mass[P] * aP - Q[P]

    def drive_forces(self, z: np.ndarray, v: np.ndarray, aP: np.ndarray,
                     Q: Optional[np.ndarray] = None, inputs=None) -> np.ndarray:
        """
        Return the force each drive's actuator applies along its direction (``DriveTable.forces``).

        A displacement drive's share D_d^T lambda_P of the constraint forces
        (``constraint_forces``), a force drive's commanded force (its entry of ``inputs``).
        """
        reactions = (self.constraint_forces(z, v, aP, Q) if len(self.drives.displacement)
                     else np.zeros(len(self.part.prescribed)))
        return self.drives.forces(self.part.D, reactions, inputs)

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
        (i_drive, (cdx, cdy)), (i_far, (cfx, cfy)), (ax, ay) = self.compression
        return float(compression_of(z, self.z0, i_drive, cdx, cdy, i_far, cfx, cfy, ax, ay))
