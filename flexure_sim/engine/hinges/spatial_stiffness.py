"""
Hinge stiffness in space: 6x6 matrices from geometry, and how they move with the frame.

Every matrix is in the hinge frame at the hinge's centre of stiffness, rotations first:
K = diag(k_rx, k_ry, k_rz, k_x, k_y, k_z) for the symmetric hinges below (Pa, N/m, N m/rad).
The in-plane block (rz, x, y) is the planar engine's 3x3 (``hinges.stiffness``) unchanged, so
a planar mechanism keeps its in-plane behaviour; the out-of-plane terms (rx, ry, z) are beam
theory over the hinge's profile (Lobontiu, "Compliant Mechanisms: Design of Flexure Hinges",
CRC 2002, ch. 2: the compliances are integrals of 1/(E I), 1/(G J) and 1/(kappa G A) along
the hinge), with

- bending out of the plane: 1/k_r = int dl / (E I_o(l)), I_o = h w^3 / 12 the second moment
  about the in-plane transverse axis (w: the width out of the plane, h: the in-plane thickness);
- translation out of the plane at the centre: 1/k_z = int l^2 dl / (E I_o(l)) + int dl /
  (kappa G w h(l)), Timoshenko's shear term with Cowper's coefficient for a rectangle
  kappa = 10 (1 + nu) / (12 + 11 nu) (G. R. Cowper, J. Appl. Mech. 33 (1966) 335);
- torsion about the hinge's length: Saint-Venant's 1/k_sv = int dl / (G J(l)) with the exact
  torsion constant of a rectangle (Timoshenko and Goodier, "Theory of Elasticity", 3rd ed.
  1970, sec. 109), J = a b^3 [1/3 - 64 b / (pi^5 a) sum_{n odd} tanh(n pi a / (2 b)) / n^5],
  a >= b the sides; plus the restraint of warping by the two rigid ends, k_w = (w^2 / 12)
  k_t, k_t the in-plane transverse stiffness of the same profile in Euler-Bernoulli bending
  (each strip of the width bends between the ends). For a uniform strip k_w is Vlasov's
  12 E C_w / L^3 with C_w = w^3 h^3 / 144 (AISC Design Guide 9, 2003, Appendix C), and
  k_sv + k_w is within 11 % below the exact built-in solution (G J / L) / (1 - 2 tanh(x/2)/x),
  x = L sqrt(G J / (E C_w)) (Timoshenko and Gere, "Theory of Elastic Stability", 1961,
  sec. 5.3) for every x. Without it a notch much wider than long would be
  hundreds of times too soft in torsion (the stage's notch: 3.8 against 829 N m/rad).

``notch``: circular notch of hole diameter D, neck h, plate thickness t: the length runs
along the hinge frame's x axis, the neck's thickness h(l) = h + 2 r - 2 sqrt(r^2 - l^2)
(r = D/2, |l| <= r) along y, the width t along z. ``cantilever`` (leaf): length along y,
thickness along x, width along z (the planar engine's conventions). ``rod``: a round wire
flexure (3-D files only), length along y. ``matrix``: a given
symmetric positive definite 6x6 (``K``). Further models with numeric keys register in
``MODELS`` (``register``). The finite-element hinge (``model: fe``, whose block names a shape)
is checked by the loader's fe block and gives its 6x6 from a 3-D solid (engine/hinges/fe/
solid.py) in this frame and order, so it replaces ``notch`` or ``cantilever`` as it stands.
"""
from __future__ import annotations

from typing import Callable

import numpy as np

from flexure_sim.engine.hinges import stiffness as planar
from flexure_sim.engine.kinematics import hyperdual as hd

#: Gauss-Legendre nodes and weights on [-1, 1] for the notch integrals (module docstring).
_NODES, _WEIGHTS = np.polynomial.legendre.leggauss(64)
#: Terms of the rectangle's torsion series (tanh(n pi a/2b) -> 1: the tail is below 1e-18).
_ODD = np.arange(1, 400, 2, dtype=float)


def torsion_constant(a: float, b: float) -> float:
    """
    Return Saint-Venant's torsion constant J (m^4) of an a x b rectangle (module docstring).

    a and b are floats or HyperDual numbers (the sides compared by their values).
    """
    long, short = (a, b) if hd.real(a) >= hd.real(b) else (b, a)
    ratio = short / long
    series = (np.tanh(_ODD * np.pi / (2.0 * ratio)) / _ODD**5).sum()
    return long * short**3 * (1.0 / 3.0 - 64.0 * ratio / np.pi**5 * series)


def cowper(nu: float) -> float:
    """Return Cowper's shear coefficient of a rectangular section, 10 (1 + nu) / (12 + 11 nu)."""
    return 10.0 * (1.0 + nu) / (12.0 + 11.0 * nu)


def out_of_plane(length, weight, thickness, width: float, E: float, nu: float):
    """
    Return (k_torsion, k_bending, k_translation) of a profile given by quadrature.

    ``length``, ``weight``, ``thickness``: nodes l_i along the hinge (about its centre),
    their weights, and the in-plane thickness h(l_i); ``width``: the width out of the plane.
    The formulas are the module docstring's; every argument may be a float or a HyperDual
    (design sensitivities, ``analysis.spatial_sensitivity``).
    """
    G = planar.shear_modulus(E, nu)
    l, wgt, h = (hd.asarray(v) for v in (length, weight, thickness))
    bend = (wgt * 12.0 / (E * h * width**3)).sum()
    shift = (wgt * l**2 * 12.0 / (E * h * width**3)).sum()
    shear = (wgt / (cowper(nu) * G * width * h)).sum()
    twist = (wgt / (G * hd.asarray([torsion_constant(width, h[i]) for i in range(len(h))]))).sum()
    transverse = 1.0 / (wgt * l**2 * 12.0 / (E * width * h**3)).sum()
    return 1.0 / twist + width**2 / 12.0 * transverse, 1.0 / bend, 1.0 / (shift + shear)


def notch_profile(D: float, h: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """
    Return quadrature (l_i, weights, h(l_i)) of the circular notch's profile over |l| <= r.

    With l = r sin(phi), h(phi) = h + 2 r (1 - cos phi), and tan(phi/2) = k tan(psi),
    k = sqrt(h / (h + 4 r)): dl / h(l) = (2 k r / h) cos(phi) d psi, so every integrand of
    ``out_of_plane`` is smooth in psi on |psi| <= atan(1/k) for any h/r, and 64 Gauss-Legendre
    points give it to rounding (a test checks against scipy.integrate.quad).
    """
    r = 0.5 * D
    k = np.sqrt(h / (h + 4.0 * r))
    top = np.arctan(1.0 / k)
    psi = top * _NODES
    phi = 2.0 * np.arctan(k * np.tan(psi))
    thick = h + 2.0 * r * (1.0 - np.cos(phi))
    dphi = 2.0 * k / (np.cos(psi) ** 2 * (1.0 + (k * np.tan(psi)) ** 2))
    return r * np.sin(phi), top * _WEIGHTS * r * np.cos(phi) * dphi, thick


def notch_stiffness(D: float, h: float, t: float, E: float, nu: float) -> np.ndarray:
    """
    6x6 stiffness of a circular notch hinge (module docstring; length along x).

    In plane: ``hinges.stiffness.notch_stiffness`` (the dissertation's eqs. 5.27-5.33);
    out of plane: beam theory over the notch profile, width t.
    """
    k_rz, k_x, k_y = _diagonal(planar.notch_stiffness(D, h, t, E, nu))
    k_rx, k_ry, k_z = out_of_plane(*notch_profile(D, h), t, E, nu)
    return _diag([k_rx, k_ry, k_rz, k_x, k_y, k_z])


def cantilever_stiffness(length: float, thickness: float, width: float, E: float,
                         nu: float) -> np.ndarray:
    """
    6x6 stiffness of a leaf spring at its centre (module docstring; length along y).

    In plane: ``hinges.stiffness.cantilever_stiffness`` (eq. 5.8); out of plane: torsion
    about y, bending about x and translation along z of the uniform profile (two-point
    Gauss-Legendre is exact for it).
    """
    k_rz, k_x, k_y = _diagonal(planar.cantilever_stiffness(length, thickness, width, E, nu))
    half = 0.5 * length
    nodes = half * np.array([-1.0, 1.0]) / np.sqrt(3.0)
    k_ry, k_rx, k_z = out_of_plane(nodes, [half, half], [thickness, thickness], width, E, nu)
    return _diag([k_rx, k_ry, k_rz, k_x, k_y, k_z])


def rod_stiffness(length: float, diameter: float, E: float, nu: float) -> np.ndarray:
    """
    6x6 stiffness of a round wire (rod) flexure at its centre, length along y.

    Bending about x and z: E I / L; translation along x and z: 1 / (L^3 / (12 E I) + L /
    (kappa G A)) with Cowper's kappa = 6 (1 + nu) / (7 + 6 nu) of a circle; torsion about y:
    G J / L (a circle does not warp); axial: E A / L; I = pi d^4 / 64, J = 2 I, A = pi d^2 / 4.
    """
    G = planar.shear_modulus(E, nu)
    area = np.pi * diameter**2 / 4.0
    inertia = np.pi * diameter**4 / 64.0
    kappa = 6.0 * (1.0 + nu) / (7.0 + 6.0 * nu)
    bend = E * inertia / length
    shift = 1.0 / (length**3 / (12.0 * E * inertia) + length / (kappa * G * area))
    return _diag([bend, 2.0 * G * inertia / length, bend, shift, E * area / length, shift])


def _diagonal(M) -> list:
    """Return the diagonal entries of a square float or HyperDual matrix."""
    return [M[i, i] for i in range(len(M))]


def _diag(values) -> np.ndarray:
    """Return the diagonal matrix of ``values``: floats, or a HyperDual if any is one."""
    return hd.asarray([[v if i == j else 0.0 for j in range(len(values))]
                       for i, v in enumerate(values)])


#: 6x6 stiffness models with a geometry: the formula and its arguments (the file's keys).
MODELS: dict[str, tuple[Callable[..., np.ndarray], tuple[str, ...]]] = {
    "notch": (notch_stiffness, ("D", "h", "t", "E", "nu")),
    "cantilever": (cantilever_stiffness, ("length", "thickness", "width", "E", "nu")),
    "rod": (rod_stiffness, ("length", "diameter", "E", "nu")),
}


def register(name: str, formula: Callable[..., np.ndarray], keys: tuple[str, ...]) -> None:
    """Make ``model: name`` available in 3-D mechanism files: formula(*keys) -> 6x6 K."""
    MODELS[name] = (formula, tuple(keys))


def adjoint(R: np.ndarray, p: np.ndarray) -> np.ndarray:
    """
    Return Ad(R, p) (6x6, rotation first): a twist in frame c' -> the same twist in frame c.

    For a frame c' with pose (R, p) in frame c, (w, v) in c' (v the velocity of c''s origin)
    is (R w, R v + p x R w) in c (the spatial eq. 4.38).
    """
    R, p = np.asarray(R, dtype=float), np.asarray(p, dtype=float)
    P = np.array([[0.0, -p[2], p[1]], [p[2], 0.0, -p[0]], [-p[1], p[0], 0.0]])
    A = np.zeros((6, 6))
    A[:3, :3] = A[3:, 3:] = R
    A[3:, :3] = P @ R
    return A


def transform_stiffness(K: np.ndarray, R: np.ndarray, p: np.ndarray) -> np.ndarray:
    """
    Return the stiffness for hinge frames moved by (R, p) on both bodies: Ad^T K Ad.

    The deflection is conjugated, D = g D' g^-1, so its twist and its dual quaternion's vector
    part map by Ad(R, p) and the potential keeps its value (Sections 3.3, 4.6, in space).
    """
    A = adjoint(R, p)
    return A.T @ np.asarray(K, dtype=float) @ A
