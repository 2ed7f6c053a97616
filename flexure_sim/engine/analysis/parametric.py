"""
The mechanism's hinge forces as a function of its coordinates *and* its design parameters.

It is written in arithmetic that accepts hyper-dual numbers (``kinematics/hyperdual.py``).

The engine's force paths (``solver/assembly.py``, ``solver/kernels.py``) take floats only.
Sensitivities need the forces with derivative parts flowing from a parameter of the mechanism file
(a notch thickness h, a hinge position, a body mass) through the stiffness formulas
(``stiffness.notch_stiffness`` / ``cantilever_stiffness``, called unchanged), the hinge
positions, the relative displacement r(z) (eq. 2.81 with the poses of eq. 6.1) and the
quadratic laws (twistor 4.7, twist 3.4). ``forces`` is that chain written with NumPy
operations only, so the same code runs on floats and on ``HyperDual`` arrays:

    r = (alpha, p),  alpha = th_B + phi_b - th_A - phi_a,
    p = R(th_A + phi_a)^T (P_B + R(th_B) c_b - P_A - R(th_A) c_a),
    c = (xi, x1, x2) (twistor, 2.132-2.135) or (tau, t1, t2) (twist, 2.106-2.108),
    total_r = dc/dr^T (W c + C dc/dr r_dot)       (W = 4K, C = 4B twistor; K, B twist),
    Q = -dr/dz^T total_r,   wrench on B = -(total_0, R(alpha)^T total_{1,2})  (3.53, 4.35).

It is the quadratic-law path of ``kernels.quadratic_forces`` written for generic
arithmetic; a test checks that both agree to rounding and that its derivative parts equal
the engine's exact Jacobians.

Design parameters by path are in ``mechanism/parameters.py``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from flexure_sim.engine.kinematics import hyperdual as hd
from flexure_sim.engine.mechanism.parameters import Design


@dataclass
class Forces:
    """
    Q (..., N) generalized forces.

    R (..., n, 3) deflections; wrench (..., n, 3) on body B in frame b (moment, fx, fy); energy
    (..., n).
    """

    Q: Any
    r: Any
    wrench: Any
    energy: Any


def forces(
    design: Design, twistor: np.ndarray, ia: np.ndarray, ib: np.ndarray, z, v=None
) -> Forces:
    """
    Return the hinge forces at coordinates z and velocities v, as in the module docstring.

    z and v have length N in the last axis; float or HyperDual; v None: at rest, no damping
    terms.
    """
    A, B = 3 * ia, 3 * ib
    xA, yA, thA = z[..., A], z[..., A + 1], z[..., A + 2]
    xB, yB, thB = z[..., B], z[..., B + 1], z[..., B + 2]
    ca, cb = design.ca, design.cb
    cosA, sinA, cosB, sinB = np.cos(thA), np.sin(thA), np.cos(thB), np.sin(thB)
    beta = thA + design.phia
    ce, se = np.cos(beta), np.sin(beta)
    wa1 = cosA * ca[..., 0] - sinA * ca[..., 1]
    wa2 = sinA * ca[..., 0] + cosA * ca[..., 1]
    wb1 = cosB * cb[..., 0] - sinB * cb[..., 1]
    wb2 = sinB * cb[..., 0] + cosB * cb[..., 1]
    d1 = xB + wb1 - xA - wa1
    d2 = yB + wb2 - yA - wa2
    p1 = ce * d1 + se * d2
    p2 = -se * d1 + ce * d2
    alpha = thB + design.phib - beta
    # dr/dzz rows (alpha, p1, p2) over (xA, yA, thA, xB, yB, thB), as Assembly.relative.
    ta1, ta2 = -ce * wa2 + se * wa1, se * wa2 + ce * wa1
    tb1, tb2 = -ce * wb2 + se * wb1, se * wb2 + ce * wb1
    dr = (
        (0.0, 0.0, -1.0, 0.0, 0.0, 1.0),
        (-ce, -se, p2 - ta1, ce, se, tb1),
        (se, -ce, -p1 - ta2, -se, ce, tb2),
    )
    c, dc = _law_coordinates(twistor, alpha, p1, p2)
    scale = np.where(twistor, 4.0, 1.0)[:, None, None]
    W = _entries(design.K * scale)
    e = [_dot(W[k], c) for k in range(3)]
    energy = 0.5 * _dot(c, e)
    if v is not None:  # damping: C (dc/dr) r_dot, with r_dot = dr/dzz v
        vv = [v[..., A], v[..., A + 1], v[..., A + 2], v[..., B], v[..., B + 1], v[..., B + 2]]
        rdot = [_dot(dr[i], vv) for i in range(3)]
        cdot = [_dot(dc[k], rdot) for k in range(3)]
        C = _entries(design.B * scale)
        e = [e[k] + _dot(C[k], cdot) for k in range(3)]
    total = [_dot([dc[k][i] for k in range(3)], e) for i in range(3)]
    q_local = [-_dot([dr[i][j] for i in range(3)], total) for j in range(6)]
    Q = _scatter(q_local, ia, ib, z.shape[-1])
    ca_, sa_ = np.cos(alpha), np.sin(alpha)
    wrench = _stack(
        [-total[0], -(ca_ * total[1] + sa_ * total[2]), -(-sa_ * total[1] + ca_ * total[2])]
    )
    r = _stack([alpha, p1, p2])
    return Forces(Q, r, wrench, energy)


def _dot(coefficients, values):
    """
    sum_i a_i x_i.

    Skipping the structural zeros and units of the coefficient lists (most entries of dr/dzz and
    dc/dr, off-diagonal stiffness) -- they cost four array products each in hyper-dual arithmetic.
    """
    terms = []
    for a, x in zip(coefficients, values):
        if isinstance(a, float):
            if a == 0.0:
                continue
            terms.append(x if a == 1.0 else (-x if a == -1.0 else a * x))
        elif isinstance(x, float) and x == 0.0:
            continue
        else:
            terms.append(a * x)
    if not terms:
        return 0.0
    out = terms[0]
    for t in terms[1:]:
        out = out + t
    return out


def _entries(M):
    """Rows of M[..., k, m] (n, 3, 3) as nested lists, 0.0 where every part is zero."""
    parts = hd.parts_of(M) if isinstance(M, hd.HyperDual) else (M,)
    return [
        [0.0 if not any(np.any(p[..., k, m]) for p in parts) else M[..., k, m] for m in range(3)]
        for k in range(3)
    ]


def _law_coordinates(twistor, alpha, p1, p2):
    """Return c (3 components) and dc/dr (3x3) for twistor (xi, x1, x2) or twist (tau, t1, t2)."""
    sg, xi = np.cos(0.5 * alpha), np.sin(0.5 * alpha)
    x1 = 0.5 * (sg * p1 + xi * p2)
    x2 = 0.5 * (-xi * p1 + sg * p2)
    if np.all(twistor):
        return (xi, x1, x2), (
            (0.5 * sg, 0.0, 0.0),
            (0.5 * x2, 0.5 * sg, 0.5 * xi),
            (-0.5 * x1, -0.5 * xi, 0.5 * sg),
        )
    f, f1 = _half_cot(alpha)
    t = (alpha, f * p1 + 0.5 * alpha * p2, f * p2 - 0.5 * alpha * p1)
    dt = (
        (1.0, 0.0, 0.0),
        (f1 * p1 + 0.5 * p2, f, 0.5 * alpha),
        (f1 * p2 - 0.5 * p1, -0.5 * alpha, f),
    )

    def pick(a, b):
        return _where(twistor, a, b)

    return (
        tuple(pick(a, b) for a, b in zip((xi, x1, x2), t)),
        tuple(
            tuple(pick(a, b) for a, b in zip(ra, rb))
            for ra, rb in zip(
                (
                    (0.5 * sg, 0.0, 0.0),
                    (0.5 * x2, 0.5 * sg, 0.5 * xi),
                    (-0.5 * x1, -0.5 * xi, 0.5 * sg),
                ),
                dt,
            )
        ),
    )


def _half_cot(alpha):
    """Return f = (a/2) cot(a/2) and f' (series below |a| = 1e-2, as hinge_laws)."""
    a_real = hd.real(alpha)
    small = np.abs(a_real) < 1e-2
    safe = _where(small, 1.0, alpha)
    s, co = np.sin(0.5 * safe), np.cos(0.5 * safe)
    f_exact = 0.5 * safe * co / s
    f1_exact = 0.5 * co / s - 0.25 * safe / (s * s)
    a2 = alpha * alpha
    f_series = 1.0 - a2 / 12.0 - a2 * a2 / 720.0 - a2 * a2 * a2 / 30240.0
    f1_series = -alpha * (1.0 / 6.0 + a2 / 180.0 + a2 * a2 / 5040.0)
    return _where(small, f_series, f_exact), _where(small, f1_series, f1_exact)


def _where(cond, x, y):
    if not isinstance(x, hd.HyperDual) and not isinstance(y, hd.HyperDual):
        return np.where(cond, x, y)
    xs, ys = hd.parts_of(x), hd.parts_of(y)
    shape = np.broadcast_shapes(np.shape(cond), xs[0].shape, ys[0].shape)
    return hd.HyperDual(
        *(
            np.where(cond, np.broadcast_to(a, shape), np.broadcast_to(b, shape))
            for a, b in zip(xs, ys)
        )
    )


def _stack(items):
    if any(isinstance(x, hd.HyperDual) for x in items):
        return hd.stack(items)
    return np.stack(np.broadcast_arrays(*items), axis=-1)


def _scatter(q_local, ia, ib, N):
    """
    Sum the per-hinge six forces into the N generalized forces.

    One product with the 0/1 scatter matrix (a linear map, applied part by part for HyperDuals).
    """
    n = len(ia)
    S = np.zeros((n, 6, N))
    rows = np.arange(n)
    for j in range(3):
        S[rows, j, 3 * ia + j] += 1.0
        S[rows, 3 + j, 3 * ib + j] += 1.0
    S = S.reshape(6 * n, N)
    q = _stack(q_local)  # (..., n, 6)
    if isinstance(q, hd.HyperDual):
        return hd.HyperDual(
            *(
                p.reshape(p.shape[:-2] + (6 * n,)) @ S if p.ndim else p
                for p in (q.a, q.b, q.c, q.d)
            )
        )
    return q.reshape(q.shape[:-2] + (6 * n,)) @ S
