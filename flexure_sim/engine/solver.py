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
(``Drive``); u is part of the integrated state y = (z_F, v_F, u). Stepping uses the
**exponential trapezoidal rule**: with A an exact Jacobian dF/dy taken at some earlier
state, F0 = F(y_n, t_n) and N(y, t) = F(y, t) - F0 - A (y - y_n),

    y_{n+1} = y_n + h phi_1(hA) F0 + h phi_2(hA) N(y_{n+1}, t_{n+1}),

the variation-of-constants formula with the remainder N interpolated linearly over the
step. The linear part is integrated exactly at any step, so the stage's stiff, heavily
damped hinge modes (eigenvalues near -1e8 1/s) are no constraint on h; the remainder is
solved by fixed-point iteration, which contracts by about |J - A| / |J| per sweep (two
sweeps for the stage), so A can be reused for many steps: it is re-computed only when the
iteration stops contracting (or, optionally, when the configuration moved by more than
``relinearize_tol``). The converged step does not depend on where A was taken; the method
is second order. phi_1 and phi_2 come from one matrix exponential per linearization.

The static equilibrium for a given drive input is Newton's method on Q_F(z) = 0 with the
exact stiffness dQ_F/dz_F.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Optional

import numpy as np
import scipy.linalg

from . import stepping

from .assembly import Assembly
from .hinge_laws import LawBatch
from .kinematics import J, rot
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
    compression: of the compression hinge (``Simulation.hinge_compression``): along the drive
    axis, at its centre of stiffness, its drive side's displacement minus its far side's (m),
    or None.
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


@dataclass(frozen=True)
class StaticSweep:
    """Static answers for a list of drive inputs (m): output displacement (m), compression
    (m; NaN without a compression hinge), drive force (N), and total Newton iterations."""

    inputs: np.ndarray
    outputs: np.ndarray
    compressions: np.ndarray
    drive_forces: np.ndarray
    iterations: int


@dataclass
class StepStats:
    """Counters of the stepping work, for diagnostics and benchmarks."""

    steps: int = 0
    linearizations: int = 0
    iterations: int = 0


@dataclass(frozen=True)
class _Linearization:
    """Where and what: configuration z, Jacobian A, h phi_1(hA), h phi_2(hA), and the drive
    work's rows (g, g^T Psi_1, g^T Psi_2) and scalars (``stepping.step_energy``)."""

    z: np.ndarray
    A: np.ndarray
    phi1: np.ndarray
    phi2: np.ndarray
    erows: np.ndarray
    escal: np.ndarray


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

    ``dt``: fixed step (s). The Jacobian is computed at the first step and again whenever
    the remainder iteration stops contracting; with ``relinearize_tol`` it is also
    recomputed when the configuration has moved by more than that (rad for angles, metres /
    ``length_scale`` for positions) since the last linearization (0: every step).
    The answer does not depend on where the Jacobian was taken, only the iteration count.
    """

    #: The remainder iteration has converged when its last change is below
    #: iteration_rtol |y| + atol in every component (atol: 1e-12 of the mechanism's size in
    #: positions, 1e-12 rad in angles, those per step in rates, 1e-12 of the stroke in u).
    iteration_rtol = 1e-10
    #: Largest number of remainder iterations before re-linearizing within the step.
    max_iterations = 8
    #: A step that needed more iterations than this re-linearizes before the next one.
    relinearize_after = 3

    def __init__(self, mechanism: Mechanism, dt: float = DEFAULT_STEP, relinearize_tol: Optional[float] = None):
        if not (dt > 0 and np.isfinite(dt)):
            raise ValueError(f"dt must be a positive number of seconds, got {dt!r}")
        self.mechanism = mechanism
        self.assembly = Assembly(mechanism)
        self.dt = float(dt)
        if relinearize_tol is not None and not relinearize_tol >= 0:
            raise ValueError(f"relinearize_tol must be None or >= 0, got {relinearize_tol!r}")
        self.relinearize_tol = relinearize_tol
        self.drive: Optional[Drive] = mechanism.drive
        nb = len(mechanism.bodies)
        self.mass = np.repeat([[b.mass, b.mass, b.inertia] for b in mechanism.bodies], 1, axis=0).ravel()
        self.z0 = np.array([b.pose for b in mechanism.bodies], dtype=float).ravel()
        self.part = self._partition(mechanism, nb)
        self._motion = self._motion_arrays()
        self._compression = compression_points(mechanism)
        self.length_scale = max(1e-3, float(np.ptp(self.z0.reshape(nb, 3)[:, :2]))) if nb > 1 else 1.0
        self.stats = StepStats()
        self._lin: Optional[_Linearization] = None
        self._cache: Optional[tuple] = None  # (state, command, F, energy rates)
        self._clock: Optional[tuple] = None  # (state, origin t, steps since origin): see step()
        self._mass_free = self.mass[self.part.free]
        self.state = self.initial_state()
        self._atol = self._iteration_atol()
        self._args = self._kernel_args() if self.assembly.compiled else None

    def _motion_arrays(self) -> tuple:
        """Arguments of stepping.prescribed_motion after (t, u, command)."""
        part = self.part
        sines = [c for _, c in part.timed]
        return (
            self.drive.response_time if self.drive else 1.0,
            self.drive is not None,
            self.z0[part.prescribed].copy(),
            part.du.astype(float),
            np.array([j for j, _ in part.timed], dtype=np.int64),
            np.array([c.amplitude for c in sines], dtype=float),
            np.array([2.0 * np.pi * c.frequency for c in sines], dtype=float),
            np.array([c.phase for c in sines], dtype=float),
        )

    def _iteration_atol(self) -> np.ndarray:
        free = self.part.free
        per_coord = np.where(free % 3 == 2, 1e-12, 1e-12 * self.length_scale)
        parts = [per_coord, per_coord / self.dt]
        if self.drive:
            parts.append([1e-12 * (self.drive.stroke[1] - self.drive.stroke[0])])
        return np.concatenate(parts)

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
        self._cache = None
        self._clock = None

    # ------------------------------------------------------- prescribed motion
    def _prescribed(self, t: float, u: float, command: float):
        """z_P, v_P, a_P: prescribed coordinates, their rates and accelerations."""
        return stepping.prescribed_motion(t, u, command, *self._motion)

    def _full(self, zF, vF, t, u, command):
        part = self.part
        zP, vP, aP = self._prescribed(t, u, command)
        z = np.empty(len(self.z0))
        v = np.empty(len(self.z0))
        z[part.free], z[part.prescribed] = zF, zP
        v[part.free], v[part.prescribed] = vF, vP
        return z, v, aP

    # ------------------------------------------------------------- dynamics
    def _jacobian(self, y: np.ndarray, t: float, command: float, load_gradient: bool = False):
        """Exact A = dF/dy for y = (z_F, v_F, u): rows dz_F/dt = v_F, M_F dv_F/dt = Q_F(z, v),
        du/dt = (command - u)/tau, with z_P, v_P depending on u through the drive axis.
        With ``load_gradient`` also g = dq/dy of the drive load q = du^T Q_P: (A, g)."""
        part = self.part
        nF = len(part.free)
        u = y[2 * nF] if self.drive else 0.0
        z, v, _ = self._full(y[:nF], y[nF:2 * nF], t, u, command)
        hf = self.assembly.forces(z, v, jacobian=True)
        mF = self._mass_free
        m = len(y)
        A = np.zeros((m, m))
        A[:nF, nF:2 * nF] = np.eye(nF)
        Kzz, Kvv = hf.dQ_dz, hf.dQ_dv
        FF = np.ix_(part.free, part.free)
        A[nF:2 * nF, :nF] = Kzz[FF] / mF[:, None]
        A[nF:2 * nF, nF:2 * nF] = Kvv[FF] / mF[:, None]
        if self.drive:
            tau = self.drive.response_time
            FP = np.ix_(part.free, part.prescribed)
            A[nF:2 * nF, 2 * nF] = (Kzz[FP] @ part.du - Kvv[FP] @ part.du / tau) / mF
            A[2 * nF, 2 * nF] = -1.0 / tau
        if not load_gradient:
            return A
        g = np.zeros(m)
        if self.drive:
            PF, PP = np.ix_(part.prescribed, part.free), np.ix_(part.prescribed, part.prescribed)
            g[:nF] = part.du @ Kzz[PF]
            g[nF:2 * nF] = part.du @ Kvv[PF]
            g[2 * nF] = part.du @ (Kzz[PP] @ part.du - Kvv[PP] @ part.du / self.drive.response_time)
        return A, g

    def _pack(self, state: State) -> np.ndarray:
        part = self.part
        parts = [state.z[part.free], state.v[part.free]]
        if self.drive:
            parts.append([state.u])
        return np.concatenate(parts)

    def _linearize(self, y: np.ndarray, t: float, command: float) -> None:
        """Exact Jacobian A at y and the matrices h phi_1(hA), h phi_2(hA) of the step.

        Both come from one exponential of the block matrix [[hA, I, 0], [0, 0, I], [0, 0, 0]]
        (its first block row is [e^{hA}, h phi_1(hA), h^2 phi_2(hA)] up to the powers of h).
        With a drive, also the rows of its exact work (``stepping.step_energy``): g = dq/dy
        of the drive load q = du^T Q_P and h phi_1(h (A - I/tau)) from one more exponential.
        """
        A, g = self._jacobian(y, t, command, load_gradient=True)
        m, h = A.shape[0], self.dt
        aug = np.zeros((3 * m, 3 * m))
        aug[:m, :m] = h * A
        aug[:m, m:2 * m] = np.eye(m)
        aug[m:2 * m, 2 * m:] = np.eye(m)
        E = scipy.linalg.expm(aug)
        phi1, phi2 = h * E[:m, m:2 * m], h * E[:m, 2 * m:]
        erows = np.zeros((3, m))
        escal = np.zeros(6)
        escal[stepping.E_BALANCE] = float(not self.part.timed)
        if self.drive:
            tau = self.drive.response_time
            shifted = np.zeros((2 * m, 2 * m))
            shifted[:m, :m] = h * A - (h / tau) * np.eye(m)
            shifted[:m, m:] = np.eye(m)
            shifted_phi1 = h * scipy.linalg.expm(shifted)[:m, m:]
            psi1, psi2 = stepping.weighted_phi(A, phi1, phi2, h, tau, shifted_phi1)
            erows[0], erows[1], erows[2] = g, g @ psi1, g @ psi2
            du = self.part.du
            escal[stepping.E_PSI0] = tau * -np.expm1(-h / tau)
            escal[stepping.E_DECAY] = np.exp(-h / tau)
            escal[stepping.E_DRIVE_MASS] = float(du @ (self.mass[self.part.prescribed] * du))
            escal[stepping.E_TAU] = tau
            escal[stepping.E_HAS_DRIVE] = 1.0
        self._lin = _Linearization(self._z_of(y, t, command), A, phi1, phi2, erows, escal)
        self.stats.linearizations += 1

    def _moved_too_far(self, z: np.ndarray) -> bool:
        tol = self.relinearize_tol
        if tol is None:
            return False
        moved = np.abs(z - self._lin.z)
        moved[0::3] /= self.length_scale
        moved[1::3] /= self.length_scale
        return bool(np.max(moved) > tol)

    def _rhs_python(self, y: np.ndarray, t: float, command: float, _args=None):
        """F(y, t) and the energy rates (``stepping.energy_rates``) through Assembly (any law)."""
        part = self.part
        nF = len(part.free)
        u = y[2 * nF] if self.drive else 0.0
        z, v, aP = self._full(y[:nF], y[nF:2 * nF], t, u, command)
        Q, potential, dissipation = self.assembly.generalized_forces(z, v)
        F = np.empty_like(y)
        F[:nF] = y[nF:2 * nF]
        F[nF:2 * nF] = Q[part.free] / self._mass_free
        if self.drive:
            F[2 * nF] = (command - u) / self.drive.response_time
        sine_index = self._motion[4]
        return F, stepping.energy_rates(Q, v, potential, dissipation, part.prescribed, self.mass, part.du.astype(float),
                                        sine_index, aP)

    def _kernel_args(self) -> tuple:
        a = self.assembly
        part = self.part
        tau, has_drive, zP0, du, sine_index, sine_amp, sine_w, sine_phase = self._motion
        return (part.free.astype(np.int64), part.prescribed.astype(np.int64), self.mass, zP0, du, tau, has_drive,
                sine_index, sine_amp, sine_w, sine_phase, a._ia, a._ib, a._ca, a._cb, a.phia, a.phib, a._kind,
                a._W, a._C)

    def _rhs(self, y: np.ndarray, t: float, command: float):
        if self.assembly.compiled:
            return stepping.kernel_rhs(y, t, command, self._args)
        return self._rhs_python(y, t, command)

    def _advance(self, n, y, t, command, F0, aux0):
        lin = self._lin
        common = (n, y, t, self.dt, command, lin.A, lin.phi1, lin.phi2, self.iteration_rtol, self._atol,
                  self.max_iterations, self.relinearize_after, F0, aux0, lin.erows, lin.escal)
        if self.assembly.compiled:
            return stepping.advance(*common, self._args)
        return stepping.advance_interpreted(*common, self)

    def step(self, n: int = 1) -> None:
        """Advance n fixed steps of the exponential trapezoidal rule (module docstring) with
        the actuator command held at state.command.

        Time is origin + k dt, k the steps taken since the origin (the t of a state this
        simulation did not step itself), not a running sum: t stays on the step grid however
        long the run, so stamps derived from it stay on the tick grid."""
        s = self.state
        command = s.command
        clock = self._clock
        if clock is None or clock[0] is not s:
            clock = (s, s.t, 0)
        _, origin, k = clock
        dt = self.dt
        y, t = self._pack(s), s.t
        cache = self._cache
        if cache is not None and cache[0] is s and cache[1] == command:
            F0, aux0 = cache[2:4]
        else:
            F0, aux0 = self._rhs(y, t, command)
        dissipated, work = s.dissipated, s.drive_work + self._jump_work(s, command)
        remaining = int(n)
        fresh = False
        while remaining > 0:
            if self._lin is None or (self.relinearize_tol is not None and self._moved_too_far(self._z_of(y, t, command))):
                self._linearize(y, t, command)
                fresh = True
            chunk = 1 if self.relinearize_tol is not None else remaining
            y, F0, aux0, dd, dw, steps, iterations, status = self._advance(chunk, y, t, command, F0, aux0)
            dissipated += dd
            work += dw
            remaining -= steps
            k += steps
            t = origin + k * dt
            self.stats.steps += steps
            self.stats.iterations += iterations
            if status == stepping.NOT_CONTRACTING:
                if steps == 0 and fresh:
                    raise SolverError(
                        f"step to t = {t + dt:.6g} s did not converge even with a fresh Jacobian; "
                        f"reduce the step ({dt:g} s)")
                self._lin = None
            elif status == stepping.SLOW:
                self._lin = None
            if steps:
                fresh = False
        if not np.all(np.isfinite(y)):
            raise SolverError(f"non-finite state at t = {t:.6g} s (step {dt:g} s)")
        nF = len(self.part.free)
        u = float(y[2 * nF]) if self.drive else 0.0
        z, v, _ = self._full(y[:nF], y[nF:2 * nF], t, u, command)
        self.state = State(t, z, v, u, command, dissipated, work)
        self._clock = (self.state, origin, k)
        # F at the new state seeds the next call while the command is unchanged.
        self._cache = (self.state, command, F0, aux0)

    def _jump_work(self, s: State, command: float) -> float:
        """Work of the drive's velocity jump when the command changes: the prescribed
        velocities jump from those of ``s`` to those of the new command, which takes the
        kinetic energy 1/2 M_P (v_P+^2 - v_P-^2) from the actuator (an impulse M_P dv_P
        acting at the mean velocity)."""
        P = self.part.prescribed
        vP = self._prescribed(s.t, s.u, command)[1]
        return float(0.5 * self.mass[P] @ (vP * vP - s.v[P] * s.v[P]))

    def _z_of(self, y, t, command):
        nF = len(self.part.free)
        return self._full(y[:nF], y[nF:2 * nF], t, y[2 * nF] if self.drive else 0.0, command)[0]

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

        Newton's method on Q_F(z_F) = 0 from the unstressed pose with the exact tangent
        stiffness dQ_F/dz_F (see ``_newton``); converged when the update is below tol
        (relative to the mechanism's size). Without free coordinates (every body fixed or
        driven) the prescribed pose is the equilibrium: 0 iterations, forces as reported.
        """
        zF, iterations = self._newton(u, t, self.z0[self.part.free].copy(), None, tol, max_iter)[:2]
        z = self._z_static(zF, t, u)
        Q = self.assembly.generalized_forces(z, np.zeros_like(z))[0]
        residual = float(np.max(np.abs(Q[self.part.free]), initial=0.0))
        state = State(t, z, np.zeros_like(z), u, u)
        return StaticResult(self.snapshot(state), iterations, residual, z)

    def static_sweep(self, inputs, t: float = 0.0, tol: float = 1e-13) -> StaticSweep:
        """Static equilibria for many drive inputs, each started from the previous one and
        reusing the factorised stiffness while Newton keeps contracting fast."""
        inputs = np.asarray(inputs, dtype=float)
        if not np.all(np.isfinite(inputs)):
            raise ValueError("drive inputs must be finite")
        out = np.full(len(inputs), np.nan)
        comp = np.full(len(inputs), np.nan)
        force = np.zeros(len(inputs))
        zF = self.z0[self.part.free].copy()
        lu = None
        total = 0
        mech = self.mechanism
        P = self.part.prescribed
        for k, u in enumerate(inputs):
            zF, iterations, lu = self._newton(float(u), t, zF, lu, tol, 50)
            total += iterations
            z = self._z_static(zF, t, float(u))
            if mech.output is not None:
                i = mech.body_index(mech.output.body)
                out[k] = (z[3 * i:3 * i + 2] - self.z0[3 * i:3 * i + 2]) @ np.array(mech.output.axis)
            if self._compression is not None:
                comp[k] = self.hinge_compression(z)
            if self.drive is not None:
                lam = -self.assembly.generalized_forces(z, np.zeros_like(z))[0][P]
                force[k] = lam @ self.part.du
        return StaticSweep(inputs, out, comp, force, total)

    def _z_static(self, zF: np.ndarray, t: float, u: float) -> np.ndarray:
        return self._full(zF, np.zeros(len(zF)), t, u, u)[0]

    def _newton(self, u, t, zF, lu, tol, max_iter):
        """Newton on Q_F(z_F) = 0 with the exact stiffness. A factorisation from a nearby
        solution (``lu``) is reused while its updates shrink at least tenfold; an update that
        does not is discarded and the stiffness re-factorised at the current point, so the
        iteration is never worse than Newton's. Returns (z_F, iterations, factorisation)."""
        if not np.isfinite(u):
            raise ValueError(f"drive input must be finite, got {u!r}")
        free = self.part.free
        if len(free) == 0:
            return zF, 0, None  # every coordinate prescribed: the equilibrium is the prescription
        lengths = np.where(np.isin(free % 3, (0, 1)), self.length_scale, 1.0)
        previous = np.inf
        for it in range(1, max_iter + 1):
            z = self._z_static(zF, t, u)
            if lu is None:
                hf = self.assembly.forces(z, np.zeros_like(z), jacobian=True)
                K = hf.dQ_dz[np.ix_(free, free)]
                if not np.all(np.isfinite(K)):
                    raise SolverError("non-finite stiffness in the static solve")
                lu = scipy.linalg.lu_factor(K, check_finite=False)
                if np.any(np.diag(lu[0]) == 0.0):
                    raise SolverError("singular stiffness: a free body is not held by any hinge")
                Q = hf.Q[free]
                fresh = True
            else:
                Q = self.assembly.generalized_forces(z, np.zeros_like(z))[0][free]
                fresh = False
            dz = scipy.linalg.lu_solve(lu, -Q)
            size = float(np.max(np.abs(dz / lengths)))
            if not fresh and size > 0.1 * previous:
                lu = None  # a stale factorisation that no longer contracts fast: refresh here
                continue
            zF = zF + dz
            if size < tol:
                return zF, it, lu
            previous = size
        raise SolverError(f"static solve did not converge in {max_iter} iterations")

    # ------------------------------------------------------------- reporting
    def snapshot(self, state: Optional[State] = None) -> Snapshot:
        """Everything the simulation reports, at ``state`` (default: the current state)."""
        s = state or self.state
        Q, deflections, wrenches, energy, _ = self.assembly.report(s.z, s.v)
        _, _, aP = self._prescribed(s.t, s.u, s.command)
        lam = self.mass[self.part.prescribed] * aP - Q[self.part.prescribed]  # constraint forces
        mech = self.mechanism
        nb = len(mech.bodies)
        drive_force = 0.0
        if self.drive:
            drive_force = float(lam @ self.part.du)  # along the drive axis
        output = None
        if mech.output is not None:
            i = mech.body_index(mech.output.body)
            output = float((s.z[3 * i:3 * i + 2] - self.z0[3 * i:3 * i + 2]) @ np.array(mech.output.axis))
        return Snapshot(
            t=s.t,
            poses=s.z.reshape(nb, 3).copy(),
            velocities=s.v.reshape(nb, 3).copy(),
            deflections=deflections,
            wrenches=wrenches,
            drive_input=s.u,
            drive_command=s.command,
            drive_force=drive_force,
            output=output,
            compression=self.hinge_compression(s.z),
            kinetic_energy=float(0.5 * np.sum(self.mass * s.v**2)),
            potential_energy=energy,
            dissipated=s.dissipated,
            drive_work=s.drive_work,
        )

    def hinge_compression(self, z: np.ndarray) -> Optional[float]:
        """Compression of the mechanism's compression hinge at coordinates z (m), or None.

        Measured at the hinge's centre of stiffness (``compression_points``), along the
        drive axis: the displacement from rest of the centre as carried by the hinge's
        drive side minus as carried by its other side. Positive when the hinge takes up
        drive motion (its far side advances less than its drive side). It does not depend
        on which body is called A, nor on where the hinge frames are put.
        """
        if self._compression is None:
            return None
        (i_drive, c_drive), (i_far, c_far), axis = self._compression
        return float((_point_displacement(i_drive, c_drive, z, self.z0)
                      - _point_displacement(i_far, c_far, z, self.z0)) @ axis)


def _point_displacement(i: int, c: np.ndarray, z: np.ndarray, z0: np.ndarray) -> np.ndarray:
    """Displacement from rest (root frame) of the point at c (body coordinates) on body i."""
    def at(zz):
        th = zz[3 * i + 2]
        cs, sn = np.cos(th), np.sin(th)
        return zz[3 * i:3 * i + 2] + np.array([cs * c[0] - sn * c[1], sn * c[0] + cs * c[1]])

    return at(z) - at(z0)


def stiffness_centre(K: np.ndarray) -> np.ndarray:
    """Centre of stiffness of a hinge in its frame's coordinates: the point where the
    stiffness at rest K = [[Ko, Kc^T], [Kc, Kt]] (moment first) decouples. Moving the frame
    by p turns the coupling into Kc + Kt (-J p) (``kinematics.transform_stiffness``), which
    vanishes at p = -J Kt^-1 Kc."""
    K = np.asarray(K, dtype=float)
    return -J @ np.linalg.solve(K[1:, 1:], K[1:, 0])


def compression_points(mech: Mechanism):
    """((drive body, centre in its coordinates), (far body, centre), drive axis) for the
    mechanism's compression hinge, or None.

    The drive side is the hinge's body fewer hinges away from the driven body; when both
    are equally far, the one whose rest centre lies further back along the drive axis.
    The centre of stiffness comes from the law's Hessian at rest (any law).
    """
    drive = mech.drive
    if mech.compression_hinge is None or drive is None:
        return None
    h = mech.hinges[mech.hinge_index(mech.compression_hinge)]
    law = LawBatch([h.law]).evaluate(np.zeros(1), np.zeros((1, 2)), np.zeros((1, 3)))
    centre = stiffness_centre(law.hess[0])
    axis = np.array(drive.axis, dtype=float)
    hops = _hinge_distance(mech, mech.body_index(drive.body))
    sides = []
    for frame in (h.a, h.b):
        i = mech.body_index(frame.body)
        local = np.array(frame.position) + rot(frame.angle) @ centre
        back = float(np.array(mech.bodies[i].pose[:2]) @ axis)
        sides.append(((hops[i], back), (i, local)))
    sides.sort(key=lambda side: side[0])
    return sides[0][1], sides[1][1], axis


def _hinge_distance(mech: Mechanism, start: int) -> list:
    """Number of hinges between each body and body ``start`` (inf where unconnected)."""
    dist = [np.inf] * len(mech.bodies)
    dist[start] = 0
    frontier = [start]
    while frontier:
        nxt = []
        for h in mech.hinges:
            ia, ib = mech.body_index(h.a.body), mech.body_index(h.b.body)
            for i, j in ((ia, ib), (ib, ia)):
                if i in frontier and dist[j] == np.inf:
                    dist[j] = dist[i] + 1
                    nxt.append(j)
        frontier = nxt
    return dist
