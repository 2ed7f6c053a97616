"""
`flexure-sim frf` at one frequency and at a list of them, and the refusals of `frf`/`modes`.

Run as a user runs them (subprocesses). The response is checked against a second method: the
first-order state space that `flexure-sim linearize` exports, G(s) = C (sI - A)^-1 B + D
solved with NumPy at s = 2 pi i f (frf solves the second-order form, a 12 x 12 system).
"""
from __future__ import annotations

import csv
import os
import subprocess
import sys

import numpy as np
import pytest

from conftest import ROOT

#: Every test here runs the command line in subprocesses (seconds each).
pytestmark = pytest.mark.slow


def _cli(*args: str, cwd) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "flexure_sim.cli", *map(str, args)], cwd=cwd,
                          capture_output=True, text=True, timeout=300,
                          env={**os.environ, "PYTHONPATH": str(ROOT), "MPLBACKEND": "Agg"})


@pytest.fixture(scope="module")
def state_space(tmp_path_factory):
    """Return the stage's exported model at 1.35 um: (A, B, C, D, output names)."""
    work = tmp_path_factory.mktemp("ss")
    p = _cli("linearize", "microstage", "--input", "1.35e-6", "-o", "m.npz", cwd=work)
    assert p.returncode == 0, p.stderr
    m = np.load(work / "m.npz")
    return m["A"], m["B"], m["C"], m["D"], list(m["output_names"])


def _expected(state_space, f: float) -> complex:
    A, B, C, D, names = state_space
    k = names.index("output")
    s = 2j * np.pi * f
    return (C[k] @ np.linalg.solve(s * np.eye(len(A)) - A, B[:, 0]) + D[k, 0])


def _rows(path) -> list[dict]:
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def test_one_frequency(tmp_path, state_space):
    p = _cli("frf", "microstage", "--input", "1.35e-6", "--fmin", "200", "--fmax", "200",
             "--points", "1", "--csv", "-o", "one", cwd=tmp_path)
    assert p.returncode == 0 and p.stderr == "", p.stderr
    (row,) = _rows(tmp_path / "one" / "frf.csv")
    g = complex(float(row["output.real"]), float(row["output.imag"]))
    assert float(row["frequency_hz"]) == 200.0
    assert g == pytest.approx(_expected(state_space, 200.0), rel=1e-9)
    assert f"200 Hz: |G| {abs(g):.6g}, phase" in p.stdout
    assert (tmp_path / "one" / "frf.png").stat().st_size > 10_000


def test_a_list_of_frequencies_in_ascending_order(tmp_path, state_space):
    p = _cli("frf", "microstage", "--input", "1.35e-6", "--frequencies", "900,40,300.6",
             "--csv", "-o", "list", cwd=tmp_path)
    assert p.returncode == 0 and p.stderr == "", p.stderr
    rows = _rows(tmp_path / "list" / "frf.csv")
    assert [float(r["frequency_hz"]) for r in rows] == [40.0, 300.6, 900.0]
    for r in rows:
        g = complex(float(r["output.real"]), float(r["output.imag"]))
        assert g == pytest.approx(_expected(state_space, float(r["frequency_hz"])), rel=1e-9)
    lines = [line.strip() for line in p.stdout.splitlines()]
    assert [line.split(" Hz:")[0] for line in lines if " Hz: |G| " in line] == \
        ["40", "300.6", "900"]


@pytest.mark.parametrize("args, message", [
    (("frf", "--fmax", "inf"), "--fmax inf: must be a positive, finite frequency (Hz)"),
    (("frf", "--fmin", "nan"), "--fmin nan: must be a positive, finite frequency (Hz)"),
    (("frf", "--fmin", "0"), "--fmin 0.0: must be a positive, finite frequency (Hz)"),
    (("frf", "--fmin", "300", "--fmax", "200"), "--fmin 300 Hz is above --fmax 200 Hz"),
    (("frf", "--fmin", "200", "--fmax", "200"), "one frequency is --fmin F --fmax F --points 1"),
    (("frf", "--fmin", "100", "--fmax", "200", "--points", "1"),
     "one frequency is --fmin F --fmax F --points 1"),
    (("frf", "--points", "0"), "argument --points: '0': expected a positive integer"),
    (("frf", "--frequencies", "40,x"), "--frequencies '40,x': 'x' is not a number"),
    (("frf", "--frequencies", "40,-1"), "'-1' is not a positive, finite frequency (Hz)"),
    (("frf", "--frequencies", "40", "--points", "3"), "give it without --fmin, --fmax and"),
    (("modes", "--count", "0"), "argument --count: '0': expected a positive integer"),
])
def test_nonsense_is_refused_in_one_line(tmp_path, args, message):
    p = _cli(args[0], "microstage", *args[1:], "-o", "out", cwd=tmp_path)
    assert p.returncode == 2, p.stdout
    assert message in p.stderr and "Traceback" not in p.stderr and "Warning" not in p.stderr
    assert not (tmp_path / "out").exists()


def test_a_drive_given_twice_is_refused_by_name(tmp_path):
    p = _cli("modes", "xy_stage", "--input", "x=1e-6,x=2e-6", cwd=tmp_path)
    assert p.returncode == 2
    assert p.stderr == ("flexure-sim modes: error: --input 'x=1e-6,x=2e-6': drive x is given "
                        "twice\n")
