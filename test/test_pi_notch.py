"""
The PI + notch law (flexure_sim/control/pi_notch.py) without ROS, against scipy.signal.

The linear law is C(z) N(z) with C(z) = kp + ki T z / (z - 1) and N(z) the bilinear transform
(pre-warped) of the analog notch; the notch's gain at f_0 is its depth; the anti-windup keeps the
command off the limit once the error reverses.
"""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import signal

from flexure_sim.control.pi_notch import PIConfig, PIController, notch_coefficients

T = 1e-3


def analog_notch_discretised(f0: float, zeta: float, depth: float):
    """Return scipy's bilinear transform of N(s) with w0 pre-warped to (2/T) tan(w0 T / 2)."""
    wa = 2.0 / T * math.tan(math.pi * f0 * T)
    return signal.bilinear([1.0, 2 * depth * zeta * wa, wa**2], [1.0, 2 * zeta * wa, wa**2],
                           fs=1 / T)


@pytest.mark.parametrize("f0, zeta, depth",
                         [(300.6, 0.1, 0.0), (120.0, 0.3, 0.2), (450.0, 0.05, 0.5)])
def test_notch_coefficients_equal_scipy_bilinear_and_the_gain_at_f0_is_the_depth(f0, zeta, depth):
    b, a = notch_coefficients(f0, zeta, depth, T)
    b_ref, a_ref = analog_notch_discretised(f0, zeta, depth)
    np.testing.assert_allclose(b, b_ref / a_ref[0], rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(a, a_ref / a_ref[0], rtol=1e-12, atol=1e-14)
    _, h = signal.freqz(b, a, worN=[0.0, f0, 0.5 / T - 1e-9], fs=1 / T)
    np.testing.assert_allclose(np.abs(h), [1.0, depth, 1.0], atol=1e-9)


def test_linear_law_equals_scipy_lfilter_of_pi_times_notch():
    kp, ki, f0, zeta, depth = 0.01, 20.0, 300.0, 0.2, 0.1
    ctrl = PIController(PIConfig(kp, ki, T, -1.0, 1.0, f0, zeta, depth))
    rng = np.random.default_rng(3)
    errors = rng.normal(0.0, 1e-6, 500)
    u = np.array([ctrl.update(e, 0.0) for e in errors])
    b_n, a_n = notch_coefficients(f0, zeta, depth, T)
    filtered = signal.lfilter(b_n, a_n, errors)
    expected = signal.lfilter([kp + ki * T, -kp], [1.0, -1.0], filtered)
    np.testing.assert_allclose(u, expected, rtol=1e-9, atol=1e-18)


def test_pi_closed_form_for_a_constant_error_and_reset():
    kp, ki, e = 0.5, 10.0, 2e-6
    ctrl = PIController(PIConfig(kp, ki, T, -1.0, 1.0))
    u = [ctrl.update(e, 0.0) for _ in range(5)]
    np.testing.assert_allclose(u, [kp * e + ki * T * e * (k + 1) for k in range(5)], rtol=1e-14)
    ctrl.reset()
    assert ctrl.update(e, 0.0) == u[0]


def test_anti_windup_holds_the_integral_at_the_limit_and_leaves_it_at_once():
    kp, ki, u_max = 0.01, 20.0, 1e-6
    ctrl = PIController(PIConfig(kp, ki, T, 0.0, u_max))
    e = 5e-5  # kp e = 0.5 u_max; the integral grows by ki T e = u_max per sample
    for _ in range(2000):  # 2 s of it: without anti-windup I would reach 2000 u_max
        u = ctrl.update(e, 0.0)
    assert u == u_max
    # The integral stopped exactly where it carries the command to the limit.
    assert ctrl.integral == pytest.approx(u_max - kp * e, rel=1e-12)
    # The error reverses: the command leaves the limit at the first sample.
    assert ctrl.update(0.0, 4e-5) < u_max  # -7e-7 clipped to 0; wound up it would stay at u_max
    assert PIController(PIConfig(kp, ki, T, 0.0, u_max)).update(-1e-5, 0.0) == 0.0


@pytest.mark.parametrize("config, problem", [
    (PIConfig(0.01, 20.0, 0.0, 0.0, 1e-6), "period must be positive"),
    (PIConfig(-0.01, 20.0, T, 0.0, 1e-6), "kp and ki must not be negative"),
    (PIConfig(0.01, 20.0, T, 2e-6, 1e-6), "command_min"),
    (PIConfig(0.01, 20.0, T, 0.0, 1e-6, notch_frequency=500.0), "below the Nyquist"),
    (PIConfig(0.01, 20.0, T, 0.0, 1e-6, notch_frequency=300.0, notch_damping=0.0),
     "notch_damping"),
    (PIConfig(0.01, 20.0, T, 0.0, 1e-6, notch_frequency=300.0, notch_depth=1.5), "notch_depth"),
    (PIConfig(0.01, math.nan, T, 0.0, 1e-6), "finite"),
])
def test_bad_configurations_are_refused_with_the_reason(config, problem):
    assert problem in config.problem()
    with pytest.raises(ValueError, match=problem):
        PIController(config)


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_a_non_finite_input_is_refused_and_leaves_integral_and_notch_untouched(bad):
    from flexure_sim.control.pi_notch import NonFiniteInput

    config = PIConfig(0.005, 10.0, T, -1.0, 1.0, notch_frequency=300.6, notch_damping=0.1)
    law, fresh = PIController(config), PIController(config)
    good = [(2e-5, 0.0), (2e-5, 1e-6), (2e-5, 3e-6), (2e-5, 4e-6)]
    answers = [law.update(*good[0])]
    with pytest.raises(NonFiniteInput, match="measurement"):
        law.update(2e-5, bad)
    with pytest.raises(NonFiniteInput, match="setpoint"):
        law.update(bad, 1e-6)
    answers += [law.update(*s) for s in good[1:]]
    assert answers == [fresh.update(*s) for s in good]
