"""
Fixed-step stiff-stable stepping of a ``SpatialModel``, updating a ``data.Data``.

The planar engine's exponential trapezoidal rule (``solver.integrator``, ``solver.step_loop``):
y_{n+1} = y_n + h phi_1(hA) F_0 + h phi_2(hA) N(y_{n+1}) with an exact Jacobian A taken at an
earlier state (``SpatialModel.jacobian``) and re-taken only when the remainder iteration stops
contracting (or the configuration moved by more than ``relinearize_tol``). The linearization
(A, h phi_1, h phi_2 from the block exponential of ``integrator.phi_matrices``, one per
independent block of A: ``phi_by_blocks``) is the planar engine's ``integrator.linearize``;
the loop is the planar engine's (``integrator.march``, with its retries), its compiled part
``step_loop``'s with the spatial right-hand side (``spatial_kernels.advance``). Time stays
on the step grid, as there.
"""
from __future__ import annotations

import math

import numpy as np
import scipy.sparse.csgraph

from flexure_sim.engine.solver import spatial_kernels as kernels
from flexure_sim.engine.solver.integrator import Stepper, march, phi_matrices
from flexure_sim.engine.solver.integrator import moved_too_far as planar_moved_too_far
from flexure_sim.engine.solver.kernel_pack import loop_args
from flexure_sim.engine.solver.model import SolverError
from flexure_sim.engine.solver.spatial_model import SpatialModel
from flexure_sim.engine.solver.state import Data, Linearization, State
from flexure_sim.engine.solver.step_energy import NO_ENERGY


def phi_by_blocks(A: np.ndarray, h: float) -> tuple[np.ndarray, np.ndarray]:
    """
    Return h phi_1(hA) and h phi_2(hA), one exponential per independent block of A.

    The state's coordinates that A does not couple (exactly zero entries both ways: a planar
    stage's in-plane and out-of-plane motion at an in-plane state) form separate blocks
    (``scipy.sparse.csgraph.connected_components``); the exponential of each block's
    augmented matrix (``integrator.phi_matrices``) costs (3 m_b)^3 instead of (3 m)^3 for the
    whole, so the stage opened in 3-D linearizes in a quarter of the time. One block: the
    whole matrix, as the planar engine does it.
    """
    count, label = scipy.sparse.csgraph.connected_components((A != 0) | (A.T != 0),
                                                             directed=False)
    if count == 1:
        return phi_matrices(A, h)[1:]
    phi1, phi2 = np.zeros_like(A), np.zeros_like(A)
    for b in range(count):
        idx = np.flatnonzero(label == b)
        block = np.ix_(idx, idx)
        phi1[block], phi2[block] = phi_matrices(A[block], h)[1:]
    return phi1, phi2


def linearize(model: SpatialModel, data: Data, y: np.ndarray, t: float, command) -> None:
    """Exact Jacobian at y and the step's h phi_1(hA), h phi_2(hA), into ``data.lin``."""
    A = model.jacobian(y, t, command)
    phi1, phi2 = phi_by_blocks(A, model.dt)
    data.lin = Linearization(model.unpack(y, t, command)[0], A, phi1, phi2, NO_ENERGY,
                             loop_args(A, phi1, phi2, NO_ENERGY, model.kernel_args))
    data.stats.linearizations += 1


def moved_too_far(model: SpatialModel, data: Data, z: np.ndarray) -> bool:
    """Whether z moved further than ``relinearize_tol`` (``integrator.moved_too_far``)."""
    return planar_moved_too_far(model, data, z, per_body=6, translations=3)


def _advance(model: SpatialModel, data: Data, n, y, t, rows, held, F0, aux0, ye, origin, k):
    """Advance up to n steps in the compiled spatial loop (``spatial_kernels.advance``)."""
    lin = data.lin
    assert lin is not None  # march() linearizes before it advances
    return kernels.advance_packed(n, y, t, model.dt, rows, held, model.iteration_rtol,
                                  model.atol, model.max_iterations, model.relinearize_after, F0,
                                  aux0, ye, lin.packed, origin, k)


#: The planar engine's step loop (``integrator.march``) with the spatial model's pieces.
SPATIAL = Stepper(linearize, _advance, moved_too_far)


def step(model: SpatialModel, data: Data, n: int = 1) -> None:
    """
    Advance ``data`` n fixed steps with the drives' commands held at state.command.

    From the state it stepped last, the next call takes y, the kernel's command vector and F
    from the cache (as ``integrator.step``), and the loop returns the coordinates
    (``spatial_kernels.spatial_coordinates``): the tip-tilt stage's step(1) 18 us against 32 us
    when each call packed y, built the command and unpacked z and w in Python (step(10): 48
    against 62 us; two interleaved runs, best of 7 x 2000 calls).
    """
    s = data.state
    cache: tuple = data.cache or ()
    seeded = bool(cache) and cache[0] is s
    held = data.held_command(s)  # commands held on: the last vector
    if held is not None:
        command, key = held
    else:
        command = np.ascontiguousarray(model.actuator_command(s.command), dtype=float)
        key = command.tobytes()
    rows = command.reshape(1, -1)
    clock = data.clock
    if clock is None or clock[0] is not s:
        clock = (s, s.t, 0)
    _, origin, k = clock
    t = s.t
    y = cache[5] if seeded else model.pack(s)  # bit for bit: s was unpacked from it
    if seeded and cache[1] == key:
        F0, aux0, ye = cache[2:5]
    else:
        F0, aux0 = model.rhs(y, t, command)
        ye = y
    y, t, k, F0, aux0, ye, command, _, _, z, w, finite = march(
        model, data, n, (y, t, origin, k), rows, command, (F0, aux0, ye), (0.0, 0.0), SPATIAL)
    if z is None or w is None:  # no step asked for
        z, w, _ = model.unpack(y, t, command)
        finite = bool(np.isfinite(y).all())
    if not finite:
        raise SolverError(f"non-finite state at t = {t:.6g} s (step {model.dt:g} s)")
    model.check_range(z)
    nF = len(model.part.free)
    u = model.state_u(y[2 * nF:2 * nF + model.n_actuators])
    data.state = State(t, z, w, u, s.command, math.nan, math.nan)
    data.clock = (data.state, origin, k)
    data.seed(F0, aux0, ye, y, command)
