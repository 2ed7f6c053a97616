"""
The piezo actuator (engine/actuators/piezo.py) alone against a linear spring load.

A command series in, the applied displacement and force out.

The stage is represented by its stiffness k_L along the drive (for a mechanism: the exact
tangent at rest, `load_stiffness`), quasi-statically (no stage mass): the stack (k_s) and the
load in series give x_out = x_a k_s / (k_s + k_L) and F = k_L x_out (actuators/piezo.py, P8).

The command is piecewise linear between the given samples (a triangle is exact with its
corners). Each linear piece is integrated by ``scipy.integrate.solve_ivp`` (Radau, with the
exact Jacobian `piezo.jacobian`), starting from the actuator at rest; without an amplifier
lag the state's V_a is the command itself, reset at every corner (exactly, by `piezo.jump`
on the first one), and the hysteresis integrates dh/dt with the piece's rate.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.integrate import solve_ivp

from flexure_sim.engine.actuators import piezo
from flexure_sim.engine.actuators.piezo import PiezoSpec


@dataclass(frozen=True)
class PiezoRun:
    """
    One simulated command series; arrays over the evaluation times ``t`` (s).

    command (V or m, the spec's command kind), voltage V_a (V), states (n, k), free stroke
    x_a (m), output x_out (m, the applied displacement), force (N, on the stage).
    """

    t: np.ndarray
    command: np.ndarray
    voltage: np.ndarray
    states: np.ndarray
    free_stroke: np.ndarray
    output: np.ndarray
    force: np.ndarray


def simulate(spec: PiezoSpec, times, commands, k_load: float = 0.0, t_eval=None,
             rtol: float = 1e-9) -> PiezoRun:
    """
    Integrate the actuator for the piecewise-linear command through (``times``, ``commands``).

    ``k_load`` (N/m, >= 0, inf: blocked) is the load spring; ``t_eval`` the output times
    (default ``times``), within [times[0], times[-1]].
    """
    times = np.asarray(times, dtype=float)
    commands = np.asarray(commands, dtype=float)
    if times.ndim != 1 or times.shape != commands.shape or len(times) < 2:
        raise ValueError("times, commands: expected two 1-D arrays of the same length >= 2")
    if not (np.all(np.isfinite(times)) and np.all(np.isfinite(commands))):
        raise ValueError("times, commands: must be finite")
    if np.any(np.diff(times) <= 0):
        raise ValueError("times: must increase strictly")
    if not (k_load >= 0):
        raise ValueError(f"k_load: must be >= 0 (N/m), got {k_load!r}")
    if math.isinf(k_load) and math.isinf(spec.stiffness):
        raise ValueError("k_load: a rigid stack against a rigid load has no defined force")
    t_eval = times if t_eval is None else np.asarray(t_eval, dtype=float)
    if np.any(t_eval < times[0]) or np.any(t_eval > times[-1]) or np.any(np.diff(t_eval) < 0):
        raise ValueError("t_eval: must be sorted and within [times[0], times[-1]]")
    volts = np.asarray(piezo.command_voltage(spec, commands), dtype=float)
    s = piezo.initial_state(spec)
    if not spec.lagged:
        s = piezo.jump(spec, s, float(volts[0]))
    states = np.empty((spec.size, len(t_eval)))
    at_start = t_eval == times[0]
    states[:, at_start] = s[:, None]
    atol = np.concatenate([[1e-9 * max(abs(spec.v_max), abs(spec.v_min), 1.0)],
                           np.full(spec.size - 1, 1e-9 * spec.gain * (spec.v_max - spec.v_min))])
    for k in range(len(times) - 1):
        t0, t1, v0, v1 = times[k], times[k + 1], volts[k], volts[k + 1]
        rate = (v1 - v0) / (t1 - t0)

        def v_cmd(t, t0=t0, v0=v0, rate=rate):
            return v0 + rate * (t - t0)

        inside = (t_eval > t0) & (t_eval <= t1)
        wanted = np.append(t_eval[inside & (t_eval < t1)], t1)  # t1 last: the piece's end
        sol = solve_ivp(
            lambda t, y: piezo.rhs(spec, y, v_cmd(t), rate), (t0, t1), s, method="Radau",
            jac=lambda t, y: piezo.jacobian(spec, y, v_cmd(t), rate)[0],
            t_eval=wanted, rtol=rtol, atol=atol)
        if sol.status != 0:
            raise RuntimeError(f"piezo integration failed on [{t0:g}, {t1:g}] s: {sol.message}")
        states[:, inside] = sol.y if inside.any() and t_eval[inside][-1] == t1 else sol.y[:, :-1]
        s = sol.y[:, -1].copy()
        if not spec.lagged:  # V_a is the command: remove the integration's rounding
            states[0, inside] = v_cmd(t_eval[inside])
            s[0] = v1
    x_a = piezo.free_stroke(spec, states)
    x_out = piezo.series_output(spec.stiffness, k_load, x_a)
    # F = k_L x_out; blocked (k_L inf, x_out = 0): the stack's k_s x_a (P7)
    force = (piezo.stack_force(spec, x_a, x_out) if math.isinf(k_load) else k_load * x_out)
    command = np.interp(t_eval, times, commands)
    return PiezoRun(t_eval, command, states[0].copy(), states, x_a, x_out, np.asarray(force))


def stepped(sim, drive: int, times, commands, every: int = 1) -> PiezoRun:
    """
    Step ``sim`` (a ``Simulation``) through the piecewise-linear command of drive ``drive``.

    The dynamic counterpart of `simulate`: the whole mechanism (mass, damping, the stack
    spring) in the engine's stepping (engine/solver/actuation.py). The command is sampled at each
    step's start and held over it; every ``every``-th step's end is returned, the command
    paired with the output it produced. ``force`` is the stack's (P7; the drive force of a
    rigid stack), ``output`` the driven body's displacement along the drive.
    """
    times = np.asarray(times, dtype=float)
    commands = np.asarray(commands, dtype=float)
    model = sim.model
    actuated = [a for a in model.drives.actuation if a.drive == drive]
    if len(model.drives) != 1 or not actuated:
        raise ValueError("stepped: needs a mechanism with one drive with an actuator block")
    n = int(round((times[-1] - times[0]) / sim.dt))
    held = np.interp(times[0] + np.arange(n) * sim.dt, times, commands)
    keep = np.arange(every - 1, n, every)
    spec, states = actuated[0].spec, np.empty((actuated[0].spec.size, len(keep)))
    out, force, j = np.empty(len(keep)), np.empty(len(keep)), 0
    for k in range(n):
        sim.set_command(float(held[k]))
        sim.step(1)
        if j < len(keep) and k == keep[j]:
            snap = sim.snapshot()
            out[j], force[j] = snap.drive_positions[drive], snap.drive_stack_forces[drive]
            states[:, j] = sim.state.actuator[actuated[0].states]
            j += 1
    return PiezoRun(times[0] + (keep + 1) * sim.dt, held[keep], states[0].copy(), states,
                    np.asarray(piezo.free_stroke(spec, states)), out, force)


def triangle(spec: PiezoSpec, frequency: float, cycles: int) -> tuple[np.ndarray, np.ndarray]:
    """
    Corners (times, commands) of a triangular command over the full range, from its minimum.

    The command kind is the spec's: v_min .. v_max (V) or the stroke's ends (m).
    """
    if not (frequency > 0 and math.isfinite(frequency)):
        raise ValueError(f"frequency: must be a positive number of Hz, got {frequency!r}")
    if cycles < 1:
        raise ValueError(f"cycles: must be at least 1, got {cycles!r}")
    lo, hi = spec.v_min, spec.v_max
    if spec.command == "displacement":
        lo, hi = (float(piezo.nominal_displacement(spec, v)) for v in (lo, hi))
    times = np.arange(2 * cycles + 1) * (0.5 / frequency)
    commands = np.where(np.arange(2 * cycles + 1) % 2 == 0, lo, hi).astype(float)
    return times, commands


def loop_width(voltage: np.ndarray, output: np.ndarray, centre: float) -> float:
    """
    Width of the last closed loop at voltage ``centre``: descending minus ascending branch.

    The last rising and the last falling sweep of ``voltage`` (monotone pieces) are each
    interpolated linearly at ``centre``.
    """
    dv = np.diff(voltage)
    up, down = _last_sweep(voltage, output, dv > 0), _last_sweep(voltage, output, dv < 0)
    rising = np.interp(centre, *up)
    falling = np.interp(centre, *down[:, ::-1])
    return float(falling - rising)


def _last_sweep(v: np.ndarray, x: np.ndarray, moving: np.ndarray) -> np.ndarray:
    ends = np.flatnonzero(moving)
    if ends.size == 0:
        raise ValueError("the command has no rising and falling sweep")
    last = ends[-1]
    first = last
    while first > 0 and moving[first - 1]:
        first -= 1
    return np.vstack([v[first:last + 2], x[first:last + 2]])


def load_stiffness(sim) -> float:
    """
    k_L (N/m): the exact tangent of the drive force in the drive input at rest.

    The static gain of the ``drive_force`` output of the exact linearisation at rest
    (engine/analysis/linear.py), of the mechanism with its stacks made rigid
    (``actuation.rigid_stacks``: the stage alone, the load the stack works against).
    """
    from flexure_sim.engine.solver.actuation import rigid_stacks
    from flexure_sim.engine.analysis.linear import linearize, static_gain
    from flexure_sim.engine.solver.simulation import Simulation

    if len(sim.model.drives.stack):
        sim = Simulation(rigid_stacks(sim.mechanism))
    return float(static_gain(linearize(sim, 0.0, wrenches=False), ["drive_force"])[0])
