"""
Rayleigh and modal damping from the stage's modes at rest (mechanism/damping_models.py).

Checked by an independent method: the eigenvalues of the damped state matrix [[0, I], [-M^-1 K,
-M^-1 C]] (their ratios -Re/|lambda|), and the logarithmic decrement of a free decay of the first
mode, ln(x_k / x_{k+1}) = 2 pi zeta / sqrt(1 - zeta^2).
"""
from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.linalg

from flexure_sim.engine.mechanism.loader import load_mechanism
from flexure_sim.engine.mechanism.damping_models import (
    modal_matrix, rayleigh_coefficients, rayleigh_matrix, rayleigh_ratios)
from flexure_sim.engine.analysis.linear import linearize, modes
from flexure_sim.engine.solver.simulation import Simulation


@pytest.fixture(scope="module")
def stage():
    model = linearize(Simulation(load_mechanism("microstage")), wrenches=False)
    m = modes(model)
    return model.mass, model.stiffness, m.shapes, 2 * np.pi * m.frequencies


def state_ratios(mass, stiffness, damping) -> np.ndarray:
    """Damping ratios of the oscillatory poles of M x'' + C x' + K x = 0, ascending |pole|."""
    n = len(mass)
    minv = np.diag(1.0 / mass)
    a = np.block([[np.zeros((n, n)), np.eye(n)], [-minv @ stiffness, -minv @ damping]])
    poles = np.linalg.eigvals(a)
    poles = poles[poles.imag > 0]
    poles = poles[np.argsort(np.abs(poles))]
    return -poles.real / np.abs(poles)


def test_modal_damping_gives_every_mode_its_ratio(stage):
    mass, stiffness, shapes, omega = stage
    zeta = np.full(omega.size, 0.01)
    zeta[1] = 0.02
    c = modal_matrix(mass, shapes, omega, zeta)
    np.testing.assert_allclose(c, c.T, rtol=0, atol=1e-12 * np.abs(c).max())
    np.testing.assert_allclose(state_ratios(mass, stiffness, c), zeta, rtol=1e-6)


def test_rayleigh_ratios_match_the_poles_and_hit_the_two_targets(stage):
    mass, stiffness, shapes, omega = stage
    alpha, beta = rayleigh_coefficients(0.01, omega[0], 0.03, omega[2])
    ratios = rayleigh_ratios(alpha, beta, omega)
    assert ratios[0] == pytest.approx(0.01, rel=1e-12)
    assert ratios[2] == pytest.approx(0.03, rel=1e-12)
    c = rayleigh_matrix(alpha, beta, mass, stiffness)
    underdamped = ratios < 1
    np.testing.assert_allclose(state_ratios(mass, stiffness, c)[: underdamped.sum()],
                               ratios[underdamped], rtol=1e-6)


def test_free_decay_of_the_first_mode_has_the_logarithmic_decrement_of_zeta(stage):
    mass, stiffness, shapes, omega = stage
    zeta = 0.01
    c = modal_matrix(mass, shapes, omega, zeta)
    n = len(mass)
    minv = np.diag(1.0 / mass)
    a = np.block([[np.zeros((n, n)), np.eye(n)], [-minv @ stiffness, -minv @ c]])
    wd = omega[0] * math.sqrt(1 - zeta**2)
    period = 2 * math.pi / wd
    step = scipy.linalg.expm(a * period)  # exact: one damped period
    x = np.r_[shapes[:, 0], np.zeros(n)]
    amplitudes = []
    for _ in range(5):
        amplitudes.append(x[:n] @ np.diag(mass) @ shapes[:, 0])  # modal coordinate 1
        x = step @ x
    decrements = np.log(np.array(amplitudes[:-1]) / np.array(amplitudes[1:]))
    np.testing.assert_allclose(decrements, 2 * math.pi * zeta / math.sqrt(1 - zeta**2), rtol=1e-9)


def test_bad_arguments_are_named():
    with pytest.raises(ValueError, match="omega"):
        rayleigh_ratios(1.0, 1e-5, np.array([0.0, 1.0]))
    with pytest.raises(ValueError, match="omega_1, omega_2"):
        rayleigh_coefficients(0.01, 10.0, 0.02, 10.0)
    with pytest.raises(ValueError, match="shapes"):
        modal_matrix(np.ones(3), np.eye(2), np.ones(2), 0.01)
    with pytest.raises(ValueError, match="zeta"):
        modal_matrix(np.ones(2), np.eye(2), np.ones(2), -0.1)
