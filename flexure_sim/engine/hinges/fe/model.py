"""
The ``model: fe`` hinge: stiffness and peak-stress coefficients in SI units, with derivatives.

Scaling. elastic.py solves with E = 1, a unit plate thickness and lengths in the shape's
reference length ell (the neck h, or the leaf's thickness); plane elasticity is linear in E
and in the plate thickness t, so with the dimensionless stiffness K^ of the solve

    K_oo = E t ell^2 K^_oo,   K_of = E t ell K^_of,   K_ff = E t K^_ff

(moment index o, force indices f), and the peak stress under a moment m or a force f is
sigma = m s^_m / (t ell^2) or f s^_f / (t ell). The solve depends only on the ratios of the
other lengths to ell, Poisson's ratio and the plane (solves.Case).

Plane stress or strain (``plane: auto``): plane stress is the thin-plate limit (the plate's
faces are free and the stress through the thickness vanishes); plane strain is the interior
of a plate much thicker than the hinge is long. A plate's free faces disturb the plane-strain
state over a depth of the order of the hinge's in-plane dimensions (Saint-Venant), so
``auto`` takes plane strain when the plate thickness t is at least the hinge's clamp-to-clamp
length (D for a circular notch, 2a for an elliptical one, ``length`` otherwise) and plane
stress below. The true three-dimensional stiffness lies between the two; the two differ by up
to 1/(1 - nu^2) (12 % in bending for nu = 0.33), and ``flexure-sim hinge`` prints both.

Derivatives. Design sensitivities pass hyper-dual numbers (engine/kinematics/hyperdual.py) for the
geometry, E and nu. E, t and ell enter through the scaling above, in hyper-dual arithmetic,
exactly. The dimensionless results F (K^ and s^) are functions of the ratios and nu, which
the finite-element model gives only pointwise: their first and second derivatives are central
differences of solves on the base mesh moved onto the perturbed outline (solves.morph), with
relative step ``STEP`` (1e-3 of each ratio, 1e-3 absolute for nu), and combined by the
hyper-dual rule

    F(a + b e1 + c e2 + d e1e2) = F(a) + F_k (b_k e1 + c_k e2 + d_k e1e2) + F_kl b_k c_l e1e2.

The moved mesh makes F smooth in the parameters, so the differences are free of re-meshing
noise: their truncation error is O(STEP^2) ~ 1e-6 relative and rounding ~1e-10 / STEP^2;
test_fe_model.py compares them with differences of independently meshed solves. One
parameter costs 3 solves (cached), a pair 4 more.
"""
from __future__ import annotations

import itertools
from typing import Any, Mapping

import numpy as np

from flexure_sim.engine.kinematics import hyperdual as hd
from flexure_sim.engine.hinges.fe.shapes import ShapeError, profile, shape
from flexure_sim.engine.hinges.fe.solves import DEFAULT_RESOLUTION, Case, solve

#: Relative finite-difference step of the derivatives in the ratios (absolute for nu).
STEP = 1e-3

#: Internal (leaf along x) -> the cantilever's convention (leaf along the hinge frame's y):
#: external component i is SIGN[i] times internal component ORDER[i].
_LEAF_ORDER = (0, 2, 1)
_LEAF_SIGN = (1.0, -1.0, 1.0)


def _real(x) -> float:
    return float(np.real(hd.real(x)))


def clamp_length(name: str, values: Mapping[str, Any]) -> float:
    """Return the hinge's clamp-to-clamp length, m (plain float)."""
    s = shape(name)
    ratios = tuple(_real(values[k]) / _real(values[s.lengths[0]]) for k in s.lengths[1:])
    return 2.0 * profile(name, ratios).half * _real(values[s.lengths[0]])


def plane_of(name: str, values: Mapping[str, Any], plane: str = "auto") -> str:
    """``stress`` or ``strain``: ``plane`` itself, or the module docstring's rule for auto."""
    if plane != "auto":
        return plane
    return "strain" if _real(values[shape(name).plate]) >= clamp_length(name, values) else "stress"


def _parts(x) -> tuple[float, float, float, float]:
    a, b, c, d = (float(np.asarray(p)) for p in hd.parts_of(x))
    return a, b, c, d


def _evaluate(case: Case, ratios, nu) -> np.ndarray:
    """
    [K^ (9), s^ (3), f^ (3k)] of the case's mesh moved to (ratios, nu); the case itself if equal.

    f^: the fibres' signed stresses (k, 3) under the unit wrenches, row by row (elastic.py).
    """
    target = None if (tuple(ratios) == case.ratios and nu == case.nu) else (tuple(ratios), nu)
    res = solve(case, target)
    return np.concatenate([np.linalg.inv(res.compliance).ravel(), res.peak, res.fibres.ravel()])


def dimensionless(name: str, values: Mapping[str, Any], nu, plane: str = "auto",
                  n: int = DEFAULT_RESOLUTION):
    """
    Return (K^ (3, 3), s^ (3,), f^ (k, 3), plane) of a hinge, the solve's convention scaled out.

    Floats, or object arrays of HyperDual scalars when the ratios or nu carry derivative parts
    (module docstring). The leaf is already turned to the cantilever's convention.
    """
    s = shape(name)
    plane = plane_of(name, values, plane)
    ell = values[s.lengths[0]]
    variables = [values[k] / ell for k in s.lengths[1:]] + [nu]
    parts = [_parts(v) for v in variables]
    a = [p[0] for p in parts]
    if not all(np.isfinite(a)):
        raise ShapeError(f"{name}: the geometry or nu is not finite ({a})")
    case = Case(name, tuple(a[:-1]), a[-1], plane, n)
    f0 = _evaluate(case, a[:-1], a[-1])
    active = [k for k, p in enumerate(parts) if any(p[1:])]
    if not active:
        out = f0
    else:
        steps = {k: STEP * (abs(a[k]) if k < len(a) - 1 else 1.0) for k in active}

        def at(shift: dict) -> np.ndarray:
            v = list(a)
            for k, dv in shift.items():
                v[k] += dv
            return _evaluate(case, v[:-1], v[-1])

        grad, hess = {}, {}
        for k in active:
            fp, fm = at({k: steps[k]}), at({k: -steps[k]})
            grad[k] = (fp - fm) / (2 * steps[k])
            hess[k, k] = (fp - 2 * f0 + fm) / steps[k] ** 2
        for k, j in itertools.combinations(active, 2):
            if not (any(parts[k][1:3]) and any(parts[j][1:3])):
                continue
            hk, hj = steps[k], steps[j]
            corners = (at({k: hk, j: hj}) - at({k: hk, j: -hj})
                       - at({k: -hk, j: hj}) + at({k: -hk, j: -hj}))
            hess[k, j] = hess[j, k] = corners / (4 * hk * hj)
        B = sum(grad[k] * parts[k][1] for k in active)
        C = sum(grad[k] * parts[k][2] for k in active)
        D = sum(grad[k] * parts[k][3] for k in active)
        D = D + sum(hess[k, j] * parts[k][1] * parts[j][2]
                    for k in active for j in active if (k, j) in hess)
        out = np.array([hd.HyperDual(*p) for p in zip(f0, B, C, D)], dtype=object)
    K, peak, fibres = out[:9].reshape(3, 3), out[9:12], out[12:].reshape(-1, 3)
    if name == "leaf":
        K = np.array([[_LEAF_SIGN[i] * _LEAF_SIGN[j] * K[_LEAF_ORDER[i], _LEAF_ORDER[j]]
                       for j in range(3)] for i in range(3)], dtype=K.dtype)
        peak = np.array([peak[o] for o in _LEAF_ORDER], dtype=peak.dtype)
        # sigma = a_int . w_int, w_int[ORDER[i]] = SIGN[i] w[i]: a[i] = SIGN[i] a_int[ORDER[i]]
        fibres = np.array([[_LEAF_SIGN[i] * row[_LEAF_ORDER[i]] for i in range(3)]
                           for row in fibres], dtype=fibres.dtype).reshape(-1, 3)
    return K, peak, fibres, plane


def _scaled(K, ell, factor):
    """E t S K^ S with S = diag(ell, 1, 1) (module docstring), element by element."""
    scale = (ell, 1.0, 1.0)
    rows = [[factor * scale[i] * scale[j] * K[i, j] for j in range(3)] for i in range(3)]
    return np.array(rows, dtype=object if K.dtype == object or _is_hd(factor, ell) else float)


def _is_hd(*xs) -> bool:
    return any(isinstance(x, hd.HyperDual) for x in xs)


def stiffness(name: str, values: Mapping[str, Any], E, nu, plane: str = "auto",
              n: int = DEFAULT_RESOLUTION):
    """
    Return the planar 3x3 stiffness of a ``model: fe`` hinge, SI units, at its frame.

    ``values``: the shape's geometry keys (shapes.SHAPES), floats or HyperDual; float array, or
    an object array of HyperDual entries when anything carries derivative parts.
    """
    return hinge(name, values, E, nu, plane, n)[0]


def stress_coefficients(name: str, values: Mapping[str, Any], nu, plane: str = "auto",
                        n: int = DEFAULT_RESOLUTION):
    """
    Peak von Mises stress per unit wrench component, (Pa/(N m), Pa/N, Pa/N), at the hinge frame.

    The stress under a wrench w is at most sum_i c_i |w_i| (von Mises is a norm of the stress
    tensor, so the peak of a sum is at most the sum of the peaks): exact for one component,
    a conservative bound for combined loads.
    """
    return hinge(name, values, 1.0, nu, plane, n)[1]


def fibre_coefficients(name: str, values: Mapping[str, Any], nu, plane: str = "auto",
                       n: int = DEFAULT_RESOLUTION) -> np.ndarray:
    """
    Signed stress per unit wrench at the surface's critical points, (k, 3), at the hinge frame.

    Row p holds (Pa/(N m), Pa/N, Pa/N): the von Mises stress at point p, signed as its
    tangential stress (tension positive), is row_p . (m, f_x, f_y) (elastic.py).
    """
    return hinge(name, values, 1.0, nu, plane, n)[2]


def hinge(name: str, values: Mapping[str, Any], E, nu, plane: str = "auto",
          n: int = DEFAULT_RESOLUTION):
    """
    Return (stiffness (3, 3), peak coefficients [3], fibre coefficients (k, 3)) of one solve.

    The three results of ``stiffness``, ``stress_coefficients`` and ``fibre_coefficients``;
    the stresses scale as sigma = m s^_m / (t ell^2), f s^_f / (t ell) (module docstring).
    """
    s = shape(name)
    ell, t = values[s.lengths[0]], values[s.plate]
    K, peak, fibres, _ = dimensionless(name, values, nu, plane, n)
    per = [t * ell * ell, t * ell, t * ell]
    rows = [[row[j] / per[j] for j in range(3)] for row in fibres]
    dual = fibres.dtype == object or _is_hd(ell, t)
    fibres = np.array(rows, dtype=object if dual else float).reshape(-1, 3)
    return _scaled(K, ell, E * t), [peak[j] / per[j] for j in range(3)], fibres
