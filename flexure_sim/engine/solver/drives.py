"""
The drives of a ``Model``: their constants, inputs and commands, and what each one does.

A mechanism has any number of named drives (``mechanism.Drive``), in constraint order:

- a **displacement drive** d prescribes its body's coordinates, z_P = z_P0 + D_d u_d, where
  u_d, the actuator output, follows the drive's command c_d as a first-order lag of its own,
  du_d/dt = (c_d - u_d) / tau_d; the u_d are integrated states (y = (z_F, v_F, u));
- a **prescribed drive** (a displacement drive with ``response_time: 0``) prescribes its
  displacement p_d(t) itself, with its rate and acceleration, from a program (``programs``):
  z_P = z_P0 + D_d p_d(t), no state; a held command c_d is reached by a ramp over one step;
- a **force drive** j applies the generalized force e_j f_j (virtual work; e_j its direction)
  on coordinates that stay free; the commanded force f_j is held as it is (no lag);
- a **stack drive** s, a displacement drive whose piezo ``actuator:`` block has a finite stack
  stiffness k_s (engine/solver/actuation.py): its body's coordinate along the axis is free (its
  other coordinates held as a displacement drive holds them) and the stack acts as a spring between
  the actuator's free stroke x_s (held over a step) and the body:
  Q += e_s k_s (x_s - e_s . (z - z0)), potential 1/2 k_s (x_s - e_s . (z - z0))^2
  (actuators/piezo.py P7).

A ``Model`` holds them in a ``DriveTable``. The stepping kernel takes the commands in *kernel
order* (``DriveTable.order``): the displacement drives' commands, then the force drives' forces,
then the stack drives' free strokes (``DriveTable.kernel_command``; an actuated drive's entry is
its actuator's free stroke, not the user's command: solver/actuation.py). A state holds u as an
array of one actuator output per displacement drive and its commands as an array of one value per
drive (``state.State``; ``Simulation.set_command``), whatever their number.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Iterator, Optional, TypeVar, Union

import numpy as np

from flexure_sim.engine.actuators.piezo import PiezoSpec
from flexure_sim.engine.actuators.piezo_steps import Actuators
from flexure_sim.engine.mechanism import spatial_parts
from flexure_sim.engine.mechanism.parts import Drive, Mechanism
from flexure_sim.engine.solver.programs import PIECE_WIDTH, hold

if TYPE_CHECKING:  # partition.py imports this module
    from flexure_sim.engine.solver.partition import Partition

#: A drive of a planar or a spatial mechanism (mechanism/parts.py, spatial_parts.py): a
#: ``DriveTable`` holds either.
AnyDrive = Union[Drive, spatial_parts.Drive]
_Mechanism = TypeVar("_Mechanism", Mechanism, spatial_parts.Mechanism)


def stacked(drive) -> bool:
    """Tell whether a drive is a stack drive: a displacement drive with a finite stack k_s."""
    return (drive.kind == "displacement" and drive.actuator is not None
            and not math.isinf(drive.actuator.stiffness))


def transparent(spec) -> bool:
    """
    Tell whether an actuator block is the identity (a drive without it behaves the same).

    A nominal-displacement command, no hysteresis, no creep, unlimited bandwidth, rigid stack:
    x_a = x_c (P1, P3, P6 with h = c_i = 0); such a drive skips the actuator so that its results
    are bit-identical to a drive without the block (not merely equal to rounding).
    """
    return (spec is None or (spec.command == "displacement" and spec.alpha == 0.0
                             and not spec.creep and not spec.lagged
                             and math.isinf(spec.stiffness)))


@dataclass(frozen=True)
class Actuated:
    """
    One drive with a (non-identity) actuator.

    ``drive``: its index (``DriveTable.names`` order); ``slot``: its entry in the kernel's
    command vector (``DriveTable.order``); ``states``: its slice of ``State.actuator``;
    ``stack``: whether it is a stack drive (finite k_s).
    """

    drive: int
    slot: int
    spec: PiezoSpec
    states: slice
    stack: bool


def actuated(drives: "DriveTable") -> tuple[Actuated, ...]:
    """Return the drives of the table whose actuator block is not the identity."""
    order = list(drives.order)
    out: list[Actuated] = []
    offset = 0
    for k, d in enumerate(drives):
        spec = d.actuator
        if d.kind != "displacement" or transparent(spec):
            continue
        assert spec is not None, "transparent(None) is True"
        size = spec.size
        out.append(Actuated(k, order.index(k), spec, slice(offset, offset + size), stacked(d)))
        offset += size
    return tuple(out)


class DriveTable:
    """
    Every drive of a ``model.Model``, by kind, with the constants the stepping kernel takes.

    Iterating, indexing and ``len`` give the mechanism's ``Drive`` objects in constraint order;
    ``names`` their names and ``directions`` their directions e_k (rows over the 3 n_bodies
    coordinates: drive k's input is e_k . (z - z0), a force drive's generalized force e_k f).
    The index arrays (into that order) of each kind:

    - ``displacement``: the drives that prescribe their body's displacement (each a column of
      ``Partition.D``, in this order); of those ``lagged``: a first-order lag of its command,
      whose output u is an integrated state (in the order of u), and ``prescribed``
      (``response_time: 0``): the displacement follows its program exactly (module doc);
    - ``force``: the force drives; ``stack``: the stack drives (a finite piezo stack, ``stacked``).

    ``order``: the kernel's command vector holds the lagged drives' commands, then the force
    drives' forces, then the stack drives' free strokes, then per prescribed drive the kernel row
    of its program's piece (``programs.PIECE_WIDTH`` entries from ``first_program``;
    ``kernel_command``).
    """

    def __init__(self, mechanism: _Mechanism, part: Partition, z0: np.ndarray) -> None:
        # ``z0``: the model's rest coordinates (3 per body, or the spatial engine's 6).
        drives = tuple(mechanism.drives)
        self._drives: tuple[AnyDrive, ...] = drives
        n, N = len(drives), len(z0)
        self.names: tuple[str, ...] = tuple(d.name for d in drives)
        self.directions = np.array([d.direction(mechanism) for d in drives]).reshape(n, N)
        self.displacement = np.array(
            [k for k, d in enumerate(drives) if d.kind == "displacement" and not stacked(d)],
            dtype=int)
        self.lagged = np.array([k for k in self.displacement if drives[k].response_time > 0],
                               dtype=int)
        self.prescribed = np.array([k for k in self.displacement
                                    if drives[k].response_time == 0], dtype=int)
        self.force = np.array([k for k, d in enumerate(drives) if d.kind == "force"], dtype=int)
        self.stack = np.array([k for k, d in enumerate(drives) if stacked(d)], dtype=int)
        self.order = np.concatenate([self.lagged, self.force, self.stack]).astype(int)
        #: Where the prescribed drives' piece rows start in the kernel's command vector.
        self.first_program = len(self.order)
        #: The kernel's command vector is the commands as they are (no program rows, drive
        #: order); ``plain``: moreover one drive, so a number is its whole command.
        self.in_order = (not len(self.prescribed)
                         and bool(np.array_equal(self.order, np.arange(n))))
        self.plain = self.in_order and n == 1
        lagged = [drives[k] for k in self.lagged]
        #: Time constant (s) and stroke span (m) per lagged drive (the order of u).
        self.tau = np.array([d.response_time for d in lagged], dtype=float)
        self.stroke_span = np.array([d.stroke[1] - d.stroke[0] for d in lagged], dtype=float)
        column = {int(k): j for j, k in enumerate(self.displacement)}
        #: D^T, rows contiguous: dz_P/du_d per lagged drive; D_p: dz_P/dp_d per prescribed
        #: drive (columns).
        self.lag_rows = np.ascontiguousarray(part.D[:, [column[k] for k in self.lagged]].T,
                                             dtype=float)
        self.D_prescribed = np.ascontiguousarray(
            part.D[:, [column[k] for k in self.prescribed]], dtype=float).reshape(
                len(part.prescribed), len(self.prescribed))
        #: Direction e_j (rows) of each force drive, and e_j . z0.
        self.force_dir = np.ascontiguousarray(self.directions[self.force], dtype=float).reshape(
            len(self.force), N)
        self.force_z0 = self.force_dir @ z0
        #: Per stack drive: direction e_s (rows), e_s . z0 and the stack stiffness k_s (N/m).
        self.stack_dir = np.ascontiguousarray(self.directions[self.stack], dtype=float).reshape(
            len(self.stack), N)
        self.stack_z0 = self.stack_dir @ z0
        self.stack_k = np.array([drives[k].actuator.stiffness for k in self.stack], dtype=float)
        #: sum_s k_s e_s e_s^T: minus the stack springs' exact dQ/dz (None without stacks).
        self.stack_K = ((self.stack_dir.T * self.stack_k) @ self.stack_dir
                        if len(self.stack) else None)
        #: The drives with a (non-identity) piezo actuator (engine/solver/actuation.py), and
        #: their numbers as arrays, for stepping them n steps in one call (piezo_steps.py).
        self.actuation = actuated(self)
        self.actuators = Actuators(self.actuation)
        self._z0 = z0
        #: Per drive, its body's index (``bodies``) and the (coordinate 0..2 of the body, index
        #: into the prescribed coordinates) pairs it holds (``holds``, from ``Partition.held``):
        #: where its reaction acts.
        self.bodies = np.array([mechanism.body_index(d.body) for d in drives], dtype=int)
        place = {int(c): j for j, c in enumerate(part.prescribed)}
        self.holds = tuple(tuple((c % 3, place[c]) for c in coords) for coords in part.held)

    def __len__(self) -> int:
        return len(self._drives)

    def __iter__(self) -> Iterator[AnyDrive]:
        return iter(self._drives)

    def __getitem__(self, k: int) -> AnyDrive:
        return self._drives[k]

    def __bool__(self) -> bool:
        return bool(self._drives)

    @property
    def kernel_width(self) -> int:
        """Return the length of the kernel's command vector (``kernel_command``)."""
        return len(self.order) + PIECE_WIDTH * len(self.prescribed)

    @property
    def n_lags(self) -> int:
        """Return the number of lagged drives (actuator outputs u in the state)."""
        return len(self.lagged)

    def require_rigid(self, what: str) -> None:
        """Raise ValueError naming the drives with a finite stack, which ``what`` cannot handle."""
        if len(self.stack):
            names = ", ".join(self.names[k] for k in self.stack)
            raise ValueError(f"{what}: drive {names} has a finite-stiffness piezo stack, whose "
                             "input is its actuator's free stroke; use the stage with rigid "
                             "stacks (actuation.rigid_stacks) or step to a steady state")

    def check_state(self, u: np.ndarray, command: np.ndarray) -> None:
        """Raise ValueError unless a state's u and command have this table's lengths."""
        if len(u) != self.n_lags or len(command) != len(self):
            raise ValueError(f"state: u has {len(u)} entries and command {len(command)}; the "
                             f"mechanism has {self.n_lags} displacement drives (one actuator "
                             f"output each) and {len(self)} drives (one command each)")

    def kernel_command(self, command: np.ndarray, programs: tuple = (),
                       t: float = 0.0) -> np.ndarray:
        """
        Return the kernel's command vector (``order``) from one command per drive.

        ``command``: one value per drive (``names`` order), as a state holds it; ``programs``:
        a state's programs (one per drive or none, ``State.programs``): a prescribed drive's
        entry is its program's piece in force at ``t`` (``Program.row``), or, without a program,
        its command held.
        """
        if self.in_order:  # a closed loop's tick: ~0.3 us against ~1 us for the general path
            return np.array(command, dtype=float, ndmin=1)
        values = np.asarray(command, dtype=float)
        out = values[self.order]
        if not len(self.prescribed):
            return np.ascontiguousarray(out)
        rows = [programs[k].row(t) if programs and programs[k] is not None
                else hold(values[k]) for k in self.prescribed]
        return np.ascontiguousarray(np.concatenate([out] + rows))

    def kernel_rows(self, state, dt: float, n: int) -> Optional[np.ndarray]:
        """
        Return the kernel's command vector of each of n steps from ``state`` (None: no program).

        Shape (n, ``kernel_width``): a lagged or force drive with a program holds its value at
        each step's midpoint, a prescribed drive's the piece in force there; the other drives
        hold the state's commands.
        """
        programs = state.programs
        if not programs or all(p is None for p in programs):
            return None
        mid = state.t + dt * (np.arange(int(n)) + 0.5)
        rows = np.repeat(self.kernel_command(state.command, programs, mid[0])[None, :], n, axis=0)
        slot = {int(k): j for j, k in enumerate(self.order)}
        for k, program in enumerate(programs):
            if program is None:
                continue
            if k in slot:
                rows[:, slot[k]] = program.values(mid)
            else:
                j = self.first_program + PIECE_WIDTH * list(self.prescribed).index(k)
                rows[:, j:j + PIECE_WIDTH] = program.rows(mid)
        return rows

    def held_command(self, row: np.ndarray, command: np.ndarray, programs: tuple) -> np.ndarray:
        """
        Return a state's ``command`` after a step that held the kernel vector ``row``.

        The lagged and force drives with a program take the value it held; the others keep
        theirs (a prescribed drive's command is its target, set with the program).
        """
        out = np.array(command, dtype=float)
        for j, k in enumerate(self.order):
            if programs and programs[k] is not None:
                out[k] = row[j]
        return out

    def state_inputs(self, u: np.ndarray, command: np.ndarray, programs: tuple = (),
                     t: float = 0.0) -> np.ndarray:
        """
        Return each drive's input in a stepped state (``names`` order).

        A lagged drive's actuator output u, a prescribed drive's displacement (its program's
        value at t, or its command without one), a force drive's commanded force.
        """
        out = np.zeros(len(self))
        out[self.lagged] = u
        command = np.asarray(command, dtype=float)
        out[self.force] = command[self.force]
        for k in self.prescribed:
            out[k] = (programs[k].value(t) if programs and programs[k] is not None
                      else command[k])
        return out

    def inputs(self, value) -> np.ndarray:
        """
        Return one input per drive (``names`` order).

        From a number (a single drive), a sequence of one value per drive, or a {name: value}
        mapping naming every drive; ValueError naming the problem (and the drive) otherwise,
        also for non-finite values.
        """
        names = self.names
        if isinstance(value, dict):
            unknown = sorted(set(value) - set(names))
            missing = [n for n in names if n not in value]
            if unknown or missing:
                problems = [f"{what} {names_}" for what, names_ in
                            (("unknown", unknown), ("missing", missing)) if names_]
                raise ValueError(f"drive inputs: {', '.join(problems)} "
                                 f"(drives: {', '.join(names) or 'none'})")
            out = np.array([_number(value[n], n) for n in names], dtype=float)
        elif np.ndim(value) == 0:
            if len(names) > 1:
                raise ValueError(f"one number given for {len(names)} drives "
                                 f"({', '.join(names)}): give one value per drive")
            out = np.full(len(names), _number(value, names[0] if names else "drive"))
        else:
            try:
                out = np.asarray(value, dtype=float).ravel()
            except (TypeError, ValueError):
                raise ValueError(f"drive inputs must be numbers, got {value!r}") from None
            if len(out) != len(names):
                raise ValueError(f"{len(out)} drive inputs given for {len(names)} drives "
                                 f"({', '.join(names) or 'none'})")
        bad = [n for n, x in zip(names, out) if not np.isfinite(x)]
        if bad:
            raise ValueError(f"drive inputs must be finite, got {value!r} "
                             f"(drive {', '.join(bad)})")
        return out

    def forces(self, D: np.ndarray, reactions: np.ndarray, inputs=None) -> np.ndarray:
        """
        Return the force each drive's actuator applies (``names`` order).

        Along its direction (N; N m on theta): a displacement drive's share D_d^T lambda_P of
        the constraint forces ``reactions`` = lambda_P (``Model.constraint_forces``; D:
        ``Partition.D``); a force drive's commanded force (its entry of ``inputs``, 0 without).
        """
        out = np.zeros(len(self))
        if len(self.displacement):
            out[self.displacement] = D.T @ reactions
        if inputs is not None and len(self.force):
            out[self.force] = np.asarray(inputs, dtype=float)[self.force]
        return out

    def wrenches(self, reactions: np.ndarray, forces: np.ndarray, z: np.ndarray) -> np.ndarray:
        """
        Return the full wrench each drive applies to its body: (n_drives, 3), (moment, fx, fy).

        What the drive's constraints and actuator apply to the driven body, in the body's frame
        at its origin (the moment about the origin, the forces along the body's axes): the
        constraint forces ``reactions`` = lambda_P (``Model.constraint_forces``, eq. 6.4) on the
        coordinates the drive prescribes (its axis and the coordinates it holds: the reaction of
        a held drive tip in force x, y and moment), plus e_k f_k for a force drive's force or a
        stack drive's spring force f_k (``forces``, ``forces`` order). The body's generalized
        forces on (x, y, theta) are the force in the root frame and the moment about the body's
        origin, turned into the body's frame by R(theta)^T. Along the drive's axis it is
        ``forces`` (a rigid drive's constraint force).
        """
        n = len(self)
        root = np.zeros((n, 3))           # (fx, fy, moment) in the root frame
        for k, held in enumerate(self.holds):
            for c, j in held:
                root[k, c] += reactions[j]
        for k in np.concatenate([self.force, self.stack]).astype(int):
            i = self.bodies[k]
            root[k] += self.directions[k, 3 * i:3 * i + 3] * forces[k]
        theta = z[3 * self.bodies + 2] if n else np.zeros(0)
        cs, sn = np.cos(theta), np.sin(theta)
        out = np.empty((n, 3))
        out[:, 0] = root[:, 2]
        out[:, 1] = cs * root[:, 0] + sn * root[:, 1]
        out[:, 2] = -sn * root[:, 0] + cs * root[:, 1]
        return out

    def positions(self, z: np.ndarray) -> np.ndarray:
        """
        Return each driven body's displacement along its drive's direction.

        Per drive, the driven body's displacement from rest along the drive's direction (a
        displacement drive's input; where a force drive's body has moved).
        """
        return self.directions @ (z - self._z0)


def _number(value, name: str) -> float:
    """Return a drive input as a float; ValueError naming the drive for anything else."""
    try:
        return float(value)
    except (TypeError, ValueError):
        raise ValueError(f"drive {name!r}: input must be a number, got {value!r}") from None
