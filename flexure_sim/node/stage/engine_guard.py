"""
What the engine can follow.

Refusing actuator strokes beyond it, holding the state when a step fails anyway (no ROS).

Two lines of defence keep input from ever stopping the node (issue 16.10):

1. `StrokeProbe` checks a new stroke before it is accepted: the mechanism must have a static
   equilibrium (``Simulation.static``, Newton with the exact stiffness) at both ends. Where
   there is none — the microstage driven 1 mm, hundreds of times its 2 um stroke, bends its
   hinges past anything the twistor model converges on — the engine cannot follow a command
   there either, so the parameter is refused with the engine's reason.
2. `EngineHold` makes a tick transactional: it saves the engine state and the actuator target
   before the tick's steps; if a step fails (``SolverError``) or the result is not finite, it
   puts both back, so the simulation holds its last good state and nothing non-finite is
   ever published, and counts the failure for the diagnostics.
"""
from __future__ import annotations

import dataclasses
from typing import Any, Optional

import numpy as np

from flexure_sim.engine.mechanism.parts import Mechanism
from flexure_sim.engine.actuators.piezo import nominal_displacement
from flexure_sim.engine.solver.simulation import Simulation, SolverError
from flexure_sim.node.inputs.drive_kind import command_kind


class StrokeProbe:
    """
    Static-equilibrium check of stroke ends on a simulation of its own.

    The node's simulation is stepped by another thread. Results are cached per value; the first
    check builds the probe (tens of milliseconds).
    """

    def __init__(self, mechanism: Mechanism, dt: float, simulation: Any = Simulation) -> None:
        self._mechanism = mechanism
        self._dt = dt
        #: The engine's simulation class (``Simulation``, or ``SpatialSimulation`` in 3-D).
        self._simulation = simulation
        self._sim: Optional[Simulation] = None
        self._known: dict[tuple, Optional[str]] = {}

    def end_problem(self, name: str, value: float, drive: Optional[str] = None,
                    unit: str = "m") -> Optional[str]:
        """
        Why the engine cannot hold the actuator at ``value`` (in ``unit``), or None.

        ``drive``: of a mechanism with several drives, the one at ``value`` (the others at 0).
        A voltage command's ``value`` (V) is held at its nominal displacement
        (engine/actuators/piezo.py, P1).
        """
        value = float(value)
        key = (drive, value)
        if key not in self._known:
            if self._sim is None:
                self._sim = self._simulation(self._mechanism, dt=self._dt)
            drives = self._mechanism.drives
            one = next((d for d in drives if d.name == drive), drives[0] if drives else None)
            held = value
            if command_kind(one) == "voltage":
                held = float(nominal_displacement(one.actuator, value))
            inputs: Any = held
            if drive is not None:
                inputs = {d.name: (held if d.name == drive else 0.0) for d in drives}
            try:
                self._sim.static(inputs)
                self._known[key] = None
            except SolverError as exc:
                self._known[key] = (
                    f"{name}: the engine finds no static equilibrium of {self._mechanism.name} at "
                    f"{value:g} {unit} ({exc}); it could not follow a command there")
            except (ValueError, ArithmeticError):
                self._known[key] = None  # the static solver cannot judge: run-time hold guards
        return self._known[key]

    def problem(self, stroke_min: float, stroke_max: float) -> Optional[str]:
        """Why [stroke_min, stroke_max] is beyond the engine, or None."""
        return (self.end_problem("stroke_max", stroke_max)
                or self.end_problem("stroke_min", stroke_min))


class EngineHold:
    """
    Saves the engine state (and the drive filter's targets) before a tick.

    `restore` puts them back after a failed step. Counts failures (`failures`) and keeps the last
    reason.
    """

    def __init__(self) -> None:
        self.failures = 0
        self.last_error = ""
        self._state: Any = None
        self._targets: Optional[tuple[float, float]] = None

    def save(self, sim: Simulation, drive_filter: Any) -> None:
        """
        Remember the state before the tick's steps.

        The state object itself and its command: stepping makes a new ``State`` with new
        arrays and never writes into the old one's (``test_model_data.py`` pins it), while
        ``set_command`` replaces the command of the current one. Keeping the reference costs
        ~0.2 us where a copy cost ~3 us.
        """
        state = sim.state
        command = state.command
        self._state = (state, command.copy() if isinstance(command, np.ndarray) else command)
        self._targets = (drive_filter.target, drive_filter.applied) if drive_filter else None

    def restore(self, sim: Simulation, drive_filter: Any, exc: BaseException) -> str:
        """
        Back to the saved state after ``exc``.

        The drive target returns to where the actuator was (the command the engine could not follow
        is dropped). Returns the reason logged.
        """
        self.failures += 1
        state, command = self._state
        sim.state = dataclasses.replace(state, command=command).copy()
        dropped = ""
        if drive_filter is not None and self._targets is not None:
            target, applied = self._targets
            if np.any(drive_filter.target != applied):
                dropped = f"; drive command {drive_filter.describe(drive_filter.target)} dropped"
            drive_filter.hold(applied)
        self.last_error = f"{type(exc).__name__}: {exc}"
        return (f"the engine failed at t = {sim.state.t:.9g} s ({self.last_error}); state held"
                + dropped)
