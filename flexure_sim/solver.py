"""Constrained dynamics, fixed-step stiff-stable stepping and static equilibrium.

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

The driven coordinate follows the actuator output u, a first-order lag of the command
(``Drive``); u is part of the integrated state, so within a step the whole system is
autonomous. Stepping uses the **exponential Rosenbrock-Euler** method:

    y_{n+1} = y_n + h phi_1(h A) F(y_n) + h^2 phi_2(h A) dF/dt,

with A = dF/dy the exact Jacobian. It is exact for linear dynamics at any step, hence
stable for the stage's stiff, heavily damped hinge modes (eigenvalues near -2e7 1/s), and
second order for nonlinear ones. phi_1, phi_2 come from one matrix exponential of an
augmented matrix. The Jacobian (and its exponential) may be reused while the
configuration barely moves (``relinearize_tol``), which makes a step a matrix-vector
product plus one force evaluation.

The static equilibrium for a given drive input is Newton's method on Q_F(z) = 0 with the
exact stiffness dQ_F/dz_F.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Optional

import numpy as np
import scipy.linalg

from .assembly import Assembly, HingeForces
from .mechanism import COORDINATE_NAMES, Drive, Fixed, Mechanism, SineRate

#: Default fixed step (s): 10 steps per millisecond.
DEFAULT_STEP = 1e-4


class SolverError(RuntimeError):
    """The solver could not produce a finite answer (names the cause)."""


@dataclass
class State:
    """Simulation state. z, v: (x, y, theta) and (vx, vy, omega) per body in the root frame
    (3 n_bodies, body order). u: actuator output (m) along the drive axis; command: the
    actuator's current target (m). Energy bookkeeping since the last reset:
    dissipated (J) by hinge damping and drive_work (J) done by the prescribed coordinates."""

    t: float
    z: np.ndarray
    v: np.ndarray
    u: float = 0.0
    command: float = 0.0
    dissipated: float = 0.0
    drive_work: float = 0.0

    def copy(self) -> "State":
        return replace(self, z=self.z.copy(), v=self.v.copy())


@dataclass(frozen=True)
class Snapshot:
    """What the simulation reports at one instant (SI units throughout).

    poses (n_bodies, 3): x, y (m), theta (rad) in the root frame; velocities likewise.
    deflections (n_hinges, 3): (alpha, p_x, p_y) of frame b relative to frame a, in frame a
    (rotation, axial, shear for the stage's unrotated hinge frames).
    wrenches (n_hinges, 3): (moment, fx, fy), the wrench each hinge exerts on its body B,
    in frame b, moment about b's origin.
    drive_force: force the actuator applies to the driven body along the drive axis (N).
    output: output body's displacement along the output axis from rest (m) or None.
    compression: displacement of the compression hinge's frame on body B minus that on
    body A, along the drive axis (m), or None.
    """

    t: float
    poses: np.ndarray
    velocities: np.ndarray
    deflections: np.ndarray
    wrenches: np.ndarray
    drive_input: float
    drive_command: float
    drive_force: float
    output: Optional[float]
    compression: Optional[float]
    kinetic_energy: float
    potential_energy: float
    dissipated: float
    drive_work: float


@dataclass(frozen=True)
class StaticResult:
    """Static equilibrium: the snapshot at rest, and Newton's iteration count and residual."""

    snapshot: Snapshot
    iterations: int
    residual: float
    z: np.ndarray


@dataclass
class StepStats:
    """Counters of the stepping work, for diagnostics and benchmarks."""

    steps: int = 0
    linearizations: int = 0


@dataclass
class _Partition:
    free: np.ndarray
    prescribed: np.ndarray
    # Per prescribed coordinate: d z_P / d u (drive axis component).
    du: np.ndarray
    # Sine-rate constraints: (index into prescribed, constraint).
    timed: list = field(default_factory=list)


class Simulation:
    """A mechanism, its state, and the stepping / static solvers.

    ``dt``: fixed step (s). ``relinearize_tol``: the Jacobian is recomputed when the
    configuration has moved by more than this (rad for angles, and metres / ``length_scale``
    for positions) since the last linearization; 0 recomputes it every step.
    """

    def __init__(self, mechanism: Mechanism, dt: float = DEFAULT_STEP, relinearize_tol: float = 0.0):
        if not (dt > 0 and np.isfinite(dt)):
            raise ValueError(f"dt must be a positive number of seconds, got {dt!r}")
        self.mechanism = mechanism
        self.assembly = Assembly(mechanism)
        self.dt = float(dt)
        self.relinearize_tol = float(relinearize_tol)
        self.drive: Optional[Drive] = mechanism.drive
        nb = len(mechanism.bodies)
        self.mass = np.repeat([[b.mass, b.mass, b.inertia] for b in mechanism.bodies], 1, axis=0).ravel()
        self.z0 = np.array([b.pose for b in mechanism.bodies], dtype=float).ravel()
        self.part = self._partition(mechanism, nb)
        self.length_scale = max(1e-3, float(np.ptp(self.z0.reshape(nb, 3)[:, :2]))) if nb > 1 else 1.0
        self.stats = StepStats()
        self._lin: Optional[tuple[np.ndarray, np.ndarray]] = None  # (z at linearization, h phi_1)
        self.state = self.initial_state()

    # --------------------------------------------------------------- structure
    def _partition(self, mech: Mechanism, nb: int) -> _Partition:
        prescribed: dict[int, float] = {}
        timed = []
        for c in mech.constraints:
            i = mech.body_index(c.body)
            if isinstance(c, Fixed):
                for k in range(3):
                    prescribed[3 * i + k] = 0.0
            elif isinstance(c, Drive):
                prescribed[3 * i] = c.axis[0]
                prescribed[3 * i + 1] = c.axis[1]
                prescribed[3 * i + 2] = 0.0
            elif isinstance(c, SineRate):
                prescribed[3 * i + COORDINATE_NAMES.index(c.coordinate)] = 0.0
                timed.append((3 * i + COORDINATE_NAMES.index(c.coordinate), c))
        P = np.array(sorted(prescribed), dtype=int)
        F = np.array([k for k in range(3 * nb) if k not in prescribed], dtype=int)
        pos = {k: j for j, k in enumerate(P)}
        return _Partition(F, P, np.array([prescribed[k] for k in P]), [(pos[k], c) for k, c in timed])

    def initial_state(self) -> State:
        """All bodies at their unstressed poses, at rest, actuator at zero, t = 0."""
        return State(0.0, self.z0.copy(), np.zeros_like(self.z0))

    def reset(self) -> None:
        """Back to the initial state; statistics restart."""
        self.state = self.initial_state()
        self.stats = StepStats()
        self._lin = None

    # ------------------------------------------------------- prescribed motion
    def _prescribed(self, t: float, u: float, command: float):
        """z_P, v_P, a_P and their explicit time derivatives (dz_P/dt, dv_P/dt at fixed u)."""
        part = self.part
        tau = self.drive.response_time if self.drive else 1.0
        udot = (command - u) / tau
        uddot = -udot / tau
        zP = self.z0[part.prescribed] + part.du * u
        vP = part.du * udot
        aP = part.du * uddot
        zt = np.zeros_like(zP)
        vt = np.zeros_like(zP)
        for j, c in part.timed:
            off, rate, acc = c.offset(t)
            zP[j] += off
            vP[j] = rate
            aP[j] = acc
            zt[j] = rate
            vt[j] = acc
        return zP, vP, aP, zt, vt

    def _full(self, zF, vF, t, u, command):
        part = self.part
        zP, vP, aP, zt, vt = self._prescribed(t, u, command)
        z = np.empty(len(self.z0))
        v = np.empty(len(self.z0))
        z[part.free], z[part.prescribed] = zF, zP
        v[part.free], v[part.prescribed] = vF, vP
        return z, v, aP, zt, vt

    # ------------------------------------------------------------- dynamics
    def _rhs(self, y, t, command, jacobian):
        part = self.part
        nF = len(part.free)
        zF, vF = y[:nF], y[nF:2 * nF]
        u = y[2 * nF] if self.drive else 0.0
        z, v, aP, zt, vt = self._full(zF, vF, t, u, command)
        hf = self.assembly.forces(z, v, jacobian=jacobian)
        mF = self.mass[part.free]
        F = np.empty_like(y)
        F[:nF] = vF
        F[nF:2 * nF] = hf.Q[part.free] / mF
        tau = self.drive.response_time if self.drive else 1.0
        if self.drive:
            F[2 * nF] = (command - u) / tau
        A = Ft = None
        if jacobian:
            m = len(y)
            A = np.zeros((m, m))
            A[:nF, nF:2 * nF] = np.eye(nF)
            Kzz, Kvv = hf.dQ_dz, hf.dQ_dv
            FF = np.ix_(part.free, part.free)
            FP = np.ix_(part.free, part.prescribed)
            A[nF:2 * nF, :nF] = Kzz[FF] / mF[:, None]
            A[nF:2 * nF, nF:2 * nF] = Kvv[FF] / mF[:, None]
            if self.drive:
                A[nF:2 * nF, 2 * nF] = (Kzz[FP] @ part.du - Kvv[FP] @ part.du / tau) / mF
                A[2 * nF, 2 * nF] = -1.0 / tau
            Ft = np.zeros(m)
            Ft[nF:2 * nF] = (Kzz[FP] @ zt + Kvv[FP] @ vt) / mF
        return F, A, Ft, hf, z, v, aP

    def _pack(self, state: State) -> np.ndarray:
        part = self.part
        parts = [state.z[part.free], state.v[part.free]]
        if self.drive:
            parts.append([state.u])
        return np.concatenate(parts)

    def _drive_power(self, hf: HingeForces, v: np.ndarray, aP: np.ndarray) -> tuple[float, np.ndarray]:
        """Constraint forces lambda_P = M_P a_P - Q_P and their power on the prescribed motion."""
        P = self.part.prescribed
        lam = self.mass[P] * aP - hf.Q[P]
        return float(lam @ v[P]), lam

    def _phi_vector(self, A: np.ndarray, Ft: np.ndarray, F0: np.ndarray) -> np.ndarray:
        """h phi_1(hA) F0 + h^2 phi_2(hA) Ft from one exponential of an (m+2) matrix."""
        m = len(F0)
        aug = np.zeros((m + 2, m + 2))
        aug[:m, :m] = A
        aug[:m, m] = Ft
        aug[:m, m + 1] = F0
        aug[m, m + 1] = 1.0
        return scipy.linalg.expm(self.dt * aug)[:m, m + 1]

    def _phi_matrix(self, A: np.ndarray) -> np.ndarray:
        """h phi_1(hA) as a matrix, for reuse over several steps."""
        m = A.shape[0]
        aug = np.zeros((2 * m, 2 * m))
        aug[:m, :m] = A
        aug[:m, m:] = np.eye(m)
        return scipy.linalg.expm(self.dt * aug)[:m, m:]

    def _needs_linearization(self, s: State) -> bool:
        if self._lin is None or self.relinearize_tol <= 0 or self.part.timed:
            return True
        moved = np.abs(s.z - self._lin[0])
        moved[0::3] /= self.length_scale
        moved[1::3] /= self.length_scale
        return bool(np.max(moved) > self.relinearize_tol)

    def step(self, n: int = 1) -> None:
        """Advance n fixed steps with the actuator command held at state.command."""
        for _ in range(n):
            self._step_once()

    def _step_once(self) -> None:
        s = self.state
        y = self._pack(s)
        if self._needs_linearization(s):
            F0, A, Ft, hf, z, v, aP = self._rhs(y, s.t, s.command, jacobian=True)
            self.stats.linearizations += 1
            if self.relinearize_tol > 0 and not self.part.timed:
                self._lin = (s.z.copy(), self._phi_matrix(A))
                dy = self._lin[1] @ F0
            else:
                dy = self._phi_vector(A, Ft, F0)
        else:
            F0, _, _, hf, z, v, aP = self._rhs(y, s.t, s.command, jacobian=False)
            dy = self._lin[1] @ F0
        y1 = y + dy
        p0, _ = self._drive_power(hf, v, aP)
        d0 = float(hf.dissipation.sum())
        t1 = s.t + self.dt
        nF = len(self.part.free)
        u1 = float(y1[2 * nF]) if self.drive else 0.0
        z1, v1, aP1, _, _ = self._full(y1[:nF], y1[nF:2 * nF], t1, u1, s.command)
        if not (np.all(np.isfinite(z1)) and np.all(np.isfinite(v1))):
            raise SolverError(f"non-finite state after the step to t = {t1:.6g} s (step {self.dt:g} s)")
        hf1 = self.assembly.forces(z1, v1, jacobian=False)
        p1, _ = self._drive_power(hf1, v1, aP1)
        d1 = float(hf1.dissipation.sum())
        self.state = State(
            t1, z1, v1, u1, s.command,
            s.dissipated + 0.5 * self.dt * (d0 + d1),
            s.drive_work + 0.5 * self.dt * (p0 + p1),
        )
        self.stats.steps += 1

    # -------------------------------------------------------------- command
    def set_command(self, command: float) -> None:
        """Set the actuator target (m along the drive axis); must be finite."""
        if not np.isfinite(command):
            raise ValueError(f"drive command must be finite, got {command!r}")
        if self.drive is None:
            raise ValueError(f"mechanism {self.mechanism.name!r} has no drive")
        self.state.command = float(command)

    # -------------------------------------------------------------- statics
    def static(self, u: float, t: float = 0.0, tol: float = 1e-13, max_iter: int = 50) -> StaticResult:
        """Static equilibrium with the actuator output held at u (and timed constraints at t).

        Newton's method on Q_F(z_F) = 0 with the exact tangent stiffness, from the
        unstressed pose; converged when the update is below tol (relative to the
        mechanism's size).
        """
        if not np.isfinite(u):
            raise ValueError(f"drive input must be finite, got {u!r}")
        part = self.part
        zF = self.z0[part.free].copy()
        vF = np.zeros(len(part.free))
        it = 0
        for it in range(1, max_iter + 1):
            z, v, _, _, _ = self._full(zF, vF, t, u, u)
            hf = self.assembly.forces(z, np.zeros_like(z), jacobian=True)
            K = hf.dQ_dz[np.ix_(part.free, part.free)]
            try:
                dz = np.linalg.solve(K, -hf.Q[part.free])
            except np.linalg.LinAlgError:
                raise SolverError("singular stiffness: a free body is not held by any hinge") from None
            zF = zF + dz
            scaled = dz.copy()
            scaled[np.isin(part.free % 3, (0, 1))] /= self.length_scale
            if np.max(np.abs(scaled)) < tol:
                break
        else:
            raise SolverError(f"static solve did not converge in {max_iter} iterations")
        z, v, _, _, _ = self._full(zF, vF, t, u, u)
        hf = self.assembly.forces(z, np.zeros_like(z))
        residual = float(np.max(np.abs(hf.Q[part.free])))
        state = State(t, z, np.zeros_like(z), u, u)
        return StaticResult(self.snapshot(state), it, residual, z)

    # ------------------------------------------------------------- reporting
    def snapshot(self, state: Optional[State] = None) -> Snapshot:
        """Everything the simulation reports, at ``state`` (default: the current state)."""
        s = state or self.state
        hf = self.assembly.forces(s.z, s.v)
        _, _, aP, _, _ = self._prescribed(s.t, s.u, s.command)
        _, lam = self._drive_power(hf, s.v, aP)
        mech = self.mechanism
        nb = len(mech.bodies)
        drive_force = 0.0
        compression = None
        if self.drive:
            i = mech.body_index(self.drive.body)
            idx = {k: j for j, k in enumerate(self.part.prescribed)}
            drive_force = float(lam[idx[3 * i]] * self.drive.axis[0] + lam[idx[3 * i + 1]] * self.drive.axis[1])
            if mech.compression_hinge is not None:
                compression = self.frame_displacement_difference(mech.compression_hinge, s.z) @ np.array(self.drive.axis)
        output = None
        if mech.output is not None:
            i = mech.body_index(mech.output.body)
            output = float((s.z[3 * i:3 * i + 2] - self.z0[3 * i:3 * i + 2]) @ np.array(mech.output.axis))
        return Snapshot(
            t=s.t,
            poses=s.z.reshape(nb, 3).copy(),
            velocities=s.v.reshape(nb, 3).copy(),
            deflections=hf.r.copy(),
            wrenches=hf.wrench_b.copy(),
            drive_input=s.u,
            drive_command=s.command,
            drive_force=drive_force,
            output=output,
            compression=compression,
            kinetic_energy=float(0.5 * np.sum(self.mass * s.v**2)),
            potential_energy=float(hf.energy.sum()),
            dissipated=s.dissipated,
            drive_work=s.drive_work,
        )

    def frame_displacement_difference(self, hinge_name: str, z: np.ndarray) -> np.ndarray:
        """Displacement from rest of a hinge's frame on body B minus that of its frame on A
        (root frame, m)."""
        h = self.mechanism.hinges[self.mechanism.hinge_index(hinge_name)]
        return self._frame_displacement(h.b, z) - self._frame_displacement(h.a, z)

    def _frame_displacement(self, frame, z: np.ndarray) -> np.ndarray:
        i = self.mechanism.body_index(frame.body)
        c = np.array(frame.position)

        def at(zz):
            th = zz[3 * i + 2]
            cs, sn = np.cos(th), np.sin(th)
            return zz[3 * i:3 * i + 2] + np.array([cs * c[0] - sn * c[1], sn * c[0] + cs * c[1]])

        return at(z) - at(self.z0)
