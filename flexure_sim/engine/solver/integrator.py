"""
Fixed-step stiff-stable stepping of a ``Model``, updating a ``Data``.

Stepping uses the **exponential trapezoidal rule**: with A an exact Jacobian dF/dy taken
at some earlier state, F0 = F(y_n, t_n) and N(y, t) = F(y, t) - F0 - A (y - y_n),

    y_{n+1} = y_n + h phi_1(hA) F0 + h phi_2(hA) N(y_{n+1}, t_{n+1}),

the variation-of-constants formula with the remainder N interpolated linearly over the
step. The linear part is integrated exactly at any step, so the stage's stiff, heavily
damped hinge modes (eigenvalues near -1e8 1/s) are no constraint on h; the remainder is
solved by fixed-point iteration, which contracts by about |J - A| / |J| per sweep (two
sweeps for the stage), so A can be reused for many steps: it is re-computed only when the
iteration stops contracting (or, optionally, when the configuration moved by more than
``relinearize_tol``). The converged step does not depend on where A was taken; the method
is second order. phi_1 and phi_2 come from one matrix exponential per linearization. The
dissipated energy and the drive work are integrated as exactly as the motion, each on its
own (``step_energy``).
"""
from __future__ import annotations

import math
from typing import Any, Callable, NamedTuple

import numpy as np
import scipy.linalg

from flexure_sim.engine.solver import kernel_pack, step_energy, step_loop as stepping
from flexure_sim.engine.solver.state import Data, Linearization, State
from flexure_sim.engine.solver.model import Model, SolverError

#: Steps per call when the drives follow programs (bounds the per-step command rows' memory).
BLOCK = 4096


def linearize(model: Model, data: Data, y: np.ndarray, t: float, command) -> None:
    """
    Exact Jacobian A at y and the matrices h phi_1(hA), h phi_2(hA) of the step, into ``data.lin``.

    Both come from one exponential of the block matrix [[hA, I, 0], [0, 0, I], [0, 0, 0]]
    (its first block row is [e^{hA}, h phi_1(hA), h^2 phi_2(hA)] up to the powers of h).
    Also the matrices of the step's energy integrals (``step_energy.energy_matrices``): the
    damping matrix C = -dQ/dv, and per displacement drive g = dq/dy of its load
    q = D_d^T Q_P and h phi_1(h (A - I/tau)) = (A - I/tau)^-1 (e^{-h/tau} e^{hA} - I), one
    linear solve with the e^{hA} already at hand (A - I/tau is regular: A's eigenvalues have
    no positive real part for a damped mechanism; an exponential is the fallback).
    """
    tangent = model.tangent(y, t, command) if model.energy else None
    A = model.jacobian(y, t, command) if tangent is None else tangent.A
    m, h = A.shape[0], model.dt
    expA, phi1, phi2 = phi_matrices(A, h)
    if model.energy:
        part = model.part
        tau, D = model.motion[0], model.motion[2]
        shifted = [_shifted_phi1(A, expA, h, tk) for tk in tau]
        drive_mass = [float(dk @ (model.mass[part.prescribed] * dk))
                      for dk in model.drives.lag_rows]
        # The timed coordinates: sine rates, then those the prescribed drives' programs move
        # (their velocity is entry AUX_LOAD + n_lags + i of the energy rates).
        first = step_energy.AUX_LOAD + len(tau)
        sines = np.array([[j, c.amplitude, 2.0 * np.pi * c.frequency, c.phase, -1.0]
                          for j, c in part.timed]
                         + [[j, 0.0, 0.0, 0.0, first + i]
                            for i, j in enumerate(model.program_index)],
                         dtype=float).reshape(-1, 5).T
        timed = [j for j, _ in part.timed] + list(model.program_index)
        # How the program coordinates' displacement and velocity force dv_F/dt.
        nF, pc = len(part.free), model.program_index
        forcing = np.zeros((m, 2 * len(pc)))
        assert tangent is not None, "model.energy: taken above"
        dz, dv = tangent.free_by_prescribed
        forcing[nF:2 * nF, :len(pc)] = dz[:, pc] / model.mass_free[:, None]
        forcing[nF:2 * nF, len(pc):] = dv[:, pc] / model.mass_free[:, None]
        emats = step_energy.energy_matrices(
            A, phi1, phi2, h, tangent.G, tangent.damping, part.free, part.prescribed, D,
            drive_mass, tau, shifted, sines, tangent.load_rows[timed], forcing)
    else:
        emats = step_energy.NO_ENERGY
    packed = (kernel_pack.loop_args(A, phi1, phi2, emats, model.kernel_args) if model.compiled
              else None)
    data.lin = Linearization(model.unpack(y, t, command)[0], A, phi1, phi2, emats, packed)
    data.stats.linearizations += 1


def phi_matrices(A: np.ndarray, h: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """
    Return e^{hA}, h phi_1(hA) and h phi_2(hA) from one exponential (``linearize``).

    The exponential of [[hA, I, 0], [0, 0, I], [0, 0, 0]] has the first block row
    [e^{hA}, phi_1(hA), phi_2(hA)].
    """
    m = A.shape[0]
    aug = np.zeros((3 * m, 3 * m))
    aug[:m, :m] = h * A
    aug[:m, m:2 * m] = np.eye(m)
    aug[m:2 * m, 2 * m:] = np.eye(m)
    E = scipy.linalg.expm(aug)
    return E[:m, :m], h * E[:m, m:2 * m], h * E[:m, 2 * m:]


def _shifted_phi1(A: np.ndarray, expA: np.ndarray, h: float, tau: float) -> np.ndarray:
    """Return h phi_1(h (A - I/tau)) from e^{hA} by one solve (see ``linearize``)."""
    m = A.shape[0]
    shifted = A - np.eye(m) / tau
    try:
        out = np.linalg.solve(shifted, np.exp(-h / tau) * expA - np.eye(m))
        if np.all(np.isfinite(out)):
            return out
    except np.linalg.LinAlgError:
        pass
    aug = np.zeros((2 * m, 2 * m))
    aug[:m, :m], aug[:m, m:] = h * shifted, np.eye(m)
    return h * scipy.linalg.expm(aug)[:m, m:]


def moved_too_far(model: Any, data: Data, z: np.ndarray, per_body: int = 3,
                  translations: int = 2) -> bool:
    """
    Whether z is further than ``relinearize_tol`` from the linearization's z.

    Translations (the first ``translations`` of each body's ``per_body`` coordinates: the
    planar x, y; the spatial x, y, z) count relative to ``model.length_scale``, rotations in rad.
    """
    tol = model.relinearize_tol
    if tol is None:
        return False
    if data.lin is None:  # none yet: one is due
        return True
    moved = np.abs(z - data.lin.z).reshape(-1, per_body)
    moved[:, :translations] /= model.length_scale
    return bool(np.max(moved) > tol)


def _advance(model: Model, data: Data, n, y, t, rows, held, F0, aux0, ye, origin, k):
    """Run the stepping loop's up to n steps from (y, t = origin + k dt) (``stepping.advance``)."""
    lin = data.lin
    assert lin is not None  # step() linearizes before it advances
    if model.compiled:  # the fixed arrays as one structure (``kernel_pack``)
        return stepping.advance_packed(
            n, y, t, model.dt, rows, held, model.iteration_rtol, model.atol,
            model.max_iterations, model.relinearize_after, F0, aux0, ye, lin.packed, origin, k)
    return stepping.advance_interpreted(
        n, y, t, model.dt, rows, held, lin.A, lin.phi1, lin.phi2, model.iteration_rtol,
        model.atol, model.max_iterations, model.relinearize_after, F0, aux0, ye, lin.emats,
        model, origin, k)


def warm(model: Model, data: Data) -> None:
    """
    Take the next step under the held command in the stepping loop and discard it.

    Nothing of ``data`` changes. What it leaves is the loop's code and data in the caches of
    the core that runs it: the paced node calls it in the busy-wait before a tick
    (``pacing.Pacer``), where an idle core had let them go cold. A 1 kHz node's engine part at
    rest took 40.5-43.1 us against 42.7-45.4 us without (three interleaved 6 s runs of
    ``tools/bench/measure.py --mode realtime``; the same ten steps in one process, back to
    back: 34.5 us). Only where the next call will run the compiled loop from this state as it
    stands: a linearization at hand (none is taken here), the seed cached, no programs. It
    never raises: a step that fails fails in the call that takes it.
    """
    s, cache, lin, clock = data.state, data.cache, data.lin, data.clock
    if (not model.compiled or lin is None or not cache or cache[0] is not s or cache[8]
            or clock is None or clock[0] is not s):
        return
    command = cache[6]
    try:
        _advance(model, data, 1, cache[5], s.t, command.reshape(1, -1), command, cache[2],
                 cache[3], cache[4], clock[1], clock[2])
    except Exception:  # noqa: BLE001 - see the docstring
        pass


def jump_work(model: Model, s: State, command) -> float:
    """
    Work of the drives' velocity jumps when the commands change (``command``: kernel order).

    The prescribed velocities jump from those of ``s`` to those of the new command, which takes the
    kinetic energy 1/2 M_P (v_P+^2 - v_P-^2) from the actuator (an impulse M_P dv_P acting at the
    mean velocity).
    """
    P = model.part.prescribed
    vP = model.prescribed(s.t, s.u, command)[1]
    return float(0.5 * model.mass[P] @ (vP * vP - s.v[P] * s.v[P]))


def step(model: Model, data: Data, n: int = 1, command=None, rows=None) -> None:
    """
    Advance ``data`` n fixed steps with the drives' commands held at state.command.

    ``command``: the kernel's command vector (``DriveTable.kernel_command``) to hold instead of
    the state's (the piezo actuators' free strokes, engine/solver/actuation.py). ``rows``: one
    such vector per step, shape (n, len(command)), to hold step by step instead (``command``
    then is the one held before the first step; each change is the drives' work,
    ``stepping.switch_work``).

    Without ``command``, the drives with a program (``State.programs``) follow it, one kernel
    command row per step (``DriveTable.kernel_rows``; ``BLOCK`` steps per call at most).

    Time is origin + k dt, k the steps taken since the origin (the t of a state this data
    did not step itself), not a running sum: t stays on the step grid however long the
    run, so stamps derived from it stay on the tick grid.

    A step whose iteration does not converge even with a fresh Jacobian is retried once with the
    Jacobian taken where the lagged drives have settled (their rates zero): after a command step
    a lag far faster than the step gives the prescribed body a huge rate for a tiny part of the
    step, and the damping's derivative at that rate is no model of the rest of the step (the
    answer does not depend on where the Jacobian is taken, only the iteration's convergence).
    """
    s = data.state
    cache: tuple = data.cache or ()
    seeded = bool(cache) and cache[0] is s
    if command is None:
        if s.programs and n > BLOCK:
            for start in range(0, int(n), BLOCK):
                step(model, data, min(BLOCK, int(n) - start))
            return
        if s.programs:
            command = model.drives.kernel_command(s.command, s.programs, s.t - 0.5 * model.dt)
            rows = model.drives.kernel_rows(s, model.dt, n)
            key = command.tobytes()
        else:
            last = data.held_command(s)  # commands held on: the last vector
            command, key = last if last is not None else _kernel_command(model, s)
    else:
        command = np.ascontiguousarray(command, dtype=float)
        key = command.tobytes()
    under = command  # the command the loop's seed F0, aux0 are taken under
    plain = rows is None  # one command held over the n steps (``_retaken``)
    rows = command.reshape(1, -1) if plain else np.ascontiguousarray(rows, dtype=float)
    clock = data.clock
    if clock is None or clock[0] is not s:
        clock = (s, s.t, 0)
    _, origin, k = clock
    dt = model.dt
    t = s.t
    if seeded:
        y = cache[5]  # model.pack(s), bit for bit: s was unpacked from it
        if cache[1] == key:
            F0, aux0, ye = cache[2:5]
        elif plain and n >= 1 and _retaken(model, s, cache[6], command):
            under, F0, aux0, ye = cache[6], cache[2], cache[3], cache[4]
        else:
            F0, aux0 = model.rhs(y, t, command)
            ye = y
    else:
        y = model.pack(s)
        F0, aux0 = model.rhs(y, t, command)
        ye = y
    if model.energy:
        dissipated, work = s.dissipated, s.drive_work + jump_work(model, s, command)
    else:
        dissipated = work = math.nan
    y, t, k, F0, aux0, ye, command, dissipated, work, z, v, finite = march(
        model, data, n, (y, t, origin, k), rows, under, (F0, aux0, ye), (dissipated, work),
        PLANAR)
    if z is None or v is None:  # no step asked for
        finite = bool(np.isfinite(y).all())
        z, v, _ = model.unpack(y, t, command)
    if not finite:
        raise SolverError(f"non-finite state at t = {t:.6g} s (step {dt:g} s)")
    u = y[model.u_slice]  # State copies it
    held = model.drives.held_command(command, s.command, s.programs) if s.programs else s.command
    data.state = State(t, z, v, u, held, dissipated, work, programs=s.programs)
    data.clock = (data.state, origin, k)
    # The command vector also serves the tick report (``tick_report.TickReport.fill_data``).
    data.seed(F0, aux0, ye, y, command)


def _kernel_command(model: Model, s: State) -> tuple:
    """Return (the kernel's command vector of ``s``'s commands, its key)."""
    command = model.drives.kernel_command(s.command)
    return command, command.tobytes()


def _retaken(model: Model, s: State, before: np.ndarray, command: np.ndarray) -> bool:
    """
    Whether the compiled loop may take F under a new ``command`` itself (a closed loop's tick).

    Where the held command changes, the loop evaluates F and the energy rates at the step's
    start under the new one (``step_loop._advance``): the same compiled ``kernel_rhs`` on the
    same y and t as ``model.rhs`` here, one call into compiled code fewer per tick (a call
    unboxes the kernel's ~30 arrays): the stage's closed-loop tick 59.0 -> 57.6 us
    (tools/bench/tick_profile.py ``call_costs``, ``call_moving``; the values compared as
    lists, ~0.1 us, where ``np.any`` cost ~1.9 us and ate the gain). Only for the plain case:
    compiled, no energies (the loop would count the switch's work that ``jump_work`` counts),
    the kernel's command the drives' own (``DriveTable.in_order``: no prescribed drive, so
    the coordinates do not depend on the command) and no programs; and only when the values
    differ (the loop compares values: a command that differs only in the sign of a zero keeps
    the rhs here).
    """
    return (model.compiled and not model.energy and model.drives.in_order and not s.programs
            and command.tolist() != before.tolist())


class Stepper(NamedTuple):
    """What ``march`` calls that depends on the engine: planar (``PLANAR``) or spatial."""

    linearize: Callable
    advance: Callable
    moved_too_far: Callable


def march(model, data: Data, n: int, at: tuple, rows: np.ndarray, command: np.ndarray,
          seed: tuple, energies: tuple, stepper: Stepper) -> tuple:
    """
    Take n steps from y at time t = origin + k dt: the loop of ``step``, for both engines.

    ``at`` = (y, t, origin, k); ``seed`` = (F0, aux0, ye) of the step loop; ``energies`` =
    (dissipated, work) so far. Linearizes when there is no Jacobian (or the configuration moved
    more than ``relinearize_tol``), advances in compiled chunks, takes a fresh Jacobian when
    the remainder iteration stops contracting or contracts slowly, and retries a step that
    does not converge with a fresh one once where the lagged drives have settled (``step``).
    Return (y, t, k, F0, aux0, ye, command, dissipated, work, z, v, finite): z, v and finite
    as the last chunk's loop returned them for y (``step_loop._advance``; None when no step
    was asked for).
    """
    y, t, origin, k = at
    F0, aux0, ye = seed
    dissipated, work = energies
    dt = model.dt
    remaining = int(n)
    fresh = settled = False
    z = v = None
    finite = True
    while remaining > 0:
        ahead = rows if remaining == n else rows[min(int(n) - remaining, len(rows) - 1):]
        if data.lin is None or (model.relinearize_tol is not None and stepper.moved_too_far(
                model, data, model.unpack(y, t, command)[0])):
            stepper.linearize(model, data, y, t, ahead[0])
            fresh = True
        chunk = 1 if model.relinearize_tol is not None else remaining
        (y, F0, aux0, ye, command, dd, dw, steps, iterations, status, z, v,
         finite) = stepper.advance(model, data, chunk, y, t, ahead, command, F0, aux0, ye,
                                   origin, k)
        dissipated += dd
        work += dw
        remaining -= steps
        k += steps
        t = origin + k * dt
        data.stats.steps += steps
        data.stats.iterations += iterations
        if status == stepping.NOT_CONTRACTING:
            if steps == 0 and fresh:
                if settled or not model.drives.n_lags:
                    raise SolverError(_not_converging(model, t + dt))
                stepper.linearize(model, data, y, t, _settled(model, y, ahead[0]))
                settled = True
                continue
            data.lin = None
        elif status == stepping.SLOW:
            data.lin = None
        if steps:
            fresh = settled = False
    return y, t, k, F0, aux0, ye, command, dissipated, work, z, v, finite


PLANAR = Stepper(linearize, _advance, moved_too_far)


def _settled(model: Model, y: np.ndarray, command: np.ndarray) -> np.ndarray:
    """Return ``command`` with each lagged drive's entry at its output u in y (rates zero)."""
    nF, n = len(model.part.free), model.drives.n_lags
    out = command.copy()
    out[:n] = y[2 * nF:2 * nF + n]
    return out


def _not_converging(model: Model, t: float) -> str:
    """Why a step did not converge, and what to do (naming lags faster than the step)."""
    dt = model.dt
    drives = model.drives
    fast = [f"{drives.names[k]} ({tau:g} s)" for k, tau in zip(drives.lagged, drives.tau)
            if tau < dt]
    text = (f"step to t = {t:.6g} s did not converge even with a fresh Jacobian; reduce the "
            f"step ({dt:g} s)")
    if fast:
        text += (f"; drive {', '.join(fast)} lags its command much faster than the step: give "
                 "it response_time: 0 (its displacement then follows the command, a step rising "
                 "over one engine step, or a program exactly), or a step near its response time")
    return text
