"""
Piezo actuators (engine/actuators/piezo.py) in the stepping of a ``Model``: operator splitting.

A drive with an ``actuator:`` block takes its command in the actuator's unit (V for
``command: voltage``, the nominal displacement in m otherwise). The actuator's states (amplifier
voltage V_a, Bouc-Wen h, creep c_i) do not depend on the stage (actuators/piezo.py: one-way
coupling), so one engine step of h = dt splits exactly into

1. the actuator over [t, t + h] under the held command (``piezo.advance``: the amplifier and
   the hysteresis exactly, creep to second order in h / tau_i), then
2. the stage over the same step with the actuator's free stroke held at the step's mean
   x_h = (x_a(t+) + x_a(t + h)) / 2 (x_a(t+): after the jump of an unlimited-bandwidth
   amplifier at t, `piezo.jump`).

Holding the mean instead of interpolating x_a linearly over the step keeps the kernel's
held-command form; for the drive's lag du/dt = (x_a(t) - u)/tau its one-step error against a
linear x_a of rate r is r h^3 / (12 tau^2) (expand both exact solutions), so the splitting is
second order in h like the integrator itself (test/test_actuation.py measures the order
against scipy's Radau on the coupled system).

How x_a reaches the stage (``drives.stacked``):

- **rigid stack** (no ``stiffness``): x_a is the command of the drive's first-order lag,
  du/dt = (x_a - u) / response_time; ``response_time`` keeps its meaning (the drive's
  mechanical response to its actuator's stroke) and the drive's force is the constraint
  force as without the block;
- **finite stack** k_s: the body is free along the axis (its other coordinates held as the
  rigid drive holds them, so k_s -> inf tends to the rigid drive) and pulled by the stack
  spring, Q += e k_s (x_h - e . (z - z0)) (``stepping.applied_forces``, in both the compiled
  and the interpreted right-hand side; exact Jacobian -k_s e e^T, ``Model.jacobian``). The
  drive's ``response_time`` is not used: the stage's mass and k_s are its dynamics.

Energy: the stack spring's potential 1/2 k_s (x_h - e . (z - z0))^2 is part of the mechanism's
(conservative while x_h is held); moving the anchor from x_h to x_h' at configuration z
between steps is the actuator's work 1/2 k_s ((x_h' - p)^2 - (x_h - p)^2), p = e . (z - z0),
counted in ``drive_work`` with the velocity jumps of ``dynamics.jump_work``
(``stepping.switch_work``).

Cost: the actuators' n steps in one compiled call (``piezo_steps``), then the stage's in one
call of the stepping loop with one command row per step (``dynamics.step``).

An actuator block that is the identity (``drives.transparent``) is skipped: the drive is
bit-identical to one without the block.
"""
from __future__ import annotations

import dataclasses
import math

import numpy as np

from flexure_sim.engine.solver import integrator as dynamics
from flexure_sim.engine.actuators import piezo
from flexure_sim.engine.solver.state import Data, State
from flexure_sim.engine.mechanism.parts import Drive, Mechanism


def states(model, s: State) -> np.ndarray:
    """Return the actuators' states of ``s`` (each at rest, ``piezo.initial_state``, if None)."""
    if s.actuator is not None:
        return s.actuator
    parts = [piezo.initial_state(a.spec) for a in model.drives.actuation]
    return np.concatenate(parts) if parts else np.zeros(0)


def free_strokes(model, s: State) -> np.ndarray:
    """Return each actuated drive's free stroke x_a (m, P6) at ``s`` (``DriveTable.actuation``)."""
    x = states(model, s)
    return np.array([float(piezo.free_stroke(a.spec, x[a.states]))
                     for a in model.drives.actuation])


def held(model, s: State) -> np.ndarray:
    """Return the free strokes the stage sees at ``s``: those held over its last step."""
    return s.held if s.held is not None else free_strokes(model, s)


def kernel_command(model, s: State, strokes=None) -> np.ndarray:
    """
    Return the kernel's command vector at ``s``.

    The state's, with each actuated drive's entry replaced by its free stroke ``strokes``
    (default: the held ones, ``held``).
    """
    command = model.drives.kernel_command(s.command, s.programs, s.t - 0.5 * model.dt)
    strokes = held(model, s) if strokes is None else strokes
    for a, x in zip(model.drives.actuation, strokes):
        command[a.slot] = x
    return command


#: Steps per call of the compiled loops (bounds the per-step command rows' memory).
BLOCK = 4096


def step(model, data: Data, n: int = 1) -> None:
    """
    Advance ``data`` by n fixed steps, splitting each into the actuators and the stage.

    See the module doc. The actuators' n steps first (``piezo_steps``: their states do not
    depend on the stage), then the stage's n steps in one call of the stepping loop
    (``dynamics.step``), each holding its step's mean strokes; the stack springs' anchor moves
    between steps are counted there (``stepping.switch_work``).
    Without actuated drives, ``dynamics.step`` itself (one call for the n steps).
    """
    drives = model.drives
    if not drives.actuation:
        dynamics.step(model, data, n)
        return
    commands = data.state.command
    volts = np.array([float(piezo.command_voltage(a.spec, commands[a.drive]))
                      for a in drives.actuation])
    actuators = drives.actuators
    slots = [a.slot for a in drives.actuation]
    remaining = int(n)
    while remaining > 0:  # the command is held: only the actuators' states change
        chunk = min(remaining, BLOCK)
        s = data.state
        after, strokes = actuators.run(chunk, states(model, s), volts, model.dt)
        rows = drives.kernel_rows(s, model.dt, chunk)
        if rows is None:
            rows = np.repeat(drives.kernel_command(s.command)[None, :], chunk, axis=0)
        rows[:, slots] = strokes
        dynamics.step(model, data, chunk, kernel_command(model, s), rows)
        data.state.actuator, data.state.held = after, strokes[-1].copy()
        remaining -= chunk


def report(model, s: State, forces: np.ndarray, inputs: np.ndarray) -> dict:
    """
    Return the per-drive actuator figures of a snapshot (``Snapshot``).

    Fills in place the stack drives' ``forces`` (k_s (x_h - p), P7) and ``inputs``
    (p = e . (z - z0), the applied displacement).

    NaN where a drive has no (non-identity) actuator. The stack springs' potential energy
    is returned as ``stack_energy``.
    """
    n = len(model.drives)
    volts, strokes, stack = np.full(n, np.nan), np.full(n, np.nan), np.full(n, np.nan)
    x, hold = states(model, s), held(model, s)
    energy = 0.0
    for a, xh in zip(model.drives.actuation, hold):
        volts[a.drive] = x[a.states][0]
        strokes[a.drive] = float(piezo.free_stroke(a.spec, x[a.states]))
        if a.stack:
            p = float(model.drives.directions[a.drive] @ (s.z - model.z0))
            force = float(piezo.stack_force(a.spec, xh, p))
            inputs[a.drive], forces[a.drive], stack[a.drive] = p, force, force
            energy += 0.5 * force * (xh - p)
        else:
            stack[a.drive] = forces[a.drive]
    return {"drive_voltages": volts, "drive_free_strokes": strokes,
            "drive_stack_forces": stack, "stack_energy": energy}


def rigid_stacks(mech: Mechanism) -> Mechanism:
    """
    Return ``mech`` with every actuator's stack rigid (``stiffness`` inf).

    The stage as the load of its stacks: with the rigid drive's constraints (the axis
    prescribed, the other coordinates held as a finite stack holds them), its exact tangent
    along the drive is the load stiffness k_L of the series formula (actuators/piezo.py P8,
    ``piezo_run.load_stiffness``).
    """
    constraints = tuple(
        dataclasses.replace(c, actuator=dataclasses.replace(c.actuator, stiffness=math.inf))
        if isinstance(c, Drive) and c.actuator is not None else c for c in mech.constraints)
    return dataclasses.replace(mech, constraints=constraints)
