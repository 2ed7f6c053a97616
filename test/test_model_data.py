"""
Model apart from Data (issue 10 item 2).

Several runs share one model's constants and step independently, exactly as separate simulations
do.
"""
import copy

import numpy as np
import pytest

from flexure_sim.engine.mechanism.loader import load_mechanism
from flexure_sim.engine.solver.model import Model
from flexure_sim.engine.solver.simulation import Simulation

U_IN = 1.35e-6


def _drive(sim, plan):
    for command, steps in plan:
        sim.set_command(command)
        sim.step(steps)
    return sim


def _same(a, b):
    sa, sb = a.snapshot(), b.snapshot()
    assert np.array_equal(a.state.z, b.state.z) and np.array_equal(a.state.v, b.state.v)
    assert (a.state.t, a.state.dissipated, a.state.drive_work) == \
        (b.state.t, b.state.dissipated, b.state.drive_work)
    assert np.array_equal(a.state.u, b.state.u)
    assert (sa.output, sa.compression, sa.drive_force) == \
        (sb.output, sb.compression, sb.drive_force)
    assert a.stats == b.stats


@pytest.mark.parametrize("name", ["microstage", "fourbar_mixed"])
def test_two_data_on_one_model_step_like_two_simulations(name):
    mech = load_mechanism(name)
    model = Model(mech)
    frozen = copy.deepcopy(model.__dict__)
    shared = [Simulation(model), Simulation(model)]
    alone = [Simulation(mech), Simulation(mech)]
    has_drive = model.drive is not None
    if has_drive:
        plans = ([(U_IN, 7), (0.4 * U_IN, 30), (U_IN, 13)], [(0.2 * U_IN, 20), (U_IN, 30)])
    else:
        plans = ([(None, 50)], [(None, 20), (None, 17)])
    # Interleave the shared runs so that each steps while the other is mid-run.
    for k in range(3):
        for sims, plan in ((shared, plans[0]), (shared[::-1], plans[1]),
                           (alone, plans[0]), (alone[::-1], plans[1])):
            if k < len(plan):
                command, steps = plan[k]
                if command is not None:
                    sims[0].set_command(command)
                sims[0].step(steps)
    assert shared[0].model is shared[1].model
    _same(shared[0], alone[0])
    _same(shared[1], alone[1])
    assert not np.array_equal(shared[0].state.z, shared[1].state.z)
    for key, value in frozen.items():  # stepping never wrote into the model
        if isinstance(value, np.ndarray):
            assert np.array_equal(getattr(model, key), value), key


def test_reset_of_one_run_leaves_the_other():
    model = Model(load_mechanism("microstage"))
    a, b = Simulation(model), Simulation(model)
    _drive(a, [(U_IN, 10)])
    _drive(b, [(U_IN, 10)])
    a.reset()
    assert a.state.t == 0.0 and np.array_equal(a.state.z, model.z0)
    assert b.state.t == pytest.approx(1e-3) and b.snapshot().output > 0


def test_a_model_fixes_its_step():
    model = Model(load_mechanism("microstage"), dt=2e-4)
    assert Simulation(model).dt == 2e-4
    with pytest.raises(ValueError, match="belong to the model"):
        Simulation(model, dt=1e-5)


@pytest.mark.parametrize("name", ["microstage", "xy_stage"])
def test_stepping_makes_a_new_state_and_leaves_the_old_one_as_it_was(name):
    """
    A step replaces the state and never writes into the one before.

    The node's engine hold keeps a reference to the state before a tick instead of a copy
    (node/stage/engine_guard.py); stepping with a command held, then with a new one, must leave
    every array of each earlier state untouched.
    """
    sim = Simulation(load_mechanism(name))
    n = len(sim.model.drives)
    commands = ([1e-6] * n if n > 1 else 1e-6), ([2e-6] * n if n > 1 else 2e-6)
    for command in commands:
        sim.set_command(command)
        for steps in (1, 5):
            before = sim.state
            kept = copy.deepcopy(before)
            sim.step(steps)
            assert sim.state is not before
            for field in ("t", "z", "v", "u", "command", "dissipated", "drive_work"):
                np.testing.assert_array_equal(getattr(before, field), getattr(kept, field))
            assert not np.shares_memory(sim.state.z, before.z)
            assert not np.shares_memory(sim.state.v, before.v)
