"""
Hyper-dual numbers: a value with two first derivatives and their mixed second derivative.

A hyper-dual number is x = a + b e1 + c e2 + d e1e2 with e1^2 = e2^2 = 0 and e1 e2 = e2 e1
(Fike and Alonso, "The development of hyper-dual numbers for exact second-derivative
calculations", AIAA 2011-886). Seeding a parameter p as p + e1 + e2 (one parameter) or two
parameters as p + e1 and q + e2 and evaluating any smooth function f with this arithmetic
gives

    f = f + (df/dp) e1 + (df/dq) e2 + (d2f/dp dq) e1e2

exactly -- no step size, no cancellation: the derivative parts are the true derivatives of
the real part, as the note ``reference/hyper-dual-twist-of-a-joint.md`` says of a joint's
twist carried together with its derivative. Every elementary function obeys

    f(x) = f(a) + f'(a) b e1 + f'(a) c e2 + (f'(a) d + f''(a) b c) e1e2.

``HyperDual`` is vectorised: the four parts are NumPy arrays that broadcast like the real
part (an extra leading axis in the derivative parts carries several seed directions at once).
Parts are real, or complex where a caller adds a complex step on top of the hyper-dual parts
for one third derivative (engine/analysis/sensitivity.py, the first mode's second derivative).
NumPy ufuncs dispatch to it through ``__array_ufunc__``, so ``np.sin(x)``, ``x * array`` and
``array * x`` all work; so does ``np.sqrt`` in the stiffness formulas of ``hinges/stiffness.py``.
"""

from __future__ import annotations

from typing import Any, Iterable

import numpy as np

__all__ = ["HyperDual", "seed", "parts_of", "real", "stack", "from_objects", "asarray"]


def _parts(x):
    if isinstance(x, HyperDual):
        return x.a, x.b, x.c, x.d
    return x, 0.0, 0.0, 0.0


def _part(x) -> np.ndarray:
    """One part as a float array, or as a complex array if it is complex (module docstring)."""
    if isinstance(x, complex) or getattr(getattr(x, "dtype", None), "kind", "") == "c":
        return np.asarray(x)
    return np.asarray(x, dtype=float)


def _chain(x: "HyperDual", f, f1, f2) -> "HyperDual":
    """f(x) from f(a), f'(a), f''(a) (the module docstring's rule)."""
    return HyperDual(f, f1 * x.b, f1 * x.c, f1 * x.d + f2 * x.b * x.c)


class HyperDual:
    """a + b e1 + c e2 + d e1e2 with array-valued parts (see the module docstring)."""

    __array_priority__ = 100.0
    __slots__ = ("a", "b", "c", "d")

    def __init__(self, a, b=0.0, c=0.0, d=0.0):
        self.a = _part(a)
        self.b = _part(b)
        self.c = _part(c)
        self.d = _part(d)

    # ------------------------------------------------------------------ basics
    @property
    def shape(self) -> tuple:
        return np.broadcast_shapes(self.a.shape, self.b.shape, self.c.shape, self.d.shape)

    @property
    def ndim(self) -> int:
        return len(self.shape)

    def __len__(self) -> int:
        shape = self.shape
        if not shape:
            raise TypeError("len() of a scalar HyperDual")
        return shape[0]

    def __repr__(self) -> str:
        return f"HyperDual({self.a!r}, {self.b!r}, {self.c!r}, {self.d!r})"

    def __getitem__(self, key) -> "HyperDual":
        s = self.shape
        trailing = isinstance(key, tuple) and len(key) > 0 and key[0] is Ellipsis

        def pick(p):
            if p.ndim == 0:
                return p
            if trailing and p.shape[-(len(key) - 1):] == s[-(len(key) - 1):]:
                return p[key]  # indexes trailing axes only: keep the part's own leading shape
            return np.broadcast_to(p, s)[key]

        return HyperDual(*(pick(p) for p in (self.a, self.b, self.c, self.d)))

    def __setitem__(self, key, value) -> None:
        shape = self.shape
        for name, v in zip("abcd", _parts(value)):
            part = getattr(self, name)
            if part.shape != shape or not part.flags.writeable:
                part = np.array(np.broadcast_to(part, shape))
            part[key] = v
            setattr(self, name, part)

    def sum(self, axis=None) -> "HyperDual":
        s = self.shape
        return HyperDual(
            *(np.broadcast_to(p, s).sum(axis=axis) for p in (self.a, self.b, self.c, self.d))
        )

    # -------------------------------------------------------------- arithmetic
    def __neg__(self):
        return HyperDual(-self.a, -self.b, -self.c, -self.d)

    def __pos__(self):
        return self

    def __add__(self, other):
        oa, ob, oc, od = _parts(other)
        return HyperDual(self.a + oa, self.b + ob, self.c + oc, self.d + od)

    __radd__ = __add__

    def __sub__(self, other):
        oa, ob, oc, od = _parts(other)
        return HyperDual(self.a - oa, self.b - ob, self.c - oc, self.d - od)

    def __rsub__(self, other):
        return (-self).__add__(other)

    def __mul__(self, other):
        if not isinstance(other, HyperDual):
            return HyperDual(self.a * other, self.b * other, self.c * other, self.d * other)
        a, b, c, d = self.a, self.b, self.c, self.d
        e, f, g, h = other.a, other.b, other.c, other.d
        return HyperDual(a * e, a * f + b * e, a * g + c * e, a * h + b * g + c * f + d * e)

    __rmul__ = __mul__

    def reciprocal(self) -> "HyperDual":
        inv = 1.0 / self.a
        return _chain(self, inv, -inv * inv, 2.0 * inv * inv * inv)

    def __truediv__(self, other):
        if not isinstance(other, HyperDual):
            return self * (1.0 / np.asarray(other, dtype=float))
        return self * other.reciprocal()

    def __rtruediv__(self, other):
        return self.reciprocal() * other

    def __pow__(self, n):
        if isinstance(n, HyperDual):
            return exp(n * log(self))
        n = float(n)
        if n == 2.0:
            return self * self
        a = self.a
        return _chain(self, a**n, n * a ** (n - 1.0), n * (n - 1.0) * a ** (n - 2.0))

    def __rpow__(self, base):
        return exp(self * np.log(base))

    # ---------------------------------------------------------- NumPy protocol
    def __array_ufunc__(self, ufunc, method, *inputs, **kwargs):
        if method != "__call__" or kwargs.get("out") is not None:
            return NotImplemented
        fn = _UFUNCS.get(ufunc)
        if fn is None:
            return NotImplemented
        return fn(*inputs)


# ------------------------------------------------------------ elementary functions


def _lift(x) -> HyperDual:
    return x if isinstance(x, HyperDual) else HyperDual(x)


def sin(x):
    x = _lift(x)
    s, c = np.sin(x.a), np.cos(x.a)
    return _chain(x, s, c, -s)


def cos(x):
    x = _lift(x)
    s, c = np.sin(x.a), np.cos(x.a)
    return _chain(x, c, -s, -c)


def tan(x):
    x = _lift(x)
    t = np.tan(x.a)
    sec2 = 1.0 + t * t
    return _chain(x, t, sec2, 2.0 * t * sec2)


def sqrt(x):
    x = _lift(x)
    r = np.sqrt(x.a)
    return _chain(x, r, 0.5 / r, -0.25 / (r * x.a))


def exp(x):
    x = _lift(x)
    e = np.exp(x.a)
    return _chain(x, e, e, e)


def log(x):
    x = _lift(x)
    inv = 1.0 / x.a
    return _chain(x, np.log(x.a), inv, -inv * inv)


def tanh(x):
    """Hyperbolic tangent t of the real part a: its derivatives are 1 - t^2 and -2 t (1 - t^2)."""
    x = _lift(x)
    t = np.tanh(x.a)
    s = 1.0 - t * t
    return _chain(x, t, s, -2.0 * t * s)


def arctan(x):
    x = _lift(x)
    q = 1.0 / (1.0 + x.a * x.a)
    return _chain(x, np.arctan(x.a), q, -2.0 * x.a * q * q)


def arctan2(y, x):
    """
    atan2(y, x) = theta0 + atan(w), w = (x0 y - y0 x) / (x0 x + y0 y) with x0, y0 the real parts.

    W has real part 0, so atan(w) = w up to e1e2 (w^3 = 0), and theta0 carries the quadrant.
    """
    ya, xa = _parts(y)[0], _parts(x)[0]
    w = (xa * _lift(y) - ya * _lift(x)) / (xa * _lift(x) + ya * _lift(y))
    return HyperDual(np.arctan2(ya, xa), w.b, w.c, w.d)


def absolute(x):
    """|x| (derivatives of the branch at the real part; not differentiable at 0)."""
    x = _lift(x)
    s = np.sign(x.a)
    return HyperDual(np.abs(x.a), s * x.b, s * x.c, s * x.d)


def _binary(op):
    return lambda u, v: op(_lift(u), v)


_UFUNCS: dict[Any, Any] = {
    np.add: lambda u, v: _lift(u) + v,
    np.subtract: lambda u, v: _lift(u) - v,
    np.multiply: lambda u, v: _lift(u) * v,
    np.true_divide: lambda u, v: _lift(u) / v,
    np.negative: lambda u: -_lift(u),
    np.positive: lambda u: u,
    np.power: lambda u, v: _lift(u) ** v,
    np.square: lambda u: _lift(u) * u,
    np.reciprocal: lambda u: _lift(u).reciprocal(),
    np.sin: sin,
    np.cos: cos,
    np.tan: tan,
    np.sqrt: sqrt,
    np.exp: exp,
    np.log: log,
    np.arctan: arctan,
    np.tanh: tanh,
    np.arctan2: arctan2,
    np.absolute: absolute,
}


# ----------------------------------------------------------------- construction


def seed(value, e1: float = 0.0, e2: float = 0.0) -> HyperDual:
    """
    Return value + e1 e1 + e2 e2.

    A parameter seeded for its derivatives (e1 = e2 = 1 for the first and second derivative in one
    parameter).
    """
    return HyperDual(value, e1, e2, 0.0)


def real(x) -> np.ndarray:
    """Return the real part (x itself for plain numbers)."""
    return x.a if isinstance(x, HyperDual) else np.asarray(x, dtype=float)


def parts_of(x) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Return (a, b, c, d) of x broadcast to a common shape (zeros for a plain number)."""
    x = _lift(x)
    s = x.shape
    a, b, c, d = (np.broadcast_to(p, s) for p in (x.a, x.b, x.c, x.d))
    return a, b, c, d


def from_objects(values: Iterable) -> HyperDual:
    """
    Return a HyperDual array from a (nested) sequence or object array of numbers and HyperDuals.

    Such as ``np.diag([Ko, k1, k2])`` of hyper-dual scalars.
    """
    arr = np.asarray(values, dtype=object)
    out = [np.empty(arr.shape) for _ in range(4)]
    for idx, v in np.ndenumerate(arr):
        for k, p in enumerate(_parts(v)):
            out[k][idx] = float(np.asarray(p))
    return HyperDual(*out)


def stack(items, axis: int = -1) -> HyperDual:
    """np.stack for HyperDuals (plain numbers allowed)."""
    lifted = [_lift(x) for x in items]
    out = []
    for n in "abcd":
        parts = [getattr(x, n) for x in lifted]
        shape = np.broadcast_shapes(*(p.shape for p in parts))
        out.append(np.stack([np.broadcast_to(p, shape) for p in parts], axis=axis))
    return HyperDual(*out)


def asarray(values):
    """
    Return nested sequences of numbers as a float array, or a HyperDual array if any is one.

    Entries may be numbers, HyperDuals (scalars or arrays) and arrays (also object arrays of
    both, as ``np.diag`` of hyper-dual scalars gives); a HyperDual result has zero derivative
    parts where the entries are plain numbers.
    """
    if isinstance(values, HyperDual):
        return values
    if not _holds_dual(values):
        return np.asarray(values, dtype=float)
    if any(np.ndim(v) > 0 and (isinstance(v, HyperDual) or getattr(v, "dtype", object) != object)
           for v in values):  # arrays, one per item: stacked along a new first axis
        items = [asarray(v) for v in values]
        shape = np.broadcast_shapes(*(np.shape(v) if not isinstance(v, HyperDual) else v.shape
                                      for v in items))
        parts = [np.zeros((len(items),) + shape) for _ in range(4)]
        for i, item in enumerate(items):
            for part, p in zip(parts, _parts(item)):
                part[i] = p
        return HyperDual(*parts)
    return from_objects(values)  # numbers and hyper-dual scalars


def _holds_dual(values) -> bool:
    if isinstance(values, HyperDual):
        return True
    if isinstance(values, (list, tuple)) or (isinstance(values, np.ndarray)
                                             and values.dtype == object):
        return any(_holds_dual(v) for v in values)
    return False
