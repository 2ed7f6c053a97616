"""
The drives of a ``Model``: their constants, inputs and commands, and what each one does.

A mechanism has any number of named drives (``mechanism.Drive``), in constraint order:

- a **displacement drive** d prescribes its body's coordinates, z_P = z_P0 + D_d u_d, where
  u_d, the actuator output, follows the drive's command c_d as a first-order lag of its own,
  du_d/dt = (c_d - u_d) / tau_d; the u_d are integrated states (y = (z_F, v_F, u));
- a **force drive** j applies the generalized force e_j f_j (virtual work; e_j its direction)
  on coordinates that stay free; the commanded force f_j is held as it is (no lag);
- a **stack drive** s, a displacement drive whose piezo ``actuator:`` block has a finite stack
  stiffness k_s (engine/solver/actuation.py): its body's coordinate along the axis is free (its
  other coordinates held as a displacement drive holds them) and the stack acts as a spring between
  the actuator's free stroke x_s (held over a step) and the body:
  Q += e_s k_s (x_s - e_s . (z - z0)), potential 1/2 k_s (x_s - e_s . (z - z0))^2
  (actuators/piezo.py P7).

The stepping kernel takes the commands in *actuator order*: the displacement drives' commands,
then the force drives' forces, then the stack drives' free strokes (``actuator_command``; an
actuated drive's entry is its actuator's free stroke, not the user's command: solver/actuation.py).
A state keeps u and the commands in the simplest form: a number for a single actuator (single
drive), a vector otherwise
(``state_u``; ``Simulation.set_command``).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Callable, Optional, Union

import numpy as np

from flexure_sim.engine.actuators.piezo import PiezoSpec
from flexure_sim.engine.actuators.piezo_steps import Actuators

if TYPE_CHECKING:  # model.py imports this module
    from flexure_sim.engine.solver.model import Partition


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

    ``drive``: its index (``Model.drive_names`` order); ``slot``: its entry in the kernel's
    command vector (actuator order); ``states``: its slice of ``State.actuator``; ``stack``:
    whether it is a stack drive (finite k_s).
    """

    drive: int
    slot: int
    spec: PiezoSpec
    states: slice
    stack: bool


def actuated(model: "DriveMixin") -> tuple[Actuated, ...]:
    """Return the drives of ``model`` whose actuator block is not the identity."""
    order = list(model.actuator_command(np.arange(len(model.drives), dtype=float)).astype(int))
    out, offset = [], 0
    for k, d in enumerate(model.drives):
        if d.kind != "displacement" or transparent(d.actuator):
            continue
        size = d.actuator.size
        out.append(Actuated(k, order.index(k), d.actuator, slice(offset, offset + size),
                            stacked(d)))
        offset += size
    return tuple(out)


class DriveMixin:
    """
    The per-drive part of ``model.Model``: inputs, commands and forces of every drive.

    Needs the model's ``drives``, ``drive_names``, ``drive_directions``, ``displacement_index``,
    ``force_index``, ``part``, ``mass``, ``z0`` and ``assembly``.
    """

    # What the host model sets in its constructor (declarations only, for the type checker);
    # a drive is a planar or a spatial ``Drive`` (mechanism/parts.py, spatial_parts.py).
    drives: tuple[Any, ...]
    drive: Optional[Any]
    drive_names: tuple[str, ...]
    drive_directions: np.ndarray
    displacement_index: np.ndarray
    force_index: np.ndarray
    stack_index: np.ndarray
    part: Partition
    mass: np.ndarray
    z0: np.ndarray
    generalized_forces: Callable[[np.ndarray, np.ndarray], tuple[np.ndarray, float, float]]

    def _drive_constants(self) -> None:
        """Set the actuator time constants and the force drives' directions (kernel arrays)."""
        actuators = [self.drives[k] for k in self.displacement_index]
        #: Time constant (s) and stroke span (m) per displacement drive (actuator order).
        self.tau = np.array([d.response_time for d in actuators], dtype=float)
        self.stroke_span = np.array([d.stroke[1] - d.stroke[0] for d in actuators], dtype=float)
        #: D^T, rows contiguous: dz_P/du_d per displacement drive.
        self.D_rows = np.ascontiguousarray(self.part.D.T, dtype=float)
        #: Direction e_j (rows) of each force drive, and e_j . z0.
        self.force_dir = np.ascontiguousarray(
            self.drive_directions[self.force_index], dtype=float).reshape(
                len(self.force_index), len(self.z0))
        self.force_z0 = self.force_dir @ self.z0
        #: Per stack drive: direction e_s (rows), e_s . z0 and the stack stiffness k_s (N/m).
        self.stack_dir = np.ascontiguousarray(
            self.drive_directions[self.stack_index], dtype=float).reshape(
                len(self.stack_index), len(self.z0))
        self.stack_z0 = self.stack_dir @ self.z0
        self.stack_k = np.array([self.drives[k].actuator.stiffness for k in self.stack_index],
                                dtype=float)
        #: sum_s k_s e_s e_s^T: minus the stack springs' exact dQ/dz (None without stacks).
        self.stack_K = (self.stack_dir.T * self.stack_k) @ self.stack_dir if len(
            self.stack_index) else None
        self._order = np.concatenate([self.displacement_index, self.force_index,
                                      self.stack_index]).astype(int)
        #: The drives with a (non-identity) piezo actuator (engine/solver/actuation.py).
        self.actuation = actuated(self)
        #: Their numbers as arrays, for stepping them n steps in one call
        # (actuators/piezo_steps.py).
        self.actuators = Actuators(self.actuation)

    def require_rigid(self, what: str) -> None:
        """Raise ValueError naming the drives with a finite stack, which ``what`` cannot handle."""
        if len(self.stack_index):
            names = ", ".join(self.drive_names[k] for k in self.stack_index)
            raise ValueError(f"{what}: drive {names} has a finite-stiffness piezo stack, whose "
                             "input is its actuator's free stroke; use the stage with rigid "
                             "stacks (actuation.rigid_stacks) or step to a steady state")

    @property
    def n_actuators(self) -> int:
        """Return the number of displacement drives (actuator states u)."""
        return len(self.displacement_index)

    def actuator_command(self, command) -> np.ndarray:
        """
        Return the kernel's command vector: displacement drives' commands, then the forces.

        ``command``: a state's command (a number: every drive's; or one value per drive, in
        ``drive_names`` order).
        """
        values = np.broadcast_to(np.asarray(command, dtype=float), (len(self.drives),))
        return np.ascontiguousarray(values[self._order], dtype=float)

    def kernel_command(self, command) -> np.ndarray:
        """
        Return ``command`` as the kernel takes it.

        An array is taken as already in actuator order (``actuator_command``); a number is
        every drive's.
        """
        if isinstance(command, np.ndarray):
            return command
        return np.full(len(self.drives), float(command))

    def actuator_u(self, u) -> np.ndarray:
        """One actuator output per displacement drive from a state's u (number or vector)."""
        if np.ndim(u) == 0:  # a state's number: np.full is ~10x cheaper than broadcasting
            return np.full(self.n_actuators, float(u))
        return np.broadcast_to(np.asarray(u, dtype=float), (self.n_actuators,)).astype(float)

    def state_u(self, u: np.ndarray) -> Union[float, np.ndarray]:
        """Return a state's u from the actuator outputs: a number (none or one), else a vector."""
        if self.n_actuators <= 1:
            return float(u[0]) if self.n_actuators else 0.0
        return np.array(u, dtype=float)

    def state_inputs(self, u, command) -> np.ndarray:
        """
        Return each drive's input in a stepped state.

        Per drive (``drive_names`` order): a displacement drive's actuator output u, a force
        drive's commanded force.
        """
        out = np.zeros(len(self.drives))
        out[self.displacement_index] = self.actuator_u(u)
        if len(self.force_index):
            commands = np.broadcast_to(np.asarray(command, dtype=float), (len(self.drives),))
            out[self.force_index] = commands[self.force_index]
        return out

    def drive_inputs(self, value) -> np.ndarray:
        """
        Return one input per drive (``drive_names`` order).

        One input per drive (``drive_names`` order) from a number (a single drive), a sequence of
        one value per drive, or a {name: value} mapping naming every drive; ValueError naming the
        problem (and the drive) otherwise, also for non-finite values.
        """
        names = self.drive_names
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

    def drive_force(self, z: np.ndarray, v: np.ndarray, aP: np.ndarray,
                    Q: Optional[np.ndarray] = None) -> float:
        """
        Force the actuator applies to the driven body along the drive axis (N).

        The drive-axis component of the constraint forces lambda_P = M_P a_P - Q_P (eq. 6.4) for
        the single displacement drive; 0 without one.
        """
        if self.drive is None:
            return 0.0
        if Q is None:
            Q = self.generalized_forces(z, v)[0]
        P = self.part.prescribed
        return float((self.mass[P] * aP - Q[P]) @ self.part.du)

    def drive_forces(self, z: np.ndarray, v: np.ndarray, aP: np.ndarray,
                     Q: Optional[np.ndarray] = None, inputs=None) -> np.ndarray:
        """
        Return the force each drive's actuator applies.

        Per drive (``drive_names`` order), the force (N; N m on theta) its actuator applies along
        its direction: a displacement drive's share D_d^T lambda_P of the constraint forces
        lambda_P = M_P a_P - Q_P (eq. 6.4; Q the hinges' forces); a force drive's commanded force
        (its entry of ``inputs``, 0 without).
        """
        out = np.zeros(len(self.drives))
        if len(self.displacement_index):
            if Q is None:
                Q = self.generalized_forces(z, v)[0]
            P = self.part.prescribed
            out[self.displacement_index] = self.part.D.T @ (self.mass[P] * aP - Q[P])
        if inputs is not None and len(self.force_index):
            out[self.force_index] = np.asarray(inputs, dtype=float)[self.force_index]
        return out

    def drive_positions(self, z: np.ndarray) -> np.ndarray:
        """
        Return each driven body's displacement along its drive's direction.

        Per drive, the driven body's displacement from rest along the drive's direction (a
        displacement drive's input; where a force drive's body has moved).
        """
        return self.drive_directions @ (z - self.z0)


def _number(value, name: str) -> float:
    """Return a drive input as a float; ValueError naming the drive for anything else."""
    try:
        return float(value)
    except (TypeError, ValueError):
        raise ValueError(f"drive {name!r}: input must be a number, got {value!r}") from None
