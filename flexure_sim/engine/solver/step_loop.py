"""
The exponential trapezoidal rule, as one loop that Numba compiles when it can.

For y' = F(y, t), an exact Jacobian A = dF/dy taken at some earlier state,
F0 = F(y_n, t_n) and the remainder N(y, t) = F(y, t) - F0 - A (y - y_n), a step is

    y_{n+1} = U + h phi_2(hA) N(y_{n+1}, t_{n+1}),     U = y_n + h phi_1(hA) F0,

(the variation-of-constants formula with N interpolated linearly over the step), solved by
fixed-point iteration from y_{n+1} = U. The iteration contracts by about |J - A| / |J| per
sweep; it has converged when its last change is below rtol |U| + atol in every component.

The dissipated energy and drive work are integrated within each step from the same linear
model (``step_energy``).

``advance`` runs up to n steps and stops early with a status when the iteration does not
contract (1) or contracts slowly (2), so the caller can re-linearize. The loop calls
``rhs(y, t, command, args)`` -> (F, energy rates ``energy_rates``): compiled with the force
kernel for quadratic laws (``advance``), or as plain Python with ``Model.rhs_python``
for any law (``advance_interpreted``); one source, two bindings of ``rhs`` (and of
``switch``, the work of a change of the held command between steps: ``switch_work``). Where
the constraints put the prescribed coordinates: ``motion``.
"""
from __future__ import annotations

import math
import types

import numpy as np

from flexure_sim.engine import jit as kernel_cache
from flexure_sim.engine.solver import step_energy as step_energy_module
from flexure_sim.engine.jit import njit
from flexure_sim.engine.solver.kernel_pack import LoopArgs
from flexure_sim.engine.solver.kernels import quadratic_forces
from flexure_sim.engine.solver.motion import coordinates, kernel_coordinates, prescribed_motion
from flexure_sim.engine.solver.step_energy import (
    AUX_APPLIED, AUX_DISSIPATION, AUX_ENERGY, AUX_LOAD, AUX_TIMED_POWER,
)
from flexure_sim.engine.solver.step_energy import step_energy, workspace_size

CONVERGED, NOT_CONTRACTING, SLOW = 0, 1, 2


@njit(cache=True, inline="always")
def applied_forces(Q, z, command, n_actuators, force_dir, force_z0, stack_dir, stack_z0,
                   stack_k):
    """
    Add the force drives' and the stack springs' forces to Q; return (applied, springs).

    Force drives: sum_j e_j f_j, f_j = command[n_actuators + j] (held over a step), e_j = row
    j of force_dir (virtual work); ``applied`` = sum_j f_j e_j . (z - z0), the held forces'
    potential, changes by exactly their work. Stack drives s (``drives.stacked``, after the
    force drives in ``command``): the spring k_s between the held free stroke x_s and the
    body, Q += e_s k_s (x_s - e_s . (z - z0)) (actuators/piezo.py P7); ``springs`` = sum_s 1/2 k_s
    (x_s - e_s . (z - z0))^2, their potential (part of the mechanism's: with x_s held it is
    conservative; a change of x_s between steps is the actuator's work, solver/actuation.py).
    """
    applied = 0.0
    for j in range(force_dir.shape[0]):
        f = command[n_actuators + j]
        travel = -force_z0[j]
        for i in range(Q.shape[0]):
            Q[i] += force_dir[j, i] * f
            travel += force_dir[j, i] * z[i]
        applied += f * travel
    springs = 0.0
    first = n_actuators + force_dir.shape[0]
    for j in range(stack_dir.shape[0]):
        stretch = command[first + j] + stack_z0[j]
        for i in range(Q.shape[0]):
            stretch -= stack_dir[j, i] * z[i]
        f = stack_k[j] * stretch
        for i in range(Q.shape[0]):
            Q[i] += stack_dir[j, i] * f
        springs += 0.5 * f * stretch
    return applied, springs


@njit(cache=True)
def kernel_rhs(y, t, command, args):
    """
    F(y, t) and the energy rates (``step_energy.AUX_*``) with the compiled quadratic-law forces.

    y = (z_F, v_F, u) with one u per lagged drive; command: the kernel's command vector
    (``DriveTable.kernel_command``).
    args = (free, prescribed, mass, zP0, D, tau, sine_index, sine_amp, sine_w, sine_phase, Dp,
    first_program, program_index, force_dir, force_z0, stack_dir, stack_z0, stack_k, ia, ib, ca,
    cb, phia, phib, kind, W, C, damping) -- see Model._kernel_args; ``damping``: the mechanism's
    damping matrix (0 x 0 without one), Q -= damping v and dissipation += v^T damping v
    (``Model.add_damping``).
    """
    (free, prescribed, mass, zP0, D, tau, sine_index, sine_amp, sine_w, sine_phase, Dp,
     first_program, program_index, force_dir, force_z0, stack_dir, stack_z0, stack_k, ia, ib,
     ca, cb, phia, phib, kind, W, C, damping) = args
    nF = free.shape[0]
    nd = tau.shape[0]
    u = y[2 * nF:2 * nF + nd]
    N = mass.shape[0]
    z, v, aP = coordinates(y, t, command, free, prescribed, N, tau, zP0, D, sine_index,
                           sine_amp, sine_w, sine_phase, Dp, first_program)
    Q = np.empty(N)
    n = ia.shape[0]
    potential, dissipation = quadratic_forces(
        z, v, ia, ib, ca, cb, phia, phib, kind, W, C, Q, np.empty((n, 3)), np.empty((n, 3))
    )
    if damping.shape[0]:
        cv = damping @ v
        Q -= cv
        dissipation += v @ cv
    applied, springs = applied_forces(Q, z, command, nd, force_dir, force_z0, stack_dir,
                                      stack_z0, stack_k)
    potential += springs
    m = y.shape[0]
    out = np.empty(m + AUX_LOAD + nd + 2 * program_index.shape[0])  # F, energy rates
    F = out[:m]
    for i in range(nF):
        F[i] = y[nF + i]
        F[nF + i] = Q[free[i]] / mass[free[i]]
    for k in range(nd):
        F[2 * nF + k] = (command[k] - u[k]) / tau[k]
    return F, energy_rates(out[m:], Q, v, potential, dissipation, applied, prescribed, mass, D,
                           sine_index, program_index, aP)


@njit(cache=True, inline="always")
def energy_rates(aux, Q, v, potential, dissipation, applied, prescribed, mass, D, sine_index,
                 program_index, aP):
    """
    Fill and return ``aux``: the energy figures the stepping loop integrates.

    The figures are indexed by ``step_energy.AUX_*``.

    Power of the timed constraints (sine rates, then the coordinates the prescribed drives'
    programs move: ``program_index``) sum v_P (M a_P - Q_P), dissipated power, mechanical energy
    T + U, the held forces' potential (``applied_forces``), per lagged drive k its load
    D_k . Q_P, then the velocity of each program coordinate and then their accelerations (for
    the step's linear model).
    """
    nd = D.shape[1]
    for k in range(nd):
        load = 0.0
        for i in range(prescribed.shape[0]):
            load += D[i, k] * Q[prescribed[i]]
        aux[AUX_LOAD + k] = load
    timed = 0.0
    for i in range(sine_index.shape[0]):
        j = prescribed[sine_index[i]]
        timed += (mass[j] * aP[sine_index[i]] - Q[j]) * v[j]
    q = program_index.shape[0]
    for i in range(q):
        j = prescribed[program_index[i]]
        timed += (mass[j] * aP[program_index[i]] - Q[j]) * v[j]
        aux[AUX_LOAD + nd + i] = v[j]
        aux[AUX_LOAD + nd + q + i] = aP[program_index[i]]
    kinetic = 0.0
    for j in range(mass.shape[0]):
        kinetic += 0.5 * mass[j] * v[j] * v[j]
    aux[AUX_TIMED_POWER] = timed
    aux[AUX_DISSIPATION] = dissipation
    aux[AUX_ENERGY] = kinetic + potential
    aux[AUX_APPLIED] = applied
    return aux


@njit(cache=True)
def switch_work(y, t, old, new, free, prescribed, mass, tau, zP0, D, sine_index, sine_amp,
                sine_w, sine_phase, Dp, first_program, n_forces, stack_dir, stack_z0, stack_k):
    """
    Return the drives' work when the held command changes from ``old`` to ``new`` at (y, t).

    The prescribed velocities jump (``dynamics.jump_work``; a lag's command or a program's piece
    changes, at a continuous position): 1/2 M_P (v_P+^2 - v_P-^2); the
    stack springs' anchors move at fixed z (solver/actuation.py): sum_s 1/2 k_s
    ((x_s' - p_s)^2 - (x_s - p_s)^2), p_s = e_s . (z - z0). ``n_forces``: the force drives'
    count (the stacks' strokes follow the force drives' forces in the command).
    """
    nF = free.shape[0]
    nd = tau.shape[0]
    u = y[2 * nF:2 * nF + nd]
    zP, v0, _ = prescribed_motion(t, u, old, tau, zP0, D, sine_index, sine_amp, sine_w,
                                  sine_phase, Dp, first_program)
    v1 = prescribed_motion(t, u, new, tau, zP0, D, sine_index, sine_amp, sine_w, sine_phase, Dp,
                           first_program)[1]
    work = 0.0
    for i in range(prescribed.shape[0]):
        work += 0.5 * mass[prescribed[i]] * (v1[i] * v1[i] - v0[i] * v0[i])
    if stack_dir.shape[0]:
        z = np.empty(mass.shape[0])
        for i in range(nF):
            z[free[i]] = y[i]
        for i in range(prescribed.shape[0]):
            z[prescribed[i]] = zP[i]
        first = nd + n_forces
        for j in range(stack_dir.shape[0]):
            p = -stack_z0[j]
            for i in range(z.shape[0]):
                p += stack_dir[j, i] * z[i]
            x0, x1 = old[first + j] - p, new[first + j] - p
            work += 0.5 * stack_k[j] * (x1 * x1 - x0 * x0)
    return work


@njit(cache=True)
def kernel_switch_work(y, t, old, new, args):
    """`switch_work` with the compiled kernel's arguments (``kernel_rhs``)."""
    (free, prescribed, mass, zP0, D, tau, sine_index, sine_amp, sine_w, sine_phase, Dp,
     first_program, _, force_dir, _, stack_dir, stack_z0, stack_k) = args[:18]
    return switch_work(y, t, old, new, free, prescribed, mass, tau, zP0, D, sine_index, sine_amp,
                       sine_w, sine_phase, Dp, first_program, force_dir.shape[0], stack_dir,
                       stack_z0, stack_k)


def _advance(
    n,
    y,
    t,
    dt,
    commands,
    held,
    A,
    phi1,
    phi2,
    rtol,
    atol,
    max_iter,
    slow_after,
    F0,
    aux0,
    ye,
    emats,
    args,
    origin,
    clock,
):
    """
    Up to n steps from (y, t) with F0 = F(y, t) and aux0 its energy rates, taken at ye.

    Step i holds the command row commands[i] (the last row for the steps beyond: one row holds
    one command over all). F0 and aux0 are those under ``held``; where a step's row differs
    from the command held before it, F0 and aux0 are re-evaluated at its start under the row
    and the switch's work (``switch``) is added to the drive work: a piezo actuator's held
    strokes, one row per step (solver/actuation.py).

    Returns (y, F, aux, ye, held, dissipated, work, steps, iterations, status, z, v, finite):
    the state, its F and energy rates after the steps taken (at t + steps dt), the point where
    those rates were evaluated (the accepted y is one correction further), the command they
    were taken under, the dissipated energy and drive work over the steps
    (``step_energy.step_energy``, with the matrices ``emats``), why it stopped, all coordinates
    and velocities there (``where``; at the caller's time origin + (clock + steps) dt: t = origin
    + clock dt, and time is kept on the step grid, not summed) and whether every entry of y is
    finite. Taking z and v here spares the caller a second call into compiled code, which
    unboxes every array argument again (~0.1 us each; ``advance_packed`` takes the fixed ones as
    one structure).
    ``rhs``, ``switch`` and ``where`` are globals of the function (see the end of this module),
    not arguments: Numba cannot cache functions that take compiled functions as arguments.
    """
    dissipated = 0.0
    work = 0.0
    steps = 0
    iterations = 0
    status = CONVERGED
    rows = commands.shape[0]
    form_e = math.nan   # x^T C_x x at ye (``step_energy``), once a step has taken it
    ews = np.empty(workspace_size(emats, y.shape[0]))   # its scratch, once per call
    for i in range(n):
        command = commands[min(i, rows - 1)]
        if np.any(command != held):
            t0 = t + i * dt
            F0, aux0 = rhs(y, t0, command, args)
            ye = y
            form_e = math.nan
            work += switch(y, t0, held, command, args)
            held = command
        t1 = t + (i + 1) * dt  # on the step grid, not a running sum
        U = y + phi1 @ F0
        weight = rtol * np.abs(U) + atol
        y1 = U.copy()
        previous = np.inf
        converged = False
        k = 0
        F1, aux1 = F0, aux0
        N1 = F0  # replaced in the first iteration
        ye1 = y1
        for k in range(1, max_iter + 1):
            F1, aux1 = rhs(y1, t1, command, args)
            N1 = F1 - F0 - A @ (y1 - y)
            y_next = U + phi2 @ N1
            change = np.max(np.abs(y_next - y1) / weight) if y.shape[0] else 0.0
            if not math.isfinite(change):
                break
            if change <= 1.0:
                # F at the accepted point, to first order in a change below tolerance;
                # the energy rates stay where they were evaluated (ye1).
                F1 = F1 + A @ (y_next - y1)
                ye1 = y1
                y1 = y_next
                converged = True
                break
            if change > 0.5 * previous:
                break
            previous = change
            y1 = y_next
        if not converged:
            status = NOT_CONTRACTING
            break
        dd, dw, form_e = step_energy(y, ye, y1, ye1, F0, N1, aux0, aux1, command, t1 - dt, dt,
                                     emats, form_e, ews)
        dissipated += dd
        work += dw
        y = y1
        F0, aux0, ye = F1, aux1, ye1
        steps += 1
        iterations += k
        if k > slow_after:
            status = SLOW
            break
    z, v = where(y, origin + (clock + steps) * dt, held, args)
    finite = True
    for i in range(y.shape[0]):
        finite = finite and math.isfinite(y[i])
    return (y, F0, aux0, ye, held, dissipated, work, steps, iterations, status, z, v, finite)


#: The right-hand side the compiled loop calls (resolved when Numba compiles ``advance``).
rhs = kernel_rhs
#: The work of a change of the held command, likewise.
switch = kernel_switch_work
#: All coordinates and velocities where the loop stopped, likewise.
where = kernel_coordinates

#: The loop, compiled with the quadratic-law kernel.
advance = njit(cache=True)(_advance)


@njit(cache=True)
def advance_packed(n, y, t, dt, commands, held, rtol, atol, max_iter, slow_after, F0, aux0, ye,
                   packed: LoopArgs, origin, clock):
    """
    ``advance`` with the linearization's and the model's arrays as one structure.

    ``packed``: ``kernel_pack.LoopArgs`` (that module says why: a call from Python unboxes it as
    one object instead of ~45 arrays).
    """
    return advance(n, y, t, dt, commands, held, packed.A, packed.phi1, packed.phi2, rtol, atol,
                   max_iter, slow_after, F0, aux0, ye, packed.emats, packed.args, origin, clock)


# Numba's cache of each kernel is keyed on its own file only (``kernel_cache``).
kernel_cache.revalidate(kernel_cache.dispatchers_of(step_energy_module, globals()), __file__)


def _interpreted_rhs(y, t, command, model):
    return model.rhs_python(y, t, command)


def _interpreted_where(y, t, command, model):
    return model.unpack(y, t, command)[:2]


def _interpreted_switch_work(y, t, old, new, model):
    d = model.drives
    return switch_work(y, t, old, new, model.part.free.astype(np.int64),
                       model.part.prescribed.astype(np.int64), model.mass, *model.motion,
                       d.force_dir.shape[0], d.stack_dir, d.stack_z0, d.stack_k)


#: The same loop as plain Python, calling ``Model.rhs_python`` (any hinge law); pass the
#: Model as ``args``.
advance_interpreted = types.FunctionType(
    _advance.__code__, {**globals(), "rhs": _interpreted_rhs,
                        "switch": _interpreted_switch_work, "where": _interpreted_where},
    "advance_interpreted")
