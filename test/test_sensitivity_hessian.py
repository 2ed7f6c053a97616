"""
The full Hessian of ``flexure-sim sensitivity``: every entry exact, from one hyper-dual evaluation.

The off-diagonal entries are checked against central differences of the exact first
derivatives of re-solved mechanisms (the first derivatives at shifted parameters: an
independent route to the mixed derivative), the diagonal against the one-parameter runs.
"""
from __future__ import annotations

import copy
import json
import subprocess
import sys

import numpy as np
import pytest

from conftest import ROOT
from flexure_sim.engine.analysis.sensitivity import sensitivities
from flexure_sim.engine.mechanism.parameters import Parameters

U = 1.35e-6
#: The stage's seven hinge neck thicknesses, each hinge's own copy of the notch model.
NECKS = [f"hinges.{h}.stiffness.h" for h in "abcdefg"]
OUTPUTS = ["gain", "compression", "first_mode"]


def _cli(*args) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "flexure_sim.cli", *args], cwd=ROOT,
                          capture_output=True, text=True, timeout=600)


@pytest.fixture(scope="module")
def stage():
    return Parameters("microstage")


@pytest.fixture(scope="module")
def hessian7():
    """``flexure-sim sensitivity microstage --wrt <7 necks> --json``, as a user runs it."""
    p = _cli("sensitivity", "microstage", "--wrt", ",".join(NECKS), "--of", ",".join(OUTPUTS),
             "--input", str(U), "--json")
    assert p.returncode == 0, p.stderr
    return json.loads(p.stdout)


def _with_neck(stage, hinge: str, h: float) -> Parameters:
    """Return the stage with one hinge's own notch neck h, edited in the document by hand."""
    data = copy.deepcopy(stage.data)
    entry = next(e for e in data["hinges"] if e["name"] == hinge)
    entry["stiffness"] = dict(data["stiffness_models"][entry["stiffness"]], h=h)
    return Parameters("microstage", data=data)


def test_the_stages_7x7_hessian_is_symmetric_and_its_diagonal_is_each_parameters_own(
        stage, hessian7):
    for o in OUTPUTS:
        H = np.array(hessian7["hessian"][o])
        assert H.shape == (7, 7)
        assert np.array_equal(H, H.T)
        for i, p in enumerate(NECKS):
            assert hessian7["second"][o][f"{p}|{p}"] == H[i, i]
            for j, q in enumerate(NECKS[i + 1:], i + 1):
                assert hessian7["second"][o][f"{p}|{q}"] == H[i, j]
    for i, p in enumerate(NECKS):  # the one-parameter run: the same evaluation, the same bits
        alone = sensitivities(stage, [p], OUTPUTS, U)
        for o in OUTPUTS:
            assert hessian7["hessian"][o][i][i] == alone["second"][o][f"{p}|{p}"]
            assert hessian7["gradient"][o][p] == alone["gradient"][o][p]


def test_the_off_diagonal_entries_are_differences_of_the_first_derivatives(stage, hessian7):
    """
    d/dh_j of the exact gradient, by central differences in h_j (Richardson, steps 2 and 1 %).

    The gradients at shifted necks come from re-solved mechanisms (a new static equilibrium and
    first mode for each); measured agreement <= 1e-8 of the column's largest entry.
    """
    h0 = stage.value(NECKS[0])
    for j, q in enumerate(NECKS):
        hinge = q.split(".")[1]

        def grad(h):
            res = sensitivities(_with_neck(stage, hinge, h), NECKS, OUTPUTS, U)
            return np.array([[res["gradient"][o][p] for p in NECKS] for o in OUTPUTS])

        d = 2e-2 * h0
        coarse = (grad(h0 + d) - grad(h0 - d)) / (2 * d)
        fine = (grad(h0 + d / 2) - grad(h0 - d / 2)) / d
        fd = (4 * fine - coarse) / 3  # (n_outputs, 7): column j of each Hessian
        for k, o in enumerate(OUTPUTS):
            H = np.array(hessian7["hessian"][o])
            off = [i for i in range(7) if i != j]
            np.testing.assert_allclose(H[off, j], fd[k, off], rtol=0,
                                       atol=1e-6 * np.abs(H[:, j]).max(), err_msg=f"{o}, {q}")


def test_the_text_table_is_the_json_hessian(hessian7):
    p = _cli("sensitivity", "microstage", "--wrt", ",".join(NECKS), "--of", "gain",
             "--input", str(U))
    assert p.returncode == 0, p.stderr
    lines = p.stdout.splitlines()
    for k, path in enumerate(NECKS, 1):
        assert any(line.startswith(f"parameter {k}: {path} = ") for line in lines)
    rows = [line.split() for line in lines if line.strip().startswith("i=")]
    assert [r[0] for r in rows] == [f"i={i}" for i in range(1, 8)]
    table = np.array([[float(x) for x in r[1:]] for r in rows])
    np.testing.assert_allclose(table, hessian7["hessian"]["gain"], rtol=1e-9)


def test_a_shared_models_number_and_one_hinges_copy_of_it_mix_as_the_physics_does(stage):
    """
    d2 gain / d(notch h) d(hinge a's own D): hinge a's copy of the notch model follows its h.

    Against central differences in h of the exact d gain / d D_a of re-solved mechanisms.
    """
    h_path, d_path = "stiffness_models.notch.h", "hinges.a.stiffness.D"
    exact = sensitivities(stage, [h_path, d_path], ["gain"], U)["second"]["gain"]
    h0 = stage.value(h_path)

    def grad(h):
        data = copy.deepcopy(stage.data)
        data["stiffness_models"]["notch"]["h"] = h
        return sensitivities(Parameters("microstage", data=data), [d_path], ["gain"],
                             U)["gradient"]["gain"][d_path]

    d = 1e-2 * h0
    fd = (4 * (grad(h0 + d / 2) - grad(h0 - d / 2)) / d
          - (grad(h0 + d) - grad(h0 - d)) / (2 * d)) / 3
    assert exact[f"{h_path}|{d_path}"] == pytest.approx(fd, rel=1e-6)
