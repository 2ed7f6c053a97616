"""
Design sensitivities of a mechanism with several drives (issue 13): the XY stage.

``gain.<output>.<drive>`` is the static gain matrix's entry at the equilibrium of --input.
Expected values: the gain matrix ``simulate --static`` reports (statics.static_gain), and
Richardson-extrapolated central differences of the gain matrix and first mode of re-solved
mechanisms (the YAML number changed, the engine's linearisation re-run).
"""

import copy
import json

import numpy as np
import pytest
import yaml

from flexure_sim.cli import gain_matrix, main
from flexure_sim.engine.analysis import linear
from flexure_sim.engine.mechanism.loader import mechanism_from_dict
from flexure_sim.engine.mechanism.parameters import ParameterError, Parameters
from flexure_sim.engine.analysis.sensitivity import sensitivities
from flexure_sim.engine.solver.simulation import Simulation

U = {"x": 1e-5, "y": 4e-6}
H, T = "stiffness_models.notch.h", "stiffness_models.leaf.thickness"
KEYS = ["gain.x.x", "gain.y.x", "gain.theta.y"]


@pytest.fixture(scope="module")
def params():
    return Parameters("xy_stage")


@pytest.fixture(scope="module")
def result(params):
    return sensitivities(params, [H, T], KEYS + ["first_mode"], U)


def _solved(data, u):
    """Return (gain.x.x, gain.y.x, gain.theta.y, first mode) of the re-solved mechanism."""
    sim = Simulation(mechanism_from_dict(data))
    lm = linear.linearize(sim, u, wrenches=False)
    G = linear.gain_matrix(lm, ["x", "y", "theta"])
    return np.array([G[0, 0], G[1, 0], G[2, 1], linear.modes(lm).frequencies[0]])


def _with(params, h=None, t=None):
    data = copy.deepcopy(params.data)
    if h is not None:
        data["stiffness_models"]["notch"]["h"] = h
    if t is not None:
        data["stiffness_models"]["leaf"]["thickness"] = t
    return data


def _richardson(f, x, dx):
    d1 = (f(x + dx) - f(x - dx)) / (2 * dx)
    d2 = (f(x + dx / 2) - f(x - dx / 2)) / dx
    return (4 * d2 - d1) / 3


def test_gains_at_rest_are_the_matrix_simulate_static_reports(params):
    res = sensitivities(params, [H], ["gain"], {"x": 0.0, "y": 0.0})
    reported = gain_matrix(Simulation(params.mechanism))
    assert list(res["values"]) == [f"gain.{o}.{d}" for o in reported["outputs"]
                                   for d in reported["drives"]]
    got = np.array(list(res["values"].values())).reshape(3, 2)
    np.testing.assert_allclose(got, reported["matrix"], rtol=1e-9)


def test_first_derivatives_agree_with_central_differences(params, result):
    """Gains and the first mode in h (notches) and t (leaves): rel 1e-6 (measured 1e-8)."""
    h0, t0 = params.value(H), params.value(T)
    fd_h = _richardson(lambda h: _solved(_with(params, h=h), U), h0, 1e-3 * h0)
    fd_t = _richardson(lambda t: _solved(_with(params, t=t), U), t0, 1e-3 * t0)
    for k, o in enumerate(KEYS + ["first_mode"]):
        assert result["gradient"][o][H] == pytest.approx(fd_h[k], rel=1e-6), o
        assert result["gradient"][o][T] == pytest.approx(fd_t[k], rel=1e-6), o
    assert result["input"] == U


def test_second_derivatives_of_the_gains_agree_with_central_differences(params, result):
    h0, t0 = params.value(H), params.value(T)
    dh, dt = 1e-2 * h0, 1e-2 * t0

    def f(h, t):
        return _solved(_with(params, h=h, t=t), U)[:3]

    def hh(d):
        return (f(h0 + d, t0) - 2 * f(h0, t0) + f(h0 - d, t0)) / d**2

    def ht(a, b):
        return (f(h0 + a, t0 + b) - f(h0 + a, t0 - b) - f(h0 - a, t0 + b)
                + f(h0 - a, t0 - b)) / (4 * a * b)

    fd_hh = (4 * hh(dh / 2) - hh(dh)) / 3
    fd_ht = (4 * ht(dh / 2, dt / 2) - ht(dh, dt)) / 3
    for k, o in enumerate(KEYS):
        assert result["second"][o][f"{H}|{H}"] == pytest.approx(fd_hh[k], rel=1e-4), o
        assert result["second"][o][f"{H}|{T}"] == pytest.approx(fd_ht[k], rel=1e-4), o


def test_a_force_drives_gain_and_its_derivative(params, tmp_path):
    """Drive y a force on piezo_y: gain.y.y in m/N at 0.5 N, the held force in the equilibrium."""
    data = copy.deepcopy(params.data)
    data["constraints"][2] = {"type": "force", "name": "y", "body": "piezo_y", "axis": [0, 1],
                              "response_time": 1e-3, "stroke": [-10, 10], "slew_rate": 1e3}
    path = tmp_path / "xy_force.yaml"
    path.write_text(yaml.safe_dump(data))
    u = {"x": 2e-6, "y": 0.5}
    res = sensitivities(Parameters(str(path)), [H], ["gain.y.y", "gain.x.y"], u)

    def gains(h):
        lm = linear.linearize(Simulation(mechanism_from_dict(_with_data(data, h))), u,
                              wrenches=False)
        return linear.static_gain(lm, ["y", "x"], "y")

    h0 = params.value(H)
    np.testing.assert_allclose([res["values"]["gain.y.y"], res["values"]["gain.x.y"]],
                               gains(h0), rtol=1e-9)
    # step 1 % of h: the cross gain (1e-3 of the direct one) is a small difference in G(0)
    fd = _richardson(gains, h0, 1e-2 * h0)
    np.testing.assert_allclose([res["gradient"]["gain.y.y"][H], res["gradient"]["gain.x.y"][H]],
                               fd, rtol=1e-6)


def _with_data(data, h):
    data = copy.deepcopy(data)
    data["stiffness_models"]["notch"]["h"] = h
    return data


def test_single_drive_gain_stays_the_secant_and_its_tangent_is_the_linear_models():
    params = Parameters("microstage")
    res = sensitivities(params, [H], ["gain", "gain.output.drive"], 2e-6)
    lm = linear.linearize(Simulation(params.mechanism), 2e-6, wrenches=False)
    snap = Simulation(params.mechanism).static(2e-6).snapshot
    assert res["values"]["gain"] == pytest.approx(snap.output / 2e-6, rel=1e-12)
    assert res["values"]["gain.output.drive"] == pytest.approx(
        linear.static_gain(lm, ["output"])[0], rel=1e-9)


def test_sensitivity_command_with_several_drives(capsys):
    argv = ["sensitivity", "xy_stage", "--wrt", H, "--of", "gain", "--input", "x=1e-5,y=4e-6",
            "--json"]
    assert main(argv) == 0
    out = json.loads(capsys.readouterr().out)
    assert list(out["values"]) == ["gain.x.x", "gain.x.y", "gain.y.x", "gain.y.y",
                                   "gain.theta.x", "gain.theta.y"]
    assert out["input"] == U
    # first_mode at the default input: the top of every drive's stroke
    assert main(["sensitivity", "xy_stage", "--wrt", H, "--of", "first_mode"]) == 0
    assert "drive inputs x 15 um, y 15 um" in capsys.readouterr().out
    for argv, message in (
        (["--of", "gain.z.x"], "no such gain (gain.<output>.<drive>: gain.x.x, gain.x.y"),
        (["--of", "gain", "--input", "1e-6"], "--input: one number given for 2 drives (x, y)"),
        (["--of", "peak_stress", "--input", "0,0"], "every drive input is 0"),
        (["--of", "gain", "--input", "x=1e-6,y=zero"], "'zero' is not a number"),
    ):
        assert main(["sensitivity", "xy_stage", "--wrt", H] + argv) == 2
        err = capsys.readouterr().err
        assert message in err and err.count("\n") == 1, err


def test_an_unknown_gain_is_a_parameter_error(params):
    with pytest.raises(ParameterError, match="gain.theta.y"):
        sensitivities(params, [H], ["gain.x.z"], U)
