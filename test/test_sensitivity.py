"""
Exact design sensitivities by hyper-dual numbers against finite differences.

The finite differences are of re-solved mechanisms (the engine's own static solver and
eigen-analysis, from edited YAML).
"""

import copy
import json

import numpy as np
import pytest

from flexure_sim.cli import main
from flexure_sim.engine.analysis import linear
from flexure_sim.engine.mechanism.loader import mechanism_from_dict
from flexure_sim.engine.mechanism.parameters import ParameterError, Parameters
from flexure_sim.engine.analysis.sensitivity import sensitivities
from flexure_sim.engine.solver.simulation import Simulation
from flexure_sim.engine.hinges.stress import stress_table

U = 1.35e-6
H_C, X_C = "hinges.c.stiffness.h", "hinges.e.stiffness.D"
FRAME = "hinges.a.a.at.0"  # x of hinge a's frame on body2 (the input lever), 7 mm


@pytest.fixture(scope="module")
def params():
    return Parameters("microstage")


def _resolve(params, changes):
    """
    Gain, compression, first mode and peak hinge stress, re-solved by the engine.

    The stage with the YAML numbers changed: a stiffness entry (``stiffness_models.notch.X``,
    ``hinges.<h>.stiffness.X``) in the file's data, a hinge frame position
    (``hinges.<h>.<a|b>.at.<i>``) in the loaded mechanism (``_replaced``: a moved frame
    prestresses its hinge, which the file's coincidence check would refuse).
    """
    data = copy.deepcopy(params.data)
    frames = {}
    for path, value in changes.items():
        keys = path.split(".")
        if keys[0] == "hinges" and keys[2] in ("a", "b"):
            frames[path] = value
        elif keys[0] == "hinges":
            entry = [h for h in data["hinges"] if h["name"] == keys[1]][0]
            if isinstance(entry["stiffness"], str):
                entry["stiffness"] = dict(data["stiffness_models"][entry["stiffness"]])
            entry["stiffness"][keys[3]] = value
        else:
            data["stiffness_models"]["notch"][keys[2]] = value
    mech = mechanism_from_dict(data)
    for path, value in frames.items():
        _, hinge, frame, _, index = path.split(".")
        mech = _replaced(mech, hinge, frame, int(index), value)
    sim = Simulation(mech)
    snap = sim.static(U).snapshot
    first = linear.modes(linear.linearize(sim, U, wrenches=False)).frequencies[0]
    peak = max(v["stress"] for v in stress_table(snap.wrenches, mech).values())
    return np.array([snap.output / U, snap.compression, first, peak])


def _richardson_first(f, x, dx):
    d1 = (f(x + dx) - f(x - dx)) / (2 * dx)
    d2 = (f(x + dx / 2) - f(x - dx / 2)) / dx
    return (4 * d2 - d1) / 3


@pytest.fixture(scope="module")
def result(params):
    return sensitivities(params, [H_C, X_C], ["gain", "compression", "first_mode"], U)


def test_first_derivatives_agree_with_central_differences(params, result):
    for path in (H_C, X_C):
        x0 = params.value(path)
        fd = _richardson_first(lambda x: _resolve(params, {path: x})[:3], x0, 2e-3 * x0)
        exact = [result["gradient"][o][path] for o in ("gain", "compression", "first_mode")]
        np.testing.assert_allclose(exact, fd, rtol=1e-6)


def test_second_derivatives_agree_with_central_differences(params, result):
    """d2/dh2, d2/dD2 and d2/dh dD of gain and compression (two hinges) against re-solves."""
    h0, t0 = params.value(H_C), params.value(X_C)
    fd = _second_differences(lambda h, t: _resolve(params, {H_C: h, X_C: t})[:2],
                             h0, t0, 1e-2 * h0, 1e-2 * t0)
    for k, o in enumerate(("gain", "compression")):
        got = result["second"][o]
        exact = [got[f"{H_C}|{H_C}"], got[f"{X_C}|{X_C}"], got[f"{H_C}|{X_C}"]]
        np.testing.assert_allclose(exact, [d[k] for d in fd], rtol=1e-4, err_msg=o)


def test_second_derivatives_through_a_hinge_frame_position(params):
    """
    d2/dx2 and d2/dh dx of gain and compression, x a hinge frame coordinate, h a neck.

    The frame position (x of hinge a's frame on the input lever) flows through the kinematics
    (r(z) and the twistor), h through the stiffness formula; the mixed derivative couples the
    two. Steps 1.6 um in x (the differences of re-solves carry ~1e-11 relative rounding, so
    the step cannot be much smaller) and 1 % in h.
    """
    res = sensitivities(params, [H_C, FRAME], ["gain", "compression"], U)
    h0, x0 = params.value(H_C), params.value(FRAME)
    fd = _second_differences(lambda h, x: _resolve(params, {H_C: h, FRAME: x})[:2],
                             h0, x0, 1e-2 * h0, 1.6e-6)
    for k, o in enumerate(("gain", "compression")):
        got = res["second"][o]
        exact = [got[f"{H_C}|{H_C}"], got[f"{FRAME}|{FRAME}"], got[f"{H_C}|{FRAME}"]]
        np.testing.assert_allclose(exact, [d[k] for d in fd], rtol=1e-4, err_msg=o)


def _second_differences(f, x0, y0, dx, dy):
    """
    d2f/dx2, d2f/dy2 and d2f/dx dy by central differences, Richardson-extrapolated.

    Steps dx, dy and their halves.
    """
    def xx(d):
        return (f(x0 + d, y0) - 2 * f(x0, y0) + f(x0 - d, y0)) / d**2

    def yy(d):
        return (f(x0, y0 + d) - 2 * f(x0, y0) + f(x0, y0 - d)) / d**2

    def xy(a, b):
        return (f(x0 + a, y0 + b) - f(x0 + a, y0 - b) - f(x0 - a, y0 + b)
                + f(x0 - a, y0 - b)) / (4 * a * b)

    return ((4 * xx(dx / 2) - xx(dx)) / 3, (4 * yy(dy / 2) - yy(dy)) / 3,
            (4 * xy(dx / 2, dy / 2) - xy(dx, dy)) / 3)


def test_first_mode_second_derivatives_agree_with_central_differences(params, result):
    """
    d2 f1 / dh2, dD2 and dh dD (two hinges) against re-solved eigen-analyses.

    Exact by Nelson's eigenvector derivative and a complex step on the hyper-dual parts
    (engine/analysis/sensitivity.py).
    """
    h0, d0 = params.value(H_C), params.value(X_C)
    fd = _second_differences(lambda h, d: _resolve(params, {H_C: h, X_C: d})[2],
                             h0, d0, 1e-2 * h0, 1e-2 * d0)
    got = result["second"]["first_mode"]
    exact = [got[f"{H_C}|{H_C}"], got[f"{X_C}|{X_C}"], got[f"{H_C}|{X_C}"]]
    np.testing.assert_allclose(exact, fd, rtol=1e-4)


def test_first_mode_second_derivatives_through_the_mass_matrix(params):
    """d2 f1 / dm2 and d2 f1 / dh dm: the M_p, M_pq terms of the eigenvalue's second derivative."""
    mech, mass = params.mechanism, "bodies.body4.mass"
    res = sensitivities(params, [H_C, mass], ["first_mode"], U)["second"]["first_mode"]
    h0, m0 = params.value(H_C), params.value(mass)

    def first(h, m):
        data = copy.deepcopy(params.data)
        entry = [e for e in data["hinges"] if e["name"] == "c"][0]
        if isinstance(entry["stiffness"], str):
            entry["stiffness"] = dict(data["stiffness_models"][entry["stiffness"]])
        entry["stiffness"]["h"] = h
        sim = Simulation(_replaced(mechanism_from_dict(data), body="body4", mass=m))
        return linear.modes(linear.linearize(sim, U, wrenches=False)).frequencies[0]

    assert mech.bodies[mech.body_index("body4")].mass == m0
    fd_hh, fd_mm, fd_hm = _second_differences(first, h0, m0, 1e-2 * h0, 1e-2 * m0)
    assert res[f"{mass}|{mass}"] == pytest.approx(fd_mm, rel=1e-4)
    assert res[f"{H_C}|{mass}"] == pytest.approx(fd_hm, rel=1e-4)
    assert res[f"{H_C}|{H_C}"] == pytest.approx(fd_hh, rel=1e-4)


def test_peak_stress_derivatives_agree_with_central_differences(params):
    """
    First (1e-6) and second (1e-4) derivatives of the peak stress in hinge c's h and D.

    Hinge c carries the peak; D flows through both its stiffness and its concentration factor.
    """
    d_c = "hinges.c.stiffness.D"
    res = sensitivities(params, [H_C, d_c], ["peak_stress"], U)
    h0, d0 = params.value(H_C), params.value(d_c)
    for path, x0 in ((H_C, h0), (d_c, d0)):
        fd = _richardson_first(lambda x: _resolve(params, {path: x})[3], x0, 2e-3 * x0)
        assert res["gradient"]["peak_stress"][path] == pytest.approx(fd, rel=1e-6), path
    fd = _second_differences(lambda h, d: _resolve(params, {H_C: h, d_c: d})[3],
                             h0, d0, 1e-2 * h0, 1e-2 * d0)
    got = res["second"]["peak_stress"]
    exact = [got[f"{H_C}|{H_C}"], got[f"{d_c}|{d_c}"], got[f"{H_C}|{d_c}"]]
    np.testing.assert_allclose(exact, fd, rtol=1e-4)


OUT = {"gain": 0, "compression": 1, "first_mode": 2, "peak_stress": 3}
# Steps: 4, 2, 1 % of h (10, 5, 2.5 um); 0.2, 0.1, 0.05 um of the frame position, where the
# first-order remainder's cubic term (large in the frame position: its ratio is 4.95 at 2 um)
# is below 2 % of the quadratic one.
STEPS = {H_C: (1e-5, 5e-6, 2.5e-6), FRAME: (2e-7, 1e-7, 5e-8)}


def _remainders(params, path, output, order):
    """|f(p + d) - Taylor polynomial of the given order at p| for the steps STEPS[path]."""
    res = sensitivities(params, [path], [output], U)
    v, g = res["values"][output], res["gradient"][output][path]
    s = res["second"][output][f"{path}|{path}"] if order == 2 else 0.0
    p0 = params.value(path)
    return np.array([
        abs(_resolve(params, {path: p0 + d})[OUT[output]] - (v + g * d + 0.5 * s * d * d))
        for d in STEPS[path]
    ])


@pytest.mark.parametrize("path, output", [
    (H_C, "gain"), (H_C, "compression"), (H_C, "first_mode"), (H_C, "peak_stress"),
    (FRAME, "gain"), (FRAME, "compression"), (FRAME, "first_mode"),
])
def test_taylor_remainder_falls_as_the_square_of_the_step(params, path, output):
    """
    |f(p + d) - f(p) - f'(p) d| falls by 4 when d halves: the gradient is the derivative.

    With a wrong gradient (by delta) the remainder would be ~delta d and fall by 2. The peak
    stress is not taken against the frame position: moving hinge a's frame prestresses hinge
    a, and the |m|, |f_x| of the stress formula are not smooth where a wrench component of a
    hinge passes zero.
    """
    errors = _remainders(params, path, output, order=1)
    np.testing.assert_allclose(errors[:-1] / errors[1:], 4.0, rtol=0.05)


@pytest.mark.parametrize("path, output", [
    (H_C, "gain"), (H_C, "compression"), (H_C, "first_mode"),
    (FRAME, "gain"), (FRAME, "compression"),
])
def test_second_order_taylor_remainder_falls_as_the_cube_of_the_step(params, path, output):
    """
    |f(p + d) - (f + f' d + f'' d^2 / 2)| falls by 8 when d halves: f'' is the derivative.

    Left out where that remainder is at the re-solve's rounding level (~1e-12 relative for the
    first mode against the frame position, ~1e-9 for the peak stress against h).
    """
    errors = _remainders(params, path, output, order=2)
    np.testing.assert_allclose(errors[:-1] / errors[1:], 8.0, rtol=0.05)


def test_bad_parameter_paths_are_named(params):
    with pytest.raises(ParameterError,
                       match="bodies.body9.mass: bodies has no element named 'body9'"):
        params.check("bodies.body9.mass")
    with pytest.raises(ParameterError, match="^hinges.a.a.body is 'body2', not a finite number"):
        params.check("hinges.a.a.body")
    with pytest.raises(ParameterError, match="name the same number"):
        sensitivities(params, ["hinges.a.stiffness.h", "hinges.0.stiffness.h"], ["gain"], U)


def test_sensitivity_command_json(capsys):
    assert (
        main(
            [
                "sensitivity",
                "microstage",
                "--wrt",
                "stiffness_models.notch.h,bodies.body4.mass",
                "--of",
                "gain,first_mode,peak_stress",
                "--json",
            ]
        )
        == 0
    )
    out = json.loads(capsys.readouterr().out)
    assert out["gradient"]["gain"]["bodies.body4.mass"] == 0.0  # statics do not depend on mass
    assert out["gradient"]["first_mode"]["bodies.body4.mass"] < 0
    assert "stiffness_models.notch.h|bodies.body4.mass" in out["second"]["peak_stress"]
    assert main(["sensitivity", "microstage", "--wrt", "nonsense.key"]) == 2
    assert "nonsense.key: the document has no key 'nonsense'" in capsys.readouterr().err


def test_sensitivity_command_reports_the_first_modes_mixed_second_derivative(result, capsys):
    """--wrt A,B --of first_mode: d2 f1 / dA dB in the JSON and in the text."""
    argv = ["sensitivity", "microstage", "--wrt", f"{H_C},{X_C}", "--of", "first_mode",
            "--input", str(U)]
    assert main(argv + ["--json"]) == 0
    second = json.loads(capsys.readouterr().out)["second"]["first_mode"]
    expected = result["second"]["first_mode"]
    for key in (f"{H_C}|{H_C}", f"{X_C}|{X_C}", f"{H_C}|{X_C}"):
        assert second[key] == pytest.approx(expected[key], rel=1e-9)
    assert main(argv) == 0
    text = capsys.readouterr().out
    assert f"parameter 1: {H_C} = " in text and f"parameter 2: {X_C} = " in text
    line = [t.split() for t in text.splitlines() if t.strip().startswith("i=1 ")]
    assert len(line) == 1, text
    assert float(line[0][2]) == pytest.approx(expected[f"{H_C}|{X_C}"], rel=1e-9)


def _replaced(mech, hinge=None, frame=None, index=None, value=None, body=None, mass=None):
    """
    Return the engine's mechanism with one hinge frame coordinate or one body mass changed.

    Bypassing the file's coincidence check (a moved frame prestresses its hinge).
    """
    import dataclasses

    if hinge is not None:
        hinges = list(mech.hinges)
        k = mech.hinge_index(hinge)
        f = getattr(hinges[k], frame)
        pos = list(f.position)
        pos[index] = value
        hinges[k] = dataclasses.replace(
            hinges[k], **{frame: dataclasses.replace(f, position=tuple(pos))}
        )
        return dataclasses.replace(mech, hinges=tuple(hinges))
    bodies = list(mech.bodies)
    i = mech.body_index(body)
    bodies[i] = dataclasses.replace(bodies[i], mass=mass)
    return dataclasses.replace(mech, bodies=tuple(bodies))


def test_derivatives_through_the_kinematics_and_the_mass_matrix(params):
    """A hinge frame position flows through r(z) and the twistor; a mass only through M."""
    mech = params.mechanism
    path = "hinges.c.b.at.1"
    res = sensitivities(
        params, [path, "bodies.body4.mass"], ["gain", "compression", "first_mode"], U
    )
    y0 = params.value(path)

    def solve(y):
        sim = Simulation(_replaced(mech, "c", "b", 1, y))
        snap = sim.static(U).snapshot
        return np.array([snap.output / U, snap.compression])

    fd = _richardson_first(solve, y0, 1e-6)
    exact = [res["gradient"][o][path] for o in ("gain", "compression")]
    np.testing.assert_allclose(exact, fd, rtol=1e-6)

    m0 = params.value("bodies.body4.mass")

    def first(m):
        sim = Simulation(_replaced(mech, body="body4", mass=m))
        return linear.modes(linear.linearize(sim, U, wrenches=False)).frequencies[0]

    fd_m = _richardson_first(first, m0, 1e-2 * m0)
    assert res["gradient"]["first_mode"]["bodies.body4.mass"] == pytest.approx(fd_m, rel=1e-6)


def test_first_mode_sensitivity_of_a_mechanism_without_drive(capsys):
    assert (
        main(
            [
                "sensitivity",
                "fourbar_mixed",
                "--wrt",
                "stiffness_models.notch.h",
                "--of",
                "first_mode",
                "--json",
            ]
        )
        == 0
    )
    out = json.loads(capsys.readouterr().out)
    assert out["gradient"]["first_mode"]["stiffness_models.notch.h"] > 0  # thicker: stiffer
    assert main(["sensitivity", "fourbar_mixed", "--wrt", "stiffness_models.notch.h"]) == 2
    assert "names no output body" in capsys.readouterr().err


def test_compression_sensitivity_does_not_depend_on_hinge_labels(params, tmp_path):
    """
    Relabel the compression hinge (A and B swapped): the derivative stays the engine's.

    The engine measures compression drive side minus far side (engine/solver/compression.py); the
    sensitivity must differentiate that same definition, not B minus A.
    """
    import yaml

    data = copy.deepcopy(params.data)
    hinge = [h for h in data["hinges"] if h["name"] == "a"][0]
    hinge["a"], hinge["b"] = hinge["b"], hinge["a"]
    path = tmp_path / "swapped.yaml"
    path.write_text(yaml.safe_dump(data))
    swapped = Parameters(str(path))
    got = sensitivities(swapped, [H_C], ["compression"], U)["gradient"]["compression"][H_C]
    x0 = swapped.value(H_C)
    fd = _richardson_first(lambda x: _resolve(swapped, {H_C: x})[1], x0, 2e-3 * x0)
    assert got == pytest.approx(fd, rel=1e-6)
    assert got == pytest.approx(result_of(params)[H_C], rel=1e-9)  # same physics, same number


def result_of(params):
    return sensitivities(params, [H_C], ["compression"], U)["gradient"]["compression"]
