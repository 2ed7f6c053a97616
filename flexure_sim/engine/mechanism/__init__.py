"""
Mechanisms as data: bodies, hinges, drives; their YAML files loaded and checked.

- ``actuator_block``: The ``actuator:`` block of a drive (a piezo stack,
  engine/actuators/piezo.py), checked.
- ``builtins``: Where the built-in mechanisms (the ``config/*.yaml`` files shipped with the
  package) live.
- ``constraints_block``: Constraints, drives, outputs and the output sensor of a mechanism file,
  checked.
- ``damping_block``: Damping in a mechanism file, checked: each hinge's ``damping`` and the
  mechanism's ``damping:``.
- ``damping_models``: Damping models built from the modes at rest.
- ``doc_paths``: Paths into a mechanism's YAML document.
- ``loader``: Loading mechanisms from YAML, with validation that names the file, the key and the
  problem.
- ``parameters``: Design parameters of a mechanism file by path, and the Design they build.
- ``parts``: Mechanisms as plain data: bodies, hinges, constraints, drive (the MjModel of
  flexure_sim).
- ``planar_in_space``: A planar mechanism file opened in 3-D: the same mechanism with its
  out-of-plane freedoms.
- ``polynomial_files``: Polynomial hinge files.
- ``spatial_loader``: Loading spatial mechanisms: ``space: 3d`` files, and planar files opened in
  3-D.
- ``spatial_parts``: Spatial mechanisms as plain data: bodies, hinges, constraints, drives and
  outputs in 3-D.
- ``stiffness_block``: Hinge stiffness in a mechanism file, checked: a ``stiffness`` specification
  and K's validity.
- ``values``: Checked reading of values from a mechanism file, with messages that name the file and
  the key.
- ``yaml_files``: Reading text and YAML data files, with one-line errors that name the file and the
  problem.
"""
