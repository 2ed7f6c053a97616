"""
The exact linearisation with several drives (issue 13): the XY stage's MIMO model.

Expected values from independent sources: central differences of the engine's static solves in
each drive's input, the gain matrix ``simulate --static`` reports (statics.static_gain: the
tangent stiffness alone), the engine's time-domain simulation under a sinusoidal command of one
drive, and the undamped frequencies against the damped poles as the damping vanishes.
"""

import copy
import json

import numpy as np
import pytest

from flexure_sim.cli import gain_matrix, main
from flexure_sim.engine.analysis import linear
from flexure_sim.engine.mechanism.loader import (
    ConfigError, load_mechanism, mechanism_from_dict, resolve_mechanism_path,
)
from flexure_sim.engine.solver.simulation import Simulation, State
from flexure_sim.engine.mechanism.yaml_files import read_yaml

from test_linear import _scaled_damping  # one copy of the test helper

U = {"x": 3e-6, "y": 5e-6}  # an equilibrium under load, both drives moved
OUTPUTS = ["x", "y", "theta", "drive_force.x", "drive_force.y"]


@pytest.fixture(scope="module")
def xy():
    return load_mechanism("xy_stage")


@pytest.fixture(scope="module")
def model(xy):
    return linear.linearize(Simulation(xy), U)


def _measures(snap) -> np.ndarray:
    """x, y, theta, each drive's force, every hinge wrench (the rows of ``_rows``)."""
    return np.concatenate([[snap.outputs[n] for n in ("x", "y", "theta")], snap.drive_forces,
                           snap.wrenches.ravel()])


def _rows(mech) -> list:
    return OUTPUTS + [f"hinges.{h.name}.{c}" for h in mech.hinges
                      for c in linear.WRENCH_COMPONENTS]


def test_model_has_one_input_and_one_actuator_state_per_drive(model, xy):
    assert model.input_names == ["x", "y"]
    assert model.B.shape == (32, 2) and model.D.shape[1] == 2  # 15 free coordinates, 2 lags
    assert model.state_names[-2:] == ["drive.x.u", "drive.y.u"]
    assert model.output_names[:5] == OUTPUTS
    np.testing.assert_array_equal(model.u0, [U["x"], U["y"]])
    # the engine's own Jacobian at the equilibrium, not a copy of it
    sim = Simulation(xy)
    nF = len(model.free)
    y = np.concatenate([model.z[model.free], np.zeros(nF), model.u0])
    np.testing.assert_array_equal(model.A, sim.model.jacobian(
        y, 0.0, sim.model.drives.kernel_command(model.u0)))


def test_static_gain_matrix_is_the_central_difference_of_static_solves(model, xy):
    """
    G(0) = D - C A^-1 B against Richardson-extrapolated central differences of static solves.

    Step 0.2 um in each drive's input (and its half): rel 1e-6 per entry for the outputs and the
    drive forces, 1e-6 of the row's largest entry for the hinge wrenches (whose cross terms
    are small differences of large ones).
    """
    sim = Simulation(xy)
    u0 = np.array([U["x"], U["y"]])

    def central(k, h):
        e = np.zeros(2)
        e[k] = h
        return (_measures(sim.static(u0 + e).snapshot)
                - _measures(sim.static(u0 - e).snapshot)) / (2 * h)

    h = 2e-7
    fd = np.column_stack([(4 * central(k, h / 2) - central(k, h)) / 3 for k in range(2)])
    rows = [model.output_index(n) for n in _rows(xy)]
    G = model.D[rows] - model.C[rows] @ np.linalg.solve(model.A, model.B)
    np.testing.assert_array_equal(G, linear.gain_matrix(model, _rows(xy)))
    np.testing.assert_allclose(G[:5], fd[:5], rtol=1e-6, atol=0)
    scale = np.abs(fd[5:]).max(axis=1, keepdims=True)
    assert np.all(np.abs(G[5:] - fd[5:]) <= 1e-6 * scale)
    # the per-input column of static_gain is the same matrix
    np.testing.assert_array_equal(linear.static_gain(model, OUTPUTS, "y"), G[:5, 1])


def test_gain_matrix_at_rest_is_what_simulate_static_reports(xy):
    sim = Simulation(xy)
    reported = gain_matrix(sim)
    lm = linear.linearize(sim)  # every drive at 0
    G = linear.gain_matrix(lm, reported["outputs"])
    want = np.array(reported["matrix"])
    assert reported["drives"] == lm.input_names
    np.testing.assert_allclose(G, want, rtol=1e-7, atol=0)
    # the designed figures of config/xy_stage.yaml
    assert G[0, 0] == pytest.approx(6.8725, rel=1e-4)
    assert G[1, 0] == pytest.approx(5.80e-3, rel=1e-3)


def _sine_response(sim, z, u0, drive, amp, freq, c):
    """
    Amplitude and phase of c . (z - z0) with drive ``drive`` commanded u0 + amp sin(2 pi f t).

    The other drive held at its input; the command sampled at each step's midpoint; fitted
    (sin, cos, constant) over whole periods after a 30 ms transient (as test_linear.py does
    for one drive).
    """
    dt = sim.dt
    sim.state = State(0.0, z.copy(), np.zeros_like(z), u0.copy(), u0.copy())
    periods = max(2, int(np.ceil(0.005 * freq)))
    n_transient, n_fit = int(round(0.03 / dt)), int(round(periods / freq / dt))
    t, y = np.empty(n_fit), np.empty(n_fit)
    for k in range(n_transient + n_fit):
        command = u0.copy()
        command[drive] += amp * np.sin(2 * np.pi * freq * (k + 0.5) * dt)
        sim.set_command(command)
        sim.step()
        if k >= n_transient:
            t[k - n_transient] = sim.state.t
            y[k - n_transient] = c @ (sim.state.z - sim.z0)
    w = 2 * np.pi * freq
    basis = np.column_stack([np.sin(w * t), np.cos(w * t), np.ones_like(t)])
    (a, b, _), *_ = np.linalg.lstsq(basis, y, rcond=None)
    return (a + 1j * b) / amp


@pytest.mark.slow
def test_cross_coupling_frf_matches_the_time_domain_response(model, xy):
    """
    Drive y -> output x (the cross-coupling, 0.08 % of the direct gain) at 40 Hz and the mode.

    Measured agreement about 1e-7 (40 Hz) and 1e-6 (359 Hz) in amplitude; tolerance 1e-3.
    """
    sim = Simulation(xy, dt=2e-6)
    c = sim.model.output_matrix[0]
    first = linear.modes(model).frequencies[0]
    for freq in (40.0, first):
        measured = _sine_response(sim, model.z, np.array(model.u0), 1, 1e-8, freq, c)
        G = linear.frf(model, [freq], ["x"], "y")[0, 0]
        assert abs(abs(measured) - abs(G)) / abs(G) < 1e-3, freq
        assert abs(np.angle(measured / G)) < 1e-3, freq


def test_modes_are_the_damped_poles_as_the_damping_vanishes(xy):
    """Im(poles) / 2 pi -> undamped frequencies (drives held); each actuator adds -1/tau."""
    undamped = linear.modes(linear.linearize(Simulation(xy), U)).frequencies
    assert len(undamped) == 15
    errors = []
    for s in (1e-3, 1e-5, 1e-7):
        md = linear.modes(linear.linearize(Simulation(_scaled_damping(xy, s)), U))
        upper = np.sort(md.poles[md.poles.imag > 0].imag) / (2 * np.pi)
        assert len(upper) == len(undamped)
        errors.append(np.max(np.abs(upper - undamped) / undamped))
        assert np.sum(np.isclose(md.poles, -1000.0, rtol=1e-12)) == 2  # two 1 ms lags
    assert errors[2] < 1e-9
    assert errors[0] > errors[1] > errors[2]


def _force_drive_xy():
    """Return the XY stage with drive y a force on piezo_y (N along y): piezo_y is then free."""
    doc = copy.deepcopy(read_yaml(resolve_mechanism_path("xy_stage"), ConfigError))
    doc["constraints"][2] = {"type": "force", "name": "y", "body": "piezo_y", "axis": [0, 1],
                             "response_time": 1e-3, "stroke": [-10, 10], "slew_rate": 1e3}
    return mechanism_from_dict(doc)


def test_a_force_drive_enters_b_as_a_generalised_force():
    """
    Its column of G(0) against central differences of static solves in the force (N).

    Richardson-extrapolated, steps 0.1 N and its half: smaller steps see the static solve's
    rounding (its residual force is ~1e-9 N on the free, stiffly held piezo_y).
    """
    sim = Simulation(_force_drive_xy())
    f0, h = 0.5, 0.1
    lm = linear.linearize(sim, {"x": 2e-6, "y": f0})
    assert lm.lags == (0, -1)  # x has an actuator state, y none
    assert "drive_position.y" in lm.output_names and "drive_force.y" not in lm.output_names
    names = ["x", "y", "theta", "drive_position.y", "drive_force.x"]
    G = linear.static_gain(lm, names, "y")

    def measures(f):
        snap = sim.static({"x": 2e-6, "y": f}).snapshot
        return np.array([snap.outputs["x"], snap.outputs["y"], snap.outputs["theta"],
                         snap.drive_positions[1], snap.drive_forces[0]])

    def central(h):
        return (measures(f0 + h) - measures(f0 - h)) / (2 * h)

    np.testing.assert_allclose(G, (4 * central(h / 2) - central(h)) / 3, rtol=1e-6)


def test_a_finite_piezo_stack_is_refused_by_name():
    doc = copy.deepcopy(read_yaml(resolve_mechanism_path("xy_stage"), ConfigError))
    doc["constraints"][1]["actuator"] = {"v_max": 100.0, "stiffness": 5e7}
    with pytest.raises(ValueError, match="drive x has a finite-stiffness piezo stack"):
        linear.linearize(Simulation(mechanism_from_dict(doc)))


# ------------------------------------------------------------------------------------- CLI


def test_frf_command_picks_the_drive_by_name_and_lists_them(tmp_path, capsys):
    argv = ["frf", "xy_stage", "--from", "y", "--to", "x", "--fmin", 10, "--fmax", 1e3,
            "--points", 5, "--csv", "-o", tmp_path]
    assert main([str(a) for a in argv]) == 0
    table = np.loadtxt(tmp_path / "frf.csv", delimiter=",", skiprows=1)
    G = linear.frf(linear.linearize(Simulation(load_mechanism("xy_stage"))), table[:, 0], ["x"],
                   "y")[0]
    np.testing.assert_allclose(table[:, 3] + 1j * table[:, 4], G, rtol=1e-8)  # 10 digits
    assert "static gain 0.0058015" in capsys.readouterr().out
    assert main(["frf", "xy_stage", "--from", "z", "-o", str(tmp_path)]) == 2
    assert "--from 'z': no such drive; mechanism 'xy_stage' has drives x, y" in (
        capsys.readouterr().err)
    assert main(["frf", "xy_stage", "-o", str(tmp_path)]) == 2
    assert "has 2 drives (x, y): name one" in capsys.readouterr().err


def test_linearize_exports_a_mimo_model_python_control_loads(tmp_path, capsys):
    import control

    path = tmp_path / "xy.npz"
    assert main(["linearize", "xy_stage", "--input", "x=3e-6,y=5e-6", "-o", str(path)]) == 0
    assert "2 inputs (x, y)" in capsys.readouterr().out
    data = np.load(path)
    assert list(data["input_names"]) == ["x", "y"]
    np.testing.assert_array_equal(data["input_u0"], [3e-6, 5e-6])
    outputs = list(data["output_names"])
    # python-control allows no '.' in signal names (hinges.<h>.moment): outputs by position
    plant = control.ss(data["A"], data["B"], data["C"], data["D"],
                       inputs=list(data["input_names"]))
    assert main(["frf", "xy_stage", "--input", "3e-6,5e-6", "--from", "y", "--to", "x", "--to",
                 "theta", "--fmin", "5", "--fmax", "2e3", "--points", "4", "--csv", "-o",
                 str(tmp_path)]) == 0
    table = np.loadtxt(tmp_path / "frf.csv", delimiter=",", skiprows=1)
    f = table[:, 0]
    for k, out in enumerate(("x", "theta")):
        resp = control.frequency_response(plant[outputs.index(out), 1], 2 * np.pi * f)
        want = table[:, 3 + 4 * k] + 1j * table[:, 4 + 4 * k]
        # python-control solves the 32 first-order states (poles from -1e3 to -7e7 1/s): it
        # agrees with frf's second-order solve to 2e-8 at 2 kHz
        np.testing.assert_allclose(np.squeeze(resp.complex), want, rtol=1e-7)
    # one number for two drives, an unknown name: one clear line each
    assert main(["linearize", "xy_stage", "--input", "1e-6", "-o", str(path)]) == 2
    assert "one number given for 2 drives (x, y)" in capsys.readouterr().err
    assert main(["modes", "xy_stage", "--input", "x=1e-6,z=0"]) == 2
    assert "unknown ['z'], missing ['y'] (drives: x, y)" in capsys.readouterr().err


def test_modes_command_of_the_xy_stage(capsys):
    assert main(["modes", "xy_stage", "--input", "x=3e-6,y=5e-6", "--count", "2",
                 "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["input"] == {"x": 3e-6, "y": 5e-6}
    want = linear.modes(linear.linearize(Simulation(load_mechanism("xy_stage")), U)).frequencies
    np.testing.assert_array_equal(out["undamped_frequencies_hz"], want)
    assert 350 < want[0] < want[1] < 370


def test_an_actuator_block_is_refused_by_the_commands(capsys):
    path = str(resolve_mechanism_path("microstage").parent / "examples" / "piezo_stage.yaml")
    assert main(["modes", path]) == 2
    assert "drive drive has a piezo actuator block" in capsys.readouterr().err
