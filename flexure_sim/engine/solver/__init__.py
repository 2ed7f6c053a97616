"""
A mechanism prepared for stepping (Model) apart from its State; the Simulation facade.

- ``actuation``: Piezo actuators (engine/actuators/piezo.py) in the stepping of a ``Model``:
  operator splitting.
- ``assembly``: Generalized forces of all hinges on all bodies, with exact Jacobians.
- ``compression``: Where and how a hinge's compression is measured (docs/engine.md, "Conventions").
- ``drives``: The drives of a ``Model``: their constants, inputs and commands, and what each one
  does.
- ``integrator``: Fixed-step stiff-stable stepping of a ``Model``, updating a ``Data``.
- ``kernels``: Compiled hot path: generalized hinge forces of quadratic laws, without Jacobians.
- ``model``: A mechanism prepared for stepping: the constants (as MuJoCo's mjModel), no state.
- ``simulation``: The simulation facade: a shared ``Model`` (constants) and its own ``Data``
  (state).
- ``snapshot``: What a simulation reports at one instant, read from a ``Model`` and a ``State``.
- ``spatial_chain``: Generalized forces of a spatial mechanism: hinges, gyroscopic terms, applied
  forces.
- ``spatial_integrator``: Fixed-step stiff-stable stepping of a ``SpatialModel``.
- ``spatial_kernels``: The spatial engine's compiled stepping: F(y, t) of a spatial mechanism, and
  the loop that steps it.
- ``spatial_model``: A spatial mechanism prepared for stepping: the constants, no state.
- ``spatial_simulation``: The spatial simulation facade: a shared ``SpatialModel`` and its own
  ``Data``.
- ``spatial_statics``: Static equilibrium of a ``SpatialModel`` and its exact static gain.
- ``state``: The mutable side of a simulation (as MuJoCo's mjData): state, counters, integrator
  caches.
- ``statics``: Static equilibrium of a ``Model``.
- ``step_energy``: Dissipated energy and drive work over one step of the exponential trapezoidal
  rule.
- ``step_loop``: The exponential trapezoidal rule, as one loop that Numba compiles when it can.
"""
