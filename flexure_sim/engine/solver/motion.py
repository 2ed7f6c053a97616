"""
Where the constraints put the prescribed coordinates z_P(t), compiled for the stepping kernel.

``prescribed_motion``: z_P, v_P, a_P of the held coordinates, the lagged and prescribed drives
and the sine rates; ``coordinates``: all coordinates and velocities from y = (z_F, v_F, u)
(the compiled ``Model.full``); ``kernel_coordinates``: the same with the kernel's arguments.
The stepping loop (``step_loop``), ``Model`` and the tick report (``tick_report``) share them.
"""
from __future__ import annotations

import math

import numpy as np

from flexure_sim.engine import jit as kernel_cache
from flexure_sim.engine.jit import njit
from flexure_sim.engine.solver.programs import PIECE_WIDTH, piece_motion


@njit(cache=True)
def prescribed_motion(t, u, command, tau, zP0, D, sine_index, sine_amp, sine_w, sine_phase,
                      Dp, first_program):
    """
    z_P, v_P, a_P.

    Held coordinates, the lagged displacement drives (column k of D: dz_P/du_k; u_k a
    first-order lag of command[k] with time constant tau[k], so v_P = sum_k D_k (command_k -
    u_k)/tau_k), the prescribed drives (column j of Dp: dz_P/dp_j, p_j(t) the program piece at
    command[first_program + j PIECE_WIDTH:], ``programs.piece_motion``) and prescribed sine
    rates (omega = a sin(w t + phase)).
    """
    nP = zP0.shape[0]
    zP = zP0.copy()
    vP = np.zeros(nP)
    aP = np.zeros(nP)
    for k in range(tau.shape[0]):
        udot = (command[k] - u[k]) / tau[k]
        udd = -udot / tau[k]
        for i in range(nP):
            zP[i] += D[i, k] * u[k]
            if k == 0:  # assigned, not added to 0: keeps the sign of a zero rate
                vP[i] = D[i, k] * udot
                aP[i] = D[i, k] * udd
            else:
                vP[i] += D[i, k] * udot
                aP[i] += D[i, k] * udd
    for k in range(Dp.shape[1]):
        o = first_program + k * PIECE_WIDTH
        p, pd, pdd = piece_motion(command[o:o + PIECE_WIDTH], t)
        for i in range(nP):
            c = Dp[i, k]
            if c != 0.0:
                zP[i] += c * p
                vP[i] += c * pd
                aP[i] += c * pdd
    for i in range(sine_index.shape[0]):
        j = sine_index[i]
        a, w, ph = sine_amp[i], sine_w[i], sine_phase[i]
        zP[j] += a / w * (math.cos(ph) - math.cos(w * t + ph))
        vP[j] = a * math.sin(w * t + ph)
        aP[j] = a * w * math.cos(w * t + ph)
    return zP, vP, aP


@njit(cache=True, inline="always")
def coordinates(y, t, command, free, prescribed, n, tau, zP0, D, sine_index, sine_amp, sine_w,
                sine_phase, Dp, first_program):
    """
    All n coordinates z, velocities v and a_P from y = (z_F, v_F, u) at t under ``command``.

    The compiled ``Model.full`` (free ones from y, prescribed ones from `prescribed_motion`).
    """
    nF = free.shape[0]
    u = y[2 * nF:2 * nF + tau.shape[0]]
    zP, vP, aP = prescribed_motion(t, u, command, tau, zP0, D, sine_index, sine_amp, sine_w,
                                   sine_phase, Dp, first_program)
    z = np.empty(n)
    v = np.empty(n)
    for i in range(nF):
        z[free[i]] = y[i]
        v[free[i]] = y[nF + i]
    for i in range(prescribed.shape[0]):
        z[prescribed[i]] = zP[i]
        v[prescribed[i]] = vP[i]
    return z, v, aP


@njit(cache=True)
def kernel_coordinates(y, t, command, args):
    """`coordinates` with the compiled kernel's arguments (``kernel_rhs``): (z, v)."""
    (free, prescribed, mass, zP0, D, tau, sine_index, sine_amp, sine_w, sine_phase, Dp,
     first_program) = args[:12]
    z, v, _ = coordinates(y, t, command, free, prescribed, mass.shape[0], tau, zP0, D,
                          sine_index, sine_amp, sine_w, sine_phase, Dp, first_program)
    return z, v


# Numba's cache of each kernel is keyed on its own file only (``kernel_cache``).
kernel_cache.revalidate(kernel_cache.dispatchers_of(globals()), __file__)
