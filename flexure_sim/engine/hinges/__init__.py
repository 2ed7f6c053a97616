"""
Hinges as parts: stiffness and peak stress from a hinge's geometry and material.

- ``spatial_stiffness``: Hinge stiffness in space: 6x6 matrices from geometry, and how they move
  with the frame.
- ``stiffness``: Hinge stiffness from geometry (dissertation Ch. 5, Appendix A notch_stiff.sci,
  cant_stiff.sci).
- ``stress``: Peak stress in notch and leaf hinges from their wrench, and the stress ratio sigma /
  sigma_y.
- ``fe``: finite-element hinges (gmsh meshes, scikit-fem solves): stiffness, peak stress and
  large-deflection wrench data from the hinge's own geometry (``model: fe``).
- ``materials``: Materials by name (the shipped ``materials.yaml``, a source per value) and a
  hinge's strengths.
- ``fatigue``: Goodman and Soderberg safety factors of a cyclic load, the critical hinge, the
  input for infinite life.
"""
