"""
A tick's report of a ``SpatialSimulation``: its snapshot, in the shape the stepping loop reads.

The planar node reports a tick in one compiled call (``engine.solver.tick_report``) and packs
it in another (``publish.tick_frame``). A mechanism in space is reported through
``SpatialSimulation.snapshot`` (the engine's one definition of every reported number) and
packed by ``publish.spatial_messages`` in a few array operations: for the tip-tilt stage
(5 bodies, 6 hinges, 3 drives, 3 outputs: 28 messages a tick) ~57 us for the snapshot and
~25 us for the packing, next to ~60 us for the ten engine steps of a 1 ms tick (measured in
one process; docs/node.md, "Mechanisms in space"), where the planar stage's compiled report
and packing take ~4 us.

`SpatialReport` offers what the loop uses of ``TickReport``: ``fill_data`` (the report of
the current state, here the snapshot), ``finite``, ``values`` and ``index`` (the outputs and
the stress ratios: none in 3-D) and ``view`` (what the display draws: the snapshot).
"""
from __future__ import annotations

from typing import Any, Optional

import numpy as np


class SpatialReport:
    """The snapshot of a spatial simulation at each tick (module docstring)."""

    def __init__(self, sim: Any) -> None:
        self.sim = sim
        mech = sim.mechanism
        no, nh = len(mech.outputs), len(mech.hinges)
        self.output_names = tuple(o.name for o in mech.outputs)
        self.index = {"outputs": slice(0, no), "stress_ratios": slice(no, no + nh)}
        #: The outputs of the last `fill_data`, then NaN stress ratios (no yield strength).
        self.values = np.full(no + nh, np.nan)
        self.finite = True
        #: The snapshot of the last `fill_data`.
        self.last_snapshot: Optional[Any] = None

    def fill_data(self, _data: Any = None) -> np.ndarray:
        """Report the simulation's current state (``SpatialSimulation.snapshot``)."""
        snap = self.sim.snapshot()
        self.last_snapshot = snap
        outputs = [snap.outputs[n] for n in self.output_names]
        self.values[self.index["outputs"]] = outputs
        parts = (snap.positions, snap.quaternions, snap.velocities, snap.angular_velocities,
                 snap.deflections, snap.wrenches, snap.drive_inputs, snap.drive_forces,
                 snap.drive_positions, np.asarray(outputs, dtype=float))
        self.finite = all(bool(np.isfinite(p).all()) for p in parts)
        return self.values

    def view(self) -> Any:
        """Return the last snapshot (what the display draws)."""
        return self.last_snapshot
