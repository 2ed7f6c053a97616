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
  plus E_f's own square, whose integrals to infinity solve Sylvester equations (integrate
  the integrand's derivative; A_f is stable): M_s^T Z + Z A_f = -P^T Q_{., f} and
  A_f^T Y_f + Y_f A_f = -Q_ff (LAPACK trsyl on the Schur blocks; those with N, nilpotent, as
  finite series in A_f^-1).

The stage at its step: 0.31 ms where the doubling of the whole generator takes 0.73 ms (best
of 10, one BLAS thread), the same G and I_W to 7e-12 of their largest entries
(``test_stiff_split``).
A generator of another form, or one without fast modes, is doubled as a whole.
"""
from __future__ import annotations

import numpy as np
import scipy.linalg.lapack as lapack

from flexure_sim.engine import jit as kernel_cache
from flexure_sim.engine.jit import njit
from flexure_sim.engine.solver.quadratic_integrals import (
    balanced_doubling, balancing, doublings, power_entries, quadratic_integrals,
)

#: A mode is fast when Re(lambda) h < -FAST: its transient within the step is below e^-50 of
#: its start (the shipped mechanisms' tails |e^{A_f h}|: 1e-22 at most, at their steps).
FAST = 50.0
#: The split pays when the whole generator's doubling is long: k doublings of an n x n
#: generator, k n^2 at least this (the stage at 1e-4 s: 16 x 75^2, 0.73 ms doubled, 0.31 ms
#: split; the four-bar, whose slow part keeps most of its stiffness: 11 x 48^2, 0.23 ms
#: doubled, 0.26 ms split).
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
        if doublings(norm) * M.shape[0] ** 2 >= SPLIT_WORK and _step_generator(M, m):
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


@njit(cache=True)
def _nilpotent_sylvester(Tinv, N, C):
    """
    X with T X - X N = C for N nilpotent, from T^-1: X = sum_j T^-(j+1) C N^j (N^j = 0 ends it).

    For the fast block T = A_f, whose eigenvalues are far from N's (all 0): two products a term
    (the stage: two terms), 5 us where LAPACK dtrsyl took ~20 us on these 11 x 50 blocks.
    """
    term = Tinv @ C
    X = term.copy()
    for _ in range(N.shape[0]):
        term = term @ N
        if not np.any(term != 0.0):
            break
        term = Tinv @ term
        X += term
    return X


@njit(cache=True)
def _times_inverse(X, Vinv, m):
    """X diag(V^-1, V^-1, I): the inputs' columns back from (f^, n^, g)."""
    out = X.copy()
    out[:, :m] = np.ascontiguousarray(X[:, :m]) @ Vinv
    out[:, m:2 * m] = np.ascontiguousarray(X[:, m:2 * m]) @ Vinv
    return out


def _split(M, Q, h, m, d):
    """
    ``step_integrals`` with the fast modes split off (module doc), or None.

    None unless some modes are fast and some slow.

    LAPACK in Python (dgees, three trsyl, gebal), the rest in two compiled calls
    (``_coordinates``, ``_assemble``): as ~40 NumPy calls on 11- to 75-wide blocks, the split
    took 0.60 ms of a fresh stage's first step, compiled 0.40 ms.
    """
    m3 = 3 * m
    N = np.ascontiguousarray(M[m:, m:])
    # Real Schur form, slow eigenvalues first (LAPACK dgees: scipy.linalg.schur's, without its
    # wrapper's checks, 8 of its 59 us; A is finite, ``balancing`` checked it).
    slow = lambda re, im: re * h > -FAST   # noqa: E731  (dgees calls it per eigenvalue)
    T, ms, _, _, Zq, _, info = lapack.dgees(slow, M[:m, :m] / d[:, None] * d[None, :],
                                            compute_v=1, sort_t=1)
    if info != 0:
        raise ValueError(f"LAPACK dgees failed on the step's Jacobian (info {info})")
    if ms in (0, m):                   # no fast mode, or no slow one: doubled as a whole
        return None
    T11, T22 = np.ascontiguousarray(T[:ms, :ms]), np.ascontiguousarray(T[ms:, ms:])
    Y = _sylvester(T11, T22, -T[:ms, ms:], False, -1)          # T11 Y - Y T22 = -T12
    Tinv = np.linalg.inv(T22)
    V, Vinv, Qh, Uh, X, XQ, Qs = _coordinates(
        np.ascontiguousarray(Zq), np.ascontiguousarray(Y), d, np.ascontiguousarray(Q),
        np.ascontiguousarray(M[:m, m3:]), N, Tinv, ms)
    Zs = _sylvester(T11, T22, -Qh[:ms, ms:m], True, 1)         # A_s^T Z_s + Z_s A_f = -B_s
    Yf = _sylvester(T22, T22, -Qh[ms:m, ms:m], True, 1)        # A_f^T Y + Y A_f = -Q_ff
    return _assemble(T11, balancing(T11), Uh, N, power_entries(N), Qs, h,
                     np.ascontiguousarray(Zs), np.ascontiguousarray(Yf), XQ, X, Tinv, V, Vinv)


@njit(cache=True)
def _coordinates(Zq, Y, d, Q, F, N, Tinv, ms):
    """
    Return V, V^-1, Q^, U^, X, (P^T Q^_{., f})'s input rows and the slow Q_s.

    Tinv: A_f^-1 (from NumPy: numba's np.linalg.inv added ~1 s to the first compilation).

    w = V w^, f = V f^, n = V n^ with V = D Z [[I, Y], [0, I]] (module doc); Q^ = T^T Q T,
    T = diag(V, V, V, I), by blocks (the step's Q damps w only); A_f X - X N = -U_f.
    """
    m, n = Zq.shape[0], Q.shape[0]
    r = n - m
    V = Zq.copy()
    V[:, ms:] += np.ascontiguousarray(Zq[:, :ms]) @ Y
    Vinv = np.ascontiguousarray(Zq.T)
    Vinv[:ms] -= Y @ np.ascontiguousarray(Zq.T[ms:])
    for i in range(m):
        for j in range(m):
            V[i, j] *= d[i]
            Vinv[i, j] /= d[j]
    Qh = Q.copy()
    VT = np.ascontiguousarray(V.T)
    for b in range(3):
        lo, hi = b * m, (b + 1) * m
        if np.any(Q[lo:hi] != 0.0):
            Qh[lo:hi] = VT @ np.ascontiguousarray(Qh[lo:hi])
            Qh[:, lo:hi] = np.ascontiguousarray(Qh[:, lo:hi]) @ V
    Uh = np.zeros((m, r))
    for i in range(m):
        Uh[i, i] = 1.0
    Uh[:, 2 * m:] = Vinv @ F
    X = _nilpotent_sylvester(Tinv, N, -np.ascontiguousarray(Uh[ms:]))
    Qsf = np.ascontiguousarray(Qh[:ms, ms:m])
    XQ = X.T @ np.ascontiguousarray(Qh[ms:m, ms:m]) + Qh[m:, ms:m]
    Qs = np.empty((ms + r, ms + r))                            # P^T Q^ P
    Qs[:ms, :ms] = Qh[:ms, :ms]
    Qs[:ms, ms:] = Qsf @ X + Qh[:ms, m:]
    Qs[ms:, :ms] = Qs[:ms, ms:].T
    Qs[ms:, ms:] = XQ @ X + X.T @ np.ascontiguousarray(Qh[ms:m, m:]) + Qh[m:, m:]
    return V, Vinv, Qh, Uh, X, XQ, Qs


@njit(cache=True)
def _assemble(T11, d, Uh, N, Ncoo, Qs, h, Zs, Yf, XQ, X, Tinv, V, Vinv):
    """
    Return G's input block and I_W from the parts (module doc).

    The slow generator's integrals (``balanced_doubling``), then the cross term, the fast
    modes' own square and the change of coordinates back.
    """
    ms, r, m = T11.shape[0], N.shape[0], V.shape[0]
    Gs, IWs = balanced_doubling(T11, d, np.ascontiguousarray(Uh[:ms]), Ncoo, Qs, h)
    Guu = np.ascontiguousarray(Gs[ms:, ms:])
    # The cross term and the fast modes' own square (module doc).
    C = -XQ - np.ascontiguousarray(Uh[:ms].T) @ Zs
    Zu = _nilpotent_sylvester(np.ascontiguousarray(Tinv.T), -N, np.ascontiguousarray(C.T)).T
    ZX = np.ascontiguousarray(Zu) @ X
    Ysym = 0.5 * (Yf + Yf.T)
    Gh = Guu - ZX - ZX.T + np.ascontiguousarray(X.T) @ (Ysym @ X)
    G = _times_inverse(np.ascontiguousarray(_times_inverse(Gh, Vinv, m).T), Vinv, m)
    # int_0^h w_f = X int_0^h K - int_0^inf e^{A_f s} ds X, int_0^inf e^{A_f s} = -A_f^-1;
    # int_0^h K = h I + sum_p h^{p+1} / (p + 1) N^p / p! (N^p / p!'s entries: ``power_entries``).
    IK = h * np.eye(r)
    for e in range(Ncoo.shape[0]):
        p = Ncoo[e, 3]
        IK[int(Ncoo[e, 0]), int(Ncoo[e, 1])] += Ncoo[e, 2] * h ** (p + 1.0) / (p + 1.0)
    IWhat = np.empty((m, r))
    IWhat[:ms] = IWs
    IWhat[ms:] = X @ IK + Tinv @ X
    IW = _times_inverse(V @ IWhat, Vinv, m)
    return 0.5 * (G + G.T), IW


# Numba's cache of each kernel is keyed on its own file only (``kernel_cache``).
kernel_cache.revalidate(kernel_cache.dispatchers_of(globals()), __file__)
