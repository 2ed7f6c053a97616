"""
Stepping with several drives, force drives and drives on a rotation (issue 13, engine).

Expected values come from independent sources: the XY stage's stiffness assembled by hand
(test_xy_stage.hand_gain), beam theory for a leaf spring's end moment (M = E I theta / L),
the exact tangent stiffness solved here by hand for a force drive, Clapeyron's theorem for the
work of a suddenly applied constant force, the first-order lag's step response for each
drive's own response_time, and the same mechanism with an idle drive replaced
by a fixed body.
"""
import copy
import dataclasses

import numpy as np
import pytest
from test_xy_stage import hand_gain

from flexure_sim.engine.mechanism.loader import (
    ConfigError, load_mechanism, mechanism_from_dict, resolve_mechanism_path,
)
from flexure_sim.engine.analysis.linear import tangent_at
from flexure_sim.engine.mechanism.parts import Drive, Fixed, Mechanism
from flexure_sim.engine.solver.simulation import Simulation
from flexure_sim.engine.mechanism.yaml_files import read_yaml

#: Settling time per level (s): the slowest mode of the stages decays in a few ms.
SETTLE = 0.05


@pytest.fixture(scope="module")
def xy():
    return load_mechanism("xy_stage")


def settle(sim: Simulation, command, seconds: float = SETTLE) -> np.ndarray:
    """Hold ``command`` for ``seconds``; return every output, ``output_names`` order."""
    sim.set_command(command)
    sim.step(int(round(seconds / sim.dt)))
    return sim.model.output_values(sim.state.z)


def test_xy_stage_settles_on_the_gain_matrix_after_a_step_on_each_drive(xy):
    # Steps from -u to +u about rest: the gain at rest to second order in u (the cross
    # couplings have a quadratic term of 0.9 % at 1 um; centred, 1e-7 relative at 0.1 um).
    u = 1e-7
    sim = Simulation(xy)
    columns = []
    for drive in ("x", "y"):
        sim.reset()
        low = settle(sim, {"x": -u if drive == "x" else 0.0, "y": -u if drive == "y" else 0.0})
        high = settle(sim, {"x": u if drive == "x" else 0.0, "y": u if drive == "y" else 0.0})
        columns.append((high - low) / (2 * u))
        assert np.max(np.abs(sim.state.v)) < 1e-9  # at rest: a steady state
    stepped = np.column_stack(columns)
    np.testing.assert_allclose(stepped, hand_gain(xy), rtol=1e-6)
    np.testing.assert_allclose(stepped, sim.static_gain(), rtol=1e-6)


def test_a_step_settles_on_the_static_solution_of_its_inputs(xy):
    sim = Simulation(xy)
    u = {"x": 1.2e-6, "y": 0.7e-6}
    stepped = settle(sim, u, 2 * SETTLE)
    static = sim.static(u).snapshot
    np.testing.assert_allclose(stepped, [static.outputs[n] for n in sim.model.output_names],
                               rtol=1e-9)
    snap = sim.snapshot()
    np.testing.assert_allclose(snap.drive_inputs, [1.2e-6, 0.7e-6], rtol=1e-12)
    np.testing.assert_allclose(snap.drive_forces, static.drive_forces, rtol=1e-8)
    np.testing.assert_array_equal(snap.drive_commands, [1.2e-6, 0.7e-6])
    assert sim.state.u.shape == (2,) and sim.state.command.shape == (2,)


def test_commands_as_a_mapping_or_a_vector_step_identically(xy):
    runs = []
    for command in ({"y": 0.3e-6, "x": 1e-6}, [1e-6, 0.3e-6], np.array([1e-6, 0.3e-6])):
        sim = Simulation(xy)
        sim.set_command(command)
        sim.step(37)
        runs.append(sim.state)
    for s in runs[1:]:
        np.testing.assert_array_equal(s.z, runs[0].z)
        np.testing.assert_array_equal(s.u, runs[0].u)
        assert s.drive_work == runs[0].drive_work


@pytest.mark.parametrize("command, message", [
    ({"x": np.nan, "y": 0.0}, "drive x"),
    ({"x": 1e-6, "y": np.inf}, "drive y"),
    ({"x": "far", "y": 0.0}, "drive 'x': input must be a number"),
    ({"x": 1e-6}, "missing ['y']"),
    ({"x": 1e-6, "y": 0.0, "z": 0.0}, "unknown ['z']"),
    ([1e-6], "1 drive inputs given for 2 drives (x, y)"),
    (1e-6, "one number given for 2 drives (x, y)"),
])
def test_a_bad_command_is_refused_naming_the_drive(xy, command, message):
    sim = Simulation(xy)
    sim.set_command({"x": 1e-6, "y": 0.0})
    with pytest.raises(ValueError) as err:
        sim.set_command(command)
    assert message in str(err.value)
    np.testing.assert_array_equal(sim.state.command, [1e-6, 0.0])  # the last good one holds


def _xy_with_response_times(taus: dict) -> Mechanism:
    """Return the XY stage from its YAML document with each drive's response_time from taus."""
    path = resolve_mechanism_path("xy_stage")
    doc = copy.deepcopy(read_yaml(path, ConfigError))
    drives = [c for c in doc["constraints"] if c["type"] == "drive"]
    assert sorted(c["name"] for c in drives) == sorted(taus)
    for c in drives:
        c["response_time"] = taus[c["name"]]
    return mechanism_from_dict(doc, str(path))


def test_each_drive_lags_its_command_with_its_own_response_time():
    # Each drive's applied input is a first-order lag of its own command, du_i/dt =
    # (c_i - u_i)/tau_i: after a step at t = 0 from rest, u_i = c_i (1 - exp(-t/tau_i)).
    # Tolerance: the exponential trapezoidal rule (dynamics.py) integrates the linear part of
    # the equations exactly, and the u rows are linear in u alone with the exact Jacobian
    # -1/tau_i, so the remainder vanishes there: each step maps u_i to
    # c_i + (u_i - c_i) exp(-h/tau_i), exact at any h. What is left is rounding: the matrix
    # exponential of the whole system (hA's stiff hinge rows are 1e4 times larger) leaves
    # the u rows coupled to the stage at 1e-16 of its norm. Measured: at most 2.5e-12 of c_i,
    # at h = 1e-4 and 5e-5 alike (no truncation error), so 1e-11 of c_i. A lag integrated to
    # second order only (the plain trapezoidal rule) would be off by (t/tau)(h/tau)^2/12 of
    # c_i exp(-t/tau): 3e-4 of c_x at t = tau_x (h/tau = 0.1, 0.033).
    taus = {"x": 1e-3, "y": 3e-3}
    commands = {"x": 1e-6, "y": 0.4e-6}
    sim = Simulation(_xy_with_response_times(taus))
    names = sim.model.drives.names
    assert names == ("x", "y")
    assert [d.response_time for d in sim.mechanism.drives] == [1e-3, 3e-3]
    sim.set_command(commands)
    scale = np.array([commands[n] for n in names])
    for t_check in (1e-4, 5e-4, 1e-3, 2e-3, 3e-3, 6e-3, 1.2e-2):
        sim.step(int(round((t_check - sim.state.t) / sim.dt)))
        t = sim.state.t
        assert t == pytest.approx(t_check, rel=1e-12)
        expected = np.array([-commands[n] * np.expm1(-t / taus[n]) for n in names])
        inputs = sim.snapshot().drive_inputs
        np.testing.assert_allclose(inputs / scale, expected / scale, rtol=0, atol=1e-11)
        np.testing.assert_array_equal(sim.state.u, inputs)
        # A swapped or shared time constant is far outside the tolerance at every check.
        for tau in ([3e-3, 1e-3], [1e-3, 1e-3], [3e-3, 3e-3]):
            wrong = np.array([-commands[n] * np.expm1(-t / tk) for n, tk in zip(names, tau)])
            assert np.max(np.abs(wrong - expected) / expected) > 1e-3


def _with_y_fixed(xy):
    """Return the XY stage with its y piezo a fixed body instead of a drive (one drive)."""
    constraints = tuple(Fixed("piezo_y") if isinstance(c, Drive) and c.name == "y" else c
                        for c in xy.constraints)
    return dataclasses.replace(xy, constraints=constraints)


def test_an_idle_drive_steps_like_a_fixed_body(xy):
    two = Simulation(xy)
    one = Simulation(_with_y_fixed(xy))
    assert one.model.drives.names == ("x",) and one.drive is not None
    for level, steps in ((1e-6, 13), (0.4e-6, 200), (1.5e-6, 150)):
        two.set_command({"x": level, "y": 0.0})
        one.set_command(level)
        two.step(steps)
        one.step(steps)
    # Equal to the remainder iteration's tolerance (1e-10 of |y|; the two have different
    # matrix sizes, so rounding differs).
    np.testing.assert_allclose(two.state.z, one.state.z, rtol=1e-10, atol=1e-15)
    assert two.state.u[0] == pytest.approx(one.state.u, rel=1e-14)
    assert two.state.drive_work == pytest.approx(one.state.drive_work, rel=1e-10)
    assert two.state.dissipated == pytest.approx(one.state.dissipated, rel=1e-10)
    np.testing.assert_allclose(two.snapshot().drive_forces[0], one.snapshot().drive_force,
                               rtol=1e-10)


def test_the_work_of_both_drives_is_counted(xy):
    # Mirror-symmetric chains, coupled by 0.08 %: both drives stepped together do twice the
    # work of one (to the coupling), and work = potential energy at rest + dissipated.
    both, alone = Simulation(xy), Simulation(xy)
    settle(both, {"x": 1e-6, "y": 1e-6})
    settle(alone, {"x": 1e-6, "y": 0.0})
    assert both.state.drive_work == pytest.approx(2 * alone.state.drive_work, rel=5e-3)
    snap = both.snapshot()
    assert both.state.drive_work - both.state.dissipated == pytest.approx(
        snap.potential_energy + snap.kinetic_energy, rel=1e-9)
    # Halving the step changes the integrated work by the method's second-order error only.
    fine = Simulation(xy, dt=both.dt / 4)
    settle(fine, {"x": 1e-6, "y": 1e-6})
    assert fine.state.drive_work == pytest.approx(both.state.drive_work, rel=1e-6)


def _microstage_pushed(force_drive: dict):
    path = resolve_mechanism_path("microstage")
    doc = copy.deepcopy(read_yaml(path, ConfigError))
    doc["constraints"][1] = force_drive
    doc.pop("compression_hinge")
    return mechanism_from_dict(doc, str(path))


def test_a_stepped_force_drive_settles_at_force_over_the_exact_tangent_stiffness():
    mech = _microstage_pushed({"type": "force", "name": "push", "body": "body6",
                               "axis": [1, 0], "response_time": 1e-3, "stroke": [-10, 10],
                               "slew_rate": 1e3})
    sim = Simulation(mech)
    assert sim.model.drives.n_lags == 0
    force = 1e-3
    settle(sim, {"push": force}, 0.1)
    snap = sim.snapshot()
    # Independent: -K_FF dz_F = e_F f with K = dQ/dz at rest (exact tangent stiffness).
    K = tangent_at(sim, sim.z0)[0]
    free = sim.part.free
    e = np.zeros(len(sim.z0))
    e[3 * mech.body_index("body6")] = 1.0
    dz = np.zeros(len(sim.z0))
    dz[free] = np.linalg.solve(-K[np.ix_(free, free)], e[free] * force)
    np.testing.assert_allclose(snap.drive_positions[0], e @ dz, rtol=1e-6)
    np.testing.assert_allclose(snap.output, sim.model.output_matrix[0] @ dz, rtol=1e-6)
    np.testing.assert_array_equal(snap.drive_forces, [force])
    np.testing.assert_array_equal(snap.drive_inputs, [force])
    # Clapeyron: a constant force applied at once does the work f x, half of it stored in
    # the (here linear) spring, half dissipated by the damping.
    work = force * snap.drive_positions[0]
    assert sim.state.drive_work == pytest.approx(work, rel=1e-9)
    assert sim.state.dissipated == pytest.approx(work / 2, rel=1e-4)


# A leaf spring 20 x 0.5 x 10 mm (aluminium) holding a disc at its centroid: bending under an
# end moment (Euler-Bernoulli) turns it by theta = M L / (E I), I = w t^3 / 12.
E, L, T, W = 69e9, 0.02, 0.5e-3, 10e-3
K_BEND = E * (W * T**3 / 12) / L


def leaf_rotor(drive: dict):
    return mechanism_from_dict({
        "name": "leaf_rotor",
        "defaults": {"law": "twistor", "damping": {"t_char": 1e-3}},
        "stiffness_models": {"leaf": {"model": "cantilever", "length": L, "thickness": T,
                                      "width": W, "E": E, "nu": 0.33}},
        "bodies": [{"name": "base", "mass": 1.0, "inertia": 1.0, "pose": [0, 0, 0]},
                   {"name": "disc", "mass": 0.01, "inertia": 1e-6, "pose": [0, 0.02, 0]}],
        "hinges": [{"name": "leaf", "a": {"body": "base", "at": [0, 0.02]},
                    "b": {"body": "disc", "at": [0, 0]}, "stiffness": "leaf"}],
        "constraints": [{"type": "fixed", "body": "base"}, drive],
        "outputs": [{"name": "angle", "body": "disc", "coordinate": "theta"}],
    })


def test_a_drive_turning_a_leaf_needs_the_beam_moment():
    theta = 1e-4
    sim = Simulation(leaf_rotor({"type": "drive", "name": "turn", "body": "disc",
                                 "axis": "theta", "response_time": 1e-3,
                                 "stroke": [-0.01, 0.01], "slew_rate": 1.0}))
    settle(sim, {"turn": theta}, 0.2)
    snap = sim.snapshot()
    assert snap.outputs["angle"] == pytest.approx(theta, rel=1e-9)
    np.testing.assert_allclose(snap.drive_forces, [K_BEND * theta], rtol=1e-6)


def test_a_torque_turns_a_leaf_by_the_beam_angle():
    torque = 2e-5
    sim = Simulation(leaf_rotor({"type": "force", "name": "torquer", "body": "disc",
                                 "axis": "theta", "response_time": 1e-3,
                                 "stroke": [-1, 1], "slew_rate": 1.0}))
    settle(sim, torque, 0.3)
    snap = sim.snapshot()
    np.testing.assert_allclose(snap.outputs["angle"], torque / K_BEND, rtol=1e-6)
    np.testing.assert_allclose(snap.drive_positions, [torque / K_BEND], rtol=1e-6)
    assert np.max(np.abs(sim.state.v)) < 1e-12
