"""``flexure-sim piezo-loop`` run as a real subprocess: the PNG and the printed loop width."""
import json
import math
import re
import subprocess
import sys

import pytest
import yaml

from conftest import ROOT

EXAMPLE = ROOT / "config" / "examples" / "piezo_stage.yaml"


def run(*args):
    return subprocess.run([sys.executable, "-m", "flexure_sim.cli", "piezo-loop", *args],
                          cwd=ROOT, capture_output=True, text=True, timeout=300)


@pytest.mark.slow
def test_loop_width_printed_equals_the_analytic_loop_and_the_png_is_written(tmp_path):
    doc = yaml.safe_load(EXAMPLE.read_text())
    block = doc["constraints"][1]["actuator"]
    block.pop("creep"), block.pop("bandwidth")  # hysteresis and the stack alone
    block["hysteresis"] = {"alpha": 0.3, "beta": 0.03, "gamma": 0.0}
    path = tmp_path / "stage.yaml"
    path.write_text(yaml.safe_dump(doc))
    png = tmp_path / "figs" / "loop.png"
    p = run(str(path), "-o", str(png), "--frequency", "2", "--json")
    assert p.returncode == 0, p.stderr
    out = json.loads(p.stdout)
    # independent figures: the guide's beam stiffness, the series springs, and the gamma = 0
    # Bouc-Wen loop (dh/dV = a - beta sgn(dV) h: half-width (a/beta)(1 - sech(beta A)))
    E, w, t, L = 69.0e9, 0.010, 0.001, 0.015
    k_L = 2 * 12 * E * (w * t**3 / 12) / L**3
    k_s, d, A = 5.0e7, 1.5e-5 / 100.0, 50.0
    analytic = 2 * 0.3 * d / 0.03 * (1 - 1 / math.cosh(0.03 * A)) * k_s / (k_s + k_L)
    assert out["load_stiffness"] == pytest.approx(k_L, rel=1e-9)
    assert out["loop_width_analytic"] == pytest.approx(analytic, rel=1e-9)
    assert out["loop_width"] == pytest.approx(analytic, rel=0.02)
    assert out["plot"] == str(png)
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png.stat().st_size > 10_000

    table = run(str(path), "-o", str(png), "--frequency", "2")
    assert table.returncode == 0, table.stderr
    assert f"loop width at 50 V: {out['loop_width']:.6g} m" in table.stdout
    assert f"steady Bouc-Wen loop (analytic): {analytic:.6g} m" in table.stdout


def test_loop_of_the_shipped_example_and_bad_input(tmp_path):
    p = run(str(EXAMPLE), "-o", str(tmp_path / "loop.png"), "--cycles", "2", "--points", "400",
            "--json")
    assert p.returncode == 0, p.stderr
    out = json.loads(p.stdout)
    assert 0.10 < out["loop_width_fraction"] < 0.15  # creep widens the 11 % Bouc-Wen loop
    for args, message in (
        (["microstage"], "needs exactly one drive with an actuator: block"),
        ([str(EXAMPLE), "--load", "-1"], "--load -1.0: must be a stiffness >= 0 N/m"),
    ):
        bad = run(*args, "-o", str(tmp_path / "bad.png"))
        assert bad.returncode == 2 and bad.stdout == ""
        assert bad.stderr.startswith("flexure-sim piezo-loop: error: ") and message in bad.stderr
        assert bad.stderr.count("\n") == 1, bad.stderr


@pytest.mark.parametrize("change, message", [
    ({"drive": "y"}, "needs drive 'y' with an actuator: block"),
    ({"frequency": 0.0}, "frequency: must be a positive number of Hz"),
    ({"cycles": 1}, "--cycles 1: need at least 2"),
    ({"points": 10}, "--points 10: need at least 100"),
    ({"load": float("nan")}, "--load nan: must be a stiffness >= 0 N/m"),
])
def test_bad_options_are_named(change, message):
    from argparse import Namespace

    from flexure_sim.tools.design.piezo_loop import loop_summary

    args = Namespace(mechanism=str(EXAMPLE), drive=None, frequency=1.0, cycles=3, points=200,
                     load=1e6)
    with pytest.raises(ValueError, match=re.escape(message)):
        loop_summary(Namespace(**{**vars(args), **change}))
