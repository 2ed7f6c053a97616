"""
The piezo actuators' fast stepping (actuators/piezo_steps.py, actuation.step) vs its definition.

The definition (actuation.py's module doc), one engine step at a time from public pieces: the
actuator by `piezo.advance` (after `piezo.jump` without an amplifier lag), the stage by one
``dynamics.step`` holding the step's mean free stroke, the stack spring's anchor move counted as
1/2 k_s ((x' - p)^2 - (x - p)^2), p = e . (z - z0). The fast path runs n steps in two compiled
calls; it must give the same motion and actuator states to the bit and the same energies to
rounding, compiled and interpreted.
"""
import dataclasses
import math

import numpy as np
import pytest

from conftest import ROOT
from flexure_sim.engine.solver import actuation, integrator as dynamics
from flexure_sim.engine.actuators import piezo
from flexure_sim.engine.mechanism.loader import load_mechanism
from flexure_sim.engine.mechanism.parts import Drive
from flexure_sim.engine.solver.simulation import Simulation

EXAMPLE = ROOT / "config" / "examples" / "piezo_stage.yaml"
EPS = np.finfo(float).eps

#: The example as is (finite stack, amplifier lag, hysteresis, creep), and a rigid stack with an
#: unlimited bandwidth (each step's jump; the drive's velocity jumps between steps).
VARIANTS = {"stack": {}, "rigid": dict(stiffness=math.inf, bandwidth=0.0)}


def stage(variant: str, compiled: bool) -> Simulation:
    """Return the example with its actuator block's fields replaced by ``VARIANTS[variant]``."""
    mech = load_mechanism(EXAMPLE)
    drive = mech.drives[0]
    new = dataclasses.replace(drive, actuator=dataclasses.replace(drive.actuator,
                                                                  **VARIANTS[variant]))
    constraints = tuple(new if isinstance(c, Drive) else c for c in mech.constraints)
    sim = Simulation(dataclasses.replace(mech, constraints=constraints), 1e-4)
    sim.assembly.compiled = compiled  # False: the interpreted path on the same mechanism
    return sim


def defined_step(sim: Simulation) -> None:
    """One engine step by the definition (module doc), without the fast path's code."""
    model, data = sim.model, sim.data
    s = data.state
    x = actuation.states(model, s)
    before = actuation.held(model, s)
    after, strokes = np.empty_like(x), np.empty(len(model.drives.actuation))
    for j, a in enumerate(model.drives.actuation):
        volts = float(piezo.command_voltage(a.spec, np.atleast_1d(s.command)[a.drive]))
        xs = x[a.states]
        start = xs if a.spec.lagged else piezo.jump(a.spec, xs, volts)
        after[a.states] = piezo.advance(a.spec, xs, volts, model.dt)
        strokes[j] = 0.5 * (float(piezo.free_stroke(a.spec, start))
                            + float(piezo.free_stroke(a.spec, after[a.states])))
        if a.stack:
            p = float(model.drives.directions[a.drive] @ (s.z - model.z0))
            k = a.spec.stiffness
            s.drive_work += 0.5 * k * ((strokes[j] - p) ** 2 - (before[j] - p) ** 2)
    dynamics.step(model, data, 1, actuation.kernel_command(model, s, strokes))
    data.state.actuator, data.state.held = after, strokes


def drive(sim: Simulation, stepper) -> None:
    """Step 60 V, then 20 V, then 100 V, each held for a while (one ``stepper`` call each)."""
    for volts, n in ((60.0, 120), (20.0, 70), (100.0, 90)):
        sim.set_command(volts)
        stepper(sim, n)


@pytest.mark.parametrize("compiled", [True, False], ids=["compiled", "interpreted"])
@pytest.mark.parametrize("variant", sorted(VARIANTS))
def test_n_steps_in_one_call_are_n_defined_steps(variant, compiled):
    """One call of n steps, and n calls of one, equal n steps of the definition."""
    reference = stage(variant, compiled)
    drive(reference, lambda sim, n: [defined_step(sim) for _ in range(n)])
    one_call, single = stage(variant, compiled), stage(variant, compiled)
    drive(one_call, lambda sim, n: sim.step(n))
    drive(single, lambda sim, n: [sim.step(1) for _ in range(n)])
    ref = reference.state
    assert ref.drive_work > 1e-4  # the anchor moves and velocity jumps are in the budget
    for sim in (one_call, single):
        s = sim.state
        assert s.t == ref.t
        assert np.array_equal(s.z, ref.z) and np.array_equal(s.v, ref.v)
        assert np.array_equal(np.atleast_1d(s.u), np.atleast_1d(ref.u))
        assert np.array_equal(s.actuator, ref.actuator)
        assert np.array_equal(s.held, ref.held)
        # the energies summed in another order (inside the loop): equal to a few rounding
        assert s.drive_work == pytest.approx(ref.drive_work, rel=4 * EPS)
        assert s.dissipated == pytest.approx(ref.dissipated, rel=4 * EPS)
    assert one_call.stats.linearizations == reference.stats.linearizations


def test_the_compiled_actuator_step_is_piezo_s_own():
    """piezo_steps compiles piezo.py's functions themselves: no second copy of P2-P6."""
    from flexure_sim.engine.actuators import piezo_steps
    assert piezo_steps.advance_values is piezo.advance_values
    assert piezo_steps.jump_values is piezo.jump_values
    assert piezo.stroke_kernel.py_func is piezo.stroke_values
    state = np.array([12.0, 3e-7, 1e-8, -2e-9])
    spec = load_mechanism(EXAMPLE).drives[0].actuator
    assert piezo.stroke_kernel(state, spec.s_min, spec.gain, spec.v_min) == piezo.free_stroke(
        spec, state)
