"""
The engine: planar flexure mechanics with the twistor-based potential energy method.

No ROS here. Layers, each importing only the ones above it:

- ``kinematics``: rotations, (R, p) <-> twist <-> twistor, adjoint maps;
- ``stiffness``: hinge stiffness from geometry (notch, cantilever);
- ``hinge_laws``, ``polynomial``: potentials, wrenches, damping, energy and power of the
  hinge laws (``monomials`` holds the polynomials' Appendix B algebra, ``polynomial_files``
  reads and writes the polynomial hinge files);
- ``mechanism``: bodies, hinges, constraints and drives as plain data; ``config`` loads and
  validates them from YAML (``yaml_files`` reads the files);
- ``assembly`` (+ the compiled ``kernels``): hinge forces on the bodies with exact Jacobians;
- ``model`` (constants of a mechanism prepared for stepping, as MuJoCo's mjModel) and
  ``data`` (state and integrator caches, as mjData); ``compression`` (where a hinge's
  compression is measured); ``dynamics`` (+ the compiled ``stepping`` loop), ``statics``,
  ``snapshot``: stepping, equilibria and reports, reading the model and updating the data;
  ``solver``: the ``Simulation`` facade over them;
- ``wrench_data``, ``fitting``, ``datasets``: measured wrenches and their CSV files, polynomial
  laws fitted to them, and the data sets (``randomtest``: Chapter 7.1).
"""
