"""
A mechanism prepared for stepping (Model) apart from its State; the Simulation facade.

- ``actuation``: Piezo actuators (engine/actuators/piezo.py) in the stepping of a ``Model``:
  operator splitting.
- ``assembly``: Generalized forces of all hinges on all bodies, with exact Jacobians.
- ``compression``: Where and how a hinge's compression is measured (README "Conventions").
- ``derivatives``: The exact derivatives of a ``Model``'s first-order system (A, the energy
  integrals' ``Tangent``).
- ``drives``: The drives of a ``Model`` (its ``DriveTable``): their constants, inputs and
  commands, and what each one does.
- ``integrator``: Fixed-step stiff-stable stepping of a ``Model``, updating a ``Data``.
- ``kernels``: Compiled hot path: generalized hinge forces of quadratic laws, without Jacobians.
- ``model``: A mechanism prepared for stepping: the constants (as MuJoCo's mjModel), no state.
- ``partition``: Which coordinates are free and which the constraints prescribe.
- ``programs``: Drive programs: a drive's input as a function of time.
- ``simulation``: The simulation facade: a shared ``Model`` (constants) and its own ``Data``
  (state).
- ``snapshot``: What a simulation reports at one instant, read from a ``Model`` and a ``State``.
- ``state``: The mutable side of a simulation (as MuJoCo's mjData): state, counters, integrator
  caches.
- ``statics``: Static equilibrium of a ``Model``.
- ``step_energy``: Dissipated energy and drive work over one step of the exponential trapezoidal
  rule.
- ``step_loop``: The exponential trapezoidal rule, as one loop that Numba compiles when it can.
"""
