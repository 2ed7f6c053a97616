"""
Formulas written once on a generic scalar: floats in Numba, NumPy arrays, HyperDual arrays.

The hinge force chain (relative displacement r(z), law coordinates, the half-cotangent, the
quadratic law) is written once in plain Python with arithmetic operators and ``np.sin`` /
``np.cos``, which work unchanged on floats compiled by Numba, on float arrays (vectorised over
hinges) and on ``kinematics.hyperdual.HyperDual`` arrays (exact sensitivities) -- as Drake
templates its multibody code on the scalar type. ``formula`` marks such a function: Python
calls it as it is, and Numba compiles the same source wherever a kernel calls it
(``numba.extending.register_jitable``, inlined).

Branches are the one thing such code cannot write with ``if``; these primitives stand in, each
with a NumPy/HyperDual implementation for Python and a scalar one for Numba:

- ``where(cond, x, y)``: x where cond holds, else y (``np.where``, part by part on HyperDuals;
  ``x if cond else y`` on scalars). A formula with a series branch evaluates its exact branch
  at a safe argument where the series is selected, as ``np.where`` evaluates both.
- ``real(x)``: the real part (``hyperdual.real``: of a HyperDual, or x as a float array; a
  scalar in Numba).
- ``dot(a, x)``: sum_i a_i x_i left to right for tuples a and x. In Python, float entries 0.0
  of ``a`` (and of ``x``) are skipped and +-1.0 taken as signs: the structural zeros and units
  of dr/dz and dc/dr cost four array products each in hyper-dual arithmetic. In Numba every
  product is taken, as the sum of exact zeros is exact.
"""
from __future__ import annotations

import numpy as np

from flexure_sim.engine.jit import HAVE_NUMBA
from flexure_sim.engine.kinematics import hyperdual as hd
from flexure_sim.engine.kinematics.hyperdual import real

__all__ = ["formula", "where", "real", "dot", "stacked"]


def formula(fn):
    """Return ``fn`` unchanged, registered so that Numba compiles calls to it (inlined)."""
    if HAVE_NUMBA:
        from numba.extending import register_jitable

        register_jitable(inline="always")(fn)
    return fn


def where(cond, x, y):
    """Return x where ``cond`` holds, else y (module docstring)."""
    if np.ndim(cond) == 0 and not isinstance(cond, np.ndarray):
        return x if cond else y
    if not isinstance(x, hd.HyperDual) and not isinstance(y, hd.HyperDual):
        return np.where(cond, x, y)
    xs, ys = hd.parts_of(x), hd.parts_of(y)
    shape = np.broadcast_shapes(np.shape(cond), xs[0].shape, ys[0].shape)
    return hd.HyperDual(*(np.where(cond, np.broadcast_to(a, shape), np.broadcast_to(b, shape))
                          for a, b in zip(xs, ys)))


def dot(a, x):
    """Return sum_i a_i x_i, left to right (module docstring: zeros and units in Python)."""
    out = None
    for ai, xi in zip(a, x):
        if isinstance(ai, float):
            if ai == 0.0:
                continue
            term = xi if ai == 1.0 else (-xi if ai == -1.0 else ai * xi)
        elif isinstance(xi, float) and xi == 0.0:
            continue
        else:
            term = ai * xi
        out = term if out is None else out + term
    return 0.0 if out is None else out


def stacked(entries, n: int, shape: tuple) -> np.ndarray:
    """
    Return a formula's nested tuple of entries for n hinges as one float array (n, *shape).

    Entries are arrays (n,) or numbers (broadcast), nested as ``shape`` says.
    """
    leaves: list = []
    todo = [entries]
    while todo:
        item = todo.pop()
        if isinstance(item, tuple):
            todo.extend(reversed(item))
        else:
            leaves.append(item)
    out = np.zeros((n, len(leaves)))
    for i, leaf in enumerate(leaves):
        if not (isinstance(leaf, float) and leaf == 0.0):  # the formulas' structural zeros
            out[:, i] = leaf
    return out.reshape((n,) + shape)


if HAVE_NUMBA:
    from numba import types
    from numba.extending import overload

    @overload(where)
    def _where_scalar(cond, x, y):
        return lambda cond, x, y: x if cond else y

    @overload(real, inline="always")
    def _real_scalar(x):
        return lambda x: x

    @overload(dot, inline="always")
    def _dot_scalar(a, x):
        if not isinstance(a, types.BaseTuple) or len(a) not in (3, 6):
            return None
        if len(a) == 3:
            return lambda a, x: a[0] * x[0] + a[1] * x[1] + a[2] * x[2]
        return lambda a, x: (a[0] * x[0] + a[1] * x[1] + a[2] * x[2] + a[3] * x[3]
                             + a[4] * x[4] + a[5] * x[5])
