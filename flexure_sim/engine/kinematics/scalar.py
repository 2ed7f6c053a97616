"""
Formulas written once on a generic scalar: floats and complex steps in Numba, HyperDual numbers.

The engine's force chains -- planar (relative displacement r(z), law coordinates, the
half-cotangent, the quadratic law) and spatial (``kinematics.quaternion``, ``laws.spatial``,
``solver.spatial_chain``) -- are written once in plain Python with arithmetic operators and
NumPy's ufuncs (``np.sin``, ``np.sqrt``, ``np.arctan``), which work unchanged on floats and
complex numbers compiled by Numba, on float arrays (vectorised over hinges), on
``kinematics.hyperdual.HyperDual`` numbers and arrays (exact derivatives: Fike and Alonso,
AIAA 2011-886; shared/reference, the hyper-dual twist of a joint) -- as Drake templates its
multibody code on the scalar type. ``formula`` marks such a function: Python calls it as it is
(so a call with hyper-dual inputs differentiates the very code the kernels step with), and
Numba compiles the same source wherever a kernel calls it (``numba.extending.register_jitable``).

Compiled, the formulas also take complex numbers: each is real-analytic and branches on real
parts only, so the complex step f(x + i h)/h, h = 1e-40, gives exact first derivatives at
compiled speed (Squire and Trapp, SIAM Review 40 (1998) 110; Martins, Sturdza and Alonso, ACM
TOMS 29 (2003) 245): ``solver.spatial_kernels.complex_step``.

Branches are written with these primitives, each with a NumPy/HyperDual implementation for
Python and a scalar one for Numba:

- ``where(cond, x, y)``: x where cond holds, else y (``np.where``, part by part on HyperDuals;
  ``x if cond else y`` on scalars). A formula on arrays with a series branch evaluates its
  exact branch at a safe argument where the series is selected, as ``np.where`` evaluates both.
- ``real(x)``: the real part (``hyperdual.real``: of a HyperDual, or x as a float array; a
  float's value or a complex number's real part in Numba). Formulas on scalars only (the
  spatial chain, one hinge at a time) branch with ``if real(s) < limit``; inside a branch the
  formula is smooth, so the derivatives are those of the branch taken.
- ``dot(a, x)``: sum_i a_i x_i left to right for tuples a and x. In Python, float entries 0.0
  of ``a`` (and of ``x``) are skipped and +-1.0 taken as signs: the structural zeros and units
  of dr/dz and dc/dr cost four array products each in hyper-dual arithmetic. In Numba every
  product is taken, as the sum of exact zeros is exact.
- ``buffer(shape, like)``: scratch space of ``like``'s number type (an object array of zeros
  for hyper-dual numbers in Python).

``seeded``, ``zeros``, ``values_of`` and ``derivatives_of`` carry object arrays of hyper-dual
scalars in and out of a formula evaluated one scalar at a time.
"""
from __future__ import annotations

import numpy as np

from flexure_sim.engine.jit import HAVE_NUMBA
from flexure_sim.engine.kinematics import hyperdual as hd
from flexure_sim.engine.kinematics.hyperdual import real

__all__ = ["formula", "where", "real", "dot", "buffer", "stacked", "seeded", "zeros",
           "values_of", "derivatives_of"]


def formula(fn=None, *, inline: bool = True):
    """
    Return ``fn`` unchanged, registered so that Numba compiles calls to it.

    ``inline``: Numba inlines it into its callers (the small planar formulas of the force
    kernel); ``@formula(inline=False)``: compiled as a function of its own, called (the
    spatial chain's large ones, which would multiply the kernels' compile time).
    """
    if fn is None:
        return lambda f: formula(f, inline=inline)
    if HAVE_NUMBA:
        from numba.extending import register_jitable

        register_jitable(inline="always" if inline else "never")(fn)
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


def buffer(shape, like) -> np.ndarray:
    """Return scratch space of ``like``'s type: floats, or object zeros for hyper-dual numbers."""
    if isinstance(like, np.ndarray) and like.dtype != object:
        return np.empty(shape, like.dtype)
    return zeros(shape)


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


def seeded(values: np.ndarray, directions: np.ndarray) -> np.ndarray:
    """
    Return an object array of ``values`` carrying first derivatives along ``directions``.

    ``directions`` (len(values), m): row i is d value_i / d (the m seeds). Entries whose row
    is zero stay plain floats, so they cost nothing in the hyper-dual evaluation.
    """
    values = np.asarray(values, dtype=float)
    out = np.empty(values.shape, dtype=object)
    if values.size == 0:
        return out
    flat_v, flat_d = values.ravel(), np.asarray(directions).reshape(values.size, -1)
    flat = out.ravel()
    for i in range(values.size):
        row = flat_d[i]
        flat[i] = hd.HyperDual(flat_v[i], row.copy()) if np.any(row) else float(flat_v[i])
    return out


def zeros(shape) -> np.ndarray:
    """Return an object array of float zeros: a buffer hyper-dual scalars accumulate in."""
    out = np.empty(shape, dtype=object)
    out.fill(0.0)
    return out


def values_of(array: np.ndarray) -> np.ndarray:
    """Return the real parts of an object array of hyper-dual numbers and floats."""
    return np.array([float(real(x)) for x in array.ravel()], dtype=float).reshape(array.shape)


def derivatives_of(array: np.ndarray, m: int) -> np.ndarray:
    """Return d array / d seeds, shape array.shape + (m,) (zeros where an entry is a float)."""
    flat = array.ravel()
    out = np.zeros((flat.size, m))
    for i, x in enumerate(flat):
        if isinstance(x, hd.HyperDual):
            out[i] = np.broadcast_to(x.b, (m,))
    return out.reshape(array.shape + (m,))


if HAVE_NUMBA:
    from numba import types
    from numba.extending import overload

    @overload(where)
    def _where_scalar(cond, x, y):
        return lambda cond, x, y: x if cond else y

    @overload(real, inline="always")
    def _real_scalar(x):
        if isinstance(x, types.Complex):
            return lambda x: x.real
        return lambda x: x

    @overload(buffer)
    def _buffer_scalar(shape, like):
        return lambda shape, like: np.empty(shape, like.dtype)

    @overload(dot, inline="always")
    def _dot_scalar(a, x):
        if not isinstance(a, types.BaseTuple) or len(a) not in (3, 6):
            return None
        if len(a) == 3:
            return lambda a, x: a[0] * x[0] + a[1] * x[1] + a[2] * x[2]
        return lambda a, x: (a[0] * x[0] + a[1] * x[1] + a[2] * x[2] + a[3] * x[3]
                             + a[4] * x[4] + a[5] * x[5])
