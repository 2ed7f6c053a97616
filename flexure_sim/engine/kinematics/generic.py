"""
Formulas written once on a generic scalar: compiled by Numba, evaluated on hyper-dual numbers.

The spatial engine's force chain (``kinematics.quaternion``, ``laws.spatial``,
``solver.spatial_chain``) is plain Python on scalars: the arithmetic operators and NumPy's
ufuncs (``np.sin``, ``np.sqrt``, ``np.arctan``), which Numba compiles for floats and complex
numbers and which ``hyperdual.HyperDual`` implements for numbers carrying exact derivatives
(Fike and Alonso, AIAA 2011-886; shared/reference, the hyper-dual twist of a joint). Each
such function is decorated with ``generic``: the module keeps the compiled dispatcher
(the stepping kernel calls it), and ``interpreted`` rebinds the same code objects in a
namespace where every generic function calls the others' Python versions, so one evaluation
with hyper-dual inputs seeded along chosen directions gives the exact Jacobian of the very
formula the kernel steps with -- one definition, two bindings, no finite differences.

Branches (a series near a removable singularity) select on ``real_part`` of a value: the
real part of a float or complex number when compiled, of a hyper-dual number when
interpreted. Inside a branch the formula is smooth, so the derivatives are those of the branch
taken. The compiled functions also take complex numbers: every formula is real-analytic and
branches on real parts only, so the complex step f(x + i h)/h, h = 1e-40, gives exact first
derivatives at compiled speed (Squire and Trapp, SIAM Review 40 (1998) 110; Martins, Sturdza
and Alonso, ACM TOMS 29 (2003) 245): ``solver.spatial_kernels.complex_step``.
"""
from __future__ import annotations

import types

import numpy as np

from flexure_sim.engine import jit
from flexure_sim.engine.jit import njit
from flexure_sim.engine.kinematics.hyperdual import HyperDual

#: Compiled generic functions, by module name: what ``interpreted`` rebinds.
_REGISTRY: dict[str, list] = {}


def generic(function):
    """Compile ``function`` (Numba, cached) and register it for ``interpreted``."""
    dispatcher = njit(cache=True)(function)
    _REGISTRY.setdefault(function.__module__, []).append(dispatcher)
    return dispatcher


@njit(cache=True)
def real_part(x):
    """Return the real part of a float, or of a complex number (the complex step's)."""
    return x.real


def _real_part(x):
    """Return the real part of a hyper-dual number as a float, or x itself."""
    return float(x.a) if isinstance(x, HyperDual) else x


@njit(cache=True)
def buffer(shape, like):
    """Return an uninitialised array of ``like``'s type: the compiled binding's scratch buffer."""
    return np.empty(shape, like.dtype)


def _buffer(shape, like):
    """Return an object array of zeros: the interpreted binding's scratch buffer."""
    return zeros(shape)


#: What the interpreted binding uses in place of the compiled helpers.
_OVERRIDES = {"real_part": _real_part, "buffer": _buffer}


_BINDINGS: dict[str, types.SimpleNamespace] = {}


def interpreted(*modules) -> types.SimpleNamespace:
    """
    Return the interpreted binding of the generic functions of ``modules`` (by name).

    Every generic function of the modules (and of any module they take generic functions
    from) is rebuilt from its code object in a copy of its module's namespace in which the
    generic functions, and ``real_part``, are the interpreted ones. Built once per set.
    """
    key = ",".join(sorted(m.__name__ for m in modules))
    if key in _BINDINGS:
        return _BINDINGS[key]
    compiled = {id(d): d for name in _REGISTRY for d in _REGISTRY[name]}
    namespaces: dict[str, dict] = {}
    python: dict[int, types.FunctionType] = {}
    for name, dispatchers in _REGISTRY.items():
        space = namespaces.setdefault(name, {})
        for d in dispatchers:
            f = d.py_func
            python[id(d)] = types.FunctionType(f.__code__, space, f.__name__, f.__defaults__)
    for name, space in namespaces.items():
        module_vars = vars(__import__(name, fromlist=["_"]))
        space.update(module_vars)
        for attr, value in module_vars.items():
            if id(value) in compiled:
                space[attr] = python[id(value)]
        for attr, value in _OVERRIDES.items():
            if attr in space:
                space[attr] = value
    out = types.SimpleNamespace()
    for m in modules:
        for attr, value in vars(m).items():
            if id(value) in python:
                setattr(out, attr, python[id(value)])
    _BINDINGS[key] = out
    return out


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
        flat[i] = HyperDual(flat_v[i], row.copy()) if np.any(row) else float(flat_v[i])
    return out


def zeros(shape) -> np.ndarray:
    """Return an object array of float zeros: a buffer the interpreted binding accumulates in."""
    out = np.empty(shape, dtype=object)
    out.fill(0.0)
    return out


def values_of(array: np.ndarray) -> np.ndarray:
    """Return the real parts of an object array of hyper-dual numbers and floats."""
    return np.array([_real_part(x) for x in array.ravel()], dtype=float).reshape(array.shape)


def derivatives_of(array: np.ndarray, m: int) -> np.ndarray:
    """Return d array / d seeds, shape array.shape + (m,) (zeros where an entry is a float)."""
    flat = array.ravel()
    out = np.zeros((flat.size, m))
    for i, x in enumerate(flat):
        if isinstance(x, HyperDual):
            out[i] = np.broadcast_to(x.b, (m,))
    return out.reshape(array.shape + (m,))


def revalidate(namespace: dict, module_file: str) -> None:
    """
    Flush the disk caches of the generic functions a module defines, if any source changed.

    ``jit.revalidate`` over the module's own dispatchers (those of other modules are theirs to
    check: one digest per function), keyed on every source the module imports.
    """
    name = namespace["__name__"]
    jit.revalidate([d for d in jit.dispatchers_of(namespace) if d.py_func.__module__ == name],
                   module_file)


revalidate(globals(), __file__)
