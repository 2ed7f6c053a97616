"""
Kinematics: planar (rotations, twists, twistors) and spatial (quaternions, rotation vectors).

- ``generic``: Formulas written once on a generic scalar: compiled by Numba, evaluated on
  hyper-dual numbers.
- ``hyperdual``: Hyper-dual numbers: a value with two first derivatives and their mixed second
  derivative.
- ``planar``: Planar kinematics: rotations, twists and twistors (dissertation Ch. 2).
- ``relative``: A hinge's relative displacement r(z) from the poses of its two bodies, and its
  derivatives.
- ``scalar``: Formulas written once on a generic scalar: floats in Numba, NumPy arrays,
  HyperDual arrays.
- ``quaternion``: Rotations of the spatial engine: unit quaternions, rotation vectors, and their
  Jacobians.
"""
