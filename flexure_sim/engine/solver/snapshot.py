"""What a simulation reports at one instant, read from a ``Model`` and a ``State``."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Optional

import numpy as np

from flexure_sim.engine.solver import actuation
from flexure_sim.engine.solver.state import State
from flexure_sim.engine.solver.model import Model


@dataclass(frozen=True)
class Snapshot:
    """
    What the simulation reports at one instant (SI units throughout).

    poses (n_bodies, 3): x, y (m), theta (rad) in the root frame; velocities likewise.
    deflections (n_hinges, 3): (alpha, p_x, p_y) of frame b relative to frame a, in frame a
    (rotation, axial, shear for the stage's unrotated hinge frames).
    wrenches (n_hinges, 3): (moment, fx, fy), the wrench each hinge exerts on its body B,
    in frame b, moment about b's origin.
    drive_force: force the actuator applies to the driven body along the drive axis (N).
    output: output body's displacement along the output axis from rest (m) or None.
    compression: of the compression hinge (``Model.hinge_compression``): along the drive
    axis, at its centre of stiffness, its drive side's displacement minus its far side's (m),
    or None.
    drive_names, drive_inputs, drive_commands, drive_forces: per drive (``DriveTable.names``
    order) its input (a displacement drive's actuator output, the prescribed displacement; a
    force drive's commanded force), its command and the force its actuator applies
    (``Model.drive_forces``); drive_positions: each driven body's displacement along its drive's
    direction. The scalar drive_input, drive_command and drive_force are the first drive's (the
    single drive's, as before).
    outputs: {name: displacement from rest} of every output (``Model.output_values``).
    Per drive with a piezo actuator (engine/solver/actuation.py; NaN for the others):
    drive_voltages, the amplifier's output V_a (V); drive_free_strokes, the free stroke x_a (m,
    actuators/piezo.py P6); drive_stack_forces, the force the stack transmits (N: k_s (x_a - x_out)
    for a finite stack, P7, held x_a; the drive force of a rigid one). Its command is in
    drive_commands (V for ``command: voltage``), its applied displacement x_out in drive_positions
    (also its drive_inputs entry for a finite stack). potential_energy includes the stack springs'.
    drive_wrenches (n_drives, 3): (moment, fx, fy), the full wrench each drive applies to its
    body (its constraint's reaction in every coordinate it holds, plus an applied force), in the
    driven body's frame, moment about its origin (``DriveTable.wrenches``); along the drive's
    axis it is drive_forces.
    """

    t: float
    poses: np.ndarray
    velocities: np.ndarray
    deflections: np.ndarray
    wrenches: np.ndarray
    drive_input: float
    drive_command: float
    drive_force: float
    output: Optional[float]
    compression: Optional[float]
    kinetic_energy: float
    potential_energy: float
    dissipated: float
    drive_work: float
    drive_names: tuple = ()
    drive_inputs: np.ndarray = field(default_factory=lambda: np.zeros(0))
    drive_forces: np.ndarray = field(default_factory=lambda: np.zeros(0))
    drive_positions: np.ndarray = field(default_factory=lambda: np.zeros(0))
    outputs: dict = field(default_factory=dict)
    drive_commands: np.ndarray = field(default_factory=lambda: np.zeros(0))
    drive_voltages: np.ndarray = field(default_factory=lambda: np.zeros(0))
    drive_free_strokes: np.ndarray = field(default_factory=lambda: np.zeros(0))
    drive_stack_forces: np.ndarray = field(default_factory=lambda: np.zeros(0))
    drive_wrenches: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))


def snapshot(model: Model, s: State, inputs=None) -> Snapshot:
    """
    Return everything the simulation reports at state ``s``.

    Everything the simulation reports at state ``s``; ``inputs``: one per drive (a static state of
    several drives or force drives), default the state's (``Model.state_inputs``).
    """
    Q, deflections, wrenches, energy, _ = model.assembly.report(s.z, s.v)
    Q = model.add_damping(Q, s.v)[0]  # the drive forces see the damping matrix too
    drives = model.drives
    drives.check_state(s.u, s.command)
    # The prescribed motion the state was reached under (its last step's program pieces).
    command = (actuation.kernel_command(model, s) if drives.actuation
               else drives.kernel_command(s.command, s.programs, s.t - 0.5 * model.dt))
    _, _, aP = model.prescribed(s.t, s.u, command)
    if inputs is None:
        inputs = drives.state_inputs(s.u, s.command, s.programs, s.t)
    else:
        aP = np.zeros_like(aP)  # a static state: at rest
    inputs = np.array(inputs, dtype=float)
    commands = s.command
    reactions = model.constraint_forces(s.z, s.v, aP, Q)
    forces = drives.forces(model.part.D, reactions, inputs)
    piezo = actuation.report(model, s, forces, inputs)  # fills the stack drives' entries
    positions = drives.positions(s.z)
    nb = len(model.mechanism.bodies)
    return Snapshot(
        t=s.t,
        poses=s.z.reshape(nb, 3).copy(),
        velocities=s.v.reshape(nb, 3).copy(),
        deflections=deflections,
        wrenches=wrenches,
        drive_input=float(inputs[0]) if len(inputs) else 0.0,
        drive_command=float(commands[0]) if len(commands) else 0.0,
        drive_force=float(forces[0]) if len(forces) else 0.0,
        output=model.output_displacement(s.z),
        compression=model.hinge_compression(s.z),
        kinetic_energy=float(0.5 * np.sum(model.mass * s.v**2)),
        potential_energy=energy + piezo.pop("stack_energy"),
        dissipated=s.dissipated,
        drive_work=s.drive_work,
        drive_names=drives.names,
        drive_inputs=np.asarray(inputs, dtype=float).copy(),
        drive_forces=forces,
        drive_positions=positions,
        outputs=dict(zip(model.output_names, model.output_values(s.z).tolist())),
        drive_commands=commands.copy(),
        drive_wrenches=drives.wrenches(reactions, forces, s.z),
        **piezo,
    )
