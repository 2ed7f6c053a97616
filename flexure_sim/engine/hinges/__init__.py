"""
Hinges as parts: stiffness and peak stress from a hinge's geometry and material.

- ``spatial_stiffness``: Hinge stiffness in space: 6x6 matrices from geometry, and how they move
  with the frame.
- ``stiffness``: Hinge stiffness from geometry (dissertation Ch. 5, Appendix A notch_stiff.sci,
  cant_stiff.sci).
- ``stress``: Peak stress in notch and leaf hinges from their wrench, and the stress ratio sigma /
  sigma_y.
"""
