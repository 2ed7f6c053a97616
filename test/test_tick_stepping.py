"""
Stepping as a node ticks: a new command, then a few steps, call after call.

A stepping node (``stage_node``, energy off) sets a controller's new command every tick and
takes the tick's steps in one ``Simulation.step(n)`` call. Those states must be the ones of
a run with the energies on and of the same commands given as one row per step to a single
call (where the compiled loop switches command between steps), to the bit: the speed-ups of
the per-call work must not change them.
"""
from __future__ import annotations

import numpy as np
import pytest

from flexure_sim.engine.mechanism.loader import load_mechanism
from flexure_sim.engine.solver import integrator as dynamics
from flexure_sim.engine.solver.simulation import Simulation

from conftest import ROOT

STEPS_PER_TICK = 10


def _command(i: int, drives: int) -> np.ndarray:
    """Return a closed loop's commands at tick i: a few nm apart from tick to tick, per drive."""
    value = 1.0e-6 + 1e-9 * (i % 7) - 3e-9 * (i % 3)
    return np.array([value, -0.5 * value][:drives] + [0.0] * (drives - 2))


def _ticks(sim: Simulation, ticks: int) -> list[tuple[np.ndarray, np.ndarray]]:
    out = []
    n = len(sim.model.drives)
    for i in range(1, ticks + 1):
        command = _command(i, n)
        sim.set_command(float(command[0]) if n == 1 else command)
        sim.step(STEPS_PER_TICK)
        out.append((sim.state.z.copy(), sim.state.v.copy()))
    return out


@pytest.mark.parametrize("name", ["microstage", "xy_stage"])
def test_ticks_step_the_same_states_with_and_without_energies_and_in_one_call(name):
    mech = load_mechanism(ROOT / "config" / f"{name}.yaml")
    ticks = 40
    runs = {}
    for energy in (False, True):
        sim = Simulation(mech, energy=energy)
        sim.set_command(_command(0, len(sim.model.drives)))
        sim.step(20)
        runs[energy] = _ticks(sim, ticks)
        assert sim.state.t == pytest.approx(1e-4 * (20 + ticks * STEPS_PER_TICK), rel=1e-12)
    for (z0, v0), (z1, v1) in zip(runs[False], runs[True]):
        assert np.array_equal(z0, z1) and np.array_equal(v0, v1)
    # The stage moves: a test of commands that changed nothing would prove nothing.
    assert np.max(np.abs(runs[False][-1][1])) > 0.0
    assert not np.array_equal(runs[False][0][0], runs[False][-1][0])
    # The same commands as rows of one call (the loop switches command between steps).
    one = Simulation(mech, energy=False)
    one.set_command(_command(0, len(one.model.drives)))
    one.step(20)
    model = one.model
    rows = np.repeat(np.array([model.drives.kernel_command(_command(i, len(model.drives)))
                               for i in range(1, ticks + 1)]), STEPS_PER_TICK, axis=0)
    dynamics.step(model, one.data, len(rows), model.drives.kernel_command(one.state.command),
                  rows)
    assert np.array_equal(one.state.z, runs[False][-1][0])
    assert np.array_equal(one.state.v, runs[False][-1][1])


def test_a_tick_with_an_unchanged_command_steps_as_one_call():
    mech = load_mechanism("microstage")
    ticked, whole = Simulation(mech, energy=False), Simulation(mech, energy=False)
    for sim in (ticked, whole):
        sim.set_command(1.35e-6)
    for _ in range(30):
        ticked.set_command(1.35e-6)  # the node sets it again; it did not change
        ticked.step(STEPS_PER_TICK)
    whole.step(30 * STEPS_PER_TICK)
    assert np.array_equal(ticked.state.z, whole.state.z)
    assert np.array_equal(ticked.state.v, whole.state.v)
    assert ticked.state.t == whole.state.t
