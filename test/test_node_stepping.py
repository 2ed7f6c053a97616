"""
The stage node's stepping loop in this process: the engine work of one tick (no DDS traffic).

Real `Simulation`, `CommandFilter` and `StageInterface`; the loop is driven tick by tick.
"""
from __future__ import annotations

import time

import numpy as np
import pytest

from flexure_sim.engine.mechanism.loader import load_mechanism
from flexure_sim.engine.solver.simulation import Simulation
from flexure_sim.node.inputs.command_checks import CommandFilter, DriveLimits
from flexure_sim.node.publish.interface import StageInterface
from flexure_sim.node.record.session import RecordingSession
from flexure_sim.node.stage.loop_parts import LoopParts, LoopSettings
from flexure_sim.node.stage.stepping_thread import RELINEARIZE_TOL, SteppingLoop

DT = 1.0e-4
RATE = 1000.0
N_STEPS = 10


class Log:
    def info(self, _text: str) -> None:
        pass

    warning = error = info


class Discard:
    """A tick topic's publisher that the tests never read."""

    def publish(self, _data: bytes) -> None:
        pass


def make_loop(mechanism):
    """Build a real-time stepping loop of the stage at 1 kHz, not started (the test ticks)."""
    sim = Simulation(mechanism, dt=DT, relinearize_tol=RELINEARIZE_TOL)
    drive = mechanism.drive
    filt = CommandFilter(DriveLimits(drive.stroke[0], drive.stroke[1], drive.slew_rate))
    interface = StageInterface(mechanism, "realtime")
    parts = LoopParts(LoopSettings("realtime", RATE, DT), sim, interface,
                      [Discard() for _ in interface.tick_topics], RecordingSession(Log()), Log(),
                      filter=filt)
    loop = SteppingLoop(parts)
    return loop, sim, filt


def reference_ramp(mechanism, commands):
    """
    Step the drive's definition (docs/node.md: drive commands), apart from the loop's shortcuts.

    The applied target moves towards each tick's command by at most slew_rate * dt per
    engine step, and the engine takes one step per applied value.
    """
    sim = Simulation(mechanism, dt=DT, relinearize_tol=RELINEARIZE_TOL)
    slew = mechanism.drive.slew_rate * DT
    applied = 0.0
    for command in commands:
        for _ in range(N_STEPS):
            applied += min(max(command - applied, -slew), slew)
            sim.set_command(applied)
            sim.step(1)
    return sim.state


@pytest.fixture(scope="module")
def stage():
    return load_mechanism("microstage")


def test_ticks_with_new_commands_reach_the_states_of_the_step_by_step_definition(stage):
    loop, sim, filt = make_loop(stage)
    # Within one step's slew (1 um/step at 0.01 m/s), a jump the actuator ramps over two
    # ticks (2 um), ticks without a new command, and back down.
    commands = [1.0e-6, 1.0e-6 + 3e-9, 1.0e-6 - 2e-9, 0.0, 2.0e-6, 2.0e-6, 2.0e-6, 1.5e-6,
                1.5e-6 + 1e-10]
    for command in commands:
        if command != filt.target:
            filt.submit_many([command])
        loop._advance_engine()
    ref = reference_ramp(stage, commands)
    assert sim.state.t == ref.t
    np.testing.assert_array_equal(sim.state.z, ref.z)
    np.testing.assert_array_equal(sim.state.v, ref.v)
    assert sim.state.command == ref.command


def cpu_per_tick(loop, filt, new_command: bool, ticks: int = 200) -> float:
    """Thread CPU time of the engine part of one tick (s), best of five runs."""
    best = float("inf")
    for run in range(5):
        t0 = time.thread_time()
        for k in range(ticks):
            if new_command:  # a controller's answer: a few nm from the last one
                filt.submit_many([1.0e-6 + 1e-9 * ((run * ticks + k) % 7)])
            loop._advance_engine()
        best = min(best, (time.thread_time() - t0) / ticks)
    return best


def test_a_new_command_every_tick_costs_the_engine_about_what_a_tick_without_one_costs(stage):
    """
    A closed loop sends a command every tick, nearly always within one step's slew.

    Such a tick must not fall back to one Python-level engine call per step: that cost ~9x the
    engine time of a tick (0.25 ms of 1 ms on the quiet machine) and made real-time ticks late.
    """
    loop, _, filt = make_loop(stage)
    filt.submit_many([1.0e-6])
    loop._advance_engine()
    quiet = cpu_per_tick(loop, filt, new_command=False)
    commanded = cpu_per_tick(loop, filt, new_command=True)
    assert commanded < 4.0 * quiet, (commanded, quiet)
