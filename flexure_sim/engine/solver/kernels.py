"""
Compiled hot path: generalized hinge forces of quadratic laws, without Jacobians.

This is the force evaluation the stepping loop performs once per step: the hinge force chain
``laws.hinge_force.quadratic_hinge`` (relative displacement, law coordinates, quadratic law;
each formula written once on a generic scalar) compiled by Numba and applied hinge by hinge,
about 30x faster than the vectorised NumPy path for the stage (see BENCHMARKS.md).
``Assembly.forces`` (solver/assembly.py) evaluates the same formulas on arrays of hinges with
the exact Jacobians and any law. Without Numba the same function runs as plain Python.
"""
from __future__ import annotations

from flexure_sim.engine import jit as kernel_cache
from flexure_sim.engine.jit import njit
from flexure_sim.engine.laws.hinge_force import quadratic_hinge

TWISTOR, TWIST = 0, 1


@njit(cache=True)
def quadratic_forces(z, v, ia, ib, ca, cb, phia, phib, kind, W, C, Q, r_out, wrench_out):
    """
    Fill Q (3 n_bodies) with the hinge forces at (z, v); return (energy, dissipation).

    Also fills r_out (n, 3) with each hinge's deflection (alpha, p1, p2) and wrench_out (n, 3)
    with the wrench it exerts on body B in frame b (-m_b, eqs. 3.53/4.35), as in
    Assembly.forces. kind: TWISTOR or TWIST per hinge; W, C (n, 3, 3): each hinge's law
    metric and dissipation matrix on its three law coordinates (``laws.hinge_force``).
    """
    Q[:] = 0.0
    energy = 0.0
    dissipation = 0.0
    for h in range(ia.shape[0]):
        A, B = 3 * ia[h], 3 * ib[h]
        r, e, d, q, wrench = quadratic_hinge(
            kind[h] == TWISTOR,
            True,
            (z[A], z[A + 1], z[A + 2]),
            (z[B], z[B + 1], z[B + 2]),
            (v[A], v[A + 1], v[A + 2]),
            (v[B], v[B + 1], v[B + 2]),
            (ca[h, 0], ca[h, 1]),
            (cb[h, 0], cb[h, 1]),
            phia[h],
            phib[h],
            ((W[h, 0, 0], W[h, 0, 1], W[h, 0, 2]),
             (W[h, 1, 0], W[h, 1, 1], W[h, 1, 2]),
             (W[h, 2, 0], W[h, 2, 1], W[h, 2, 2])),
            ((C[h, 0, 0], C[h, 0, 1], C[h, 0, 2]),
             (C[h, 1, 0], C[h, 1, 1], C[h, 1, 2]),
             (C[h, 2, 0], C[h, 2, 1], C[h, 2, 2])),
        )
        energy += e
        dissipation += d
        r_out[h, 0], r_out[h, 1], r_out[h, 2] = r
        wrench_out[h, 0], wrench_out[h, 1], wrench_out[h, 2] = wrench
        Q[A] += q[0]
        Q[A + 1] += q[1]
        Q[A + 2] += q[2]
        Q[B] += q[3]
        Q[B + 1] += q[4]
        Q[B + 2] += q[5]
    return energy, dissipation


# The formulas compiled in live in other modules: Numba's cache must follow them (``jit``).
kernel_cache.revalidate(kernel_cache.dispatchers_of(globals()), __file__)
