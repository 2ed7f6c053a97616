"""
The compiled stepping loop's fixed arrays handed over as one structure (``kernel_pack``).

``step_loop.advance_packed`` must be ``step_loop.advance`` with the arrays, to the bit; a
simulation that holds the structures must still pickle (a `Simulation` goes to Dask workers
whole) and step on after unpickling exactly as the original does.
"""
from __future__ import annotations

import pickle

import numpy as np
import pytest

from flexure_sim.engine.mechanism.loader import load_mechanism
from flexure_sim.engine.mechanism.spatial_loader import load_spatial
from flexure_sim.engine.solver import integrator, spatial_kernels, step_loop
from flexure_sim.engine.solver.kernel_pack import LoopArgs
from flexure_sim.engine.solver.simulation import Simulation
from flexure_sim.engine.solver.spatial_simulation import SpatialSimulation


def same(a, b) -> bool:
    """Whether two loop results are equal to the bit (NaN equal to NaN)."""
    if isinstance(a, np.ndarray):
        return a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes()
    if isinstance(a, float):
        return np.float64(a).tobytes() == np.float64(b).tobytes()
    return a == b


def checked_calls(module, sim, run) -> int:
    """
    Run ``run()`` recording ``module.advance_packed``'s calls; return how many there were.

    Each call is repeated by ``module.advance`` with the linearization's and the model's arrays
    themselves, which must return the same to the bit.
    """
    calls = []
    real = module.advance_packed

    def spy(*args):
        calls.append(args)
        return real(*args)

    module.advance_packed = spy
    try:
        run()
    finally:
        module.advance_packed = real
    lin = sim.data.lin
    assert isinstance(lin.packed, LoopArgs)
    for args in calls:
        (n, y, t, dt, rows, held, rtol, atol, max_iter, slow, F0, aux0, ye, packed, origin,
         clock) = args
        assert packed is lin.packed
        by_arrays = module.advance(
            n, y, t, dt, rows, held, lin.A, lin.phi1, lin.phi2, rtol, atol, max_iter, slow, F0,
            aux0, ye, lin.emats, sim.model.kernel_args, origin, clock)
        result = real(*args)
        assert len(result) == len(by_arrays) == 13
        assert all(same(a, b) for a, b in zip(result, by_arrays))
    return len(calls)


@pytest.mark.parametrize("energy", [False, True], ids=["motion", "energies"])
def test_the_packed_loop_returns_what_the_loop_with_the_arrays_returns(energy):
    sim = Simulation(load_mechanism("microstage"), dt=1e-4, energy=energy)
    sim.set_command(1e-6)
    sim.step(20)

    def run():
        sim.set_command(1.3e-6)  # a new command: the loop re-evaluates F at the switch
        sim.step(7)
        integrator.step(sim.model, sim.data, 5, None,
                        np.array([[1.3e-6 + 1e-9 * k] for k in range(5)]))

    assert checked_calls(step_loop, sim, run) >= 2
    if energy:
        assert sim.state.dissipated > 0.0


def test_a_stepped_simulation_pickles_and_steps_on_as_the_original():
    sim = Simulation(load_mechanism("microstage"), dt=1e-4, energy=True)
    sim.set_command(1e-6)
    sim.step(30)
    lin, packed = sim.data.lin, sim.data.lin.packed
    # The structure holds the arrays themselves (no copies), and shows them to Python.
    assert packed.A is lin.A and packed.phi1 is lin.phi1 and packed.phi2 is lin.phi2
    assert all(a is b for a, b in zip(packed.emats, lin.emats)) and len(packed.emats) == 12
    assert all(a is b for a, b in zip(packed.args, sim.model.kernel_args))
    copy = pickle.loads(pickle.dumps(sim))
    assert copy.data.lin.packed is not packed
    assert np.array_equal(copy.data.lin.packed.A, lin.A)
    for s in (sim, copy):
        s.set_command(2e-6)
        s.step(25)
    a, b = sim.state, copy.state
    assert a.z.tobytes() == b.z.tobytes() and a.v.tobytes() == b.v.tobytes()
    assert (a.dissipated, a.drive_work) == (b.dissipated, b.drive_work)
    assert np.any(a.z != sim.model.z0)  # it moved


def test_the_spatial_packed_loop_returns_what_its_loop_with_the_arrays_returns():
    sim = SpatialSimulation(load_spatial("tiptilt_stage"))
    sim.set_command([1e-6, 0.0, -1e-6])
    sim.step(5)

    def run():
        sim.set_command([2e-6, 1e-6, 0.0])
        sim.step(4)

    assert checked_calls(spatial_kernels, sim, run) >= 1
    assert np.any(sim.state.z != sim.model.z0)
