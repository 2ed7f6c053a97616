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
first balanced (``scipy.linalg.matrix_balance``, powers of 2: exact), which brings |hA|_1 near
its spectral radius (the stage: 1.3e4, k = 16).

Only the blocks that are not known in closed form are propagated: the first block row [E, W]
of e^{Mt} (K(t) = sum_j (Nt)^j / j! and int_0^t K are finite sums) and G. A doubling is then
three products, G[:, :m] [E, W], [E, W]^T (G e^{Mt})[:m] and E [E, W, I_W], plus the products
by the sparse K - I, a Taylor term three products by tA, tU and the sparse tN: the stage's
integrals (m = 25, n = 75) in 1.25 ms where the dense doubling of the (n x n) generator took
2.3 ms (best of 15, one BLAS thread, both on the same busy machine; ``flexure-sim bench``
reports the whole linearization as step_cost.linearization_us).
"""
from __future__ import annotations

import math

import numpy as np
import scipy.linalg

from flexure_sim.engine import jit as kernel_cache
from flexure_sim.engine.jit import njit

#: The Taylor series start at |tA|_1 <= START. G's series sums terms up to e^{2|tA|} times its
#: value (a stiff mode's alternating terms), so rounding grows with START: 1/4 keeps it near
#: the rounding of one product. Its term j is below (2 START)^j / j! <= 1e-18 at j = TERMS.
START, TERMS = 0.25, 18


def quadratic_integrals(M: np.ndarray, Q: np.ndarray, h: float, m: int):
    """
    Return G = int_0^h e^{M^T s} Q e^{Ms} ds (n x n) and I_W = int_0^h W(s) ds (m x (n - m)).

    M = [[A, U], [0, N]] with A the first m rows and columns and N nilpotent (module doc).
    """
    n = M.shape[0]
    A, U, N = M[:m, :m], M[:m, m:], M[m:, m:]
    _, (scale, _) = scipy.linalg.matrix_balance(A, permute=False, separate=True)
    # T = diag(D, I): M = T M_b T^-1, so G = T^-1 G_b T^-1 with Q_b = T Q T, I_W = D I_Wb.
    tscale = np.concatenate((scale, np.ones(n - m)))
    Ab = A * (1.0 / scale)[:, None] * scale[None, :]
    Ub = U * (1.0 / scale)[:, None]
    Qb = Q * tscale[:, None] * tscale[None, :]
    Gb, IWb = _doubled(Ab, Ub, N, Qb, h)
    inv = 1.0 / tscale
    return inv[:, None] * Gb * inv[None, :], scale[:, None] * IWb


def _doubled(A: np.ndarray, U: np.ndarray, N: np.ndarray, Q: np.ndarray, h: float):
    """``quadratic_integrals`` of a balanced A by doubling (module doc)."""
    m, r = U.shape
    norm = np.linalg.norm(A, 1) * h
    k = max(0, int(math.ceil(math.log2(norm / START)))) if norm > START else 0
    # K(t) - I = sum_{j >= 1} t^j N^j / j! and int_0^t K = t I + sum t^{j+1} N^j / (j + 1)!,
    # finite (N nilpotent). The inputs' blocks are sparse (U = [I, 0], N = [[0, I/h], [0, 0]]
    # without programs): their products run over the nonzero rows and columns only.
    powers = [np.eye(r)]
    while np.any(powers[-1]) and len(powers) <= r:
        powers.append(powers[-1] @ N / len(powers))
    powers = powers[1:-1]
    pattern = np.sum(np.abs(powers), axis=0) if powers else np.zeros((r, r))
    nr, nc = np.flatnonzero(pattern.any(axis=1)), np.flatnonzero(pattern.any(axis=0))
    uc = np.flatnonzero(U.any(axis=0))
    blocks = np.array([p[np.ix_(nr, nc)] for p in powers]).reshape(len(powers), len(nr), len(nc))
    return _doubling(A, np.ascontiguousarray(U[:, uc]), uc, blocks, nr, nc, Q, h / 2.0 ** k, k)


@njit(cache=True)
def _doubling(A, Us, uc, blocks, nr, nc, Q, t, k):
    """
    Taylor series at t, then k doublings (module doc), compiled.

    Us = U[:, uc] (U's nonzero columns); blocks[j] = N^{j+1} / (j + 1)! on its nonzero rows nr
    and columns nc. Compiled: the stage's ~600 products, sums and copies of 25 to 75 wide
    matrices took 2.8 ms as NumPy calls (this function's ``py_func``), 1.25 ms compiled.
    """
    m, n = A.shape[0], Q.shape[0]
    r = n - m
    Ns = blocks[0]
    mnr, mnc = m + nr, m + nc
    # Taylor series at t: e^{Mt} = sum_j (Mt)^j / j!; its first block row [E, W] from
    # X_j = (tA)^j / j! and Y_j (the W block of (Mt)^j / j!): Y_{j+1} = (X_j tU + Y_j tN) / (j+1).
    tA, tUs, tNs = t * A, t * Us, t * Ns
    X, Y = np.eye(m), np.zeros((m, r))
    E, W = X.copy(), Y.copy()
    IW = np.zeros((m, r))
    # G(t) = t sum_j L_j / (j + 1)!, L_0 = Q, L_{j+1} = (tM)^T L_j + L_j (tM).
    L = Q.copy()
    G = t * Q
    factor = 1.0
    LM = np.zeros((n, n))
    for j in range(1, TERMS):
        Yn = np.zeros((m, r))
        Yn[:, uc] = X @ tUs
        Yn[:, nc] += np.ascontiguousarray(Y[:, nr]) @ tNs
        X = (X @ tA) / j
        Y = Yn / j
        E += X
        W += Y
        IW += (t / (j + 1)) * Y
        L1 = np.ascontiguousarray(L[:, :m])
        LM[:, :m] = L1 @ tA
        LM[:, m:] = 0.0
        LM[:, m + uc] = L1 @ tUs
        LM[:, mnc] += np.ascontiguousarray(L[:, mnr]) @ tNs
        L = LM + LM.T
        factor /= j + 1
        G += (t * factor) * L
    B = np.zeros((m, n))
    EWI = np.zeros((m, n + r))
    for _ in range(k):
        KI = t * blocks[0]
        for j in range(1, blocks.shape[0]):
            KI += t ** (j + 1) * blocks[j]
        B[:, :m], B[:, m:] = E, W
        GP = np.ascontiguousarray(G[:, :m]) @ B     # G e^{Mt}: first block column times [E, W] ...
        GP[:, m:] += G[:, m:]                      # ... plus the lower block times K
        GP[:, mnc] += np.ascontiguousarray(G[:, mnr]) @ KI
        Z = B.T @ GP[:m]                           # e^{M^T t} (G e^{Mt})
        Z[m:] += GP[m:]
        Z[mnc] += KI.T @ np.ascontiguousarray(GP[mnr])
        G += 0.5 * (Z + Z.T)
        EWI[:, :m], EWI[:, m:n], EWI[:, n:] = E, W, IW
        C = E @ EWI
        Wr = np.ascontiguousarray(W[:, nr])
        IW += C[:, n:] + t * W
        for j in range(blocks.shape[0]):
            IW[:, nc] += (t ** (j + 2) / (j + 2)) * (Wr @ blocks[j])
        W = C[:, m:n] + W
        W[:, nc] += Wr @ KI
        E = np.ascontiguousarray(C[:, :m])
        t = 2.0 * t
    return G, IW


# Numba's cache of each kernel is keyed on its own file only (``kernel_cache``).
kernel_cache.revalidate(kernel_cache.dispatchers_of(globals()), __file__)
