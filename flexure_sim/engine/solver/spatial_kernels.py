"""
The spatial engine's compiled stepping: F(y, t) of a spatial mechanism, and the loop that steps it.

F(y, t) for y = (z_F, w_F, u) (``spatial_model.SpatialModel``): the coordinates, the prescribed
ones and their rates from the drives (``motion.coordinates``, the planar engine's), the generalized
forces and coordinate rates of ``spatial_chain.terms``, and

    dz_F/dt = (dz/dt)_F,    dw_F/dt = (M^-1 Q)_F,    du/dt = (command - u) / tau,

with M = diag(m I, I_b) per body (a body's rotations are all free or all held, so M^-1 acts
body by body). The loop is the planar engine's exponential trapezoidal rule
(``step_loop._advance``), the same code compiled a second time with this right-hand side:
one definition of the integrator for both engines. Energy bookkeeping of the step (dissipated
energy, drive work) is not integrated in 3-D: the loop runs with ``step_energy.NO_ENERGY``.
"""
from __future__ import annotations

import types

import numpy as np

from flexure_sim.engine import jit
from flexure_sim.engine.jit import njit
from flexure_sim.engine.solver import spatial_chain as chain
from flexure_sim.engine.solver import step_loop as stepping
from flexure_sim.engine.solver.kernel_pack import LoopArgs
from flexure_sim.engine.solver.motion import coordinates
from flexure_sim.engine.solver.step_energy import AUX_LOAD


@njit(cache=True)
def spatial_rhs(y, t, command, args):
    """
    Return F(y, t) and the energy rates (``step_energy.AUX_*``) of a spatial mechanism.

    The energy rates are the drives' loads only: the steps' energies are not integrated in 3-D
    (``step_energy.NO_ENERGY``), so the chain runs without its reports (``spatial_chain.terms``).

    ``args`` (``SpatialModel.kernel_args``) = (free, prescribed, zP0, D, tau, sine_index,
    sine_amp, sine_w, sine_phase, Dp, first_program, first_force, constants, inverse_mass,
    inverse_inertia): the
    partition and the drives as the planar kernel's, ``spatial_chain.terms``'s constants, 1/m
    per body and I_b^-1 (nb, 9).
    """
    (free, prescribed, zP0, D, tau, sine_index, sine_amp, sine_w, sine_phase, Dp, first_program,
     first_force, constants, inverse_mass, inverse_inertia) = args
    nF = free.shape[0]
    nd = tau.shape[0]
    u = y[2 * nF:2 * nF + nd]
    nb = inverse_mass.shape[0]
    N = 6 * nb
    z, w, _ = coordinates(y, t, command, free, prescribed, N, tau, zP0, D, sine_index, sine_amp,
                          sine_w, sine_phase, Dp, first_program)
    Q = np.empty(N)
    zdot = np.empty(N)
    none = np.empty((0, 6))
    chain.terms(z, w, command, first_force, constants, Q, zdot, none, none, none, False)
    acc = np.empty(N)
    for i in range(nb):
        for k in range(3):
            acc[6 * i + k] = inverse_mass[i] * Q[6 * i + k]
        for k in range(3):
            s = 0.0
            for j in range(3):
                s += inverse_inertia[i, 3 * k + j] * Q[6 * i + 3 + j]
            acc[6 * i + 3 + k] = s
    m = y.shape[0]
    out = np.zeros(m + AUX_LOAD + nd)
    for i in range(nF):
        out[i] = zdot[free[i]]
        out[nF + i] = acc[free[i]]
    for k in range(nd):
        out[2 * nF + k] = (command[k] - u[k]) / tau[k]
        load = 0.0
        for i in range(prescribed.shape[0]):
            load += D[i, k] * Q[prescribed[i]]
        out[m + AUX_LOAD + k] = load
    return out[:m], out[m:]


@njit(cache=True)
def terms(z, w, command, first_force, constants, Q, zdot, deflection, wrench, power, report):
    """Return ``spatial_chain.terms`` on floats, compiled (the reports' entry from Python)."""
    return chain.terms(z, w, command, first_force, constants, Q, zdot, deflection, wrench,
                       power, report)


#: The complex step (module docstring of ``kinematics.scalar``): small enough that its square
#: is lost against every value (1e-80), large enough that h times any derivative stays far
#: from underflow.
COMPLEX_STEP = 1e-40


@njit(cache=True)
def complex_step(z, w, command, Zx, Wx, Cx, first_force, constants, n_hinges):
    """
    Return dQ/ds (N, m), d(dz/dt)/ds (N, m) and d(wrenches)/ds (n_hinges, 6, m), exact.

    Along m seeds s with dz/ds = Zx, dw/ds = Wx and d(command)/ds = Cx: per seed one
    evaluation of ``spatial_chain.terms`` at (z + i h Zx_j, w + i h Wx_j, command + i h Cx_j),
    whose imaginary parts divided by h are the derivatives (h = ``COMPLEX_STEP``).
    """
    N, m = z.shape[0], Zx.shape[1]
    h = COMPLEX_STEP
    dQ, dz, dW = np.empty((N, m)), np.empty((N, m)), np.empty((n_hinges, 6, m))
    zc, wc = np.empty(N, np.complex128), np.empty(N, np.complex128)
    cc = np.empty(command.shape[0], np.complex128)
    Q, zdot = np.empty(N, np.complex128), np.empty(N, np.complex128)
    defl = np.empty((n_hinges, 6), np.complex128)
    wrench = np.empty((n_hinges, 6), np.complex128)
    power = np.empty((n_hinges, 3), np.complex128)
    for j in range(m):
        for i in range(N):
            zc[i] = complex(z[i], h * Zx[i, j])
            wc[i] = complex(w[i], h * Wx[i, j])
        for i in range(command.shape[0]):
            cc[i] = complex(command[i], h * Cx[i, j])
        chain.terms(zc, wc, cc, first_force, constants, Q, zdot, defl, wrench, power, True)
        for i in range(N):
            dQ[i, j] = Q[i].imag / h
            dz[i, j] = zdot[i].imag / h
        for k in range(n_hinges):
            for c in range(6):
                dW[k, c, j] = wrench[k, c].imag / h
    return dQ, dz, dW


@njit(cache=True)
def no_switch_work(y, t, old, new, args):
    """Return 0: the drive work of a command change is not integrated in 3-D (module doc)."""
    return 0.0


@njit(cache=True)
def spatial_coordinates(y, t, command, args):
    """
    Return all coordinates z and quasi-velocities w at y (``SpatialModel.full``, compiled).

    The loop's ``where``: the caller takes them from the loop's return instead of a second
    call into compiled code (``step_loop._advance``).
    """
    (free, prescribed, zP0, D, tau, sine_index, sine_amp, sine_w, sine_phase, Dp, first_program,
     _, _, inverse_mass, _) = args
    z, w, _ = coordinates(y, t, command, free, prescribed, 6 * inverse_mass.shape[0], tau, zP0,
                          D, sine_index, sine_amp, sine_w, sine_phase, Dp, first_program)
    return z, w


def _bind():
    """Return ``step_loop._advance`` compiled with ``spatial_rhs``, under a name of its own."""
    code = stepping._advance.__code__.replace(co_name="_advance_spatial",
                                              co_qualname="_advance_spatial")
    space = dict(vars(stepping))
    space.update(rhs=spatial_rhs, switch=no_switch_work, where=spatial_coordinates)
    return njit(cache=True)(types.FunctionType(code, space, "_advance_spatial"))


#: The exponential trapezoidal loop of ``stepping`` with the spatial right-hand side.
advance = _bind()


@njit(cache=True)
def advance_packed(n, y, t, dt, commands, held, rtol, atol, max_iter, slow_after, F0, aux0, ye,
                   packed: LoopArgs, origin, clock):
    """``advance`` with the fixed arrays as one structure (``step_loop.advance_packed``)."""
    return advance(n, y, t, dt, commands, held, packed.A, packed.phi1, packed.phi2, rtol, atol,
                   max_iter, slow_after, F0, aux0, ye, packed.emats, packed.args, origin, clock)


# Numba keys a cache on its function's file: flush when any source of these kernels changes.
jit.revalidate([spatial_rhs, terms, complex_step, no_switch_work, spatial_coordinates, advance,
                advance_packed], __file__)
