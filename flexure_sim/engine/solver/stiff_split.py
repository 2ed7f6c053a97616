"""
The step's energy integrals with its stiff modes split off (``step_energy``).

``quadratic_integrals`` doubles G = int_0^h e^{M^T s} Q e^{Ms} ds from h / 2^k, and k follows
the stiffest mode: the stage's hinge modes near -1e8 1/s take 16 doublings of the whole
generator at its step of 1e-4 s, though they decay within ~1e-6 s. Here the Jacobian is
block-diagonalised first, A = V diag(A_s, A_f) V^-1 (a real Schur form of the balanced A sorted
so that the fast eigenvalues, Re(lambda) h < -FAST, come last; then T11 Y - Y T22 = -T12,
V = D Z [[I, Y], [0, I]], Golub & Van Loan, Matrix Computations, 4th ed., 7.6.3), and
G is assembled from three parts that cost a few small products each:

- The generator of the step (``step_energy.energy_matrices``: w' = A w + f + F g, f' = n c,
  n' = 0, g' = N_g g; u = (f, n, g) its inputs, u(s) = K(s) u_0 with K = e^{Ns} a polynomial)
  keeps its form under w = V w^, f = V f^, n = V n^: A becomes diag(A_s, A_f), F becomes
  V^-1 F. The fast part of w^ follows u quasi-statically after a transient that has died out
  long before the step ends (|e^{A_f h}| < e^{-FAST}):

      w_f(s) = X K(s) u_0 - e^{A_f s} X u_0 + e^{A_f s} w_f0,    A_f X - X N = -U_f,

  (U_f: the fast rows of the inputs' forcing), exact but for a tail of e^{A_f h}.
- With x = P z - E_f(s) D x_0 (z = (w_s, u) the slow part, P: z -> (w_s, X u, u),
  D x_0 = X u_0 - w_f0), the integrand is z^T (P^T Q P) z (doubled as before, on the slow
  generator, whose |h A_s| is ~0.5 for the stage: one doubling), minus twice a cross term and
  plus E_f's own square, whose integrals to infinity solve Sylvester equations
  (Van Loan, IEEE TAC 23 (1978) 395, eq. (3)): M_s^T Z + Z A_f = -P^T Q_{., f} and
  A_f^T Y_f + Y_f A_f = -Q_ff (LAPACK trsyl on the Schur blocks; N nilpotent and upper
  triangular).

The stage at its step: 0.52 ms where the doubling of the whole generator took 0.82 ms (best of
10, one BLAS thread), the same G and I_W to 7e-12 of their largest entries
(``test_stiff_split``).
A generator of another form, or one without fast modes, is doubled as a whole.
"""
from __future__ import annotations

import math

import numpy as np
import scipy.linalg.lapack as lapack

from flexure_sim.engine.solver.quadratic_integrals import (
    START, balancing, power_entries, quadratic_integrals,
)

#: A mode is fast when Re(lambda) h < -FAST: its transient within the step is below e^-50 of
#: its start (the shipped mechanisms' tails |e^{A_f h}|: 1e-22 at most, at their steps).
FAST = 50.0
#: The split's own cost (a Schur form, five Sylvester solves, ~20 small products: ~0.1 ms) pays
#: when the whole generator's doubling is long: k doublings of an n x n generator, k n^2 at
#: least this (the stage at 1e-4 s: 16 x 75^2, 0.82 -> 0.52 ms; the four-bar: 11 x 48^2, 0.27 ms
#: doubled, 0.39 ms split).
SPLIT_WORK = 60_000


def step_integrals(M: np.ndarray, Q: np.ndarray, h: float, m: int):
    """
    Return G's input block G[m:, m:] and I_W = int_0^h W(s) ds (``quadratic_integrals``).

    The stiff modes split off (module doc) when M is the step's generator, may have fast modes
    (trace(A) h < -FAST: with no eigenvalue in the right half-plane, a fast one needs it) and
    its doubling is long (k n^2 >= SPLIT_WORK); the doubling of the whole generator otherwise.
    """
    A = M[:m, :m]
    d = None
    if m and np.trace(A) * h < -FAST:
        d = balancing(A)
        norm = np.linalg.norm(A / d[:, None] * d[None, :], 1) * h
        k = math.ceil(math.log2(norm / START)) if norm > START else 0
        if k * M.shape[0] ** 2 >= SPLIT_WORK and _step_generator(M, m):
            split = _split(M, Q, h, m, d)
            if split is not None:
                return split
    G, IW = quadratic_integrals(M, Q, h, m, d)
    return G[m:, m:], IW


def _step_generator(M: np.ndarray, m: int) -> bool:
    """Whether M is [[A, I, 0, F], [0, 0, cI, 0], [0, 0, 0, 0], [0, 0, 0, N_g]], N_g upper."""
    n = M.shape[0]
    if m == 0 or n < 3 * m:
        return False
    c = M[m, 2 * m]
    fn = np.zeros((2 * m, 2 * m))
    fn[:m, m:] = c * np.eye(m)
    return bool(np.array_equal(M[:m, m:2 * m], np.eye(m)) and not M[:m, 2 * m:3 * m].any()
                and np.array_equal(M[m:3 * m, m:3 * m], fn) and not M[m:3 * m, 3 * m:].any()
                and not M[3 * m:, :3 * m].any() and not np.tril(M[3 * m:, 3 * m:]).any())


def _sylvester(A, B, C, transpose_a: bool, sign: int) -> np.ndarray:
    """X with op(A) X + sign X B = C, A and B (quasi-)upper triangular (LAPACK dtrsyl)."""
    X, scale, info = lapack.dtrsyl(A, B, C, trana="T" if transpose_a else "N", tranb="N",
                                   isgn=sign)
    if info < 0:
        raise ValueError(f"LAPACK dtrsyl: argument {-info} is invalid")
    return X / scale if scale != 1.0 else X


def _nilpotent_sylvester(Tinv, N, C) -> np.ndarray:
    """
    X with T X - X N = C for N nilpotent, from T^-1: X = sum_j T^-(j+1) C N^j (N^j = 0 ends it).

    For the fast block T = A_f, whose eigenvalues are far from N's (all 0): two products a term
    (the stage: two terms), 5 us where LAPACK dtrsyl took ~20 us on these 11 x 50 blocks.
    """
    term = Tinv @ C
    X = term.copy()
    for _ in range(N.shape[0]):
        term = term @ N
        if not term.any():
            break
        term = Tinv @ term
        X += term
    return X


def _times_inverse(X: np.ndarray, Vinv: np.ndarray, m: int) -> np.ndarray:
    """X diag(V^-1, V^-1, I): the inputs' columns back from (f^, n^, g)."""
    out = X.copy()
    out[:, :m] = X[:, :m] @ Vinv
    out[:, m:2 * m] = X[:, m:2 * m] @ Vinv
    return out


def _split(M, Q, h, m, d):
    """``step_integrals`` with the fast modes split off (module doc), or None without any."""
    n = M.shape[0]
    r = n - m
    A, N = M[:m, :m], M[m:, m:]
    # Real Schur form, slow eigenvalues first (LAPACK dgees: scipy.linalg.schur's, without its
    # wrapper's checks, 8 of its 59 us; A is finite, ``balancing`` checked it).
    slow = lambda re, im: re * h > -FAST   # noqa: E731  (dgees calls it per eigenvalue)
    T, ms, _, _, Zq, _, info = lapack.dgees(slow, A / d[:, None] * d[None, :], compute_v=1,
                                            sort_t=1)
    if info != 0:
        raise ValueError(f"LAPACK dgees failed on the step's Jacobian (info {info})")
    if ms == m:
        return None
    T11, T22 = T[:ms, :ms], T[ms:, ms:]
    Y = _sylvester(T11, T22, -T[:ms, ms:], False, -1)          # T11 Y - Y T22 = -T12
    V = Zq.copy()
    V[:, ms:] += Zq[:, :ms] @ Y
    Vinv = Zq.T.copy()
    Vinv[:ms] -= Y @ Zq.T[ms:]
    V *= d[:, None]
    Vinv /= d[None, :]
    # Q^ = T^T Q T with T = diag(V, V, V, I), block by block.
    Qh = Q.copy()
    for b in range(3):
        rows = slice(b * m, (b + 1) * m)
        if Q[rows].any():             # Q is symmetric; the step's damps w only
            Qh[rows] = V.T @ Qh[rows]
            Qh[:, rows] = Qh[:, rows] @ V
    Uh = np.zeros((m, r))
    Uh[:, :m] = np.eye(m)
    Uh[:, 2 * m:] = Vinv @ M[:m, 3 * m:]
    Tinv = np.linalg.inv(T22)
    X = _nilpotent_sylvester(Tinv, N, -Uh[ms:])                # A_f X - X N = -U_f
    s, f, u = slice(0, ms), slice(ms, m), slice(m, n)
    Qsf, Qff = Qh[s, f], Qh[f, f]
    XQ = X.T @ Qff + Qh[u, f]                                  # (P^T Q_{., f})'s input rows
    Qs = np.empty((ms + r, ms + r))                            # P^T Q^ P
    Qs[:ms, :ms] = Qh[s, s]
    Qs[:ms, ms:] = Qsf @ X + Qh[s, u]
    Qs[ms:, :ms] = Qs[:ms, ms:].T
    Qs[ms:, ms:] = XQ @ X + X.T @ Qh[f, u] + Qh[u, u]
    Ms = np.zeros((ms + r, ms + r))
    Ms[:ms, :ms], Ms[:ms, ms:], Ms[ms:, ms:] = T11, Uh[:ms], N
    Gs, IWs = quadratic_integrals(Ms, Qs, h, ms)
    Zs = _sylvester(T11, T22, -Qsf, True, 1)                   # A_s^T Z_s + Z_s A_f = -B_s
    Zu = _nilpotent_sylvester(Tinv.T, -N, (-XQ - Uh[:ms].T @ Zs).T).T   # N^T Z_u + Z_u A_f
    Yf = _sylvester(T22, T22, -Qff, True, 1)                   # A_f^T Y + Y A_f = -Q_ff
    ZX = Zu @ X
    Gh = Gs[ms:, ms:] - ZX - ZX.T + X.T @ (0.5 * (Yf + Yf.T)) @ X
    G = _times_inverse(_times_inverse(Gh, Vinv, m).T, Vinv, m)
    # int_0^h w_f = X int_0^h K - int_0^inf e^{A_f s} ds X, int_0^inf e^{A_f s} = -A_f^-1;
    # int_0^h K = h I + sum_p h^{p+1} / (p + 1) N^p / p! (N^p / p!'s entries: ``power_entries``).
    IK = h * np.eye(r)
    entries = power_entries(N)
    i, j, p = (entries[:, c].astype(np.int64) for c in (0, 1, 3))
    np.add.at(IK, (i, j), entries[:, 2] * h ** (p + 1.0) / (p + 1.0))
    IWf = X @ IK + Tinv @ X
    IW = _times_inverse(V @ np.vstack((IWs, IWf)), Vinv, m)
    return 0.5 * (G + G.T), IW
