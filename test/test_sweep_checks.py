"""
`flexure-sim sweep` as a user meets it (a subprocess): refusals and plots.

Outputs without a value, the scheduler address, and the plots of a study with one parameter
and many outputs.

Outputs that would be NaN in every design are refused at load with the reason (issue 31
item 5), an address that is not one is one line (item 7), and the plots come without
matplotlib's "Tight layout not applied" (issue 30 item 9).
"""
from __future__ import annotations

import os
import subprocess
import sys

import pytest
import yaml

from conftest import ROOT

#: Every test here runs the command line in subprocesses (seconds each).
pytestmark = pytest.mark.slow

H = {"name": "h", "path": "stiffness_models.notch.h", "values": [2.0e-4, 2.5e-4]}


def _sweep(tmp_path, doc: dict, *args: str) -> subprocess.CompletedProcess:
    study = tmp_path / "s.yaml"
    study.write_text(yaml.safe_dump(doc))
    return subprocess.run(
        [sys.executable, "-m", "flexure_sim.cli", "sweep", study.name, "-o",
         str(tmp_path / "out.parquet"), *args], cwd=tmp_path, capture_output=True, text=True,
        timeout=300, env={**os.environ, "PYTHONPATH": str(ROOT), "MPLBACKEND": "Agg"})


def _refused(p: subprocess.CompletedProcess) -> str:
    assert p.returncode == 1 and "Traceback" not in p.stderr, p.stderr
    (line,) = p.stderr.strip().splitlines()
    return line


def test_compression_of_a_mechanism_without_a_compression_hinge_is_refused_at_load(tmp_path):
    doc = {"mechanism": "xy_stage", "input": {"x": 1e-5, "y": 0.0},
           "outputs": ["gain", "compression"],
           "parameters": [{"name": "h", "path": "stiffness_models.notch.h",
                           "values": [2.5e-4]}]}
    line = _refused(_sweep(tmp_path, doc))
    assert line == ("flexure-sim sweep: error: s.yaml: outputs: compression: 'xy_stage' names "
                    "no compression_hinge (the hinge whose compression is measured, a key of "
                    "the mechanism file)")
    assert not (tmp_path / "out.parquet").exists()


def test_a_ratio_or_a_step_at_a_zero_input_is_refused_at_load(tmp_path):
    for output, why in (("gain", "gain = output / input is 0 / 0"),
                        ("settling_time", "a step from 0 to 0 has no settling time")):
        doc = {"mechanism": "microstage", "input": 0.0, "outputs": ["drive_force", output],
               "parameters": [H]}
        line = _refused(_sweep(tmp_path, doc))
        assert line.startswith("flexure-sim sweep: error: s.yaml: input: every drive input "
                               f"is 0 and the outputs ask for {output}: {why}"), line
    # At 0 the static outputs that have a value are fine: the force is 0 at rest.
    doc = {"mechanism": "microstage", "input": 0.0, "outputs": ["drive_force"],
           "parameters": [H]}
    p = _sweep(tmp_path, doc, "--workers", "1", "--no-plots", "--json")
    assert p.returncode == 0, p.stderr


def test_a_scheduler_address_that_is_not_one_is_one_line_and_writes_nothing(tmp_path):
    doc = {"mechanism": "microstage", "input": 1e-6, "outputs": ["gain"], "parameters": [H]}
    p = _sweep(tmp_path, doc, "--scheduler", "not a url")
    assert p.returncode == 2 and "Traceback" not in p.stderr, p.stderr
    (line,) = p.stderr.strip().splitlines()
    assert line.startswith("flexure-sim sweep: error: --scheduler 'not a url': not a "
                           "scheduler address ("), line
    assert line.endswith("expected e.g. tcp://HOST:8786"), line
    assert sorted(f.name for f in tmp_path.iterdir()) == ["s.yaml"]


def test_plots_of_one_parameter_and_many_outputs_come_without_a_layout_warning(tmp_path):
    """One bar per output left no room for the titles: 'Tight layout not applied'."""
    doc = {"mechanism": "microstage", "input": 1.35e-6, "parameters": [H],
           "outputs": ["gain", "compression", "drive_force", "first_mode",
                       "first_mode_damping", "peak_stress_ratio"]}
    p = _sweep(tmp_path, doc, "--workers", "1")
    assert p.returncode == 0, p.stderr
    # stderr holds the progress lines and nothing else
    assert all(line.startswith("flexure-sim sweep: ") for line in p.stderr.splitlines()), \
        p.stderr
    for what in ("tornado", "histograms"):
        assert (tmp_path / f"out_{what}.png").stat().st_size > 10_000
