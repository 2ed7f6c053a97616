"""
The spatial simulation facade: a shared ``SpatialModel`` (constants) and its own ``Data``.

The planar ``solver.simulation.Simulation``'s shape, so that the node and the tools can drive
either: ``step``, ``snapshot``, ``set_command``, ``reset``, ``static``, ``static_gain`` and the
``state``/``stats`` attributes (those both have are ``state.Facade``'s); the linear model and
modes are ``analysis.spatial_linear``'s. A state's z holds six coordinates per body (position,
rotation vector from rest: ``kinematics.quaternion``) and v the quasi-velocities (root-frame
velocity, body-frame angular velocity: ``solver.spatial_chain``).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Optional, Union

import numpy as np

from flexure_sim.engine.kinematics import quaternion as rotation
from flexure_sim.engine.mechanism.spatial_parts import Mechanism
from flexure_sim.engine.solver import spatial_integrator as dynamics
from flexure_sim.engine.solver import spatial_statics as statics
from flexure_sim.engine.solver.model import DEFAULT_STEP
from flexure_sim.engine.solver.spatial_model import SpatialModel
from flexure_sim.engine.solver.state import Data, Facade, State


@dataclass(frozen=True)
class SpatialSnapshot:
    """
    What the spatial simulation reports at one instant (SI units).

    positions (n_bodies, 3) in the root frame; quaternions (n_bodies, 4) (w, x, y, z): the
    orientations R0 Exp(phi); rotations (n_bodies, 3): phi; velocities (n_bodies, 3) root frame;
    angular_velocities (n_bodies, 3) body coordinates. deflections (n_hinges, 6): rotation
    vector and position of frame b relative to frame a, in a; wrenches (n_hinges, 6): the wrench
    each hinge exerts on its body B, in frame b, moment about b's origin, (m_x, m_y, m_z, f_x,
    f_y, f_z); hinge_power (n_hinges, 3): (U, P_c, P_d) per hinge (``laws.spatial``). Drives
    and outputs
    as the planar ``Snapshot``.
    """

    t: float
    positions: np.ndarray
    quaternions: np.ndarray
    rotations: np.ndarray
    velocities: np.ndarray
    angular_velocities: np.ndarray
    deflections: np.ndarray
    wrenches: np.ndarray
    hinge_power: np.ndarray
    kinetic_energy: float
    potential_energy: float
    drive_names: tuple = ()
    drive_inputs: np.ndarray = field(default_factory=lambda: np.zeros(0))
    drive_forces: np.ndarray = field(default_factory=lambda: np.zeros(0))
    drive_positions: np.ndarray = field(default_factory=lambda: np.zeros(0))
    outputs: dict = field(default_factory=dict)


def snapshot(model: SpatialModel, s: State, inputs=None) -> SpatialSnapshot:
    """Return everything the spatial simulation reports at state ``s``."""
    command = model.actuator_command(s.command) if model.drives else np.zeros(0)
    Q, _, deflections, wrenches, power, energy, _ = model.terms(s.z, s.v, command)
    _, _, aP = model.prescribed(s.t, s.u, command)
    if inputs is None:
        inputs = model.state_inputs(s.u, s.command)
    else:
        aP = np.zeros_like(aP)
    nb = len(model.mechanism.bodies)
    Z, W = s.z.reshape(nb, 6), s.v.reshape(nb, 6)
    quats = np.array([rotation.qmul(tuple(b.quaternion),
                                    tuple(rotation.quaternion_of_vector(Z[i, 3:])))
                      for i, b in enumerate(model.mechanism.bodies)]).reshape(nb, 4)
    return SpatialSnapshot(
        s.t, Z[:, :3].copy(), quats, Z[:, 3:].copy(), W[:, :3].copy(), W[:, 3:].copy(),
        deflections, wrenches, power, model.kinetic_energy(s.v), energy, model.drive_names,
        np.asarray(inputs, dtype=float).copy(), model.drive_forces(s.z, s.v, aP, Q, inputs),
        model.drive_positions(s.z),
        dict(zip(model.output_names, model.output_values(s.z).tolist())))


class SpatialSimulation(Facade):
    """A spatial model, one run's data, and the stepping, static and linear solvers."""

    def __init__(self, source: Union[Mechanism, SpatialModel], dt: float = DEFAULT_STEP,
                 relinearize_tol: Optional[float] = None):
        if isinstance(source, SpatialModel):
            if (dt not in (DEFAULT_STEP, source.dt)
                    or relinearize_tol not in (None, source.relinearize_tol)):
                raise ValueError("dt and relinearize_tol belong to the model: build another "
                                 "SpatialModel to change them")
            self.model = source
        else:
            self.model = SpatialModel(source, dt, relinearize_tol)
        self.data = Data(self.model.z0, self.model.n_actuators, len(self.model.drives))

    snapshot_of = staticmethod(snapshot)

    def step(self, n: int = 1) -> None:
        """Advance n fixed steps with the drives' commands held (``spatial_integrator.step``)."""
        dynamics.step(self.model, self.data, n)

    def set_command(self, command) -> None:
        """Set the drives' targets: a number (single drive), a sequence or a {name: value}."""
        if not self.model.drives:
            raise ValueError(f"mechanism {self.model.mechanism.name!r} has no drive")
        self.data.state.command = self.model.drive_inputs(command)

    def static(self, u, tol: float = 1e-13) -> statics.SpatialStatic:
        """Return the static equilibrium with the drives at u (``spatial_statics.static``)."""
        return statics.static(self.model, u, tol)

    def static_snapshot(self, u) -> SpatialSnapshot:
        """Return the snapshot of the static equilibrium at u."""
        st = self.static(u)
        state = State(0.0, st.z, np.zeros_like(st.z),
                      self.model.state_u(st.inputs[self.model.displacement_index]),
                      st.inputs.copy())
        return snapshot(self.model, state, st.inputs)

    def static_gain(self) -> np.ndarray:
        """Return the exact static gain at rest, outputs against drives (``static_gain``)."""
        return statics.static_gain(self.model)
