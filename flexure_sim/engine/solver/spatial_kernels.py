"""
The spatial engine's compiled stepping: F(y, t) of a spatial mechanism, and the loop that steps it.

F(y, t) for y = (z_F, w_F, u) (``spatial_model.SpatialModel``): the prescribed coordinates and
their
rates from the drives (``step_loop.prescribed_motion``, the planar engine's), the generalized
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
from flexure_sim.engine.kinematics import generic
from flexure_sim.engine.kinematics import spatial as rotation
from flexure_sim.engine.laws import spatial as coordinates
from flexure_sim.engine.solver import spatial_chain as chain
from flexure_sim.engine.solver import step_loop as stepping
from flexure_sim.engine.solver.step_energy import AUX_DISSIPATION, AUX_ENERGY, AUX_LOAD


@njit(cache=True)
def spatial_rhs(y, t, command, args):
    """
    Return F(y, t) and the energy rates (``step_energy.AUX_*``) of a spatial mechanism.

    ``args`` (``SpatialModel.kernel_args``) = (free, prescribed, zP0, D, tau, sine_index,
    sine_amp, sine_w, sine_phase, first_force, constants, inverse_mass, inverse_inertia,
    inertia): the partition and the drives as the planar kernel's, ``spatial_chain.terms``'s
    constants, 1/m per body, I_b^-1 and I_b (nb, 9).
    """
    (free, prescribed, zP0, D, tau, sine_index, sine_amp, sine_w, sine_phase, first_force,
     constants, inverse_mass, inverse_inertia, inertia) = args
    nF = free.shape[0]
    nd = tau.shape[0]
    u = y[2 * nF:2 * nF + nd]
    zP, vP, aP = stepping.prescribed_motion(t, u, command, tau, zP0, D, sine_index, sine_amp,
                                            sine_w, sine_phase)
    nb = inverse_mass.shape[0]
    N = 6 * nb
    z = np.empty(N)
    w = np.empty(N)
    for i in range(nF):
        z[free[i]] = y[i]
        w[free[i]] = y[nF + i]
    for i in range(prescribed.shape[0]):
        z[prescribed[i]] = zP[i]
        w[prescribed[i]] = vP[i]
    Q = np.empty(N)
    zdot = np.empty(N)
    nh = constants[2][0].shape[0]
    potential, dissipation = chain.terms(z, w, command, first_force, constants, Q, zdot,
                                         np.empty((nh, 6)), np.empty((nh, 6)),
                                         np.empty((nh, 3)))
    acc = np.empty(N)
    kinetic = 0.0
    for i in range(nb):
        for k in range(3):
            acc[6 * i + k] = inverse_mass[i] * Q[6 * i + k]
            kinetic += 0.5 * w[6 * i + k] * w[6 * i + k] / inverse_mass[i]
        for k in range(3):
            s = 0.0
            h = 0.0
            for j in range(3):
                s += inverse_inertia[i, 3 * k + j] * Q[6 * i + 3 + j]
                h += inertia[i, 3 * k + j] * w[6 * i + 3 + j]
            acc[6 * i + 3 + k] = s
            kinetic += 0.5 * w[6 * i + 3 + k] * h
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
    out[m + AUX_DISSIPATION] = dissipation
    out[m + AUX_ENERGY] = kinetic + potential
    return out[:m], out[m:]


@njit(cache=True)
def no_switch_work(y, t, old, new, args):
    """Return 0: the drive work of a command change is not integrated in 3-D (module doc)."""
    return 0.0


def _bind():
    """Return ``step_loop._advance`` compiled with ``spatial_rhs``, under a name of its own."""
    code = stepping._advance.__code__.replace(co_name="_advance_spatial",
                                              co_qualname="_advance_spatial")
    space = dict(vars(stepping))
    space.update(rhs=spatial_rhs, switch=no_switch_work)
    return njit(cache=True)(types.FunctionType(code, space, "_advance_spatial"))


#: The exponential trapezoidal loop of ``stepping`` with the spatial right-hand side.
advance = _bind()

# Numba keys a cache on its function's file: flush when any source of these kernels changes.
jit.revalidate(
    jit.dispatchers_of(globals(), chain, coordinates, rotation, generic), __file__)
