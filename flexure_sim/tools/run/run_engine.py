"""
The engine that ran a recorded run, for the static comparisons of ``flexure-sim analyse``.

A run of the planar engine is compared with ``Simulation``, a run in space (the recording's
``space`` is ``3d``: a ``space: 3d`` file or a planar one opened in 3-D) with
``SpatialSimulation``, through their common public methods: ``static_gain`` and the static
equilibrium's outputs at given drive inputs.
"""
from __future__ import annotations

from typing import Any


class RunEngine:
    """A simulation of a recorded mechanism, planar or spatial, and its static solves."""

    def __init__(self, mechanism: Any) -> None:
        from flexure_sim.engine.mechanism.spatial_parts import Mechanism as SpatialMechanism

        #: True: the spatial engine.
        self.spatial = isinstance(mechanism, SpatialMechanism)
        if self.spatial:
            from flexure_sim.engine.solver.spatial_simulation import SpatialSimulation
            self.sim: Any = SpatialSimulation(mechanism)
        else:
            from flexure_sim.engine.solver.simulation import Simulation
            self.sim = Simulation(mechanism)
        self.drive_names = tuple(d.name for d in mechanism.drives)
        self.output_names = tuple(o.name for o in mechanism.all_outputs)

    def static_gain(self) -> Any:
        """Return the exact static gain at rest, outputs against drives."""
        return self.sim.static_gain()

    def static_outputs(self, inputs: Any) -> dict[str, float]:
        """Return every output at the static equilibrium with the drives at ``inputs``."""
        if self.spatial:
            return dict(self.sim.static_snapshot(inputs).outputs)
        return dict(self.sim.static(inputs).snapshot.outputs)
