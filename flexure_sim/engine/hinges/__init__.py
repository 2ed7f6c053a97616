"""
Hinges as parts: stiffness and peak stress from a hinge's geometry and material.

- ``stiffness``: Hinge stiffness from geometry (dissertation Ch. 5, Appendix A notch_stiff.sci,
  cant_stiff.sci).
- ``stress``: Peak stress in notch and leaf hinges from their wrench, and the stress ratio sigma /
  sigma_y.
- ``fe``: finite-element hinges (gmsh meshes, scikit-fem solves): stiffness, peak stress and
  large-deflection wrench data from the hinge's own geometry (``model: fe``).
"""
