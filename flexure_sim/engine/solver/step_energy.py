"""
Dissipated energy and drive work over one step of the exponential trapezoidal rule.

Both are integrated from the step's own linear model, as exactly as the motion: over a step
from y_n the integrator's state is y_n + w(s) with

    w(s) = s phi_1(sA) F_0 + s^2/h phi_2(sA) N_1,     0 <= s <= h

(``stepping``), which follows the sub-microsecond transients of the stiff, heavily damped
modes after a command step exactly. What the linear model leaves of each power (zero-order
in the remainder N, tiny at both ends of the step) is added by the trapezoidal rule.

Dissipated energy (independent of the work: the energy budget T + U + D - W then checks the
integration instead of holding by construction). The dissipated power of viscous damping is
P(v) = v^T C(z) v, C = -dQ/dv = 1/2 d^2P/dv^2 (every hinge law, and any constant damping
matrix added to the forces). At the linearization the velocities are affine in the state,
v = L x + b with x = (v_F, u) the last ``nx`` entries of y (v_P = sum_k D_k (command_k -
u_k)/tau_k + the timed constraints' rates, taken at the step's start in b), so with
x(s) = x_n + S w(s) (S selects x from y)

    int_0^h P ds = h P^(x_n) + 2 (C_x x_n + c)^T S int_0^h w ds + xi^T G xi + h/2 (rho_0 + rho_1),

P^(x) = x^T C_x x + 2 c^T x + c_0 (C_x = L^T C L, c = L^T C b, c_0 = b^T C b), xi = (F_0, N_1)
(N_1 without its z rows, which vanish: F's z rows are v, which A carries exactly),
int_0^h w ds = h^2 phi_2(hA) F_0 + h^2 phi_3(hA) N_1, and G the (F_0, N_1) block of
int_0^h e^{M^T s} S^T C_x S e^{M s} ds for the generator M of (w, F_0 + s N_1/h), rho = P - P^
at the step's ends. G is Van Loan's integral (Van Loan, IEEE TAC 23 (1978) 395, Thm. 1), taken
by doubling by blocks (``quadratic_integrals``: his block exponential holds e^{-M^T h}, which
overflows for the stage's eigenvalues near -1e8 1/s) with the stiff modes split off
(``stiff_split``). One such integral per linearization;
per step the cost is O(m^2) (two quadratic forms of order m).

Drive work: a displacement drive's power is ud (D_k^T M_P a_P - q) with ud = (command - u)/tau
its rate, which decays exactly as e^{-s/tau} over the step, and q = D_k^T Q_P(y) its load, which
the linear model follows as q_0 + g^T w(s) (g = dq/dy at the linearization). So

    W = 1/2 m_d ud_0^2 (e^{-2h/tau} - 1)
        - ud_0 (q_0 tau (1 - e^{-h/tau}) + g^T Psi_1 F_0 + g^T Psi_2 N_1 + rest),

Psi_k = int_0^h e^{-s/tau} (phi_k-term of w) ds (``weighted_phi``), m_d = D_k^T M_P D_k, and
``rest`` the trapezoidal rule on what the linear model leaves of q. Timed (sine-rate)
constraints: their power sum_j v_j (M_j a_j - Q_j) with v_j held at the step's start and
Q_j = Q_j0 + dQ_j/dy w(s), so its integral takes int_0^h w ds as the dissipation does; the
rest (the rates' change over the step, the nonlinear part) by the trapezoidal rule. The
coordinates a prescribed drive's program moves are timed the same way, and in the dissipation
their velocity rises over the step as b_j + a_j s + c_j s^2 (its rate at the start, its value
at the end) with the free coordinates it forces (``energy_matrices``): at a stiff damped hinge
between a prescribed and a free body the power is a small difference of large products of
their velocities, which a velocity held over the step would spoil. The program's time
dependence is in the motion's remainder, so a program's motion and energies are second order
in the step (a lag's are exact in its linear part).

The remainder iteration accepts y_{n+1} one correction beyond the point where F and the
rates were last evaluated; the rests are taken at the points where the rates were evaluated
and q_0 moved to y_n to first order (g), so that no stale rate enters: with the stiff hinge
forces a change below the iteration's tolerance still shifts q by ~1e-4 of its value.

Several displacement drives: x holds one u per drive, L has a column -D_k/tau_k per drive,
b sums D_k command_k / tau_k, and the work sums over the drives.
"""
from __future__ import annotations

import math

import numpy as np

from flexure_sim.engine.jit import njit
from flexure_sim.engine.solver.stiff_split import step_integrals

#: Entries of the energy vector ``rhs`` returns next to F (``stepping.energy_rates``); the load
#: of displacement drive k is entry AUX_LOAD + k.
AUX_TIMED_POWER, AUX_DISSIPATION, AUX_ENERGY, AUX_APPLIED, AUX_LOAD = 0, 1, 2, 3, 4
#: Columns of the per-linearization energy scalars, one row per displacement drive.
E_PSI0, E_DECAY, E_DRIVE_MASS, E_TAU, E_HAS_DRIVE = 0, 1, 2, 3, 4
N_SCALARS = 5


@njit(cache=True, inline="always")
def step_energy(y0, ye0, y1, ye1, F0, N1, aux0, aux1, command, t0, h, emats, form0, ws):
    """
    Dissipated energy and drive work over one step (module docstring).

    y0, y1: the step's accepted states; ye0, ye1: where aux0, aux1 were evaluated; t0: the
    step's start time; command: the displacement drives' commands, then the force drives'
    forces. ``emats`` = (erows, escal, G, V, Cx^T, R, S_P, B, sines, ...) from
    ``energy_matrices``.
    The work sums over the displacement drives k (row k of erows, escal; their coordinates
    are disjoint, so each drive's work is its own) and adds the force drives' held forces'
    work, the change of their potential ``AUX_APPLIED`` (exact). ``form0``: x^T C_x x at ye0
    if known (the previous step's end: NaN if not). ``ws``: scratch of ``workspace_size``
    entries, the loop's, made once per call instead of ~10 small arrays each step. Returns the
    dissipated energy, the work and x^T C_x x at ye1 (the next step's ``form0``).
    """
    erows, escal, G, V, CxT, R, SP, B, sines, Trows, T, Ep = emats
    if escal.shape[0] == 0:   # NO_ENERGY: the model does not integrate energies
        return 0.0, 0.0, math.nan
    m = y0.shape[0]
    nx = CxT.shape[0]
    nF = m - nx
    nd = B.shape[1]
    work = 0.0
    for k in range(nd):
        ud0 = (command[k] - y0[2 * nF + k]) / escal[k, E_TAU]
        decay = escal[k, E_DECAY]
        moved = 0.0    # g^T (y_n - ye_0): q_0 moved to y_n
        gw = 0.0       # g^T (ye_1 - y_n)
        psi = 0.0
        for j in range(m):
            moved += erows[k, 0, j] * (y0[j] - ye0[j])
            gw += erows[k, 0, j] * (ye1[j] - y0[j])
            psi += erows[k, 1, j] * F0[j] + erows[k, 2, j] * N1[j]
        q0 = aux0[AUX_LOAD + k] + moved
        rest = aux1[AUX_LOAD + k] - q0 - gw
        linear = q0 * escal[k, E_PSI0] + psi + 0.5 * h * decay * rest
        work += 0.5 * escal[k, E_DRIVE_MASS] * ud0 * ud0 * (decay * decay - 1.0) - ud0 * linear
    applied = aux1[AUX_APPLIED] - aux0[AUX_APPLIED]
    if applied != 0.0:
        work += applied
    q = Ep.shape[1] // 2
    mb = B.shape[0]
    nxi = G.shape[0]
    # Scratch: b, b1 (mb), accel (2q), where (q), c, gv, rows (nx), xi, gx (nxi), vt, N1p (m).
    b, ws = ws[:mb], ws[mb:]
    b1, ws = ws[:mb], ws[mb:]
    accel, ws = ws[:2 * q], ws[2 * q:]
    where, ws = ws[:q], ws[q:]
    c, ws = ws[:nx], ws[nx:]
    gv, ws = ws[:nx], ws[nx:]
    rows, ws = ws[:nx], ws[nx:]
    xi, ws = ws[:nxi], ws[nxi:]
    gx, ws = ws[:nxi], ws[nxi:]
    vt, ws = ws[:V.shape[1]], ws[V.shape[1]:]
    # b_P: the prescribed velocities' part that does not depend on the state.
    b[:] = 0.0
    for k in range(nd):
        for i in range(B.shape[0]):
            b[i] += B[i, k] * command[k]
    # Timed constraints: power sum_j v_j lambda_j, lambda_j = M_j a_j - Q_j(y) following the
    # linear model lambda_j0 - dQ_j/dy w(s), v_j held at v_j(t0); the rest trapezoidal. A sine
    # rate's v_j(t0) from its formula, a program coordinate's as the rates at t0 hold it.
    timed0 = aux0[AUX_TIMED_POWER]
    linear = 0.0
    moved = 0.0
    ns = sines.shape[1] - q
    # The program coordinates' velocities over the step, b_j + a_j s + c_j s^2, from their
    # rates at t0 and their velocities at t0 + h (functions of time: exact at both ends): the
    # generator's gamma(0) = a_j and kappa = 2 c_j. Their forcing of the free coordinates is in
    # the generator, so it leaves the remainder: N1p.
    accel[:] = 0.0
    N1p = N1
    if q:
        N1p = ws[:m]
        N1p[:] = N1
        for k in range(q):
            slot = int(sines[4, ns + k])
            a = aux0[slot + q]
            c2 = (aux1[slot] - aux0[slot] - a * h) / (h * h)
            accel[k], accel[q + k] = a, 2.0 * c2
            where[k] = sines[0, ns + k]
            moved_z = a * h * h / 2.0 + c2 * h * h * h / 3.0
            moved_v = a * h + c2 * h * h
            for j in range(m):
                N1p[j] -= Ep[j, k] * moved_z + Ep[j, q + k] * moved_v
    for i in range(sines.shape[1]):
        slot = int(sines[4, i])
        if slot < 0:
            vj = sines[1, i] * math.sin(sines[2, i] * t0 + sines[3, i])
        else:
            vj = aux0[slot]
        b[int(sines[0, i])] = vj
        for j in range(m):
            linear += vj * (T[i, j] * F0[j] + T[i, m + j] * N1[j])
            moved += vj * Trows[i, j] * (ye1[j] - y0[j])
    rest = aux1[AUX_TIMED_POWER] - (timed0 - moved)
    work += h * timed0 - linear + 0.5 * h * rest
    # The quadratic forms as loops (NumPy's small products and their temporaries: ~1 us a step).
    for i in range(nx):
        acc = 0.0
        for j in range(mb):
            acc += R[i, j] * b[j]
        c[i] = acc
    c0 = _form(SP, b, 0, b, 0)
    p0 = c0
    xi[:m] = F0
    xi[m:m + nx] = N1p[nF:]     # N_1's z rows vanish: F's z rows are v, which A carries exactly
    xi[m + nx:] = accel
    # gv = c + Cx x_n, V^T gv and G xi accumulated along contiguous rows (of Cx^T; G is
    # symmetric, ``quadratic_integrals``): independent sums the compiler vectorizes, not one
    # chain of dependent additions per row.
    gv[:] = c
    gv = _rows_times(CxT, y0[nF:], gv)
    for i in range(nx):
        p0 += y0[nF + i] * gv[i] + c[i] * y0[nF + i]
    vt[:] = 0.0
    vt = _rows_times(V, gv, vt)
    gx[:] = 0.0
    gx = _rows_times(G, xi, gx)
    gVxi = 0.0
    quad = 0.0
    for i in range(nxi):
        gVxi += vt[i] * xi[i]
        quad += xi[i] * gx[i]
    dissipated = h * p0 + 2.0 * gVxi + quad
    if q:
        # The program velocities rise by beta(s) = a s + c s^2 over the step (the generator's
        # beta, gamma, kappa): the linear term 2 (R^T x_n + S_P b)_pc . int beta ds.
        b1[:] = b
        for k in range(q):
            a, c2 = accel[k], 0.5 * accel[q + k]
            j = int(where[k])
            gb = 0.0
            for i in range(nx):
                gb += R[i, j] * y0[nF + i]
            for i in range(mb):
                gb += SP[j, i] * b[i]
            dissipated += 2.0 * gb * (a * h * h / 2.0 + c2 * h * h * h / 3.0)
            b1[j] += a * h + c2 * h * h
    # The linear model's c, c_0 at the step's end.
    c01 = _form(SP, b1, 0, b1, 0) if q else c0
    form1 = _form_t(CxT, ye1[nF:], rows)
    end = form1 + c01
    for i in range(nx):
        c1 = c[i]
        if q:
            c1 = 0.0
            for j in range(mb):
                c1 += R[i, j] * b1[j]
        end += 2.0 * c1 * ye1[nF + i]
    start = (_form_t(CxT, ye0[nF:], rows) if math.isnan(form0) else form0) + c0
    for i in range(nx):
        start += 2.0 * c[i] * ye0[nF + i]
    rho = aux0[AUX_DISSIPATION] - start + aux1[AUX_DISSIPATION] - end
    return dissipated + 0.5 * h * rho, work, form1


@njit(cache=True, inline="always")
def workspace_size(emats, m):
    """Entries of ``step_energy``'s scratch ``ws`` for matrices ``emats`` and a state of m."""
    _, escal, G, V, CxT, _, _, B, _, _, _, Ep = emats
    if escal.shape[0] == 0:
        return 0
    q = Ep.shape[1] // 2
    return 2 * B.shape[0] + 3 * q + 3 * CxT.shape[0] + 2 * G.shape[0] + V.shape[1] + m


@njit(cache=True, inline="always")
def _rows_times(Mat, x, out):
    """
    Return ``out`` + Mat^T x, row by row of Mat: out += Mat[j] x_j for j in order, in place.

    Four rows per pass over ``out``, each entry still summed in the order of the rows (the
    same bits as one row per pass): a quarter of the loads and stores of ``out``, which the
    compiler cannot keep in registers across rows (it cannot tell ``out`` from ``Mat``).
    """
    n = Mat.shape[1]
    j = 0
    while j + 4 <= Mat.shape[0]:
        x0, x1, x2, x3 = x[j], x[j + 1], x[j + 2], x[j + 3]
        for i in range(n):
            acc = out[i]
            acc += Mat[j, i] * x0
            acc += Mat[j + 1, i] * x1
            acc += Mat[j + 2, i] * x2
            acc += Mat[j + 3, i] * x3
            out[i] = acc
        j += 4
    while j < Mat.shape[0]:
        xj = x[j]
        for i in range(n):
            out[i] += Mat[j, i] * xj
        j += 1
    return out


@njit(cache=True, inline="always")
def _form_t(MatT, x, rows):
    """
    Return x^T Mat x from Mat's transpose (``rows``: scratch of Mat's order).

    The row sums of ``_form`` (each from 0.0, in column order), taken together along MatT's
    contiguous rows, then summed in row order: the same bits.
    """
    rows[:] = 0.0
    rows = _rows_times(MatT, x, rows)
    out = 0.0
    for i in range(rows.shape[0]):
        out += x[i] * rows[i]
    return out


@njit(cache=True, inline="always")
def _form(Mat, x, i0, z, j0):
    """x[i0:]^T Mat z[j0:], summed in place."""
    out = 0.0
    for i in range(Mat.shape[0]):
        row = 0.0
        for j in range(Mat.shape[1]):
            row += Mat[i, j] * z[j0 + j]
        out += x[i0 + i] * row
    return out


#: ``emats`` of a model without energy bookkeeping (``Model.energy`` False): empty arrays of
#: the types ``energy_matrices`` returns, so the compiled loop keeps one signature.
NO_ENERGY = (np.zeros((0, 3, 0)), np.zeros((0, N_SCALARS)), np.zeros((0, 0)), np.zeros((0, 0)),
             np.zeros((0, 0)), np.zeros((0, 0)), np.zeros((0, 0)), np.zeros((0, 0)),
             np.zeros((5, 0)), np.zeros((0, 0)), np.zeros((0, 0)), np.zeros((0, 0)))


def weighted_phi(A, phi1, phi2, h, tau, shifted_phi1):
    """
    Psi_1, Psi_2 = int_0^h e^{-s/tau} (s phi_1(sA), s^2/h phi_2(sA)) ds.

    From phi1 = h phi_1(hA), phi2 = h phi_2(hA) and shifted_phi1 = h phi_1(h (A - I/tau)):
    swapping the order of integration in the variation-of-constants integrals gives

        Psi_1 = tau (h phi_1(h(A - I/tau)) - e^{-h/tau} h phi_1(hA)),
        Psi_2 = (tau^2 h phi_1(h(A - I/tau))
                 - tau e^{-h/tau} ((h + tau) h phi_1(hA) - h^2 (phi_1(hA) - phi_2(hA)))) / h.
    """
    decay = math.exp(-h / tau)
    psi1 = tau * (shifted_phi1 - decay * phi1)
    psi2 = (tau * tau * shifted_phi1 - tau * decay * ((h + tau) * phi1 - h * (phi1 - phi2))) / h
    return psi1, psi2


def energy_matrices(A, phi1, phi2, h, G_load, damping, free, prescribed, D, drive_mass, tau,
                    shifted_phi1, sines, timed_rows, forcing=None):
    """
    Build the per-linearization matrices of ``step_energy`` (module docstring).

    A, phi1 = h phi_1(hA), phi2 = h phi_2(hA): the step's; G_load: rows g_k = dq_k/dy of the
    displacement drives' loads; damping: C = -dQ/dv over all coordinates; free, prescribed:
    coordinate indices; D: dz_P/du (a column per displacement drive), drive_mass: D_k^T M_P D_k,
    tau: response times, shifted_phi1: h phi_1(h(A - I/tau_k)) (all per drive); sines: (5, n)
    rows (index into prescribed, amplitude, omega, phase, -1) of the sine-rate constraints, then
    (index into prescribed, 0, 0, 0, entry of the energy rates holding its velocity) of each
    coordinate a prescribed drive's program moves; timed_rows (n, m) their dQ_j/dy; forcing
    (m, 2 q): dF/dz_j and dF/dv_j of each program coordinate j (columns, displacements first).
    """
    m = A.shape[0]
    nF, nd = len(free), D.shape[1]
    nx = m - nF
    C = 0.5 * (damping + damping.T)
    # L = dv/dx for x = (v_F, u) (the last nx entries of y); B: v_P = B command - ... per step.
    L = np.zeros((C.shape[0], nx))
    L[free, np.arange(nF)] = 1.0
    B = np.zeros((len(prescribed), nd))
    for k in range(nd):
        L[prescribed, nF + k] = -D[:, k] / tau[k]
        B[:, k] = D[:, k] / tau[k]
    Cx = L.T @ C @ L
    R = L.T @ C[:, prescribed]
    SP = C[np.ix_(prescribed, prescribed)]
    # Generator of (w, f, n): w' = A w + f, f' = n / h, n' = 0; xi_0 = (0, F_0, N_1). With q
    # program coordinates also (pi, beta, gamma, kappa): their displacement and velocity offsets
    # from t0, pi' = beta, beta' = gamma, gamma' = kappa, kappa' = 0 (the velocity rises by
    # a s + c s^2 over the step: gamma(0) = a, kappa = 2 c, ``step_energy``), which force w as
    # they force the motion (``forcing``). Then the dissipated power's products of program and
    # free velocities integrate as exactly as the motion: at a stiff damped hinge between a
    # prescribed body and a free one the power is a small difference of large such products.
    sines = np.asarray(sines, dtype=float).reshape(5, -1)
    pc = sines[0, sines[4] >= 0.0].astype(int)
    q = len(pc)
    forcing = np.zeros((m, 2 * q)) if forcing is None else np.asarray(forcing, dtype=float)
    M = np.zeros((3 * m + 4 * q, 3 * m + 4 * q))
    M[:m, :m] = A
    M[:m, m:2 * m] = np.eye(m)
    M[m:2 * m, 2 * m:3 * m] = np.eye(m) / h
    M[:m, 3 * m:3 * m + 2 * q] = forcing
    M[3 * m:3 * m + 3 * q, 3 * m + q:] = np.eye(3 * q)
    Q = np.zeros_like(M)
    Q[nF:m, nF:m] = Cx
    Q[nF:m, 3 * m + q:3 * m + 2 * q] = R[:, pc]
    Q[3 * m + q:3 * m + 2 * q, nF:m] = R[:, pc].T
    Q[3 * m + q:3 * m + 2 * q, 3 * m + q:3 * m + 2 * q] = SP[np.ix_(pc, pc)]
    Gin, IW = step_integrals(M, Q, h, m)    # G[m:, m:]; IW: int_0^h of e^{Ms}'s [:m, m:] block
    # xi's entries (``step_energy``): f, n's rows of v_F and u (the z rows of N_1 vanish), gamma,
    # kappa.
    start = np.r_[m:2 * m, 2 * m + nF:3 * m, 3 * m + 2 * q:3 * m + 4 * q]
    rows = max(nd, 1)
    erows = np.zeros((rows, 3, m))
    escal = np.zeros((rows, N_SCALARS))
    for k in range(nd):
        psi1, psi2 = weighted_phi(A, phi1, phi2, h, tau[k], shifted_phi1[k])
        erows[k, 0], erows[k, 1], erows[k, 2] = G_load[k], G_load[k] @ psi1, G_load[k] @ psi2
        escal[k, E_PSI0] = tau[k] * -np.expm1(-h / tau[k])
        escal[k, E_DECAY] = np.exp(-h / tau[k])
        escal[k, E_DRIVE_MASS] = drive_mass[k]
        escal[k, E_TAU] = tau[k]
        escal[k, E_HAS_DRIVE] = 1.0
    timed_rows = np.asarray(timed_rows, dtype=float).reshape(len(timed_rows), m)
    out = (erows, escal, Gin[np.ix_(start - m, start - m)], IW[nF:m][:, start - m], Cx.T, R, SP, B,
           sines, timed_rows, timed_rows @ IW[:, :2 * m], forcing)
    return tuple(np.ascontiguousarray(a) for a in out)
