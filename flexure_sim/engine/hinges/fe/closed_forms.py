"""
Closed-form hinge stiffnesses that apply to a finite-element hinge's shape, one definition each.

Every formula returns the planar stiffness (3, 3) at the hinge frame in the convention of the
finite-element model (model.py): moment first, forces second; for the notches the axial
direction is the frame's x axis, for the leaf its y axis (as ``stiffness.cantilever_stiffness``).
Entries a formula does not give are NaN. E is Young's modulus as the publications use it (the
narrow-beam, plane-stress modulus); ``flexure-sim hinge`` compares them with the
finite-element stiffness of either plane.

* ``dissertation``: eqs. 5.27-5.33 (``stiffness.notch_stiffness``, Appendix A notch_stiff.sci),
  circular notch; fitted by S. Zhang and E. D. Fasse to finite-element data (the dissertation's
  reference [60]).
* ``paros_weisbord``: J. M. Paros and L. Weisbord, "How to design flexure hinges", Machine
  Design 37 (1965) 151-156, simplified equations for a thin neck (h << R), circular notch:
  K_o = 2 E t h^(5/2) / (9 pi R^(1/2)) (the dissertation's eq. 6.2) and the axial compliance
  (pi sqrt(R/h) - 2.57) / (E t). Both are the leading terms of the beam integrals below as
  h/R -> 0 (2.57 ~ 1 + pi/2; test_fe_formulas.py checks the limit).
* ``beam``: Euler-Bernoulli integrals of the notch profile w(x) = 2 y_top(x),

      C_mm = int 12 / (E t w^3) dx,  C_xx = int 1 / (E t w) dx,  C_yy = int 12 x^2 / (E t w^3) dx

  over the clamp-to-clamp length, at the centre (where the symmetric profile decouples them).
  The full (exact) equations of Paros and Weisbord (1965) for the circular notch, and the
  closed forms of N. Lobontiu, "Compliant Mechanisms: Design of Flexure Hinges" (CRC, 2003,
  Ch. 2: circular, elliptical, corner-filleted) and of Y. Wu and Z. Zhou, "Design calculations
  for flexure hinges", Rev. Sci. Instrum. 73 (2002) 3101 (circular), are these integrals
  evaluated analytically; here they are evaluated by adaptive quadrature to 1e-12, which gives
  the same numbers for every shape without transcribing long expressions.
* ``timoshenko``: ``beam`` with the shear compliance int alpha / (G t w) dx, alpha = 6/5, added
  to C_yy: Lobontiu's transverse compliance of short hinges (2003, Ch. 2).
* ``cantilever``: eq. 5.8 (``stiffness.cantilever_stiffness``, cant_stiff.sci), the leaf
  without fillets (Euler-Bernoulli: K_o = E I / L, shear 12 E I / L^3, axial E A / L).

Not included: the finite-element-fitted equations of Y. Tian, B. Shirinzadeh, D. Zhang and
Y. Zhong (Precis. Eng. 34 (2010) 92) and of Y. K. Yong, T.-F. Lu and D. C. Handley (Precis.
Eng. 32 (2008) 63), whose coefficients were not available to check against the papers.
"""
from __future__ import annotations

from typing import Callable, Mapping

import numpy as np
from scipy.integrate import quad

from flexure_sim.engine.hinges.fe.shapes import profile, ratios_of, shape
from flexure_sim.engine.hinges.stiffness import (cantilever_stiffness, notch_stiffness,
                                                 shear_modulus)

#: Shear correction of a rectangular section (Timoshenko), as a compliance factor 1/k = 6/5.
SHEAR_FACTOR = 1.2


def _diag(ko, kx, ky) -> np.ndarray:
    return np.diag([ko, kx, ky]).astype(float)


def _leaf_turn(K: np.ndarray) -> np.ndarray:
    """Turn a beam stiffness with x along the leaf to the leaf-along-y convention."""
    return np.diag([K[0, 0], K[2, 2], K[1, 1]])


def _integrals(name: str, values: Mapping[str, float]) -> tuple[float, float, float, float, float]:
    """(int 1/w^3, int x^2/w^3, int 1/w, plate thickness, ell) of the profile, SI lengths."""
    s = shape(name)
    ell = float(values[s.lengths[0]])
    prof = profile(name, ratios_of(name, values))
    cuts = sorted({0.0, prof.flat, prof.half})

    def integral(f: Callable[[float], float]) -> float:
        total = 0.0
        for lo, hi in zip(cuts[:-1], cuts[1:]):
            if hi > lo:
                total += quad(f, lo, hi, epsabs=0.0, epsrel=1e-12, limit=400)[0]
        return 2.0 * total  # symmetric profile: twice the half from 0 to l

    def width(x):
        return 2.0 * float(prof.y_top(x))

    i3 = integral(lambda x: width(x) ** -3) / ell ** 2
    ix = integral(lambda x: x * x * width(x) ** -3)
    i1 = integral(lambda x: 1.0 / width(x))
    return i3, ix, i1, float(values[s.plate]), ell


def beam(name: str, values: Mapping[str, float], E: float, nu: float) -> np.ndarray:
    """Euler-Bernoulli integrals of the profile (module docstring)."""
    i3, ix, i1, t, _ = _integrals(name, values)
    K = _diag(E * t / (12.0 * i3), E * t / i1, E * t / (12.0 * ix))
    return _leaf_turn(K) if name == "leaf" else K


def timoshenko(name: str, values: Mapping[str, float], E: float, nu: float) -> np.ndarray:
    """``beam`` with the transverse shear compliance alpha int 1/(G t w) dx (module docstring)."""
    i3, ix, i1, t, _ = _integrals(name, values)
    cy = 12.0 * ix / (E * t) + SHEAR_FACTOR * i1 / (shear_modulus(E, nu) * t)
    K = _diag(E * t / (12.0 * i3), E * t / i1, 1.0 / cy)
    return _leaf_turn(K) if name == "leaf" else K


def dissertation(name: str, values: Mapping[str, float], E: float, nu: float) -> np.ndarray:
    """Eqs. 5.27-5.33 (``stiffness.notch_stiffness``)."""
    return notch_stiffness(values["D"], values["h"], values["t"], E, nu)


def paros_weisbord(name: str, values: Mapping[str, float], E: float, nu: float) -> np.ndarray:
    """Paros-Weisbord's simplified rotational and axial stiffness (module docstring)."""
    R, h, t = 0.5 * values["D"], values["h"], values["t"]
    ko = 2.0 * E * t * h ** 2.5 / (9.0 * np.pi * np.sqrt(R))
    kx = E * t / (np.pi * np.sqrt(R / h) - 2.57)
    return _diag(ko, kx, np.nan)


def cantilever(name: str, values: Mapping[str, float], E: float, nu: float) -> np.ndarray:
    """Eq. 5.8 (``stiffness.cantilever_stiffness``) for a leaf without fillets."""
    return cantilever_stiffness(values["length"], values["thickness"], values["width"], E, nu)


#: Formula name -> (function, the shapes it applies to, a short citation).
FORMULAS = {
    "dissertation": (dissertation, ("circular",),
                     "eqs. 5.27-5.33 (Zhang and Fasse's finite-element fit)"),
    "paros_weisbord": (paros_weisbord, ("circular",),
                       "Paros and Weisbord 1965, simplified (thin neck)"),
    "beam": (beam, ("circular", "elliptical", "corner_filleted", "leaf"),
             "Euler-Bernoulli integrals = Paros-Weisbord full, Lobontiu 2003, Wu-Zhou 2002"),
    "timoshenko": (timoshenko, ("circular", "elliptical", "corner_filleted", "leaf"),
                   "beam + shear (Lobontiu 2003, short hinges)"),
    "cantilever": (cantilever, ("leaf",), "eq. 5.8 (cant_stiff.sci), no fillets"),
}


def applicable(name: str, values: Mapping[str, float]) -> list[str]:
    """Return the formulas that apply to a shape (the cantilever: a leaf without fillets)."""
    out = [f for f, (_, shapes, _) in FORMULAS.items() if name in shapes]
    if name == "leaf" and float(values.get("fillet", 0.0)) > 0:
        out.remove("cantilever")
    return out


def evaluate(name: str, values: Mapping[str, float], E: float, nu: float) -> dict:
    """Return {formula: K (3, 3)} for every applicable formula."""
    return {f: FORMULAS[f][0](name, values, E, nu) for f in applicable(name, values)}
