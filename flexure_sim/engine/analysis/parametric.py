"""
The mechanism's hinge forces as a function of its coordinates *and* its design parameters.

Sensitivities need the forces with derivative parts flowing from a parameter of the mechanism
file (a notch thickness h, a hinge position, a body mass) through the stiffness formulas (applied
by the loader, mechanism/parameters.py), the hinge frames, the relative displacement r(z) and
the quadratic laws. ``forces`` evaluates the engine's one hinge force chain,
``laws.hinge_force.quadratic_hinge`` (the formulas the compiled stepping kernel runs), on arrays
of all hinges -- floats, or ``HyperDual`` arrays (kinematics/hyperdual.py) whose parts carry
those derivatives -- and sums each hinge's six forces into the generalised forces Q.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from flexure_sim.engine.kinematics import hyperdual as hd
from flexure_sim.engine.kinematics.scalar import where
from flexure_sim.engine.laws.hinge_force import quadratic_hinge
from flexure_sim.engine.laws.quadratic import METRIC_SCALE
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
    terms. Hinges of one law kind are evaluated together; with both kinds, each hinge takes
    its own kind's results.
    """
    A, B = 3 * ia, 3 * ib
    scale = np.where(twistor, METRIC_SCALE["twistor"], METRIC_SCALE["twist"])[:, None, None]
    W, C = _entries(design.K * scale), _entries(design.B * scale)
    moving = v is not None
    vA = vB = None
    if moving:
        vA = (v[..., A], v[..., A + 1], v[..., A + 2])
        vB = (v[..., B], v[..., B + 1], v[..., B + 2])
    ca, cb = design.ca, design.cb
    kinds = [k for k in (True, False) if np.any(twistor == k)]
    results = [
        quadratic_hinge(
            kind, moving, (z[..., A], z[..., A + 1], z[..., A + 2]),
            (z[..., B], z[..., B + 1], z[..., B + 2]), vA, vB, (ca[..., 0], ca[..., 1]),
            (cb[..., 0], cb[..., 1]), design.phia, design.phib, W, C)
        for kind in kinds
    ]
    r, energy, _, q_local, wrench = (
        results[0] if len(results) == 1 else _select(twistor, results[0], results[1])
    )
    return Forces(_scatter(list(q_local), ia, ib, z.shape[-1]), _stack(list(r)),
                  _stack(list(wrench)), energy)


def _select(cond, x, y):
    """Nested results x where ``cond`` (per hinge) holds, else y (the same nesting)."""
    if isinstance(x, tuple):
        return tuple(_select(cond, a, b) for a, b in zip(x, y))
    return where(cond, x, y)


def _entries(M):
    """Rows of M[..., k, m] (n, 3, 3) as nested lists, 0.0 where every part is zero."""
    parts = hd.parts_of(M) if isinstance(M, hd.HyperDual) else (M,)
    return [
        [0.0 if not any(np.any(p[..., k, m]) for p in parts) else M[..., k, m] for m in range(3)]
        for k in range(3)
    ]


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
