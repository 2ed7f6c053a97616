"""
Hinge stiffness from geometry (dissertation Ch. 5, Appendix A notch_stiff.sci, cant_stiff.sci).

Each function returns the planar 3x3 stiffness K = [[Ko, Kc], [Kc^T, Kt]] (moment first,
forces second) in the hinge frame, at the hinge's centre of stiffness, in SI units.
"""
from __future__ import annotations

import numpy as np

from flexure_sim.errors import as_array
from flexure_sim.engine.kinematics.hyperdual import HyperDual


def _numbers(**named):
    """
    Return the named arguments as NumPy scalars.

    Arithmetic overflows to inf, which callers check, instead of raising; arrays or
    non-numbers raise a ValueError naming the argument.
    Hyper-dual numbers pass unchanged: the formulas are plain arithmetic, so exact design
    sensitivities (engine/analysis/sensitivity.py) flow through them.
    """
    return [value if isinstance(value, HyperDual) else as_array(name, value, ())[()]
            for name, value in named.items()]


def shear_modulus(E: float, nu: float) -> float:
    """G = E / (2 (1 + nu)) for an isotropic material."""
    return 0.5 * E / (1.0 + nu)


def notch_stiffness(D: float, h: float, t: float, E: float, nu: float) -> np.ndarray:
    """
    Planar stiffness of a circular notch hinge (eqs. 5.27-5.33, notch_stiff.sci).

    D: hole diameter, h: inter-hole spacing (thinnest section), t: plate thickness, all in
    metres; E: Young's modulus (Pa); nu: Poisson's ratio.
    Ko = kappa_2o E t h^2 (5.28); Kt = diag(kappa_1t E t, kappa_3t E t) (5.29-5.30), the
    first along the hinge frame's x axis, the second along its y axis, as microstage.sci
    assigns them (Kt = diag(K(4,4), K(6,6)) of the 6x6 result).
    """
    D, h, t, E, nu = _numbers(D=D, h=h, t=t, E=E, nu=nu)
    hd = h / D
    s = np.sqrt(hd)
    kappa_1t = 0.1452 * hd + 0.3568 * s
    kappa_3t = -0.06692 * hd**1.5 + 0.283 * hd - 0.03443 * s
    kappa_2o = -0.035 * hd + 0.1109 * s
    Ko = kappa_2o * E * t * h**2
    return np.diag([Ko, kappa_1t * E * t, kappa_3t * E * t])


def cantilever_stiffness(
    length: float, thickness: float, width: float, E: float, nu: float
) -> np.ndarray:
    """
    Planar stiffness of a leaf (cantilever) hinge at its centroid (eq. 5.8, cant_stiff.sci).

    The leaf runs along the hinge frame's y axis (as in fourbar.sci): bending in the plane
    gives Ko = E I / L and the shear stiffness along x, 12 E I / L^3; the axial stiffness
    along y is A E / L, with I = width * thickness^3 / 12 and A = width * thickness.
    nu is accepted for symmetry with notch_stiffness (torsion is out of plane).
    """
    length, thickness, width, E, nu = _numbers(
        length=length, thickness=thickness, width=width, E=E, nu=nu)
    del nu  # the in-plane terms do not depend on it
    inertia = width * thickness**3 / 12.0
    area = width * thickness
    L = length
    return np.diag([E * inertia / L, 12.0 * E * inertia / L**3, area * E / L])


#: Stiffness models with a geometry: the formula and the names of its arguments, as the
#: mechanism file's keys (mechanism/loader.py loads them, mechanism/parameters.py varies them).
MODELS = {
    "notch": (notch_stiffness, ("D", "h", "t", "E", "nu")),
    "cantilever": (cantilever_stiffness, ("length", "thickness", "width", "E", "nu")),
}
