"""
The mutable side of a simulation (as MuJoCo's mjData): state, counters, integrator caches.

A ``Data`` belongs to one run of one ``model.Model``; many may share the model (sweeps,
the node's reset). Nothing here knows the mechanism: stepping, statics and snapshots
read the model and update the data.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any, Callable, Optional

import numpy as np


@dataclass
class State:
    """
    Simulation state.

    z, v: (x, y, theta) and (vx, vy, omega) per body in the root frame (3 n_bodies, body order). u:
    the actuator outputs, one per displacement drive (``DriveTable.lagged`` order), along each
    drive's direction (m, rad on theta); command: the drives' current targets, one per drive
    (``DriveTable.names`` order; m or rad, a force drive's force in N or N m). Both are always
    1-D float arrays (a number given is taken as a one-entry array). Energy bookkeeping since
    the last reset: dissipated (J) by hinge damping and drive_work (J) done by the drives and the
    prescribed coordinates. actuator: the piezo actuators' states (engine/solver/actuation.py;
    None: at rest, or no actuator); held: their free strokes x_a (m) held over the last step.
    programs: per drive its ``programs.Program`` or None (one per drive, or () for none): the
    inputs that follow a function of time (``Simulation.set_programs``).
    """

    t: float
    z: np.ndarray
    v: np.ndarray
    u: np.ndarray = field(default_factory=lambda: np.zeros(0))
    command: np.ndarray = field(default_factory=lambda: np.zeros(0))
    dissipated: float = 0.0
    drive_work: float = 0.0
    actuator: Optional[np.ndarray] = None
    held: Optional[np.ndarray] = None
    programs: tuple = ()

    def __post_init__(self) -> None:
        self.u = np.array(self.u, dtype=float, ndmin=1)
        self.command = np.array(self.command, dtype=float, ndmin=1)
        if self.u.ndim != 1 or self.command.ndim != 1:
            raise ValueError(f"State: u and command must be 1-D arrays, got shapes "
                             f"{self.u.shape} and {self.command.shape}")

    def copy(self) -> "State":
        return replace(self, z=self.z.copy(), v=self.v.copy(),
                       actuator=None if self.actuator is None else self.actuator.copy(),
                       held=None if self.held is None else self.held.copy())


@dataclass
class StepStats:
    """Counters of the stepping work, for diagnostics and benchmarks."""

    steps: int = 0
    linearizations: int = 0
    iterations: int = 0


@dataclass(frozen=True)
class Linearization:
    """
    Where and what.

    Configuration z, Jacobian A, h phi_1(hA), h phi_2(hA), and the matrices of the step's
    dissipated energy and drive work (``step_energy.energy_matrices``).
    """

    z: np.ndarray
    A: np.ndarray
    phi1: np.ndarray
    phi2: np.ndarray
    emats: tuple
    #: A, phi1, phi2, emats and the model's kernel arguments as one structure for the compiled
    #: loop (``kernel_pack.LoopArgs``; None: not compiled).
    packed: Any = field(default=None, compare=False, repr=False)


class Data:
    """
    State, statistics and the integrator's caches of one run.

    ``lin``: the current linearization (None: compute at the next step); ``cache``: what the
    last step call left to seed the next one (`seed`); ``clock``: (state, origin t, steps since
    origin), so time stays on the step grid.
    """

    def __init__(self, z0: np.ndarray, n_lags: int = 0, n_drives: int = 0):
        self.z0 = np.asarray(z0, dtype=float)
        #: Lengths of a state's u and command (``DriveTable.n_lags`` and its number of drives).
        self.n_lags, self.n_drives = int(n_lags), int(n_drives)
        self.state = self.initial_state()
        self.stats = StepStats()
        self.lin: Optional[Linearization] = None
        self.cache: Optional[tuple] = None
        self.clock: Optional[tuple] = None

    def seed(self, F0: np.ndarray, aux0: np.ndarray, ye: np.ndarray, y: np.ndarray,
             command: np.ndarray) -> None:
        """
        Keep what seeds the next step call from the current state (the integrators' ``step``).

        ``cache`` = (state, command key, F and energy rates while the command is unchanged,
        where they were taken, y (the state packed, bit for bit), the kernel's command vector
        held last, the bytes of the state's commands and the programs it was held under).
        """
        s = self.state
        self.cache = (s, command.tobytes(), F0, aux0, ye, y, command, s.command.tobytes(),
                      s.programs)

    def held_command(self, s: State) -> Optional[tuple]:
        """
        Return (kernel command vector, its key) of the last step if it is state ``s``'s, or None.

        It is while ``s`` is the state that step made and its commands and programs are those
        the vector was made from (a command set since, even in place, is not).
        """
        cache = self.cache
        if (cache is None or cache[0] is not s or cache[8] != s.programs
                or cache[7] != s.command.tobytes()):
            return None
        return cache[6], cache[1]

    def initial_state(self) -> State:
        """Return the unstressed poses at rest, every actuator output and command 0, t = 0."""
        return State(0.0, self.z0.copy(), np.zeros_like(self.z0), np.zeros(self.n_lags),
                     np.zeros(self.n_drives))

    def reset(self) -> None:
        """
        Back to the initial state (unstressed poses, at rest, actuator at 0, t = 0).

        Statistics and caches restart.
        """
        self.state = self.initial_state()
        self.stats = StepStats()
        self.lin = None
        self.cache = None
        self.clock = None


class Facade:
    """
    What ``Simulation`` and ``SpatialSimulation`` share: a model (constants), its data (state).

    The subclass sets ``model`` and ``data`` and gives ``snapshot_of(model, state)``.
    """

    model: Any
    data: Data
    #: snapshot_of(model, state): the engine's snapshot function (set by the subclass).
    snapshot_of: Callable[..., Any]

    # The model's constants, as attributes of the simulation (read-only views).
    mechanism = property(lambda self: self.model.mechanism)
    dt = property(lambda self: self.model.dt)
    z0 = property(lambda self: self.model.z0)

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

    def reset(self) -> None:
        """Back to the initial state (rest poses, at rest, drives at 0, t = 0), counters 0."""
        self.data.reset()

    def snapshot(self, state: Optional[State] = None):
        """Everything the simulation reports, at ``state`` (default: the current state)."""
        return self.snapshot_of(self.model, state or self.data.state)
