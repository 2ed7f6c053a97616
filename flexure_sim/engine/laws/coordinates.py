"""
Law coordinates c(r) of a hinge's relative displacement r = (alpha, p1, p2), with derivatives.

A hinge law is a potential in law coordinates (engine/laws/quadratic.py):

- twistor: c = (sigma, xi, x1, x2) (eqs. 2.132-2.135): sigma = cos(alpha/2), xi = sin(alpha/2),
  x = 1/2 R(-alpha/2) p (eq. 2.178), R(-alpha/2) = [[sigma, xi], [-xi, sigma]]: the unit dual
  quaternion's x restricted to the plane (``quaternion.twistor_translation``, the one
  definition of it for both engines). From
  d/dalpha R(-alpha/2) = -1/2 J R(-alpha/2): dx/dalpha = -1/2 J x, dx/dp = 1/2 R(-alpha/2) --
  the virtual displacement map of eq. 4.27 written in r; d2x/dalpha2 = -1/4 x,
  d2x/dalpha dp = -1/4 J R(-alpha/2).
- twist: c = (tau, t1, t2) (eqs. 2.106-2.108): tau = alpha, t = f(alpha) p - (alpha/2) J p with
  f = (alpha/2) cot(alpha/2) (``planar.half_cot``); dt/dalpha = f' p - 1/2 J p,
  dt/dp = f I - (alpha/2) J, d2t/dalpha2 = f'' p, d2t/dalpha dp = f' I - 1/2 J.

``twistor`` and ``twist`` are the one definition of each map, on a generic scalar
(kinematics/scalar.py): compiled per hinge in the force kernel, on arrays of hinges here
(``twistor_coordinates``, ``twist_coordinates``: the ``CoordinateMap`` every law evaluates), on
HyperDual arrays for sensitivities. Each returns (c, dc) as nested tuples: c_k, dc_k/dr_i;
``twistor_second`` and ``twist_second`` the d2c_k/dr_i dr_j the assembly's exact Jacobians
need (the force chain does not: it leaves them out).
"""
from __future__ import annotations

from dataclasses import dataclass

from typing import Optional

import numpy as np

from flexure_sim.errors import as_array
from flexure_sim.engine.kinematics.planar import half_cot
from flexure_sim.engine.kinematics.quaternion import twistor_translation
from flexure_sim.engine.kinematics.scalar import formula, stacked


@formula
def twistor(alpha, p1, p2):
    """Return (sigma, xi, x1, x2) of r = (alpha, p1, p2) and their derivatives dc/dr."""
    half = 0.5 * alpha
    sg, xi = np.cos(half), np.sin(half)
    x1, x2, _ = twistor_translation(sg, (0.0, 0.0, xi), (p1, p2, 0.0))
    hs, hx = 0.5 * sg, 0.5 * xi
    nhx = -hx
    dc = ((nhx, 0.0, 0.0),
          (hs, 0.0, 0.0),
          (0.5 * x2, hs, hx),           # -1/2 (J x)_1 = +1/2 x2
          (-0.5 * x1, nhx, hs))         # -1/2 (J x)_2 = -1/2 x1
    return (sg, xi, x1, x2), dc


@formula
def twistor_second(alpha, p1, p2, c):
    """Return d2c/dr2 of the twistor (sigma, xi, x1, x2) = c of r = (alpha, p1, p2)."""
    sg, xi, x1, x2 = c
    qs, qx = 0.25 * sg, 0.25 * xi
    nqs, nqx = -qs, -qx
    zero = (0.0, 0.0, 0.0)
    return (((nqs, 0.0, 0.0), zero, zero),
            ((nqx, 0.0, 0.0), zero, zero),
            ((-0.25 * x1, nqx, qs), (nqx, 0.0, 0.0), (qs, 0.0, 0.0)),
            ((-0.25 * x2, nqs, nqx), (nqs, 0.0, 0.0), (nqx, 0.0, 0.0)))


@formula
def twist(alpha, p1, p2):
    """Return (tau, t1, t2) of r = (alpha, p1, p2) and their derivatives dc/dr."""
    f, f1, _ = half_cot(alpha)
    half = 0.5 * alpha
    c = (alpha, f * p1 + half * p2, f * p2 - half * p1)
    dc = ((1.0, 0.0, 0.0),
          (f1 * p1 + 0.5 * p2, f, half),
          (f1 * p2 - 0.5 * p1, -half, f))
    return c, dc


@formula
def twist_second(alpha, p1, p2, c):
    """Return d2c/dr2 of the twist (tau, t1, t2) = c of r = (alpha, p1, p2)."""
    _, f1, f2 = half_cot(alpha)
    zero = (0.0, 0.0, 0.0)
    return ((zero, zero, zero),
            ((f2 * p1, f1, 0.5), (f1, 0.0, 0.0), (0.5, 0.0, 0.0)),
            ((f2 * p2, -0.5, f1), (-0.5, 0.0, 0.0), (f1, 0.0, 0.0)))


# ------------------------------------------------------------- on arrays of hinges


def deflections(alpha, p, rdot=None):
    """
    Return alpha (n,), p (n, 2) (and rdot (n, 3)) as float arrays, checked.

    A ValueError names the argument of a wrong shape.
    """
    alpha = as_array("alpha", alpha, (None,))
    p = as_array("p", p, (alpha.shape[0], 2))
    if rdot is None:
        return alpha, p
    return alpha, p, as_array("rdot", rdot, (alpha.shape[0], 3))


@dataclass(frozen=True)
class CoordinateMap:
    """
    Law coordinates c(r) with first and second derivatives with respect to r.

    c: (n, k); dc: (n, k, 3) = dc/dr; d2c: (n, k, 3, 3) = d2c/dr2, None when not asked for.
    """

    c: np.ndarray
    dc: np.ndarray
    d2c: Optional[np.ndarray]


def _map(fn, fn_second, alpha, p, second: bool) -> CoordinateMap:
    """``fn`` and ``fn_second`` on n hinges, as arrays; ``second=False``: d2c None."""
    alpha, p = deflections(alpha, p)
    n = alpha.shape[0]
    p1, p2 = p[:, 0], p[:, 1]
    c, dc = fn(alpha, p1, p2)
    k = len(c)
    return CoordinateMap(stacked(c, n, (k,)), stacked(dc, n, (k, 3)),
                         stacked(fn_second(alpha, p1, p2, c), n, (k, 3, 3)) if second else None)


def twistor_coordinates(alpha, p, second: bool = True) -> CoordinateMap:
    """Twistor parameters (sigma, xi, x1, x2) of n hinges' r = (alpha, p) and derivatives."""
    return _map(twistor, twistor_second, alpha, p, second)


def twist_coordinates(alpha, p, second: bool = True) -> CoordinateMap:
    """Twist (tau, t1, t2) of n hinges' r = (alpha, p) and its derivatives (eqs. 2.106-2.108)."""
    return _map(twist, twist_second, alpha, p, second)


COORDINATES = {"twistor": twistor_coordinates, "twist": twist_coordinates}
