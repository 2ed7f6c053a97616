"""``flexure-sim simulate | modes | frf | linearize`` on 3-D mechanisms, as real subprocesses."""
import csv
import json
import re
import subprocess
import sys

import numpy as np
import pytest

from conftest import ROOT

pytestmark = pytest.mark.slow


def run(*args):
    return subprocess.run([sys.executable, "-m", "flexure_sim.cli", *args], cwd=ROOT,
                          capture_output=True, text=True, timeout=600)


def test_planar_stage_in_3d_static_equals_the_planar_command():
    planar = run("simulate", "microstage", "--drive", "step:1.35e-6", "--static", "--json")
    spatial = run("simulate", "microstage", "--space", "3d", "--drive", "step:1.35e-6",
                  "--static", "--json")
    assert planar.returncode == 0 and spatial.returncode == 0, spatial.stderr
    p, s = json.loads(planar.stdout), json.loads(spatial.stdout)
    assert s["outputs"]["output"] == pytest.approx(p["output_displacement"], rel=1e-11)
    assert s["gain_matrix"]["matrix"][0][0] == pytest.approx(p["gain"], rel=1e-3)
    k = s["body_stiffness"]["body4"]
    # z: far below the platform on its own two hinges (2 k_z = 1.58e8 N/m), the levers give
    assert 0 < k[2] < 1.58e8
    for name, hinge in s["hinges"].items():
        assert hinge["rotation"][:2] == [0.0, 0.0] and hinge["position"][2] == 0.0


def test_modes_of_the_planar_stage_in_3d_contain_the_planar_modes():
    planar = run("modes", "microstage", "--json")
    spatial = run("modes", "microstage", "--space", "3d", "--json")
    assert spatial.returncode == 0, spatial.stderr
    f2 = np.array(json.loads(planar.stdout)["undamped_frequencies_hz"])
    out = json.loads(spatial.stdout)
    f3 = np.array(out["undamped_frequencies_hz"])
    shares = np.array(out["out_of_plane_shares"])
    assert len(f3) == 24 and len(f2) == 12
    for f in f2:
        k = np.argmin(np.abs(f3 - f))
        assert abs(f3[k] - f) <= 1e-9 * f and shares[k] < 1e-12
    assert np.sum(shares > 1 - 1e-12) == 12


def test_tiptilt_static_gain_frf_and_linear_model(tmp_path):
    static = run("simulate", "tiptilt_stage", "--static", "--json")
    assert static.returncode == 0, static.stderr
    g = json.loads(static.stdout)["gain_matrix"]
    assert g["outputs"] == ["tip", "tilt", "piston"] and g["drives"] == ["p1", "p2", "p3"]
    frf = run("frf", "tiptilt_stage", "--from", "p1", "--to", "tip", "--fmin", "0.1",
              "--fmax", "1e4", "--points", "50", "--csv", "-o", str(tmp_path))
    assert frf.returncode == 0, frf.stderr
    rows = list(csv.reader((tmp_path / "frf.csv").open()))
    first = dict(zip(rows[0], rows[1]))
    magnitude = [float(v) for k, v in first.items() if k.startswith("tip") and "mag" in k][0]
    assert magnitude == pytest.approx(g["matrix"][0][0], rel=1e-6)
    lin = run("linearize", "tiptilt_stage", "-o", str(tmp_path / "model.json"))
    assert lin.returncode == 0, lin.stderr
    model = json.loads((tmp_path / "model.json").read_text())
    assert model["input_names"] == ["p1", "p2", "p3"]
    assert "hinges.wire1.force_y" in model["output_names"]


def test_tiptilt_step_response_settles_at_the_static_output():
    static = json.loads(run("simulate", "tiptilt_stage", "--drive", "step:p1=1e-5,p2=0,p3=0",
                            "--static", "--json").stdout)
    dyn = run("simulate", "tiptilt_stage", "--drive", "step:p1=1e-5,p2=0,p3=0", "--duration",
              "0.02", "--json")
    assert dyn.returncode == 0, dyn.stderr
    out = json.loads(dyn.stdout)
    assert out["outputs"]["tip"] == pytest.approx(static["outputs"]["tip"], rel=1e-6)
    assert set(out["output_at"]) == {"0.001", "0.002", "0.005"}


@pytest.mark.parametrize("args, message", [
    (("simulate", "tiptilt_stage", "--space", "2d"), "--space 2d: .* is a 3-D mechanism"),
    (("simulate", "tiptilt_stage", "--drive", "step:p1=1e-5"), r"missing \['p2', 'p3'\]"),
    (("modes", "microstage", "--space", "3d", "-o", "plots"),
     "-o: mode-shape plots are drawn for planar mechanisms only"),
    (("simulate", "fourbar_cantilever", "--space", "3d"), r"constraints\[1\]: a sine_rate"),
])
def test_errors_are_one_line(args, message):
    p = run(*args)
    assert p.returncode == 2
    assert "Traceback" not in p.stderr
    assert re.search(message, p.stderr), p.stderr


def test_the_planar_engine_names_a_3d_file():
    p = run("simulate", "tiptilt_stage", "--space", "2d")
    assert "3-D mechanism" in p.stderr
    from flexure_sim.engine.mechanism.loader import ConfigError, load_mechanism
    with pytest.raises(ConfigError, match="space: a 3-D mechanism: the planar engine"):
        load_mechanism("tiptilt_stage")


def test_drives_stepped_one_by_one_as_for_planar_mechanisms():
    """``--drive NAME=step:V`` once per drive (others at 0) is the one-spec form's equilibrium."""
    from flexure_sim.engine.mechanism.spatial_loader import load_spatial
    from flexure_sim.engine.solver.spatial_simulation import SpatialSimulation

    per_drive = run("simulate", "tiptilt_stage", "--drive", "p1=step:2e-6", "--drive",
                    "p3=step:-1e-6", "--static", "--json")
    assert per_drive.returncode == 0, per_drive.stderr
    got = json.loads(per_drive.stdout)
    snap = SpatialSimulation(load_spatial("tiptilt_stage")).static_snapshot(
        np.array([2e-6, 0.0, -1e-6]))
    assert {n: d["input"] for n, d in got["drives"].items()} == {"p1": 2e-6, "p2": 0.0,
                                                                 "p3": -1e-6}
    for name, value in snap.outputs.items():
        assert got["outputs"][name] == pytest.approx(value, rel=1e-9, abs=1e-15)
    bad = run("simulate", "tiptilt_stage", "--drive", "p1=sine:1e-6:100", "--static")
    assert bad.returncode == 2 and "Traceback" not in bad.stderr
    assert "a 3-D run steps its drives" in bad.stderr
