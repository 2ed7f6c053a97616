"""The offline command, run as a real subprocess."""
import json
import subprocess
import sys

import pytest

from conftest import ROOT
from reference_figures import JOINT_A_COMPRESSION, STAGE_GAIN, STAGE_INPUT


def run(*args):
    return subprocess.run(
        [sys.executable, "-m", "flexure_sim.cli", *args],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=300,
    )


def test_static_json():
    p = run("simulate", "microstage", "--drive", "step:1.35e-6", "--static", "--json")
    assert p.returncode == 0, p.stderr
    out = json.loads(p.stdout)
    assert out["gain"] == pytest.approx(STAGE_GAIN, rel=1e-3)
    assert out["output_displacement"] == pytest.approx(STAGE_GAIN * STAGE_INPUT, rel=1e-3)
    assert out["joint_a_compression"] == pytest.approx(JOINT_A_COMPRESSION, rel=1e-3)
    assert set(out["hinges"]) == set("abcdefg")
    assert out["wall_s"] > 0


def test_dynamic_json_reports_samples_and_wall_time():
    p = run("simulate", "microstage", "--drive", "step:1.35e-6", "--duration", "0.01", "--json")
    assert p.returncode == 0, p.stderr
    out = json.loads(p.stdout)
    assert out["mode"] == "dynamic" and out["steps"] == 100
    assert set(out["output_at"]) == {"0.001", "0.002", "0.005"}
    assert out["output_at"]["0.001"] < out["output_at"]["0.005"]
    assert out["wall_s"] > 0 and out["real_time_factor"] > 0


def test_mechanism_without_drive_reports_hinge_deflections():
    p = run("simulate", "fourbar_cantilever", "--duration", "0.02", "--json")
    assert p.returncode == 0, p.stderr
    out = json.loads(p.stdout)
    assert out["gain"] is None and out["joint_a_compression"] is None
    assert set(out["hinges"]) == set("ABCD")
    assert abs(out["hinges"]["A"]["rotation"]) > 0.01


def test_table_output_and_errors(tmp_path):
    p = run("simulate", "microstage", "--drive", "step:1.35e-6", "--static")
    assert p.returncode == 0 and "gain:" in p.stdout and f"{STAGE_GAIN:.1f}" in p.stdout
    bad = tmp_path / "broken.yaml"
    bad.write_text("name: x\nbodies: []\n")
    p = run("simulate", str(bad))
    assert p.returncode == 2
    assert "broken.yaml" in p.stderr and "bodies" in p.stderr and "Traceback" not in p.stderr
    p = run("simulate", "microstage", "--drive", "ramp:1")
    assert p.returncode == 2 and "--drive" in p.stderr
