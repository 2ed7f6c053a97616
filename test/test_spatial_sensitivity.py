"""
Exact design sensitivities in 3-D (engine/analysis/spatial_sensitivity.py).

Expected values from independent sources: the planar engine's exact sensitivities for the
in-plane gains of planar files opened in 3-D, the in-plane first mode's f ~ sqrt(t) law, and
central finite differences of the spatial engine's linear model (its DC gain matrix,
``linear_response.gain_matrix``, and its modes) for the tip-tilt stage's gain matrix and the
microstage's first out-of-plane mode.
"""
from __future__ import annotations

import copy
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from flexure_sim.engine.analysis import linear_response, spatial_linear
from flexure_sim.engine.analysis import sensitivity as planar
from flexure_sim.engine.analysis import spatial_sensitivity as spatial
from flexure_sim.engine.mechanism.doc_paths import apply
from flexure_sim.engine.mechanism.loader import resolve_mechanism_path
from flexure_sim.engine.mechanism.parameters import ParameterError, Parameters
from flexure_sim.engine.mechanism.spatial_loader import spatial_from_dict
from flexure_sim.engine.mechanism.values import ConfigError
from flexure_sim.engine.mechanism.yaml_files import read_yaml
from flexure_sim.engine.solver.spatial_model import SpatialModel

ROOT = Path(__file__).resolve().parents[1]
TIPTILT = str(ROOT / "config" / "tiptilt_stage.yaml")


def _model(params, path, value) -> SpatialModel:
    """Return the spatial model with the number at ``path`` set to ``value`` (a float)."""
    doc = apply(params.data, [params.resolve(path)[:2] + (value,)])
    return SpatialModel(spatial_from_dict(doc, str(params.path)))


def _central(f, x0, rel=1e-5):
    h = rel * abs(x0)
    return (f(x0 + h) - f(x0 - h)) / (2.0 * h)


def test_in_plane_gain_of_the_microstage_in_3d_equals_the_planar_engines_exact_one():
    wrt = ["stiffness_models.notch.h", "hinges.c.stiffness.D"]
    three = spatial.sensitivities(spatial.SpatialParameters("microstage"), wrt, ["gain"])
    two = planar.sensitivities(Parameters("microstage"), wrt, ["gain"])
    assert three["values"]["gain"] == pytest.approx(two["values"]["gain"], rel=1e-10)
    for p in wrt:
        assert three["gradient"]["gain"][p] == pytest.approx(two["gradient"]["gain"][p],
                                                             rel=1e-10)


def test_gain_matrix_of_a_displacement_and_a_force_drive_in_3d_equals_the_planar_one():
    """The XY stage with drive y a force (N) on piezo_y, loaded by both drives, in 3-D."""
    path = resolve_mechanism_path("xy_stage")
    doc = copy.deepcopy(read_yaml(path, ConfigError))
    doc["constraints"][2] = {"type": "force", "name": "y", "body": "piezo_y", "axis": [0, 1],
                             "response_time": 1e-3, "stroke": [-10, 10], "slew_rate": 1e3}
    wrt = ["stiffness_models.notch.h", "stiffness_models.leaf.thickness"]
    three = spatial.sensitivities(spatial.SpatialParameters(str(path), doc), wrt, ["gain"])
    two = planar.sensitivities(Parameters(str(path), doc), wrt, ["gain"])
    assert len(three["values"]) == 6 and set(three["values"]) == set(two["values"])
    for o, v in two["values"].items():
        assert three["values"][o] == pytest.approx(v, rel=1e-10)
        for p in wrt:
            assert three["gradient"][o][p] == pytest.approx(two["gradient"][o][p], rel=1e-9)


@pytest.mark.parametrize("output", ["first_mode", "out_of_plane_mode"])
def test_the_microstages_modes_in_3d_and_their_plate_thickness_derivative_vs_differences(output):
    params = spatial.SpatialParameters("microstage")
    path = "stiffness_models.notch.t"
    res = spatial.sensitivities(params, [path], [output])

    def frequency(t):
        model = _model(params, path, t)
        lin = spatial_linear.linearize(model, np.zeros(len(model.drives)), wrenches=False)
        md = spatial_linear.modes(lin)
        shares = spatial_linear.out_of_plane_shares(lin, md)
        k = 0 if output == "first_mode" else int(np.argmax(shares > 0.5))
        return md.frequencies[k]

    t0 = params.value(path)
    f0 = res["values"][output]
    assert f0 == pytest.approx(frequency(t0), rel=1e-9)
    if output == "first_mode":
        # in plane: every hinge stiffness is proportional to t, the in-plane masses are not,
        # so f ~ sqrt(t) exactly (central differences see the eigensolver's rounding, ~1e-7)
        assert res["gradient"][output][path] == pytest.approx(f0 / (2.0 * t0), rel=1e-9)
    else:
        fd = _central(frequency, t0)
        assert res["gradient"][output][path] == pytest.approx(fd, rel=1e-6)
    if output == "out_of_plane_mode":  # not the in-plane first mode
        assert res["values"][output] > 1.5 * spatial.sensitivities(
            params, [path], ["first_mode"])["values"]["first_mode"]


def test_the_tiptilt_stages_gain_matrix_gradient_vs_central_differences():
    params = spatial.SpatialParameters(TIPTILT)
    wrt = ["stiffness_models.leaf.thickness", "stiffness_models.wire.diameter",
           "hinges.wire2.stiffness.length"]
    res = spatial.sensitivities(params, wrt, ["gain"])
    outputs = ["tip", "tilt", "piston"]
    inputs = np.array(list(res["input"].values()))

    def gains(path, value):
        model = _model(params, path, value)
        lin = spatial_linear.linearize(model, inputs, wrenches=False)
        return linear_response.gain_matrix(lin, outputs)

    G0 = gains(wrt[0], params.value(wrt[0]))
    scale = np.max(np.abs(G0), axis=1)  # per output: the gains' size
    drives = list(res["input"])
    for o, name in enumerate(outputs):
        for d, drive in enumerate(drives):
            assert res["values"][f"gain.{name}.{drive}"] == pytest.approx(
                G0[o, d], abs=1e-9 * scale[o])
    for p in wrt:
        p0 = params.value(p)
        fd = _central(lambda v: gains(p, v), p0)
        for o, name in enumerate(outputs):
            for d, drive in enumerate(drives):
                exact = res["gradient"][f"gain.{name}.{drive}"][p]
                # relative to the row's derivative size: an exact zero (tilt from p1) has none
                assert exact == pytest.approx(fd[o, d], abs=1e-6 * np.max(np.abs(fd[o])))


def test_an_entry_of_a_6x6_matrix_hinge_is_a_parameter_too():
    """The tip-tilt stage's wires as ``model: matrix`` (their rod stiffness): the axial entry."""
    base = spatial.SpatialParameters(TIPTILT)
    doc = copy.deepcopy(base.data)
    K = spatial_from_dict(base.data, TIPTILT).hinges[0].law.K
    doc["stiffness_models"]["wire"] = {"model": "matrix", "K": K.tolist()}
    params = spatial.SpatialParameters(TIPTILT, doc)
    path, out = "stiffness_models.wire.K.4.4", "gain.piston.p1"
    res = spatial.sensitivities(params, [path], [out])
    inputs = np.array(list(res["input"].values()))

    def piston(k):
        lin = spatial_linear.linearize(_model(params, path, k), inputs, wrenches=False)
        return linear_response.gain_matrix(lin, ["piston"])[0, 0]

    assert res["gradient"][out][path] == pytest.approx(_central(piston, K[4, 4]), rel=1e-6)


def test_3d_refuses_what_it_cannot_differentiate_by_name():
    params = spatial.SpatialParameters(TIPTILT)
    with pytest.raises(ParameterError, match="bodies.platform.mass"):
        spatial.sensitivities(params, ["bodies.platform.mass"], ["gain"])
    with pytest.raises(ParameterError, match="repeated eigenvalue"):
        spatial.sensitivities(params, ["stiffness_models.leaf.thickness"], ["first_mode"])
    with pytest.raises(ParameterError, match="outputs in 3-D"):
        spatial.sensitivities(params, ["stiffness_models.leaf.thickness"], ["peak_stress"])


def _cli(*args) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "flexure_sim.cli", *args], cwd=ROOT,
                          capture_output=True, text=True, timeout=600)


def test_the_sensitivity_command_in_3d_prints_the_planar_gain_derivative():
    path = "stiffness_models.notch.h"
    p = _cli("sensitivity", "microstage", "--space", "3d", "--wrt", path, "--of", "gain",
             "--json")
    assert p.returncode == 0, p.stderr
    res = json.loads(p.stdout)
    assert res["space"] == "3d"
    two = planar.sensitivities(Parameters("microstage"), [path], ["gain"])
    assert res["gradient"]["gain"][path] == pytest.approx(two["gradient"]["gain"][path],
                                                          rel=1e-10)
    text = _cli("sensitivity", TIPTILT, "--wrt", "stiffness_models.wire.diameter", "--of",
                "gain.piston.p1")
    assert text.returncode == 0, text.stderr
    assert "gain.piston.p1 = " in text.stdout and "d/d stiffness_models.wire.diameter" in \
        text.stdout
    bad = _cli("sensitivity", TIPTILT, "--wrt", "bodies.platform.mass", "--of", "gain")
    assert bad.returncode == 2 and "Traceback" not in bad.stderr
    assert "bodies.platform.mass" in bad.stderr
