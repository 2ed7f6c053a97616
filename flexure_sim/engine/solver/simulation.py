"""
The simulation facade: a shared ``Model`` (constants) and its own ``Data`` (state).

``Simulation`` keeps the public API the node, the CLI and the tools use (constructor,
``step``, ``snapshot``, ``set_command``, ``reset``, ``static``, ``static_sweep``, the
``state``/``stats`` attributes; those it shares with ``SpatialSimulation`` are
``state.Facade``'s) over the split engine:

- ``model.Model``: the mechanism prepared for stepping (partition, masses, hinge assembly,
  compiled kernel arguments) and the formulas of F(y, t), its Jacobian and the reported
  measures; constraints by exact elimination of prescribed coordinates (eqs. 5.25, 6.4).
- ``data.Data``: state, counters, the integrator's linearization, cache and clock.
- ``dynamics``: the exponential trapezoidal rule (stiff-stable fixed steps, exact drive
  work); ``statics``: Newton's method with the exact stiffness; ``snapshot``: what is
  reported at an instant.

Several simulations of one model share it: ``Simulation(model)`` (sweeps, the node's
reset); each steps independently and exactly as a simulation built from the mechanism.
"""
from __future__ import annotations

import math
from typing import Optional, Union

import numpy as np

from flexure_sim.engine.solver import actuation, integrator, statics
from flexure_sim.engine.solver.compression import stiffness_centre
from flexure_sim.engine.solver.state import Data, Facade, State, StepStats
from flexure_sim.engine.mechanism.parts import Mechanism
from flexure_sim.engine.solver.model import DEFAULT_STEP, Model, SolverError
from flexure_sim.engine.solver.programs import Program
from flexure_sim.engine.solver.snapshot import Snapshot, snapshot
from flexure_sim.engine.solver.statics import StaticResult, StaticSweep

__all__ = [
    "DEFAULT_STEP", "Model", "Program", "Simulation", "Snapshot", "SolverError", "State",
    "StaticResult", "StaticSweep", "StepStats", "stiffness_centre",
]


class Simulation(Facade):
    """
    A model, one run's data, and the stepping / static solvers.

    ``source``: a Mechanism (a Model is built for it with ``dt`` and ``relinearize_tol``)
    or a Model to share (then ``dt``, ``relinearize_tol`` and ``energy`` are the model's).
    See ``model.Model`` for ``dt``, ``relinearize_tol`` and ``energy`` (default True).
    """

    def __init__(self, source: Union[Mechanism, Model], dt: float = DEFAULT_STEP,
                 relinearize_tol: Optional[float] = None, energy: Optional[bool] = None):
        if isinstance(source, Model):
            other_dt = dt != DEFAULT_STEP and dt != source.dt
            if (other_dt or relinearize_tol not in (None, source.relinearize_tol)
                    or energy not in (None, source.energy)):
                raise ValueError("dt, relinearize_tol and energy belong to the model: "
                                 "build another Model to change them")
            self.model = source
        else:
            self.model = Model(source, dt, relinearize_tol, True if energy is None else energy)
        self.data = Data(self.model.z0, self.model.drives.n_lags, len(self.model.drives))

    # More of the model's constants, as attributes (``state.Facade`` has the common ones).
    assembly = property(lambda self: self.model.assembly)
    drive = property(lambda self: self.model.drive)
    relinearize_tol = property(lambda self: self.model.relinearize_tol)
    mass = property(lambda self: self.model.mass)
    part = property(lambda self: self.model.part)
    length_scale = property(lambda self: self.model.length_scale)
    snapshot_of = staticmethod(snapshot)

    def initial_state(self) -> State:
        """All bodies at their unstressed poses, at rest, actuator at zero, t = 0."""
        return self.data.initial_state()

    def step(self, n: int = 1) -> None:
        """
        Advance n fixed steps with the drives' commands held at state.command (``dynamics.step``).

        T stays on the step grid. Drives with a piezo actuator step it too (``actuation.step``).
        """
        actuation.step(self.model, self.data, n)

    def warm(self) -> None:
        """Run the next step and discard it: the state is unchanged (``integrator.warm``)."""
        integrator.warm(self.model, self.data)

    def step_commands(self, commands, n: int) -> None:
        """
        Take n steps, step i holding ``commands[i]`` (the last one held for the steps beyond).

        The states of ``set_command(commands[i])`` and ``step(1)`` for each command (the last
        with ``step(n - len(commands) + 1)``): a drive filter's ramp (node/stage/engine_steps.py).
        Each entry is a command as ``set_command`` takes it; the state's command is the last.
        A bad command (ValueError) or a step that fails (``SolverError``) leaves the state as it
        was before the call.
        Where that is the same to the bit, one call of the stepping loop with one kernel command
        row per step (``integrator.step``: where a row differs from the command held, the loop
        takes F under it at the step's start, as a call does under a new command): a tick
        ramping over its 10 steps costs 92 us against 205 us for 10 calls (the same steps in
        one call: 76 us; tools/bench/tick_profile.py ``call_costs``, ``call_ramp``, the stage;
        each call costs ~10 us besides its steps). Only without the energies (the loop counts a
        command switch's work by another formula than ``integrator.jump_work``), actuators and
        programs, with the drives' commands as the kernel's (``DriveTable.in_order``) and no
        timed constraint (the loop's times within a call are t + i dt, a call's origin + k dt);
        otherwise step by step.
        """
        n = int(n)
        model, s = self.model, self.data.state
        drives = model.drives
        count = len(commands)
        if not 0 < count <= n:
            raise ValueError(f"step_commands: 1 to n = {n} commands, got {count}")
        if (count == 1 or not model.compiled or model.energy or not drives.in_order
                or len(drives.actuation) or s.programs or model.part.timed):
            before = s.command
            try:
                for i, command in enumerate(commands):
                    self.set_command(command)
                    self.step(1 if i < count - 1 else n - i)
            except BaseException:
                s.command, self.data.state = before, s  # as it was
                raise
            return
        rows = None
        if drives.plain and all(type(c) is float for c in commands):  # a filter's ramp, quickly
            rows = np.array(commands)[:, None]
        if rows is None or not np.isfinite(rows).all():  # ValueError naming a bad one
            rows = np.array([drives.inputs(c) for c in commands], dtype=float)
        before = drives.kernel_command(s.command)
        s.command = rows[-1].copy()
        try:
            integrator.step(model, self.data, n, before, rows)
        except BaseException:
            s.command = before  # as it was (in_order: the kernel's vector is the command)
            raise

    def set_command(self, command) -> None:
        """
        Set the drives' targets.

        A displacement drive's target is its actuator output's (m along its axis, rad on theta),
        a force drive's its force (N, N m on theta); a drive with a piezo ``actuator:`` block
        takes its actuator's command (V for ``command: voltage``, else the nominal m; the
        engine does not clamp it: ``piezo.command_limits`` gives the stroke in that unit). A
        number (a single drive), or one value per drive (a sequence in ``model.drives.names``
        order or a {name: value} mapping); each must be finite (ValueError naming the drive).
        Held until the next call; it replaces a drive's program (``set_programs``). A prescribed
        drive (``response_time: 0``) moves to its target over the next step, linearly (its
        displacement cannot jump: ``programs.Program.for_prescribed``).
        """
        s = self.data.state
        if type(command) is float and self.model.drives.plain and not s.programs:
            # The common case, quickly: a number for one lagged or force drive (a stepping
            # node's tick; ``DriveTable.plain``), as ``DriveTable.inputs`` makes it an array.
            if not math.isfinite(command):
                raise ValueError(f"drive command must be finite, got {command!r}")
            s.command = np.array((command,))  # ~0.3 us; np.full ~1 us
            return
        if np.ndim(command) == 0 and not isinstance(command, dict) and not np.isfinite(command):
            raise ValueError(f"drive command must be finite, got {command!r}")
        drives = self.model.drives
        if not drives:
            raise ValueError(f"mechanism {self.model.mechanism.name!r} has no drive")
        values = drives.inputs(command)
        if not len(drives.prescribed) and not s.programs:
            s.command = values
            return
        now = drives.state_inputs(s.u, s.command, s.programs, s.t)
        programs: list[Optional[Program]] = [None] * len(drives)
        for k in drives.prescribed:
            if values[k] != now[k]:
                programs[k] = Program("step", values[k] - now[k], start=s.t,
                                      initial=now[k]).for_prescribed(self.model.dt)
        s.command, s.programs = values, tuple(programs) if any(programs) else ()

    def set_programs(self, programs: dict) -> None:
        """
        Make drives follow programs of time (``programs.Program``): {drive name: program}.

        A lagged drive's command, or a force drive's force, holds each step the program's value
        at the step's midpoint; a prescribed drive's displacement follows it exactly (a step
        rising over one engine step), and must start where the drive is (ValueError otherwise:
        it cannot jump). None for a drive: it holds its present command. Drives not named keep
        what they follow. A drive with a piezo actuator takes commands only (ValueError).
        Times are simulation time (``state.t``).
        """
        drives = self.model.drives
        unknown = sorted(set(programs) - set(drives.names))
        if unknown:
            raise ValueError(f"programs: unknown drive {', '.join(unknown)} (drives: "
                             f"{', '.join(drives.names) or 'none'})")
        s = self.data.state
        actuated = {a.drive for a in drives.actuation}
        now = drives.state_inputs(s.u, s.command, s.programs, s.t)
        command = np.array(s.command, dtype=float)
        out = list(s.programs) if s.programs else [None] * len(drives)
        for name, program in programs.items():
            k = drives.names.index(name)
            if program is not None and k in actuated:
                raise ValueError(f"drive {name!r} has a piezo actuator: give it a command "
                                 "(set_command); programs drive the other drives")
            if program is not None and k in drives.prescribed:
                program = program.for_prescribed(self.model.dt)
                start = program.value(s.t)
                if not np.isclose(start, now[k], rtol=1e-12, atol=1e-15):
                    raise ValueError(
                        f"drive {name!r} (response_time 0: a prescribed displacement) is at "
                        f"{now[k]:g} but its program ({program.describe()}) is at {start:g} at "
                        f"t = {s.t:g} s: a prescribed displacement cannot jump")
                command[k] = program.final if program.final is not None else program.initial
            elif program is None:
                command[k] = now[k] if k in drives.prescribed else command[k]
            out[k] = program
        s.command, s.programs = command, tuple(out) if any(p is not None for p in out) else ()

    def static(self, u, t: float = 0.0, tol: float = 1e-13,
               max_iter: int = 50) -> StaticResult:
        """
        Return static equilibrium with the actuator outputs held at u (``statics.static``).

        u: a number (single drive), one value per drive or a {name: value} mapping.
        """
        return statics.static(self.model, u, t, tol, max_iter)

    def static_gain(self, t: float = 0.0) -> np.ndarray:
        """
        Return the exact static gain at rest, outputs against drives.

        Exact static gain at rest, outputs (rows) against drives (columns)
        (``statics.static_gain``; names: ``model.output_names``, ``model.drives.names``).
        """
        return statics.static_gain(self.model, t)

    def static_sweep(self, inputs, t: float = 0.0, tol: float = 1e-13) -> StaticSweep:
        """Return static equilibria for many drive inputs (``statics.static_sweep``)."""
        return statics.static_sweep(self.model, inputs, t, tol)

    def hinge_compression(self, z: np.ndarray) -> Optional[float]:
        """Compression of the compression hinge at coordinates z (``Model.hinge_compression``)."""
        return self.model.hinge_compression(z)
