"""
The piezo actuator model (engine/actuators/piezo.py, piezo_run.py, config_actuator.py); no ROS.

Expected values come from closed forms written here (series springs, sums of exponentials,
the gamma = 0 Bouc-Wen loop), a second method (time integration against the loop's dh/dV
solution, Newton statics against the linearisation) or finite differences.
"""
import copy
import math

import numpy as np
import pytest
import yaml
from hypothesis import given, settings
from hypothesis import strategies as st

from conftest import ROOT
from flexure_sim.engine.actuators import piezo, piezo_run
from flexure_sim.engine.solver.actuation import rigid_stacks
from flexure_sim.engine.mechanism.loader import ConfigError, load_mechanism, mechanism_from_dict
from flexure_sim.engine.mechanism.parts import Drive
from flexure_sim.engine.actuators.piezo import CreepElement, PiezoSpec
from flexure_sim.engine.solver.simulation import Simulation

EXAMPLE = ROOT / "config" / "examples" / "piezo_stage.yaml"
GAIN = 1.5e-5 / 100.0  # the example's stroke over its voltage range, m/V


def example_doc() -> dict:
    return yaml.safe_load(EXAMPLE.read_text())


def with_actuator(block) -> dict:
    doc = example_doc()
    doc["constraints"][1]["actuator"] = block
    return doc


def drive_of(doc) -> Drive:
    return [c for c in mechanism_from_dict(doc).constraints if isinstance(c, Drive)][0]


# ---------------------------------------------------------------- (a) the ideal actuator

def test_ideal_actuator_applies_the_nominal_command_exactly():
    spec = drive_of(with_actuator({"v_max": 150.0})).actuator
    assert (spec.alpha, spec.creep, spec.bandwidth, spec.stiffness) == (0.0, (), 0.0, math.inf)
    rng = np.random.default_rng(3)
    times = np.cumsum(rng.uniform(1e-4, 1e-2, 40))
    commands = rng.uniform(0.0, 1.5e-5, 40)  # nominal displacements, m
    for k_load in (0.0, 4.1e5, 2.3e7):
        run = piezo_run.simulate(spec, times, commands, k_load)
        np.testing.assert_allclose(run.output, commands, rtol=1e-14, atol=1e-21)
    assert drive_of(example_doc() | {"constraints": [
        {"type": "fixed", "body": "ground"},
        {k: v for k, v in example_doc()["constraints"][1].items() if k != "actuator"},
    ]}).actuator is None  # no block: today's ideal drive


def test_voltage_command_maps_through_the_nominal_gain():
    spec = drive_of(with_actuator({"v_min": -20.0, "v_max": 130.0,
                                   "command": "voltage"})).actuator
    assert spec.gain == pytest.approx(1.5e-5 / 150.0, rel=1e-15)
    run = piezo_run.simulate(spec, [0.0, 1.0, 2.0], [-20.0, 130.0, 55.0])
    np.testing.assert_allclose(run.output, [0.0, 1.5e-5, 0.5 * 1.5e-5], rtol=1e-14, atol=1e-21)


# ------------------------------------------------------------ (b) the Bouc-Wen loop

def sech_half_width(alpha, d, beta, A):
    """
    Half-width of the gamma = 0 loop, derived independently.

    dh/dV = a - beta sgn(dV) h is linear, H = (a/beta) tanh(beta A), and the branch from -H
    reaches (a/beta)(1 - sech(beta A)) after A.
    """
    return alpha * d / beta * (1.0 - 1.0 / math.cosh(beta * A))


def bouc_wen(alpha=0.3, beta=0.02, gamma=0.0, **kw) -> PiezoSpec:
    return PiezoSpec(gain=GAIN, v_max=100.0, command="voltage", alpha=alpha, beta=beta,
                     gamma=gamma, **kw)


@pytest.mark.parametrize("A", [5.0, 50.0, 200.0])
def test_closed_form_loop_reduces_to_the_sech_formula_without_gamma(A):
    spec = bouc_wen(beta=0.03)
    assert piezo.steady_loop_half_width(spec, A) == pytest.approx(
        sech_half_width(0.3, GAIN, 0.03, A), rel=1e-12)


@pytest.mark.parametrize("gamma", [0.0, 0.006, -0.006, 0.03])
def test_triangle_loop_width_matches_the_analytic_steady_loop(gamma):
    spec = bouc_wen(beta=0.03, gamma=gamma)
    times, commands = piezo_run.triangle(spec, 2.0, 3)
    run = piezo_run.simulate(spec, times, commands, 0.0, np.linspace(0, times[-1], 6001))
    width = piezo_run.loop_width(run.voltage, run.output, 50.0)
    expected = 2 * piezo.steady_loop_half_width(spec, 50.0)
    if gamma == 0.0:
        expected = 2 * sech_half_width(0.3, GAIN, 0.03, 50.0)
    assert width == pytest.approx(expected, rel=0.02)
    assert width == pytest.approx(expected, rel=1e-3)  # what the integration really achieves
    assert 0.05 < width / 1.5e-5 < 0.2  # a piezo-like loop of 5-20 % of the stroke


def test_jump_equals_the_time_integration_of_a_ramp():
    """The exact dh/dV sweep (jump) and solve_ivp of dh/dt along a ramp agree: rate-free."""
    spec = bouc_wen(beta=0.025, gamma=0.01)
    s = piezo.initial_state(spec)
    for v in (80.0, 10.0, 60.0, 35.0):
        s = piezo.jump(spec, s, v)
    run = piezo_run.simulate(spec, [0.0, 1.0, 2.0, 2.5, 3.0], [0.0, 80.0, 10.0, 60.0, 35.0])
    assert run.states[1, -1] == pytest.approx(s[1], rel=1e-6)
    halves = piezo.initial_state(spec)
    for v in np.linspace(0.0, 80.0, 17)[1:]:
        halves = piezo.jump(spec, halves, v)
    assert halves[1] == pytest.approx(piezo.jump(spec, piezo.initial_state(spec), 80.0)[1],
                                      rel=1e-12)


# ----------------------------------------------------------- (c) the stack in series

def test_output_loss_under_load_is_the_series_spring_formula():
    k_s, k_L = 5.0e7, 2.0e7  # x_out / x_a = 5/7
    spec = bouc_wen(stiffness=k_s, creep=(CreepElement(0.01, 0.05),))
    times, commands = piezo_run.triangle(spec, 5.0, 2)
    t = np.linspace(0, times[-1], 401)
    free = piezo_run.simulate(spec, times, commands, 0.0, t)
    loaded = piezo_run.simulate(spec, times, commands, k_L, t)
    np.testing.assert_allclose(loaded.free_stroke, free.output, rtol=1e-12, atol=1e-20)
    np.testing.assert_allclose(loaded.output, free.output * 5.0 / 7.0, rtol=1e-12, atol=1e-20)
    # force balance at the contact: the stack's k_s (x_a - x_out) equals the load's k_L x_out
    np.testing.assert_allclose(k_s * (loaded.free_stroke - loaded.output), loaded.force,
                               rtol=1e-9, atol=1e-9)
    blocked = piezo_run.simulate(spec, times, commands, math.inf, t)
    np.testing.assert_allclose(blocked.force, k_s * free.output, rtol=1e-12)  # F_b = k_s x_a
    assert np.all(blocked.output == 0.0)


def test_load_stiffness_is_the_stage_tangent_at_rest():
    """Linearisation's tangent against the guide's beam formula and Newton statics."""
    k = piezo_run.load_stiffness(Simulation(load_mechanism(EXAMPLE)))
    sim = Simulation(rigid_stacks(load_mechanism(EXAMPLE)))  # statics: the stage, rigid drive
    E, w, t, L = 69.0e9, 0.010, 0.001, 0.015
    assert k == pytest.approx(2 * 12 * E * (w * t**3 / 12) / L**3, rel=1e-9)
    u = 1e-9
    assert k == pytest.approx(sim.static(u).snapshot.drive_force / u, rel=1e-6)


# ------------------------------------------------------------------ (d) creep and lag

def test_creep_step_follows_the_chain_sum_of_exponentials():
    chain = (CreepElement(0.01, 0.1), CreepElement(0.015, 1.0), CreepElement(0.02, 10.0))
    spec = bouc_wen(beta=0.03, gamma=0.01, creep=chain)
    t = np.linspace(0.0, 30.0, 301)
    run = piezo_run.simulate(spec, [0.0, 30.0], [70.0, 70.0], 0.0, t, rtol=1e-10)
    a, p = 0.3 * GAIN, 0.04
    x_h = GAIN * 70.0 - a / p * (1 - math.exp(-p * 70.0))  # the instantaneous step, h from 0
    expected = x_h * (1 + sum(el.ratio * (1 - np.exp(-t / el.tau)) for el in chain))
    np.testing.assert_allclose(run.output, expected, rtol=1e-7)


def test_a_chain_a_decade_apart_creeps_the_logarithmic_law():
    """Ratio g per element, tau 1 ms .. 1000 s: g per time decade (PI's creep factor)."""
    g = 0.015
    spec = bouc_wen(alpha=0.0, creep=tuple(CreepElement(g, 10.0**k) for k in range(-3, 4)))
    t = np.array([0.0, 0.01, 0.1, 1.0, 10.0])
    run = piezo_run.simulate(spec, [0.0, 10.0], [50.0, 50.0], 0.0, t, rtol=1e-10)
    x = run.output / (GAIN * 50.0)
    np.testing.assert_allclose(np.diff(x)[1:], g, rtol=2e-3)  # from 10 ms to 10 s


def test_amplifier_lag_and_one_creep_element_step():
    tau_a, r, tau = 1.0 / (2 * math.pi * 50.0), 0.02, 0.05
    spec = bouc_wen(alpha=0.0, bandwidth=50.0, creep=(CreepElement(r, tau),))
    t = np.linspace(0.0, 0.3, 301)
    run = piezo_run.simulate(spec, [0.0, 0.3], [40.0, 40.0], 0.0, t, rtol=1e-10)
    D = GAIN * 40.0
    lag = D * (1 - np.exp(-t / tau_a))
    creep = r * D * (1 - (tau * np.exp(-t / tau) - tau_a * np.exp(-t / tau_a)) / (tau - tau_a))
    np.testing.assert_allclose(run.output, lag + creep, rtol=1e-6, atol=1e-9 * D)


# ------------------------------------------ the fixed-step advance stepping will use

def test_advance_under_a_held_command_matches_the_time_integration():
    chain = (CreepElement(0.01, 2e-3), CreepElement(0.02, 2e-2))
    spec = bouc_wen(beta=0.025, gamma=0.01, bandwidth=300.0, creep=chain)
    T = 0.05
    run = piezo_run.simulate(spec, [0.0, T], [80.0, 80.0], 0.0, [T], rtol=1e-11)
    one = piezo.advance(spec, piezo.initial_state(spec), 80.0, T)  # V and h exact in one step
    np.testing.assert_allclose(one[:2], run.states[:2, -1], rtol=1e-8)
    errors = []
    for n in (500, 1000):  # the engine's 1e-4 s step, and half of it
        s = piezo.initial_state(spec)
        for _ in range(n):
            s = piezo.advance(spec, s, 80.0, T / n)
        np.testing.assert_allclose(s[:2], run.states[:2, -1], rtol=1e-8)
        errors.append(np.max(np.abs(s / run.states[:, -1] - 1)))
    assert errors[0] < 1e-5 and 3.5 < errors[0] / errors[1] < 4.5  # second order in dt


def test_advance_without_a_lag_traces_the_analytic_loop():
    """Held commands sampled on a triangle (the node's ticks): the loop is the steady one."""
    spec = bouc_wen(beta=0.03, gamma=0.006)
    volts = np.concatenate([np.linspace(0, 100, 201), np.linspace(100, 0, 201)[1:]] * 3)
    s, x = piezo.initial_state(spec), []
    for v in volts:
        s = piezo.advance(spec, s, v, 1e-4)
        x.append(piezo.free_stroke(spec, s))
    width = piezo_run.loop_width(volts, np.array(x), 50.0)
    assert width == pytest.approx(2 * piezo.steady_loop_half_width(spec, 50.0), rel=1e-9)


# --------------------------------------------------------------------- (e) Jacobian

@pytest.mark.parametrize("bandwidth", [0.0, 800.0])
def test_jacobian_matches_finite_differences(bandwidth):
    spec = bouc_wen(beta=0.025, gamma=0.01, bandwidth=bandwidth,
                    creep=(CreepElement(0.01, 0.2), CreepElement(0.02, 3.0)))
    rng = np.random.default_rng(7)
    for _ in range(20):
        s = np.array([rng.uniform(0, 100), rng.uniform(-1, 1) * 2e-6,
                      *(rng.uniform(-1, 1, 2) * 1e-7)])
        v_cmd, v_rate = rng.uniform(0, 100), rng.uniform(-500, 500)
        A, B = piezo.jacobian(spec, s, v_cmd, v_rate)
        scale = np.array([1.0, 1e-6, 1e-7, 1e-7])
        for j in range(spec.size):
            e = np.zeros(spec.size)
            e[j] = 1e-6 * scale[j]
            fd = (piezo.rhs(spec, s + e, v_cmd, v_rate)
                  - piezo.rhs(spec, s - e, v_cmd, v_rate)) / (2 * e[j])
            np.testing.assert_allclose(A[:, j], fd, rtol=1e-6, atol=1e-9 * np.abs(fd).max())
        for j, (dc, dr) in enumerate(((1e-4, 0.0), (0.0, 1e-3))):
            fd = (piezo.rhs(spec, s, v_cmd + dc, v_rate + dr)
                  - piezo.rhs(spec, s, v_cmd - dc, v_rate - dr)) / (2 * (dc + dr))
            np.testing.assert_allclose(B[:, j], fd, rtol=1e-6, atol=1e-12)
    g = piezo.free_stroke_gradient(spec)
    s = np.array([30.0, 1e-7, 2e-8, -1e-8])
    fd = [(piezo.free_stroke(spec, s + 1e-3 * e) - piezo.free_stroke(spec, s - 1e-3 * e))
          / 2e-3 for e in np.eye(4)]
    np.testing.assert_allclose(g, fd, rtol=1e-9)


# ---------------------------------------------------------------- (f) the YAML block

BAD = [
    ({"v_max": 150.0, "bogus": 1}, "constraints[1].actuator.bogus: unknown key"),
    ({"bandwidth": 10.0}, "constraints[1].actuator.v_max: missing required key"),
    ({"v_max": -5.0}, "constraints[1].actuator.v_max: must be above v_min"),
    ({"v_max": 150.0, "command": "current"}, "constraints[1].actuator.command: expected one"),
    ({"v_max": 150.0, "bandwidth": -1.0}, "constraints[1].actuator.bandwidth: must not be neg"),
    ({"v_max": 150.0, "stiffness": 0.0}, "constraints[1].actuator.stiffness: must be positive"),
    ({"v_max": 150.0, "stiffness": "stiff"}, "constraints[1].actuator.stiffness: expected a nu"),
    ({"v_max": 150.0, "hysteresis": {"alpha": 0.3, "beta": 0.01, "gamma": 0.02}},
     "constraints[1].actuator.hysteresis.gamma: must lie within [-beta, beta]"),
    ({"v_max": 150.0, "hysteresis": {"alpha": 0.3}},
     "constraints[1].actuator.hysteresis.beta: missing required key"),
    ({"v_max": 150.0, "hysteresis": {"alpha": -0.1, "beta": 0.01}},
     "constraints[1].actuator.hysteresis.alpha: must not be negative"),
    ({"v_max": 150.0, "creep": [{"ratio": 0.01, "tau": 0.0}]},
     "constraints[1].actuator.creep[0].tau: must be positive"),
    ({"v_max": 150.0, "creep": {"ratio": 0.01}}, "constraints[1].actuator.creep: expected a lis"),
    ({"v_max": float("nan")}, "constraints[1].actuator.v_max: must be finite"),
    ([150.0], "constraints[1].actuator: expected a mapping"),
]


@pytest.mark.parametrize("block, message", BAD)
def test_bad_actuator_blocks_name_the_key(block, message):
    with pytest.raises(ConfigError) as err:
        mechanism_from_dict(with_actuator(block), source="stage.yaml")
    text = str(err.value)
    assert text.startswith("stage.yaml: ") and message in text and "\n" not in text


def test_actuator_on_a_force_drive_is_refused():
    doc = with_actuator({"v_max": 150.0})
    doc["constraints"][1]["type"] = "force"
    with pytest.raises(ConfigError, match=r"constraints\[1\]\.actuator: a piezo actuator "
                       r"belongs on a displacement drive"):
        mechanism_from_dict(copy.deepcopy(doc))


# ------------------------------------------------- (f) the block, fuzzed (as test_config_fuzz)

BLOCK = example_doc()["constraints"][1]["actuator"]
BLOCK_PATHS = ([(k,) for k in BLOCK] + [("hysteresis", k) for k in BLOCK["hysteresis"]]
               + [("creep", i, k) for i in range(len(BLOCK["creep"])) for k in ("ratio", "tau")])
FUZZ_VALUES = st.recursive(
    st.none() | st.booleans() | st.integers() | st.floats(allow_nan=True, allow_infinity=True)
    | st.text(max_size=8) | st.sampled_from(["voltage", "displacement", "1e-3", 1e308, -1e308,
                                             10**400, 5e-324, 0, -1]),
    lambda children: st.lists(children, max_size=3) | st.dictionaries(
        st.text(max_size=6), children, max_size=3),
    max_leaves=8)


@settings(max_examples=150, derandomize=True, deadline=None, database=None)
@given(path=st.sampled_from(BLOCK_PATHS), value=FUZZ_VALUES, remove=st.booleans())
def test_fuzzed_blocks_load_meaningfully_or_fail_in_one_line(path, value, remove):
    block = copy.deepcopy(BLOCK)
    node = block
    for key in path[:-1]:
        node = node[key]
    if remove:
        del node[path[-1]]
    else:
        node[path[-1]] = value
    try:
        spec = drive_of(with_actuator(block)).actuator
    except ConfigError as exc:
        assert str(exc).startswith("<dict>: constraints[1].actuator") and "\n" not in str(exc)
        return
    assert 0 < spec.gain < math.inf and spec.v_min < spec.v_max
    assert math.isfinite(spec.v_min) and math.isfinite(spec.v_max)
    assert 0 <= spec.bandwidth < math.inf and spec.stiffness > 0 and spec.command in (
        "voltage", "displacement")
    assert spec.alpha >= 0 and (spec.alpha == 0 or spec.beta > 0)
    assert abs(spec.gamma) <= spec.beta
    assert all(0 <= el.ratio < math.inf and 0 < el.tau < math.inf for el in spec.creep)
