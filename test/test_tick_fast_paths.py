"""
The per-call fast paths of a stepping node's tick give the states of the plain route, to the bit.

Two routes a tick takes to save calls into compiled code, each against the route it replaces:

- a new command (energy off): the compiled loop takes F under it at the step's start instead
  of ``Model.rhs`` before the loop; the plain route is the same tick with the integrator's
  cache dropped (the state packed again and F taken by ``Model.rhs``);
- a drive filter's ramp (``Simulation.step_commands``, ``engine_steps.advance``): one call of
  the stepping loop with one command row per step instead of ``set_command`` and ``step(1)``
  per step, the route written out here.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from flexure_sim.engine.mechanism.loader import load_mechanism
from flexure_sim.engine.solver.model import Model
from flexure_sim.engine.solver.simulation import Simulation
from flexure_sim.node.inputs.command_checks import CommandFilter, DriveLimits
from flexure_sim.node.stage import engine_steps

from conftest import ROOT

STEPS = 10


def _same(a: Simulation, b: Simulation) -> None:
    sa, sb = a.state, b.state
    assert sa.t == sb.t
    for name in ("z", "v", "u", "command"):
        assert np.array_equal(getattr(sa, name), getattr(sb, name)), name
    assert a.stats == b.stats


def _ramp(start: np.ndarray, end: np.ndarray, steps: int) -> list:
    """Return the commands of a ramp from ``start`` to ``end`` over ``steps`` steps (last: end)."""
    out = [start + (end - start) * (i + 1) / steps for i in range(steps)]
    return [float(c[0]) for c in out] if len(start) == 1 else out


def _one_at_a_time(sim: Simulation, commands: list, n: int) -> None:
    """Step the plain route: ``set_command``, one step per command, the last held to n steps."""
    for i, command in enumerate(commands):
        sim.set_command(command)
        sim.step(1 if i < len(commands) - 1 else n - i)


@pytest.mark.parametrize("name, energy", [("microstage", False), ("xy_stage", False),
                                          ("microstage", True)])
def test_a_ramp_in_one_call_steps_the_states_of_one_step_at_a_time(name, energy):
    mech = load_mechanism(ROOT / "config" / f"{name}.yaml")
    fast, plain = Simulation(mech, energy=energy), Simulation(mech, energy=energy)
    drives = len(fast.model.drives)
    for sim in (fast, plain):
        sim.set_command(0.3e-6 if drives == 1 else [0.3e-6, -0.2e-6])
        sim.step(20)
    for tick in range(24):
        # Ramps of 2 to 10 steps (the last ones not settling within the tick), both ways.
        end = np.array([1e-6 * ((tick % 3) - 1), 0.4e-6 * (tick % 2)][:drives])
        length = 2 + tick % 9
        commands = _ramp(fast.state.command, end, length)
        fast.step_commands(commands, STEPS if length < STEPS else length)
        _one_at_a_time(plain, commands, STEPS if length < STEPS else length)
        _same(fast, plain)
    if energy:
        assert fast.state.drive_work == plain.state.drive_work
    # The stage moved: a comparison of states at rest would prove little.
    assert np.max(np.abs(fast.state.v)) > 1e-6


def test_the_node_follows_a_ramp_as_one_step_at_a_time():
    # engine_steps.advance with a real drive filter: large commands, so each tick ramps for
    # 4 to 10 of its steps; the plain route steps one at a time with a second filter.
    mech = load_mechanism("microstage")
    fast, plain = Simulation(mech, energy=False), Simulation(mech, energy=False)
    limits = DriveLimits(-20e-6, 20e-6, slew_rate=2e-3)  # 0.2 um per 1e-4 s step
    filters = CommandFilter(limits), CommandFilter(limits)
    dt = fast.model.dt
    for tick in range(30):
        target = (0.8e-6 + 0.2e-6 * (tick % 7)) * (-1) ** tick
        for f in filters:
            f.submit(target)
        engine_steps.advance(fast, filters[0], None, STEPS, dt)
        f = filters[1]
        f.begin_tick(STEPS * dt)
        commands = [f.advance(dt)]
        while not f.settled and len(commands) < STEPS:
            commands.append(f.advance(dt))
        _one_at_a_time(plain, commands, STEPS)
        _same(fast, plain)
        assert 4 <= len(commands) <= STEPS
    assert fast.state.t == pytest.approx(30 * STEPS * dt, rel=1e-12)


def test_more_commands_than_steps_are_refused():
    sim = Simulation(load_mechanism("microstage"), energy=False)
    with pytest.raises(ValueError, match="1 to n"):
        sim.step_commands([1.1e-6] * 3, 2)
    with pytest.raises(ValueError, match="1 to n"):
        sim.step_commands([], 2)
    assert sim.state.t == 0.0


def test_a_new_command_tick_steps_as_with_a_fresh_rhs(monkeypatch):
    mech = load_mechanism("microstage")
    fast, plain = Simulation(mech, energy=False), Simulation(mech, energy=False)
    calls = {"rhs": 0}
    rhs = Model.rhs

    def counted(self, *args):
        calls["rhs"] += 1
        return rhs(self, *args)

    monkeypatch.setattr(Model, "rhs", counted)
    for sim in (fast, plain):
        sim.set_command(1e-6)
        sim.step(20)
    calls["rhs"] = 0  # each took F once to start
    for tick in range(40):
        # A new command every tick (a held one would keep the cached F, not a fresh one).
        command = 1e-6 + 1e-9 * (1 + tick % 7)
        fast.set_command(command)
        fast.step(STEPS)
        plain.data.cache = None  # the plain route: y packed again, F by Model.rhs
        plain.set_command(command)
        plain.step(STEPS)
        _same(fast, plain)
    # The plain route took F once a tick; the fast one never (the loop took it).
    assert calls["rhs"] == 40
    assert np.max(np.abs(fast.state.v)) > 0.0


@pytest.mark.parametrize("energy", [False, True])
def test_a_ramp_that_fails_leaves_the_state_as_it_was(energy):
    # With the energies on the ramp is stepped one at a time: the same promise.
    sim = Simulation(load_mechanism("microstage"), energy=energy)
    sim.set_command(1e-6)
    sim.step(5)
    before = sim.state
    command = before.command.copy()
    with pytest.raises(ValueError, match="finite"):
        sim.step_commands([1.1e-6, 1.2e-6, math.inf], STEPS)
    assert sim.state is before and np.array_equal(sim.state.command, command)
    sim.step_commands([1.1e-6, 1.2e-6], STEPS)  # and steps on from there
    assert sim.state.t == pytest.approx(before.t + STEPS * sim.dt, rel=1e-12)


@pytest.mark.parametrize("energy", [False, True])
def test_warm_runs_the_next_step_and_leaves_every_state_as_it_was(energy, monkeypatch):
    """
    ``Simulation.warm`` (the paced node's busy-wait) steps the loop once and keeps nothing.

    A simulation warmed before every tick, at rest and under a closed loop's new commands,
    steps the states and counters of one never warmed, to the bit; each warm ran the loop once
    (counted around the integrator's call); with no linearization at hand it takes none.
    """
    from flexure_sim.engine.solver import integrator

    mech = load_mechanism("microstage")
    warmed, plain = Simulation(mech, energy=energy), Simulation(mech, energy=energy)
    calls = []
    real = integrator._advance
    monkeypatch.setattr(integrator, "_advance",
                        lambda *a: calls.append(a[2]) or real(*a))
    warmed.warm()  # nothing stepped yet: no linearization, no seed
    assert calls == [] and warmed.data.lin is None and warmed.stats.linearizations == 0
    for k in range(30):
        command = 1e-6 if k < 15 else 1e-6 + 1e-9 * (k % 4)
        for sim in (warmed, plain):
            sim.set_command(command)
        if k:
            before = (warmed.data.state, warmed.data.cache, warmed.data.lin, warmed.data.clock)
            n_calls = len(calls)
            warmed.warm()
            assert calls[n_calls:] == [1]
            after = (warmed.data.state, warmed.data.cache, warmed.data.lin, warmed.data.clock)
            assert all(x is y for x, y in zip(before, after))
        for sim in (warmed, plain):
            sim.step(STEPS)
        _same(warmed, plain)
        if energy:
            assert warmed.state.dissipated == plain.state.dissipated
            assert warmed.state.drive_work == plain.state.drive_work
    warmed.data.lin = None  # a linearization due: warm leaves it to the step
    n_calls, linearizations = len(calls), warmed.stats.linearizations
    warmed.warm()
    assert len(calls) == n_calls and warmed.data.lin is None
    assert warmed.stats.linearizations == linearizations
