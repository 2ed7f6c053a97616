"""Finite-element hinges: gmsh meshes, scikit-fem solves (see the modules)."""
