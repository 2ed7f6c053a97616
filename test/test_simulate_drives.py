"""
``flexure-sim simulate`` with one program per drive (issue 30 items 1-3), run as a subprocess.

Expected values from outside the command: the XY stage's design symmetry (the Y chain is the X
chain mirrored in y = x, so swapping the drives' inputs swaps the outputs x and y and turns the
platform the other way), the exact static gain matrix (``--static`` without inputs) for small
inputs, the lag's closed form u = c (1 - e^{-t/tau}), and static runs for settled dynamic ones.
"""
import json
import math
import subprocess
import sys

import numpy as np
import pytest
import yaml

from conftest import ROOT


def simulate(*args, ok=True):
    p = subprocess.run([sys.executable, "-m", "flexure_sim.cli", "simulate", *map(str, args)],
                       cwd=ROOT, capture_output=True, text=True, timeout=300)
    if ok:
        assert p.returncode == 0, p.stderr
    return p


def simulate_json(*args) -> dict:
    return json.loads(simulate(*args, "--json").stdout)


@pytest.mark.slow
def test_a_two_drive_static_run_gives_each_drives_force_and_each_output():
    """
    ``--drive x=step:1e-5 --drive y=ramp:4e-6:2e-3 --static``: the nonlinear equilibrium.

    Outputs x and y to 1e-4 of the exact gain matrix times the inputs (the stage is nearly
    linear at 10 um; its parasitic turn is not); mirrored inputs give mirrored outputs and drive
    forces to 1e-9.
    """
    out = simulate_json("xy_stage", "--drive", "x=step:1e-5", "--drive", "y=ramp:4e-6:2e-3",
                        "--static")
    gain = simulate_json("xy_stage", "--static")["gain_matrix"]
    assert gain["drives"] == ["x", "y"] and gain["outputs"] == ["x", "y", "theta"]
    x, y = out["drives"]["x"], out["drives"]["y"]
    assert (x["input"], y["input"]) == (1e-5, 4e-6)
    assert x["force"] > 1.0 and y["force"] > 1.0
    linear = np.array(gain["matrix"]) @ [1e-5, 4e-6]
    got = np.array([out["outputs"][k] for k in ("x", "y", "theta")])
    np.testing.assert_allclose(got[:2], linear[:2], rtol=1e-4)   # measured 2.5e-5, 4.2e-5
    assert got[2] == pytest.approx(linear[2], rel=0.2)   # the turn is 13 % nonlinear at 10 um
    assert out["hinge_stress"] and set(out["hinges"]) >= {"input_x", "input_y"}
    mirror = simulate_json("xy_stage", "--drive", "y=step:1e-5", "--drive", "x=step:4e-6",
                           "--static")
    assert mirror["outputs"]["y"] == pytest.approx(out["outputs"]["x"], rel=1e-9)
    assert mirror["outputs"]["x"] == pytest.approx(out["outputs"]["y"], rel=1e-9)
    assert mirror["outputs"]["theta"] == pytest.approx(-out["outputs"]["theta"], rel=1e-9)
    assert mirror["drives"]["y"]["force"] == pytest.approx(x["force"], rel=1e-9)


def test_a_two_drive_dynamic_run_follows_each_program():
    """
    Drive x steps to 10 um, y follows a 2 ms cycloid to 4 um; after 30 ms both have settled.

    The x drive's actuator output is c (1 - e^{-t/tau}) (tau 1 ms, exact); the outputs equal the
    static run's at the programs' final values to 1e-7; the outputs at 1, 2 and 5 ms rise.
    """
    out = simulate_json("xy_stage", "--drive", "x=step:1e-5", "--drive", "y=cycloid:4e-6:2e-3",
                        "--duration", "0.03")
    static = simulate_json("xy_stage", "--drive", "x=step:1e-5", "--drive", "y=step:4e-6",
                           "--static")
    assert out["mode"] == "dynamic" and out["t"] == pytest.approx(0.03)
    assert out["drives"]["x"]["input"] == pytest.approx(1e-5 * -math.expm1(-30.0), rel=1e-11)
    assert out["drives"]["y"]["command"] == 4e-6
    assert "cycloid" in out["drives"]["y"]["program"]
    for k in ("x", "y", "theta"):
        assert out["outputs"][k] == pytest.approx(static["outputs"][k], rel=1e-7)
    for d in ("x", "y"):
        assert out["drives"][d]["force"] == pytest.approx(static["drives"][d]["force"], rel=1e-7)
    rising = [out["outputs_at"][t]["x"] for t in ("0.001", "0.002", "0.005")]
    assert 0 < rising[0] < rising[1] < rising[2] < out["outputs"]["x"] * 1.01


def test_several_drives_without_inputs_say_what_to_give_instead_of_noise():
    """``--static`` of the XY stage alone: the gain matrix and the options, no rest tables."""
    table = simulate("xy_stage", "--static").stdout
    assert "static gain" in table and "--drive x=step:A --drive y=step:A" in table
    assert "hinge deflection, frame b" not in table
    assert "hinge stress:" not in table
    out = simulate_json("xy_stage", "--static")
    assert out["mode"] == "gain" and "hinges" not in out and out["drives"] == ["x", "y"]


@pytest.mark.parametrize("args, message", [
    (["--drive", "x=step:1e-5", "--drive", "x=step:1e-6"], "given twice"),
    (["--drive", "z=step:1e-5"], "no drive 'z'"),
    (["--drive", "x=sine:1e-6:100", "--static"], "no static value"),
    (["--drive", "x=ramp:1e-6"], "ramp:A:T"),
    (["--drive", "step:1e-6"], "has 2 drives"),
])
def test_a_drive_program_that_is_not_one_is_a_one_line_error(args, message):
    p = simulate("xy_stage", *args, ok=False)
    assert p.returncode == 2 and message in p.stderr and "Traceback" not in p.stderr


def _stage_file(tmp_path, response_time) -> str:
    doc = yaml.safe_load((ROOT / "config" / "microstage.yaml").read_text())
    doc["constraints"][1]["response_time"] = response_time
    doc["constraints"][1]["stroke"] = [0.0, 2.0e-5]  # the 15 um steps below: within the stroke
    path = tmp_path / f"stage_{response_time:g}.yaml"
    path.write_text(yaml.safe_dump(doc))
    return str(path)


def test_a_prescribed_drive_follows_its_cycloid_from_the_command_line(tmp_path):
    """
    ``response_time: 0``: the drive's displacement is the cycloid; settled, the static answer.

    After 30 ms the output equals the static output at 1.35 um to 1e-7; the input is the
    cycloid's end value exactly, and at 1 ms (half way) its output is below the end value.
    """
    path = _stage_file(tmp_path, 0)
    out = simulate_json(path, "--drive", "cycloid:1.35e-6:2e-3", "--duration", "0.03")
    static = simulate_json("microstage", "--drive", "step:1.35e-6", "--static")
    assert out["drives"]["drive"]["prescribed"] is True
    assert out["drives"]["drive"]["input"] == 1.35e-6
    assert out["output_displacement"] == pytest.approx(static["output_displacement"], rel=1e-7)
    assert 0 < out["output_at"]["0.001"] < out["output_displacement"]


@pytest.mark.slow
def test_a_lag_of_a_tenth_of_a_microsecond_steps_and_one_far_shorter_says_what_to_give(tmp_path):
    """A 15 um step through a 1e-7 s lag ran into "did not converge"; 1e-12 s names the fix."""
    fast = simulate_json(_stage_file(tmp_path, 1e-7), "--drive", "step:1.5e-5", "--duration",
                         "0.005")
    ideal = simulate_json(_stage_file(tmp_path, 0), "--drive", "step:1.5e-5", "--duration",
                          "0.005")
    assert fast["output_displacement"] == pytest.approx(ideal["output_displacement"], rel=1e-4)
    p = simulate(_stage_file(tmp_path, 1e-12), "--drive", "step:1.5e-5", ok=False)
    assert p.returncode == 2 and "response_time: 0" in p.stderr and "Traceback" not in p.stderr
