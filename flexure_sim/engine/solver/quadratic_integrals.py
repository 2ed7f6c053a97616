"""
Van Loan's integrals of a step's linear model with inputs, by doubling (``step_energy``).

For the generator M = [[A, U], [0, N]] of the step's state w and its inputs (A: m x m, the
motion's Jacobian; U: m x r, how the inputs force w; N: r x r, nilpotent: the inputs are
polynomials in time) and a symmetric Q,

    G = int_0^h e^{M^T s} Q e^{M s} ds,        I_W = int_0^h W(s) ds,

with e^{Ms} = [[E(s), W(s)], [0, K(s)]] (Van Loan, "Computing integrals involving the matrix
exponential", IEEE TAC 23 (1978) 395, Thm. 1 defines G; his block exponential holds
e^{-M^T h}, which overflows for the stage's eigenvalues near -1e8 1/s, so G is taken by
doubling instead): G(2t) = G(t) + e^{M^T t} G(t) e^{Mt}, I(2t) = I(t) + e^{Mt} I(t),
e^{2Mt} = e^{Mt} e^{Mt}, from Taylor series at t = h / 2^k with |t A|_1 <= 1/4, where A is
first balanced (LAPACK gebal, powers of 2: exact), which brings |hA|_1 near
its spectral radius (the stage: 1.3e4, k = 16).

Only the blocks that are not known in closed form are propagated: the first block row [E, W]
of e^{Mt} (K(t) = sum_j (Nt)^j / j! and int_0^t K are finite sums) and G. A doubling is then
three products, G[:, :m] [E, W], [E, W]^T (G e^{Mt})[:m] and E [E, W, I_W], and a Taylor term
two, by tA; the products by the sparse U and N's powers (an identity block each without
programs) run over their entries. The stage's integrals (m = 25, n = 75): 0.9 ms where the
dense doubling of the (n x n) generator took 2.4 ms, the same G and I_W to 1e-13 (best of 15,
one BLAS thread, both on the same busy machine; ``flexure-sim bench`` reports the whole
linearization as step_cost.linearization_us).
"""
from __future__ import annotations

import math
from typing import Optional

import numpy as np
import scipy.linalg.lapack as lapack

from flexure_sim.engine import jit as kernel_cache
from flexure_sim.engine.jit import njit

#: The Taylor series start at |tA|_1 <= START. G's series sums terms up to e^{2|tA|} times its
#: value (a stiff mode's alternating terms), so rounding grows with START: 1/4 keeps it near
#: the rounding of one product. Its term j is below (2 START)^j / j! <= 1e-18 at j = TERMS.
START, TERMS = 0.25, 16


def quadratic_integrals(M: np.ndarray, Q: np.ndarray, h: float, m: int,
                        scale: Optional[np.ndarray] = None):
    """
    Return G = int_0^h e^{M^T s} Q e^{Ms} ds (n x n) and I_W = int_0^h W(s) ds (m x (n - m)).

    M = [[A, U], [0, N]] with A the first m rows and columns and N nilpotent (module doc). A is
    balanced first, T = diag(D, I): M = T M_b T^-1, so G = T^-1 G_b T^-1 with Q_b = T Q T, and
    I_W = D I_Wb. ``scale``: D's diagonal if already at hand (``balancing``).
    """
    A, U, N = M[:m, :m], M[:m, m:], M[m:, m:]
    scale = balancing(A) if scale is None else scale
    return balanced_doubling(np.ascontiguousarray(A), scale, np.ascontiguousarray(U),
                             power_entries(N), np.ascontiguousarray(Q), h)


def balancing(A: np.ndarray) -> np.ndarray:
    """
    D of A's balancing D^-1 A D: ``scipy.linalg.matrix_balance(A, permute=False)``'s.

    The same LAPACK gebal call (scaling only) and the same checks, without the wrapper's ~15 us.
    """
    if A.size == 0:
        return np.ones(len(A))
    if not np.isfinite(A).all():
        raise ValueError("array must not contain infs or NaNs")
    _, _, _, scale, info = lapack.dgebal(A, scale=1, permute=0)
    if info != 0:
        raise ValueError(f"LAPACK dgebal failed on the step's Jacobian (info {info})")
    return scale


@njit(cache=True)
def doublings(norm):
    """Doublings k from h / 2^k to h for |hA|_1 = ``norm``: |tA|_1 <= START at t = h / 2^k."""
    return max(0, int(math.ceil(math.log2(norm / START)))) if norm > START else 0


@njit(cache=True)
def balanced_doubling(A, d, U, Ncoo, Q, h):
    """
    ``quadratic_integrals`` with D = diag(d) and N's ``power_entries`` Ncoo at hand, compiled.

    A_b = D^-1 A D, U_b = D^-1 U, Q_b = T Q T with T = diag(D, I); G = T^-1 G_b T^-1 and
    I_W = D I_Wb of ``_doubling`` on A_b (module doc). Also the split's slow generator
    (``stiff_split``), which calls it from compiled code.
    """
    m, n = A.shape[0], Q.shape[0]
    inv = 1.0 / d
    ts = np.ones(n)
    ts[:m] = d
    Ab = np.empty((m, m))
    norm = 0.0
    for j in range(m):
        col = 0.0
        for i in range(m):
            Ab[i, j] = A[i, j] * inv[i] * d[j]
            col += abs(Ab[i, j])
        norm = max(norm, col * h)
    k = doublings(norm)
    count = 0
    for i in range(m):
        for j in range(n - m):
            if U[i, j] * inv[i] != 0.0:
                count += 1
    Ucoo = np.empty((count, 3))
    count = 0
    for i in range(m):
        for j in range(n - m):
            if U[i, j] * inv[i] != 0.0:
                Ucoo[count, 0], Ucoo[count, 1], Ucoo[count, 2] = i, j, U[i, j] * inv[i]
                count += 1
    Qb = np.empty_like(Q)
    for i in range(n):
        for j in range(n):
            Qb[i, j] = Q[i, j] * ts[i] * ts[j]
    Gb, IWb = _doubling(Ab, Ucoo, Ncoo, Qb, h / 2.0 ** k, k)
    for i in range(n):
        for j in range(n):
            Gb[i, j] = (1.0 / ts[i]) * Gb[i, j] * (1.0 / ts[j])
    for i in range(m):
        for j in range(n - m):
            IWb[i, j] = d[i] * IWb[i, j]
    return Gb, IWb


#: The last N and its ``power_entries``: N depends on the step and the model's programs only,
#: so every linearization of a run (and of the runs of a model) takes the same.
_last_powers: tuple = (None, None)


def power_entries(N: np.ndarray) -> np.ndarray:
    """
    N^p / p!'s entries, p >= 1, as (row, column, value, p) rows: K(t) - I = sum_p t^p N^p / p!.

    Finite (N nilpotent). As lists of entries, since they are sparse (N = [[0, I/h], [0, 0]]
    without programs; U = [I, 0]): their products are a few scaled columns, not dense
    products. Kept for the last N (``_last_powers``): 35 us of NumPy calls on the stage's
    50 x 50 N, against ~3 us to compare it.
    """
    global _last_powers
    key = (N.shape, N.tobytes())
    if _last_powers[0] == key:
        return _last_powers[1]
    r = N.shape[0]
    entries = []
    power = np.eye(r)
    for p in range(1, r + 1):
        power = power @ N / p
        if not np.any(power):
            break
        i, j = np.nonzero(power)
        entries.append(np.stack([i, j, power[i, j], np.full(len(i), p)], axis=1))
    Ncoo = np.concatenate(entries) if entries else np.zeros((0, 4))
    Ncoo.flags.writeable = False
    _last_powers = (key, Ncoo)
    return Ncoo


@njit(cache=True)
def _doubling(A, Ucoo, Ncoo, Q, t, k):
    """
    Taylor series at t, then k doublings (module doc), compiled.

    Ucoo: U's entries (row, column, value); Ncoo: those of N^p / p!, p >= 1 (row, column, value,
    p). Compiled: with dense products by U and N these ~700 products, sums and copies of 25 to
    75 wide matrices took 2.8 ms as NumPy calls, 1.25 ms compiled; by their entries, 0.9 ms.
    """
    m, n = A.shape[0], Q.shape[0]
    r = n - m
    # Taylor series at t: e^{Mt} = sum_j (Mt)^j / j!; its first block row [E, W] from
    # X_j = (tA)^j / j! and Y_j (the W block of (Mt)^j / j!): Y_{j+1} = (X_j tU + Y_j tN) / (j+1).
    tA = t * A
    X, Y = np.eye(m), np.zeros((m, r))
    E, W = X.copy(), Y.copy()
    IW = np.zeros((m, r))
    # G(t) = t sum_j L_j / (j + 1)!, L_0 = Q, L_{j+1} = (tM)^T L_j + L_j (tM).
    L = Q.copy()
    G = t * Q
    factor = 1.0
    LM = np.zeros((n, n))
    # (row, column, value) of tU and of tN (its first power), walked row by row below: a
    # column at a time strides across the matrices' rows (3x slower on the stage).
    ua, ub, uv = Ucoo[:, 0].astype(np.int64), Ucoo[:, 1].astype(np.int64), t * Ucoo[:, 2]
    first = Ncoo[:, 3] == 1.0
    na, nb = Ncoo[first, 0].astype(np.int64), Ncoo[first, 1].astype(np.int64)
    nv = t * Ncoo[first, 2]
    # The terms' products into buffers made once (7 % of the slow doubling's time).
    Yn = np.zeros((m, r))
    Xn = np.empty((m, m))
    for j in range(1, TERMS):
        Yn[:] = 0.0
        LM[:, :m] = L[:m].T @ tA                   # L symmetric: L[:, :m] = L[:m]^T
        LM[:, m:] = 0.0
        for i in range(n):
            for e in range(len(ua)):
                LM[i, m + ub[e]] += uv[e] * L[i, ua[e]]
                if i < m:
                    Yn[i, ub[e]] += uv[e] * X[i, ua[e]]
            for e in range(len(na)):
                LM[i, m + nb[e]] += nv[e] * L[i, m + na[e]]
                if i < m:
                    Yn[i, nb[e]] += nv[e] * Y[i, na[e]]
        np.dot(X, tA, Xn)
        Xn /= j
        X, Xn = Xn, X
        Yn /= j
        Y, Yn = Yn, Y
        E += X
        W += Y
        c = t / (j + 1)
        for i in range(m):
            for e in range(r):
                IW[i, e] += c * Y[i, e]
        factor /= j + 1
        _symmetric_sum(LM, L, G, t * factor, 1.0)
    B = np.zeros((m, n))
    EWI = np.zeros((m, n + r))
    ka, kb = Ncoo[:, 0].astype(np.int64), Ncoo[:, 1].astype(np.int64)
    for _ in range(k):
        kv = Ncoo[:, 2] * t ** Ncoo[:, 3]          # K - I's entries
        iv = kv * t / (Ncoo[:, 3] + 1.0)           # int_0^t K - t I's
        # e^{Mt} = [[E, W], [0, K]], K - I and int_0^t K - t I from N's powers' entries.
        B[:, :m], B[:, m:] = E, W
        GP = G[:m].T @ B                           # G e^{Mt}: first block column times [E, W] ...
        GP[:, m:] += G[:, m:]                      # ... plus the lower block times K
        for i in range(n):
            for e in range(len(ka)):
                GP[i, m + kb[e]] += kv[e] * G[i, m + ka[e]]
        Z = B.T @ GP[:m]                           # e^{M^T t} (G e^{Mt})
        Z[m:] += GP[m:]
        for e in range(len(ka)):
            Z[m + kb[e]] += kv[e] * GP[m + ka[e]]
        _symmetric_sum(Z, LM, G, 1.0, 0.5)      # G += (Z + Z^T) / 2 (LM: scratch here)
        EWI[:, :m], EWI[:, m:n], EWI[:, n:] = E, W, IW
        C = E @ EWI
        IW += C[:, n:] + t * W                     # I_W += E I_W + W int_0^t K
        Wn = C[:, m:n] + W                         # W <- E W + W K
        for i in range(m):
            for e in range(len(ka)):
                IW[i, kb[e]] += iv[e] * W[i, ka[e]]
                Wn[i, kb[e]] += kv[e] * W[i, ka[e]]
        W = Wn
        E = np.ascontiguousarray(C[:, :m])
        t = 2.0 * t
    return G, IW


@njit(cache=True)
def _symmetric_sum(X, L, G, c, w):
    """
    L = w (X + X^T) (L not X) and G += c L, row by row.

    Each entry is computed on its own (X_ij + X_ji = X_ji + X_ij), so rows are written in
    order, not columns across rows as a pass over the upper half mirrored: the stage's slow
    doubling 167 -> 148 us, the whole one 783 -> 728 us. The same values to the rounding of
    entries near zero (the stage's G: 2e-28 of its largest; the golden figures' bits hold).
    """
    n = X.shape[0]
    for i in range(n):
        for j in range(n):
            s = w * (X[i, j] + X[j, i])
            L[i, j] = s
            G[i, j] += c * s


# Numba's cache of each kernel is keyed on its own file only (``kernel_cache``).
kernel_cache.revalidate(kernel_cache.dispatchers_of(globals()), __file__)
