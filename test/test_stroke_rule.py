"""
One stroke rule for every analysis, as docs/analyses.md states it (subprocesses, as run).

A 15 um input on the stage's [0, 2 um] stroke is refused by simulate (static and dynamic),
modes, frf, linearize, sensitivity and sweep with the same line; the top of the stroke is
accepted; the page's example is what the command prints.
"""
from __future__ import annotations

import os
import re
import subprocess
import sys

import pytest
import yaml

from conftest import ROOT

#: Every test here runs the command line in subprocesses (seconds each).
pytestmark = pytest.mark.slow

REFUSAL = ("1.5e-05 m is outside the drive's stroke [0.0, 2e-06] m: the actuator cannot reach "
           "it (stage_node clamps a command there); to analyse a longer actuator, widen the "
           "drive's stroke in the mechanism file")
STUDY = {"mechanism": "microstage", "outputs": ["gain"],
         "parameters": [{"name": "h", "path": "stiffness_models.notch.h", "values": [2.5e-4]}]}
COMMANDS = {
    "simulate --static": ("simulate", "microstage", "--static", "--drive", "step:{u}"),
    "simulate": ("simulate", "microstage", "--duration", "0.002", "--drive", "step:{u}"),
    "modes": ("modes", "microstage", "--input", "{u}"),
    "frf": ("frf", "microstage", "--input", "{u}", "--points", "3", "-o", "frf"),
    "linearize": ("linearize", "microstage", "--input", "{u}", "-o", "m.npz"),
    "sensitivity": ("sensitivity", "microstage", "--wrt", "stiffness_models.notch.h", "--of",
                    "gain", "--input", "{u}"),
    "sweep": ("sweep", "study.yaml", "-o", "out.parquet", "--workers", "1", "--no-plots"),
}


def _cli(*args: str, cwd) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "flexure_sim.cli", *args], cwd=cwd,
                          capture_output=True, text=True, timeout=300,
                          env={**os.environ, "PYTHONPATH": str(ROOT), "MPLBACKEND": "Agg"})


def _run(name: str, u: str, cwd) -> subprocess.CompletedProcess:
    (cwd / "study.yaml").write_text(yaml.safe_dump({**STUDY, "input": float(u)}))
    return _cli(*(a.format(u=u) for a in COMMANDS[name]), cwd=cwd)


@pytest.mark.parametrize("name", sorted(COMMANDS))
def test_an_input_beyond_the_stroke_is_refused_alike_by_every_analysis(tmp_path, name):
    p = _run(name, "15e-6", tmp_path)
    assert p.returncode in (1, 2) and "Traceback" not in p.stderr, p.stderr
    (line,) = p.stderr.strip().splitlines()
    assert line.endswith(REFUSAL), line


@pytest.mark.parametrize("name", ["simulate --static", "modes", "sensitivity", "sweep"])
def test_the_top_of_the_stroke_is_accepted(tmp_path, name):
    p = _run(name, "2e-6", tmp_path)
    assert p.returncode == 0, p.stderr


def test_the_documented_example_is_what_modes_prints(tmp_path):
    page = (ROOT / "docs" / "analyses.md").read_text(encoding="utf-8")
    section = page.split("## Drive inputs and the stroke")[1].split("\n## ")[0]
    command, printed = re.search(r"\n\$ (flexure-sim .+)\n(.+)\n", section).groups()
    p = _cli(*command.split()[1:], cwd=tmp_path)
    assert p.stderr == printed + "\n"
    assert printed.endswith(REFUSAL)
    for name in ("`simulate`", "`modes`", "`frf`", "`linearize`", "`sensitivity`", "`sweep`"):
        assert name in section


def test_an_input_far_beyond_the_stroke_is_named_as_such_not_as_a_stiffness_failure(tmp_path):
    p = _cli("modes", "microstage", "--input", "1.0", cwd=tmp_path)
    assert p.returncode == 2
    assert "1.0 m is outside the drive's stroke [0.0, 2e-06] m" in p.stderr
    assert "positive definite" not in p.stderr


def test_several_drives_name_the_drive_beyond_its_stroke(tmp_path):
    p = _cli("sensitivity", "xy_stage", "--wrt", "stiffness_models.notch.h", "--of", "gain",
             "--input", "x=1e-5,y=4e-5", cwd=tmp_path)
    assert p.returncode == 2
    assert "--input 'x=1e-5,y=4e-5': 4e-05 m is outside drive y's stroke [0.0, 1.5e-05] m" \
        in p.stderr


def test_the_stroke_limit_of_a_two_drive_stage_says_why_it_has_none(tmp_path):
    p = _cli("simulate", "xy_stage", "--stroke-limit", cwd=tmp_path)
    assert p.returncode == 2
    assert p.stderr == ("flexure-sim: error: --stroke-limit: mechanism 'xy_stage' has 2 drives "
                        "(x, y): the stroke limit is the input of a single displacement drive "
                        "at which the first hinge yields\n")
