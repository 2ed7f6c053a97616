"""Hinge stiffness from geometry (eqs. 5.8, 5.27-5.33)."""
import numpy as np
import pytest

from flexure_sim.engine.hinges.stiffness import cantilever_stiffness, notch_stiffness
from reference_figures import NOTCH_KO, NOTCH_KX, NOTCH_KY


def test_stage_notch_hinge_matches_chapter_6():
    K = notch_stiffness(D=0.003, h=0.00025, t=0.02, E=69e9, nu=0.33)
    assert K[0, 0] == pytest.approx(NOTCH_KO, abs=6e-5)       # N m / rad
    assert K[1, 1] == pytest.approx(NOTCH_KX, rel=5e-4)      # N/m, along x
    assert K[2, 2] == pytest.approx(NOTCH_KY, rel=5e-4)      # N/m, along y
    assert np.count_nonzero(K - np.diag(np.diag(K))) == 0


def test_cantilever_hinge_of_the_fourbar():
    # 10 mm x 1 mm x 5 mm leaf, E = 5 % of aluminium.
    K = cantilever_stiffness(length=0.01, thickness=0.001, width=0.005, E=0.05 * 69e9, nu=0.3)
    second_moment = 0.005 * 0.001**3 / 12
    assert K[0, 0] == pytest.approx(0.05 * 69e9 * second_moment / 0.01)
    assert K[1, 1] == pytest.approx(12 * 0.05 * 69e9 * second_moment / 0.01**3)
    assert K[2, 2] == pytest.approx(0.005 * 0.001 * 0.05 * 69e9 / 0.01)
