"""
A spatial mechanism prepared for stepping: the constants (as MuJoCo's mjModel), no state.

The planar engine's structure in 3-D (``solver.model``): constraints by exact elimination of
prescribed coordinates (a fixed body, a drive's body, a prescribed translation coordinate),
so the state is y = (z_F, w_F, u) with z six coordinates per body and w its quasi-velocities
(``solver.spatial_chain``), u one actuator output per displacement drive (a first-order lag of
its command). The mass matrix is constant and block diagonal, so M_F dw_F/dt = Q_F(z, w)
exactly.

Exact Jacobians: the same ``spatial_chain.terms`` the kernel compiles, evaluated on complex
numbers one seed at a time (the complex step, ``spatial_kernels.complex_step``) or on
hyper-dual numbers seeded along all the state's directions at once (``kinematics.scalar``),
gives dQ/dy and d(dz/dt)/dy to rounding.
"""
from __future__ import annotations

from typing import Optional

import numpy as np

from flexure_sim.engine.kinematics import scalar
from flexure_sim.engine.kinematics.quaternion import matrix as quaternion_matrix
from flexure_sim.engine.mechanism.parts import Fixed
from flexure_sim.engine.mechanism.spatial_loader import drive_coordinates
from flexure_sim.engine.mechanism.spatial_parts import Drive, Mechanism
from flexure_sim.engine.solver import spatial_chain as chain
from flexure_sim.engine.solver import spatial_kernels as kernels
from flexure_sim.engine.solver.drives import DriveTable
from flexure_sim.engine.solver.model import DEFAULT_STEP, SolverError
from flexure_sim.engine.solver.motion import prescribed_motion
from flexure_sim.engine.solver.partition import Partition


def partition(mech: Mechanism) -> Partition:
    """Split the 6 n_bodies coordinates by the constraints (``drive_coordinates``)."""
    prescribed: set[int] = set()
    columns = []
    for c in mech.constraints:
        i = mech.body_index(c.body)
        if isinstance(c, Fixed):
            prescribed.update(range(6 * i, 6 * i + 6))
        elif isinstance(c, Drive) and c.kind == "displacement":
            prescribed.update(6 * i + k for k in drive_coordinates(c))
            columns.append(c.direction(mech))
    P = np.array(sorted(prescribed), dtype=int)
    F = np.array([k for k in range(6 * len(mech.bodies)) if k not in prescribed], dtype=int)
    D = (np.array(columns, dtype=float)[:, P].T if columns else np.zeros((len(P), 0)))
    du = D[:, 0].copy() if D.shape[1] == 1 else np.zeros(len(P))
    return Partition(F, P, du, [], D)


class SpatialModel:
    """
    The constants of a spatial mechanism prepared for stepping with fixed step ``dt`` (s).

    Same facade as ``solver.model.Model``: drives (a ``DriveTable`` of 6 coordinates per body,
    and the per-drive methods below that read it), ``pack``/``unpack``/
    ``full``, ``rhs``, ``jacobian``, ``output_values``; ``relinearize_tol`` as there. Energy
    bookkeeping of the steps is off in 3-D (``energy`` False: ``dissipated`` and
    ``drive_work`` are NaN); each hinge's energy and power are reported (``snapshot``).
    """

    #: The remainder iteration's tolerance and limits: ``solver.model.Model``'s.
    iteration_rtol = 1e-10
    max_iterations = 8
    relinearize_after = 3
    #: No energy integrals of the steps, no compression hinge; the kernel is always compiled.
    energy = False
    compression = None
    compiled = True

    def __init__(self, mechanism: Mechanism, dt: float = DEFAULT_STEP,
                 relinearize_tol: Optional[float] = None):
        if not (dt > 0 and np.isfinite(dt)):
            raise ValueError(f"dt must be a positive number of seconds, got {dt!r}")
        self.mechanism = mechanism
        self.dt = float(dt)
        self.relinearize_tol = relinearize_tol
        nb = len(mechanism.bodies)
        self.n_coordinates = 6 * nb
        masses = np.array([b.mass for b in mechanism.bodies], dtype=float)
        self.inertia = np.array([b.inertia for b in mechanism.bodies], dtype=float)
        #: Diagonal of M (the inertia tensors' diagonals on the rotations: D_d^T M_P D_d needs
        #: only the translations, which is all ``DriveMixin.drive_forces`` uses).
        self.mass = np.concatenate([np.concatenate([[m] * 3, np.diag(I)])
                                    for m, I in zip(masses, self.inertia)])
        self.z0 = np.concatenate([[*b.position, 0.0, 0.0, 0.0] for b in mechanism.bodies])
        self.part = partition(mechanism)
        #: Every drive (``drives.DriveTable``; no piezo actuator, no prescribed displacement
        #: in 3-D: every displacement drive is a lag of its command).
        self.drives = DriveTable(mechanism, self.part, self.z0)
        d = self.drives
        if len(d.prescribed):
            raise ValueError(f"drive {d.names[d.prescribed[0]]!r}: response_time 0 (a prescribed "
                             "displacement) is not available in 3-D yet; give a lag")
        self.drive_names, self.drive_directions = d.names, d.directions
        self.displacement_index, self.force_index, self.stack_index = (
            d.displacement, d.force, d.stack)
        self.tau, self.stroke_span, self.D_rows = d.tau, d.stroke_span, d.lag_rows
        self.drive = (d[0] if len(d) == 1 and len(d.displacement) == 1 else None)
        self.motion = (self.tau, self.z0[self.part.prescribed].copy(),
                       np.ascontiguousarray(self.part.D, dtype=float).reshape(
                           len(self.part.prescribed), self.n_actuators),
                       np.zeros(0, dtype=np.int64), np.zeros(0), np.zeros(0), np.zeros(0),
                       d.D_prescribed, d.first_program)
        self.constants = self._constants()
        self.kernel_args = (self.part.free.astype(np.int64),
                            self.part.prescribed.astype(np.int64), *self.motion[1:3],
                            self.motion[0], *self.motion[3:], self.first_force,
                            self.constants, 1.0 / masses,
                            np.linalg.inv(self.inertia).reshape(nb, 9))
        pos = self.z0.reshape(nb, 6)[:, :3]
        self.length_scale = max(1e-3, float(np.max(np.ptp(pos, axis=0)))) if nb > 1 else 1.0
        self.atol = self._iteration_atol()
        self.outputs = mechanism.outputs
        self.output_names = tuple(o.name for o in self.outputs)
        self.output_matrix = np.array([o.direction(mechanism) for o in self.outputs]
                                      ).reshape(len(self.outputs), 6 * nb)

    # ----------------------------------------------------------------- drives
    @property
    def n_actuators(self) -> int:
        """Return the number of displacement drives (actuator states u)."""
        return self.drives.n_lags

    def actuator_command(self, command) -> np.ndarray:
        """Return the kernel's command vector from a state's command (a number: every drive's)."""
        values = np.broadcast_to(np.asarray(command, dtype=float), (len(self.drives),))
        return self.drives.kernel_command(values)

    def kernel_command(self, command) -> np.ndarray:
        """Return ``command`` as the kernel takes it: an array as it is, a number every drive's."""
        if isinstance(command, np.ndarray):
            return command
        return np.full(len(self.drives), float(command))

    def actuator_u(self, u) -> np.ndarray:
        """Return one actuator output per displacement drive from a state's u (or a number)."""
        return np.broadcast_to(np.asarray(u, dtype=float), (self.n_actuators,)).astype(float)

    def state_u(self, u: np.ndarray) -> np.ndarray:
        """Return a state's u from the actuator outputs (``state.State``: a 1-D array)."""
        return np.array(u, dtype=float).reshape(self.n_actuators)

    def state_inputs(self, u, command) -> np.ndarray:
        """Return each drive's input in a stepped state (``DriveTable.state_inputs``)."""
        commands = np.broadcast_to(np.asarray(command, dtype=float), (len(self.drives),))
        return self.drives.state_inputs(self.actuator_u(u), commands)

    def drive_inputs(self, value) -> np.ndarray:
        """Return one input per drive from a number, a sequence or a mapping (``inputs``)."""
        return self.drives.inputs(value)

    def drive_forces(self, z: np.ndarray, v: np.ndarray, aP: np.ndarray,
                     Q: Optional[np.ndarray] = None, inputs=None) -> np.ndarray:
        """
        Return the force each drive's actuator applies (``DriveTable.forces``).

        A displacement drive's share D_d^T lambda_P of the constraint forces
        lambda_P = M_P a_P - Q_P (eq. 6.4), a force drive's commanded force.
        """
        P = self.part.prescribed
        reactions = np.zeros(len(P))
        if len(self.drives.displacement):
            if Q is None:
                Q = self.generalized_forces(z, v)[0]
            reactions = self.mass[P] * aP - Q[P]
        return self.drives.forces(self.part.D, reactions, inputs)

    def drive_positions(self, z: np.ndarray) -> np.ndarray:
        """Return each driven body's displacement along its drive's direction."""
        return self.drives.positions(z)

    @property
    def first_force(self) -> int:
        """Return where the force drives' forces start in the kernel's command vector."""
        return self.n_actuators

    def _constants(self) -> tuple:
        mech = self.mechanism
        hinges = mech.hinges
        idx = {b.name: i for i, b in enumerate(mech.bodies)}
        geometry = (
            np.array([idx[h.a.body] for h in hinges], dtype=np.int64),
            np.array([idx[h.b.body] for h in hinges], dtype=np.int64),
            np.array([h.a.position for h in hinges], dtype=float).reshape(-1, 3),
            np.array([h.b.position for h in hinges], dtype=float).reshape(-1, 3),
            np.array([h.a.quaternion for h in hinges], dtype=float).reshape(-1, 4),
            np.array([h.b.quaternion for h in hinges], dtype=float).reshape(-1, 4),
            np.array([quaternion_matrix(h.a.quaternion).ravel() for h in hinges]).reshape(-1, 9),
            np.array([quaternion_matrix(h.b.quaternion).ravel() for h in hinges]).reshape(-1, 9),
            np.array([h.law.kind for h in hinges], dtype=np.int64),
            np.ascontiguousarray([h.law.metric() for h in hinges]).reshape(-1, 6, 6),
            np.ascontiguousarray([h.law.dissipation_matrix() for h in hinges]).reshape(-1, 6, 6),
        )
        forces = [self.drives[k] for k in self.force_index]
        axes = [d.axis if d.coordinate is None else
                np.eye(3)["xyz".index(d.coordinate[-1])] for d in forces]
        return (np.array([b.quaternion for b in mech.bodies], dtype=float).reshape(-1, 4),
                self.inertia.reshape(-1, 9).copy(), geometry,
                np.array([idx[d.body] for d in forces], dtype=np.int64),
                np.array(axes, dtype=float).reshape(-1, 3),
                np.array([d.coordinate is not None and d.coordinate.startswith("r")
                          for d in forces], dtype=np.bool_))

    def _iteration_atol(self) -> np.ndarray:
        free = self.part.free
        per = np.where(free % 6 >= 3, 1e-12, 1e-12 * self.length_scale)
        return np.concatenate([per, per / self.dt, 1e-12 * self.stroke_span])

    # ------------------------------------------------------------- coordinates
    def prescribed(self, t: float, u, command):
        """Return z_P, w_P, a_P: the prescribed coordinates, their rates and accelerations."""
        return prescribed_motion(t, self.actuator_u(u), self.kernel_command(command),
                                 *self.motion)

    def full(self, zF, wF, t, u, command):
        """All coordinates z, quasi-velocities w and a_P from the free ones."""
        part = self.part
        zP, wP, aP = self.prescribed(t, u, command)
        z = np.empty(self.n_coordinates)
        w = np.empty(self.n_coordinates)
        z[part.free], z[part.prescribed] = zF, zP
        w[part.free], w[part.prescribed] = wF, wP
        return z, w, aP

    def pack(self, state) -> np.ndarray:
        """Return y = (z_F, w_F, u) of a state."""
        F = self.part.free
        return np.concatenate([state.z[F], state.v[F], self.actuator_u(state.u)])

    def unpack(self, y: np.ndarray, t: float, command):
        """Return (z, w, u) of y at time t under ``command``."""
        nF = len(self.part.free)
        u = y[2 * nF:2 * nF + self.n_actuators].copy()
        z, w, _ = self.full(y[:nF], y[nF:2 * nF], t, u, command)
        return z, w, u

    def check_range(self, z: np.ndarray) -> None:
        """Raise SolverError if a body turned beyond |phi| = pi (``kinematics.quaternion``)."""
        phi = np.linalg.norm(z.reshape(-1, 6)[:, 3:], axis=1)
        if np.any(phi > np.pi) or not np.all(np.isfinite(z)):
            i = int(np.argmax(np.where(np.isfinite(phi), phi, np.inf)))
            raise SolverError(f"body {self.mechanism.bodies[i].name!r} turned {phi[i]:.4g} rad "
                              "from its rest orientation: beyond the rotation coordinates' "
                              "range (pi)")

    # --------------------------------------------------------------- dynamics
    def terms(self, z: np.ndarray, w: np.ndarray, command=None):
        """
        Return (Q, dz/dt, deflections, wrenches, powers, potential, dissipation) at (z, w).

        Everything ``spatial_chain.terms`` fills, in floats: generalized forces (quasi-velocity
        space)
        and coordinate rates (6 n_bodies), and per hinge its deflection (rotation vector, p),
        the wrench on body B (frame b) and (U, P_c, P_d).
        """
        command = self.kernel_command(0.0 if command is None else command)
        nh = len(self.mechanism.hinges)
        N = self.n_coordinates
        Q, zdot = np.empty(N), np.empty(N)
        out = np.empty((nh, 6)), np.empty((nh, 6)), np.empty((nh, 3))
        energy, diss = kernels.terms(np.asarray(z, dtype=float), np.asarray(w, dtype=float),
                                     command, self.first_force, self.constants, Q, zdot, *out,
                                     True)
        return (Q, zdot, *out, float(energy), float(diss))

    def derivatives(self, z, w, command, Zx: np.ndarray, Wx: np.ndarray,
                    Cx: Optional[np.ndarray] = None):
        """
        Return dQ/ds, d(dz/dt)/ds and d(wrenches)/ds along seeds s (exact, complex step).

        Zx (N, m), Wx (N, m): dz/ds and dw/ds; Cx (n_command, m): d(kernel command)/ds. The
        compiled ``spatial_kernels.complex_step`` of ``spatial_chain.terms``;
        ``derivatives_hyperdual`` gives the same from hyper-dual numbers.
        """
        command = np.asarray(self.kernel_command(0.0 if command is None else command),
                             dtype=float)
        Cx = np.zeros((len(command), Zx.shape[1])) if Cx is None else Cx
        return kernels.complex_step(
            np.asarray(z, dtype=float), np.asarray(w, dtype=float), command,
            np.ascontiguousarray(Zx, dtype=float), np.ascontiguousarray(Wx, dtype=float),
            np.ascontiguousarray(Cx, dtype=float).reshape(len(command), Zx.shape[1]),
            self.first_force, self.constants, len(self.mechanism.hinges))

    def derivatives_hyperdual(self, z, w, command, Zx: np.ndarray, Wx: np.ndarray,
                              Cx: Optional[np.ndarray] = None):
        """
        Return what ``derivatives`` returns, from hyper-dual numbers (the formula in Python).

        About 100 times slower than the complex step; the two agree to rounding (a test).
        """
        m = Zx.shape[1]
        command = self.kernel_command(0.0 if command is None else command)
        cmd = (scalar.seeded(command, Cx) if Cx is not None
               else np.array(command, dtype=object))
        nh = len(self.mechanism.hinges)
        N = self.n_coordinates
        Q, zdot = scalar.zeros(N), scalar.zeros(N)
        wrench = scalar.zeros((nh, 6))
        chain.terms(scalar.seeded(z, Zx), scalar.seeded(w, Wx), cmd, self.first_force,
                    self.constants, Q, zdot, scalar.zeros((nh, 6)), wrench,
                    scalar.zeros((nh, 3)), True)
        return (scalar.derivatives_of(Q, m), scalar.derivatives_of(zdot, m),
                scalar.derivatives_of(wrench, m))

    def accelerations(self, Q: np.ndarray) -> np.ndarray:
        """Return M^-1 Q (every body; also for a stack of columns Q (N, m))."""
        nb = len(self.mechanism.bodies)
        Qb = np.asarray(Q, dtype=float).reshape((nb, 6) + np.shape(Q)[1:])
        out = np.empty_like(Qb)
        out[:, :3] = Qb[:, :3] / np.array([b.mass for b in self.mechanism.bodies]).reshape(
            (nb, 1) + (1,) * (Qb.ndim - 2))
        out[:, 3:] = np.einsum("bij,bj...->bi...", np.linalg.inv(self.inertia), Qb[:, 3:])
        return out.reshape(np.shape(Q))

    def rhs(self, y: np.ndarray, t: float, command):
        """Return F(y, t) and the energy rates (``spatial_kernels.spatial_rhs``)."""
        return kernels.spatial_rhs(np.asarray(y, dtype=float), t, self.kernel_command(command),
                                   self.kernel_args)

    def seeds(self, n_extra: int = 0):
        """Return Zx, Wx (N, m + n_extra): dz/dy and dw/dy for y = (z_F, w_F, u)."""
        part = self.part
        nF, na = len(part.free), self.n_actuators
        m = 2 * nF + na + n_extra
        N = self.n_coordinates
        Zx, Wx = np.zeros((N, m)), np.zeros((N, m))
        Zx[part.free, np.arange(nF)] = 1.0
        Wx[part.free, nF + np.arange(nF)] = 1.0
        for a, tau in enumerate(self.tau):
            Zx[part.prescribed, 2 * nF + a] = part.D[:, a]
            Wx[part.prescribed, 2 * nF + a] = -part.D[:, a] / tau
        return Zx, Wx

    def jacobian(self, y: np.ndarray, t: float, command) -> np.ndarray:
        """Exact A = dF/dy (hyper-dual evaluation of ``spatial_chain.terms``, module docstring)."""
        part = self.part
        nF = len(part.free)
        z, w, _ = self.unpack(y, t, command)
        Zx, Wx = self.seeds()
        dQ, dzdot, _ = self.derivatives(z, w, command, Zx, Wx)
        A = np.zeros((len(y), len(y)))
        A[:nF] = dzdot[part.free]
        A[nF:2 * nF] = self.accelerations(dQ)[part.free]
        for a, tau in enumerate(self.tau):
            A[2 * nF + a, 2 * nF + a] = -1.0 / tau
        return A

    def generalized_forces(self, z: np.ndarray, w: np.ndarray):
        """Return (Q, potential energy, dissipated power) at (z, w) with the drives at rest."""
        Q, *_, energy, diss = self.terms(z, w)
        return Q, energy, diss

    def output_values(self, z: np.ndarray) -> np.ndarray:
        """Return every output's displacement from rest, c_k . (z - z0)."""
        return self.output_matrix @ (z - self.z0)

    def output_displacement(self, z: np.ndarray) -> Optional[float]:
        """Return the first output's displacement from rest, or None."""
        return float(self.output_values(z)[0]) if self.outputs else None

    def kinetic_energy(self, w: np.ndarray) -> float:
        """Return 1/2 sum (m |v|^2 + omega^T I_b omega)."""
        W = np.asarray(w, dtype=float).reshape(-1, 6)
        masses = np.array([b.mass for b in self.mechanism.bodies])
        return float(0.5 * np.sum(masses * np.sum(W[:, :3] ** 2, axis=1))
                     + 0.5 * np.einsum("bi,bij,bj->", W[:, 3:], self.inertia, W[:, 3:]))
