"""Closed-form hinge stiffnesses next to the finite-element model: checks against their sources."""

import numpy as np
import pytest

from flexure_sim.engine.hinges.fe import closed_forms
from reference_figures import NOTCH_KO, NOTCH_KX, NOTCH_KY


def test_dissertation_formula_reproduces_the_printed_stage_hinge():
    K = closed_forms.dissertation("circular", {"D": 3e-3, "h": 0.25e-3, "t": 0.02}, 69e9, 0.33)
    assert np.diag(K) == pytest.approx([NOTCH_KO, NOTCH_KX, NOTCH_KY], rel=5e-4)


def test_paros_weisbord_rotation_is_the_dissertations_eq_6_2():
    # Eq. 6.2 prints KB = 2.4919 N m/rad for the stage's hinge; 2 E t h^(5/2) / (9 pi r^(1/2))
    # gives 2.4907 (0.05 % apart: the printed value's rounding of its inputs).
    K = closed_forms.paros_weisbord("circular", {"D": 3e-3, "h": 0.25e-3, "t": 0.02}, 69e9, 0.33)
    assert K[0, 0] == pytest.approx(2.4919, rel=1e-3)
    assert np.isnan(K[2, 2])


def test_paros_weisbord_simplified_is_the_thin_neck_limit_of_the_beam_integrals():
    # Their simplified equations are the leading terms of the exact beam integrals for
    # h / R -> 0; the relative gap shrinks in proportion to h / R.
    gaps = []
    for h in (1e-2, 1e-3, 1e-4):
        geo = {"D": 2.0, "h": h, "t": 1.0}
        pw = closed_forms.paros_weisbord("circular", geo, 1.0, 0.3)
        beam = closed_forms.beam("circular", geo, 1.0, 0.3)
        gaps.append(np.abs(np.diag(pw)[:2] / np.diag(beam)[:2] - 1))
    assert np.all(gaps[2] < 5e-5)
    assert gaps[0] / gaps[1] == pytest.approx([10.0, 10.0], rel=0.1)


def test_beam_integrals_of_a_straight_leaf_are_the_cantilever_formula():
    # A leaf without fillets has a constant width: the integrals are L/T^3, L^3/(12 T^3), L/T.
    geo = {"length": 0.02, "thickness": 5e-4, "width": 0.01, "fillet": 0.0}
    beam = closed_forms.beam("leaf", geo, 69e9, 0.33)
    cant = closed_forms.cantilever("leaf", geo, 69e9, 0.33)
    assert np.diag(beam) == pytest.approx(np.diag(cant), rel=1e-10)
    # Timoshenko adds the shear compliance 6/5 L / (G w T) to the transverse (x) direction.
    tim = closed_forms.timoshenko("leaf", geo, 69e9, 0.33)
    G = 69e9 / (2 * 1.33)
    want = 1 / (1 / cant[1, 1] + 1.2 * 0.02 / (G * 0.01 * 5e-4))
    assert tim[1, 1] == pytest.approx(want, rel=1e-10)


def test_beam_integral_of_the_circular_notch_by_an_independent_quadrature():
    # C_mm = int_{-R}^{R} 12 / (E t w^3) dx with w = h + 2R - 2 sqrt(R^2 - x^2), here by the
    # substitution x = R sin(phi) and a 2000-point Gauss-Legendre rule.
    R, h, t, E = 1.5e-3, 0.25e-3, 0.02, 69e9
    z, wts = np.polynomial.legendre.leggauss(2000)
    phi = 0.5 * np.pi * z
    w = h + 2 * R - 2 * R * np.cos(phi)
    cmm = np.sum(wts * 0.5 * np.pi * R * np.cos(phi) * 12 / (E * t * w ** 3))
    K = closed_forms.beam("circular", {"D": 2 * R, "h": h, "t": t}, E, 0.33)
    assert K[0, 0] == pytest.approx(1 / cmm, rel=1e-9)


def test_which_formulas_apply_to_which_shapes():
    assert closed_forms.applicable("circular", {}) == [
        "dissertation", "paros_weisbord", "beam", "timoshenko"]
    assert closed_forms.applicable("elliptical", {}) == ["beam", "timoshenko"]
    assert closed_forms.applicable("leaf", {"fillet": 0.0})[-1] == "cantilever"
    assert "cantilever" not in closed_forms.applicable("leaf", {"fillet": 1e-4})
