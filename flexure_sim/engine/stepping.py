"""The exponential trapezoidal rule, as one loop that Numba compiles when it can.

For y' = F(y, t), an exact Jacobian A = dF/dy taken at some earlier state,
F0 = F(y_n, t_n) and the remainder N(y, t) = F(y, t) - F0 - A (y - y_n), a step is

    y_{n+1} = U + h phi_2(hA) N(y_{n+1}, t_{n+1}),     U = y_n + h phi_1(hA) F0,

(the variation-of-constants formula with N interpolated linearly over the step), solved by
fixed-point iteration from y_{n+1} = U. The iteration contracts by about |J - A| / |J| per
sweep; it has converged when its last change is below rtol |U| + atol in every component.

``advance`` runs up to n steps and stops early with a status when the iteration does not
contract (1) or contracts slowly (2), so the caller can re-linearize. The loop calls
``rhs(y, t, command, args)`` -> (F, drive power, dissipated power): compiled with the force
kernel for quadratic laws (``advance``), or as plain Python with ``Simulation._rhs_python``
for any law (``advance_interpreted``); one source, two bindings of ``rhs``.
"""
from __future__ import annotations

import math
import types

import numpy as np

from .kernels import njit, quadratic_forces

CONVERGED, NOT_CONTRACTING, SLOW = 0, 1, 2


@njit(cache=True)
def prescribed_motion(t, u, command, tau, has_drive, zP0, du, sine_index, sine_amp, sine_w, sine_phase):
    """z_P, v_P, a_P: held coordinates, the drive (first-order lag of the command along
    its axis) and prescribed sine rates (omega = a sin(w t + phase))."""
    udot = (command - u) / tau if has_drive else 0.0
    zP = zP0 + du * u
    vP = du * udot
    aP = du * (-udot / tau if has_drive else 0.0)
    for i in range(sine_index.shape[0]):
        j = sine_index[i]
        a, w, ph = sine_amp[i], sine_w[i], sine_phase[i]
        zP[j] += a / w * (math.cos(ph) - math.cos(w * t + ph))
        vP[j] = a * math.sin(w * t + ph)
        aP[j] = a * w * math.cos(w * t + ph)
    return zP, vP, aP


@njit(cache=True)
def kernel_rhs(y, t, command, args):
    """F(y, t), drive power and dissipated power with the compiled quadratic-law forces.

    args = (free, prescribed, mass, zP0, du, tau, has_drive, sine_index, sine_amp, sine_w,
    sine_phase, ia, ib, ca, cb, phia, phib, kind, W, C) -- see Simulation._kernel_args.
    """
    (free, prescribed, mass, zP0, du, tau, has_drive, sine_index, sine_amp, sine_w, sine_phase,
     ia, ib, ca, cb, phia, phib, kind, W, C) = args
    nF = free.shape[0]
    u = y[2 * nF] if has_drive else 0.0
    zP, vP, aP = prescribed_motion(t, u, command, tau, has_drive, zP0, du, sine_index, sine_amp, sine_w, sine_phase)
    N = mass.shape[0]
    z = np.empty(N)
    v = np.empty(N)
    for i in range(nF):
        z[free[i]] = y[i]
        v[free[i]] = y[nF + i]
    for i in range(prescribed.shape[0]):
        z[prescribed[i]] = zP[i]
        v[prescribed[i]] = vP[i]
    Q = np.empty(N)
    n = ia.shape[0]
    _, dissipation = quadratic_forces(z, v, ia, ib, ca, cb, phia, phib, kind, W, C, Q, np.empty((n, 3)),
                                      np.empty((n, 3)))
    F = np.empty_like(y)
    for i in range(nF):
        F[i] = y[nF + i]
        F[nF + i] = Q[free[i]] / mass[free[i]]
    if has_drive:
        F[2 * nF] = (command - u) / tau
    power = 0.0
    for i in range(prescribed.shape[0]):
        j = prescribed[i]
        power += (mass[j] * aP[i] - Q[j]) * vP[i]
    return F, power, dissipation


def _advance(n, y, t, dt, command, A, phi1, phi2, rtol, atol, max_iter, slow_after, F0, p0, d0, args):
    """Up to n steps from (y, t) with F0 = F(y, t), p0, d0 the powers there.

    Returns (y, F, p, d, dissipated, work, steps, iterations, status): the state and its
    F and powers after the steps taken (at t + steps dt; the caller keeps time), the
    trapezoidal integrals of the dissipated and drive powers over them, and why it stopped. ``rhs`` is a global of the function (see
    the end of this module), not an argument: Numba cannot cache functions that take
    compiled functions as arguments.
    """
    dissipated = 0.0
    work = 0.0
    steps = 0
    iterations = 0
    status = CONVERGED
    for i in range(n):
        t1 = t + (i + 1) * dt  # on the step grid, not a running sum
        U = y + phi1 @ F0
        weight = rtol * np.abs(U) + atol
        y1 = U.copy()
        previous = np.inf
        converged = False
        k = 0
        F1, p1, d1 = F0, p0, d0
        for k in range(1, max_iter + 1):
            F1, p1, d1 = rhs(y1, t1, command, args)
            y_next = U + phi2 @ (F1 - F0 - A @ (y1 - y))
            change = np.max(np.abs(y_next - y1) / weight)
            if not math.isfinite(change):
                break
            if change <= 1.0:
                # F at the accepted point, to first order in a change below tolerance.
                F1 = F1 + A @ (y_next - y1)
                y1 = y_next
                converged = True
                break
            if change > 0.5 * previous:
                break
            previous = change
            y1 = y_next
        if not converged:
            status = NOT_CONTRACTING
            break
        dissipated += 0.5 * dt * (d0 + d1)
        work += 0.5 * dt * (p0 + p1)
        y = y1
        F0, p0, d0 = F1, p1, d1
        steps += 1
        iterations += k
        if k > slow_after:
            status = SLOW
            break
    return y, F0, p0, d0, dissipated, work, steps, iterations, status


#: The right-hand side the compiled loop calls (resolved when Numba compiles ``advance``).
rhs = kernel_rhs

#: The loop, compiled with the quadratic-law kernel.
advance = njit(cache=True)(_advance)


def _interpreted_rhs(y, t, command, simulation):
    return simulation._rhs_python(y, t, command)


#: The same loop as plain Python, calling ``Simulation._rhs_python`` (any hinge law);
#: pass the Simulation as ``args``.
advance_interpreted = types.FunctionType(
    _advance.__code__, {**globals(), "rhs": _interpreted_rhs}, "advance_interpreted")
