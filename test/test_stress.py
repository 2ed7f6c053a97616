"""Hinge stress: the notch and leaf formulas, the stage's stress ratios, the stroke limit."""

import numpy as np
import pytest

from flexure_sim.cli import main
from flexure_sim.engine import stress
from flexure_sim.engine.design import Parameters
from flexure_sim.engine.solver import Simulation


def test_notch_concentration_factor_formula():
    # K_t = (1 + t/(2R))^(9/20) (Smith, "Flexures", 2000; Lobontiu, "Compliant Mechanisms",
    # 2003): a thin neck in a wide notch concentrates little, t = 2R (h = D) gives 2^0.45.
    assert stress.notch_concentration(0.0, 3e-3) == 1.0
    assert stress.notch_concentration(3e-3, 3e-3) == pytest.approx(2**0.45, rel=1e-15)
    # The stage's hinge: h/D = 1/12 -> (13/12)^0.45 = 1.036676 (hand calculation).
    assert stress.notch_concentration(0.25e-3, 3e-3) == pytest.approx(1.036676, abs=1e-6)


def test_notch_stress_is_beam_bending_plus_axial_times_kt():
    # 1 N m on a 0.25 mm x 20 mm neck: 6 M / (t h^2) = 6 / (0.02 * 6.25e-8) = 4.8 GPa nominal;
    # 10 N axial: 10 / (0.02 * 2.5e-4) = 2 MPa. Shear force has no lever arm at the centre.
    kt = (1 + 0.25 / 3) ** 0.45
    s = stress.notch_stress(np.array([1.0, -10.0, 1e3]), 3e-3, 0.25e-3, 0.02)
    assert s == pytest.approx(kt * (4.8e9 + 2e6), rel=1e-12)


def test_leaf_stress_adds_the_shear_force_lever_arm():
    # Leaf 10 mm x 1 mm x 5 mm: end moment |m| + |f_x| L/2 = 0.01 + 2 * 0.005 = 0.02 N m;
    # 6 * 0.02 / (5e-3 * 1e-6) = 24 MPa; axial 5 N / 5e-6 m^2 = 1 MPa.
    s = stress.leaf_stress(np.array([-0.01, 2.0, 5.0]), 0.010, 0.001, 0.005)
    assert s == pytest.approx(25e6, rel=1e-12)


def test_stage_stroke_limit_reaches_yield_exactly():
    params = Parameters("microstage")
    sim = Simulation(params.mechanism)
    geometry = params.design().geometry
    u, hinge = stress.stroke_limit(sim, geometry)
    names = [h.name for h in params.mechanism.hinges]
    table = stress.stress_table(sim.static(u).snapshot.wrenches, geometry, names)
    assert stress.peak_ratio(table) == (hinge, pytest.approx(1.0, abs=1e-8))
    assert u > sim.drive.stroke[1]  # the piezo's 2 um stroke is far from yield
    # Stress grows nearly linearly with the input: the ratio at full stroke times the limit.
    full = stress.peak_ratio(
        stress.stress_table(sim.static(2e-6).snapshot.wrenches, geometry, names)
    )[1]
    assert u == pytest.approx(2e-6 / full, rel=1e-2)


def test_simulate_static_shows_stress_and_stroke_limit_command(capsys):
    import json

    assert main(["simulate", "microstage", "--drive", "step:2e-6", "--static", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert set(out["hinge_stress"]) == set("abcdefg")
    assert out["hinge_stress"]["c"]["sigma_y"] == 276e6
    assert main(["simulate", "microstage", "--stroke-limit"]) == 0
    assert "stroke limit (first hinge at yield)" in capsys.readouterr().out
    assert main(["simulate", "fourbar_mixed", "--stroke-limit"]) == 2
    assert "has no drive" in capsys.readouterr().err
