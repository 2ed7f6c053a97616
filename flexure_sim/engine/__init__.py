"""
The engine: flexure mechanics with the twistor-based potential energy method, planar and spatial.

No ROS here. Sub-packages, each importing only the ones listed before it:

- ``kinematics``: rotations, twists, twistors; hyper-dual numbers;
- ``laws``: hinge potentials (quadratic, polynomial) with wrench, damping, energy, power;
- ``hinges``: hinge stiffness and peak stress from geometry;
- ``actuators``: the piezo stack and the output sensor;
- ``mechanism``: bodies, hinges, drives as data, loaded and checked from YAML;
- ``solver``: Model (constants) and State, hinge forces, stepping, statics, Simulation;
- ``analysis``: linearisation, modes, FRF, sensitivities, sweeps;
- ``fitting``: wrench data and polynomial laws fitted to them (Chapter 7).

``jit`` holds Numba's ``njit`` and the kernel cache every compiled module uses.

The spatial engine (bodies with six coordinates, hinges with 6x6 stiffness) lives beside the
planar one in the same layers, its modules named ``spatial*``: ``kinematics.quaternion``,
``laws.spatial``, ``hinges.spatial_stiffness``, ``mechanism.spatial_loader``,
``solver.spatial_simulation`` (the facade), ``analysis.spatial_linear``.
"""
