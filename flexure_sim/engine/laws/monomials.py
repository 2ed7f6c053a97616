"""
Monomial algebra of the polynomial hinge laws (Appendix B of the dissertation).

The monomials of order <= N in n variables in idx4 order (``monomial_exponents``,
``monomial_index``), their values and gradients, the coefficients of a derivative
(eqs. 4.75-4.78, 3.73-3.75) and the substitution of a linear map (``compose_linear``, used for
the frame and body changes 3.69, 4.70). ``polynomial.PolynomialLaw`` builds on these.
"""
from __future__ import annotations

import math
from functools import lru_cache

import numpy as np

from flexure_sim.errors import as_array


# ------------------------------------------------------------------ monomial indexing

@lru_cache(maxsize=None)
def _exponent_table(n_vars: int, order: int) -> np.ndarray:
    def rec(nv: int, budget: int) -> list[tuple[int, ...]]:
        if nv == 1:
            return [(i,) for i in range(budget + 1)]
        return [
            head + (last,) for last in range(budget + 1) for head in rec(nv - 1, budget - last)
        ]

    table = np.array(rec(n_vars, order), dtype=int)
    table.setflags(write=False)
    return table


def monomial_exponents(n_vars: int, order: int) -> np.ndarray:
    """
    All exponent tuples of total degree <= order, shape (C(order + n_vars, n_vars), n_vars).

    The order is that of evalpoly4.sci / idx4.sci (Appendix B): the last variable varies
    slowest and the first fastest, so row j holds the exponents of coefficient idx = j + 1.
    """
    return _exponent_table(int(n_vars), int(order))


@lru_cache(maxsize=None)
def _index_map(n_vars: int, order: int) -> dict[tuple[int, ...], int]:
    return {tuple(int(v) for v in e): j for j, e in enumerate(_exponent_table(n_vars, order))}


def monomial_index(exponents, order: int) -> int:
    """
    Return the 0-based position of a monomial in the coefficient array of an order-N polynomial.

    idx4.sci returns this plus one.
    """
    e = tuple(int(v) for v in exponents)
    if min(e) < 0 or sum(e) > order:
        raise ValueError(f"exponents {list(e)} are not those of a monomial of order <= {order}")
    return _index_map(len(e), int(order))[e]


def monomials(u: np.ndarray, exponents: np.ndarray) -> np.ndarray:
    """Values of the monomials prod_k u_k^e_jk: u (n, k), exponents (M, k) -> (n, M)."""
    u = as_array("u", u, (None, None))
    exponents = as_array("exponents", exponents, (None, u.shape[1]), dtype=int)
    top = int(exponents.max()) if exponents.size else 0
    powers = u[:, :, None] ** np.arange(top + 1)  # (n, k, top + 1); 0.0 ** 0 == 1
    return np.prod(powers[:, np.arange(u.shape[1])[None, :], exponents], axis=-1)


def monomial_gradients(u: np.ndarray, exponents: np.ndarray) -> np.ndarray:
    """d/du_k of the monomials: u (n, k), exponents (M, k) -> (n, M, k)."""
    u = as_array("u", u, (None, None))
    exponents = as_array("exponents", exponents, (None, u.shape[1]), dtype=int)
    k = exponents.shape[1]
    out = np.empty((np.shape(u)[0], exponents.shape[0], k))
    for i in range(k):
        lowered = exponents.copy()
        lowered[:, i] = np.maximum(lowered[:, i] - 1, 0)
        out[:, :, i] = monomials(u, lowered) * exponents[:, i]
    return out


def derivative_coefficients(
    coefficients: np.ndarray, n_vars: int, order: int, var: int
) -> np.ndarray:
    """
    Coefficients of dP/du_var for P given by a dense coefficient array of order N.

    Eqs. 4.75-4.78 (3.73-3.75): c_k(idx(i)) = (i_k + 1) c_U(idx(i + e_k)). The result is
    kept in the order-N index space (its degree-N entries are zero).
    """
    exps = monomial_exponents(n_vars, order)
    src = np.nonzero(exps[:, var] > 0)[0]
    lowered = exps[src].copy()
    lowered[:, var] -= 1
    imap = _index_map(n_vars, order)
    dst = np.array([imap[tuple(e)] for e in lowered], dtype=int)
    out = np.zeros(len(exps))
    out[dst] = exps[src, var] * as_array("coefficients", coefficients, (len(exps),))[src]
    return out


def compose_linear(coefficients: np.ndarray, n_vars: int, order: int, M: np.ndarray) -> np.ndarray:
    """
    Dense coefficients of P(M u') for P given by dense order-N coefficients.

    Each homogeneous part of degree d is a symmetric tensor T (T[i1..id] = a_e / multinomial(e));
    substituting u = M u' contracts every slot with M. Exact up to rounding; the degree of
    every term is preserved, which is why a polynomial of order N in one set of twist(or)
    coordinates is one of order N in any other (3.69, 4.70).
    """
    exps = monomial_exponents(n_vars, order)
    M = as_array("M", M, (n_vars, n_vars))
    a = as_array("coefficients", coefficients, (len(exps),))
    degree = exps.sum(axis=1)
    radix = (order + 1) ** np.arange(n_vars)
    lookup = {int(code): j for j, code in enumerate(exps @ radix)}
    out = np.zeros_like(a)
    out[degree == 0] = a[degree == 0]
    for d in range(1, order + 1):
        tuples = np.indices((n_vars,) * d).reshape(d, -1).T  # (k^d, d)
        counts = np.zeros((len(tuples), n_vars), dtype=int)
        for j in range(d):
            counts[np.arange(len(tuples)), tuples[:, j]] += 1
        mono = np.array([lookup[int(c)] for c in counts @ radix])
        multinomial = math.factorial(d) / np.prod(
            [[math.factorial(int(v)) for v in row] for row in counts], axis=1
        )
        T = (a[mono] / multinomial).reshape((n_vars,) * d)
        for _ in range(d):
            T = np.tensordot(T, M, axes=([0], [0]))
        np.add.at(out, mono, T.ravel())
    return out


def describe_monomial(exponents, names: tuple[str, ...]) -> str:
    """Return a monomial as text, e.g. xi^2*x1 (the constant is "1")."""
    parts = [n if e == 1 else f"{n}^{e}" for n, e in zip(names, exponents) if e]
    return "*".join(parts) or "1"


__all__ = [
    "compose_linear", "derivative_coefficients", "describe_monomial", "monomial_exponents",
    "monomial_gradients", "monomial_index", "monomials",
]
