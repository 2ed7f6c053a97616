"""
Planar kinematics (rotations, twists, twistors) and hyper-dual numbers.

- ``hyperdual``: Hyper-dual numbers: a value with two first derivatives and their mixed second
  derivative.
- ``planar``: Planar kinematics: rotations, twists and twistors (dissertation Ch. 2).
"""
