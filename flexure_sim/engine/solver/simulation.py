"""
The simulation facade: a shared ``Model`` (constants) and its own ``Data`` (state).

``Simulation`` keeps the public API the node, the CLI and the tools use (constructor,
``step``, ``snapshot``, ``set_command``, ``reset``, ``static``, ``static_sweep``, the
``state``/``stats`` attributes) over the split engine:

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

from flexure_sim.engine.solver import actuation, statics
from flexure_sim.engine.solver.compression import stiffness_centre
from flexure_sim.engine.solver.state import Data, State, StepStats
from flexure_sim.engine.mechanism.parts import Mechanism
from flexure_sim.engine.solver.model import DEFAULT_STEP, Model, SolverError
from flexure_sim.engine.solver.snapshot import Snapshot, snapshot
from flexure_sim.engine.solver.statics import StaticResult, StaticSweep

__all__ = [
    "DEFAULT_STEP", "Model", "Simulation", "Snapshot", "SolverError", "State", "StaticResult",
    "StaticSweep", "StepStats", "stiffness_centre",
]


class Simulation:
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
        self.data = Data(self.model.z0)

    # The model's constants, as attributes of the simulation (read-only views).
    mechanism = property(lambda self: self.model.mechanism)
    assembly = property(lambda self: self.model.assembly)
    drive = property(lambda self: self.model.drive)
    dt = property(lambda self: self.model.dt)
    relinearize_tol = property(lambda self: self.model.relinearize_tol)
    z0 = property(lambda self: self.model.z0)
    mass = property(lambda self: self.model.mass)
    part = property(lambda self: self.model.part)
    length_scale = property(lambda self: self.model.length_scale)

    @property
    def state(self) -> State:
        """Return the current state; assign a State to continue from it."""
        return self.data.state

    @state.setter
    def state(self, value: State) -> None:
        self.data.state = value

    @property
    def stats(self) -> StepStats:
        """Counters of the stepping work since the last reset."""
        return self.data.stats

    @stats.setter
    def stats(self, value: StepStats) -> None:
        self.data.stats = value

    def initial_state(self) -> State:
        """All bodies at their unstressed poses, at rest, actuator at zero, t = 0."""
        return State(0.0, self.model.z0.copy(), np.zeros_like(self.model.z0))

    def reset(self) -> None:
        """Back to the initial state; statistics restart."""
        self.data.reset()

    def step(self, n: int = 1) -> None:
        """
        Advance n fixed steps with the drives' commands held at state.command (``dynamics.step``).

        T stays on the step grid. Drives with a piezo actuator step it too (``actuation.step``).
        """
        actuation.step(self.model, self.data, n)

    def set_command(self, command) -> None:
        """
        Set the drives' targets.

        A displacement drive's target is its actuator output's (m along its axis, rad on theta),
        a force drive's its force (N, N m on theta); a drive with a piezo ``actuator:`` block
        takes its actuator's command (V for ``command: voltage``, else the nominal m; the
        engine does not clamp it: ``piezo.command_limits`` gives the stroke in that unit). A
        number (a single drive), or one value per drive (a sequence in ``model.drive_names``
        order or a {name: value} mapping); each must be finite (ValueError naming the drive).
        Held until the next call.
        """
        if type(command) is float and len(self.model.drives) == 1:  # the common case, quickly
            if not math.isfinite(command):
                raise ValueError(f"drive command must be finite, got {command!r}")
            self.data.state.command = command
            return
        if np.ndim(command) == 0 and not isinstance(command, dict) and not np.isfinite(command):
            raise ValueError(f"drive command must be finite, got {command!r}")
        if not self.model.drives:
            raise ValueError(f"mechanism {self.model.mechanism.name!r} has no drive")
        values = self.model.drive_inputs(command)
        self.data.state.command = float(values[0]) if len(values) == 1 else values

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
        (``statics.static_gain``; names: ``model.output_names``, ``model.drive_names``).
        """
        return statics.static_gain(self.model, t)

    def static_sweep(self, inputs, t: float = 0.0, tol: float = 1e-13) -> StaticSweep:
        """Return static equilibria for many drive inputs (``statics.static_sweep``)."""
        return statics.static_sweep(self.model, inputs, t, tol)

    def snapshot(self, state: Optional[State] = None) -> Snapshot:
        """Everything the simulation reports, at ``state`` (default: the current state)."""
        return snapshot(self.model, state or self.data.state)

    def hinge_compression(self, z: np.ndarray) -> Optional[float]:
        """Compression of the compression hinge at coordinates z (``Model.hinge_compression``)."""
        return self.model.hinge_compression(z)
