"""
``flexure-sim hinge`` end to end, and Chapter 7 from finite elements: samples, fit, mechanism.

Real subcommands through ``flexure_sim.cli.main``; the fitted law is loaded by a mechanism
and solved. The fitted stiffness at rest is checked against the linear finite-element
stiffness (a different solve: large-deflection samples and least squares against one linear
solve).
"""

import json
from pathlib import Path

import numpy as np
import pytest

from flexure_sim.cli import main
from flexure_sim.engine.hinges.fe import model
from flexure_sim.engine.mechanism.loader import mechanism_from_dict
from flexure_sim.engine.mechanism.polynomial_files import load_law
from flexure_sim.engine.solver.simulation import Simulation
from reference_figures import NOTCH_KO

STAGE_HINGE = ["D=3e-3", "h=0.25e-3", "t=0.02", "E=69e9", "nu=0.33"]


@pytest.fixture(autouse=True)
def fresh_cache(tmp_path_factory, monkeypatch):
    """Give the module a cache directory of its own."""
    monkeypatch.setenv("FLEXURE_SIM_CACHE", str(tmp_path_factory.getbasetemp() / "fe_cli"))


def _json(capsys, argv):
    assert main(argv) == 0
    return json.loads(capsys.readouterr().out)


def test_hinge_prints_the_fe_stiffness_next_to_the_closed_forms(capsys):
    out = _json(capsys, ["hinge", "circular", *STAGE_HINGE, "--json"])
    assert out["plane"] == "strain"  # t = 20 mm >= D = 3 mm
    K = model.stiffness("circular", {"D": 3e-3, "h": 0.25e-3, "t": 0.02}, 69e9, 0.33, "strain")
    assert out["fe"]["diag"] == pytest.approx(np.diag(K).tolist(), rel=1e-12)
    f = out["formulas"]
    assert set(f) == {"dissertation", "paros_weisbord", "beam", "timoshenko"}
    assert f["dissertation"]["diag"][0] == pytest.approx(NOTCH_KO, abs=1e-4)
    for formula in f.values():
        for value, diff, fe in zip(formula["diag"], formula["difference"], out["fe"]["diag"]):
            if value is not None:
                assert diff == pytest.approx(value / fe - 1, rel=1e-12)
    assert f["paros_weisbord"]["diag"][2] is None  # no shear formula
    # The same hinge from the stage's mechanism file.
    same = _json(capsys, ["hinge", "--from", "microstage:notch", "--json"])
    assert same["fe"]["diag"] == out["fe"]["diag"]
    # ... and from the FE stage's, whose model names its material (E, nu given, strengths unused)
    fe_stage = Path(__file__).resolve().parents[1] / "config/examples/microstage_fe.yaml"
    same = _json(capsys, ["hinge", "--from", f"{fe_stage}:notch", "--json"])
    assert same["fe"]["diag"] == out["fe"]["diag"]
    # The table.
    assert main(["hinge", "--from", "microstage:notch", "--plane", "stress"]) == 0
    text = capsys.readouterr().out
    assert "FE, plane stress" in text and "dissertation" in text and "(-" in text


@pytest.mark.parametrize("argv, message", [
    (["hinge", "circular", "D=abc"], "D: expected a number, got 'abc'"),
    (["hinge", "circular", "D=3e-3", "t=0.02", "E=69e9", "nu=0.33"], "hinge.h: missing"),
    (["hinge", "circular", *STAGE_HINGE, "x=1"], "hinge.x: unknown key"),
    (["hinge", "--from", "microstage:nope"], "stiffness_models.nope: no such stiffness model"),
    (["hinge", "--from", "microstage"], "expected MECHANISM:MODEL"),
    (["hinge"], "give a shape with its values"),
    (["hinge", "circular", *STAGE_HINGE, "--samples", "3"], "--samples N needs"),
    (["hinge", "circular", *STAGE_HINGE, "--resolution", "1"], "hinge.resolution"),
])
def test_bad_input_is_one_line_and_exit_2(capsys, argv, message):
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err


def test_pictures_of_mesh_and_stress(tmp_path, capsys):
    assert main(["hinge", "circular", *STAGE_HINGE, "--resolution", "4", "--plot",
                 str(tmp_path)]) == 0
    for name in ("circular_mesh.png", "circular_stress.png"):
        assert (tmp_path / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.mark.slow
def test_chapter_7_from_finite_elements_samples_fit_and_a_mechanism(tmp_path, capsys):
    # A leaf (10 x 1 x 5 mm, E 3.45 GPa: the four-bar's) bent up to 0.05 rad: 40 large-
    # deflection samples -> flexure-sim fit (order 4, twistor) -> a one-hinge mechanism with
    # the fitted law. The law's stiffness at rest is the linear finite-element stiffness.
    data, law = tmp_path / "leaf.csv", tmp_path / "leaf.yaml"
    leaf = ["length=0.01", "thickness=1e-3", "width=5e-3", "E=3.45e9", "nu=0.3"]
    out = _json(capsys, ["hinge", "leaf", *leaf, "--resolution", "6", "--samples", "40",
                         "--alpha-max", "0.05", "--seed", "2", "-o", str(data), "--json"])
    assert out["samples"]["rows"] == 40
    assert main(["fit", str(data), "--order", "4", "-o", str(law), "--json"]) == 0
    fit = json.loads(capsys.readouterr().out)
    assert fit["train_max_rel"] < 0.05
    K = model.stiffness("leaf", {"length": 0.01, "thickness": 1e-3, "width": 5e-3,
                                 "fillet": 0.0}, 3.45e9, 0.3, n=6)
    fitted = load_law(law).stiffness_at_rest()
    assert np.diag(fitted) == pytest.approx(np.diag(K), rel=0.02)
    mech = mechanism_from_dict({
        "name": "leaf_on_ground",
        "defaults": {"law": "twistor", "damping": {"t_char": 1e-3}},
        "bodies": [{"name": "ground", "mass": 1.0, "inertia": 1.0, "pose": [0, 0, 0]},
                   {"name": "tip", "mass": 1e-3, "inertia": 1e-7, "pose": [0, 0.01, 0]}],
        "hinges": [{"name": "A", "a": {"body": "ground", "at": [0, 0.005]},
                    "b": {"body": "tip", "at": [0, -0.005]},
                    "law": {"polynomial": str(law)}}],
        "constraints": [{"type": "fixed", "body": "ground"},
                        {"type": "drive", "body": "tip", "axis": [1.0, 0.0],
                         "response_time": 1e-3, "stroke": [-1e-4, 1e-4], "slew_rate": 0.01}],
        "output": {"body": "tip", "axis": [1.0, 0.0]},
    }, source=str(tmp_path / "leaf_on_ground.yaml"))
    snap = Simulation(mech).static(1e-5).snapshot
    assert abs(snap.output - 1e-5) < 1e-12  # the driven tip is where the drive puts it
