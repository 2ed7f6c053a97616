"""Step detection and step-response metrics on synthetic signals with textbook answers."""
from __future__ import annotations

import math

import numpy as np
import pytest

from flexure_sim.tools.run import step_analysis as analysis, response_metrics
from flexure_sim.tools.run.step_analysis import Step


def first_order(
    tau: float, t: np.ndarray, t0: float = 0.0, y0: float = 0.0, y1: float = 1.0
) -> np.ndarray:
    return np.where(t <= t0, y0, y1 + (y0 - y1) * np.exp(-(t - t0) / tau))


def second_order(zeta: float, wn: float, t: np.ndarray) -> np.ndarray:
    """Return unit step response of wn^2 / (s^2 + 2 zeta wn s + wn^2), 0 < zeta < 1."""
    wd = wn * math.sqrt(1 - zeta**2)
    phi = math.acos(zeta)
    return 1 - np.exp(-zeta * wn * t) * np.sin(wd * t + phi) / math.sqrt(1 - zeta**2)


@pytest.mark.parametrize("tau", [1e-3, 0.37])
def test_first_order_settles_in_tau_ln_50_and_rises_in_tau_ln_9(tau):
    t = np.linspace(0, 20 * tau, 20001)[1:]
    y = first_order(tau, t)
    r = response_metrics.step_response(t, y, 0.0, 0.0)
    assert r.settling_time == pytest.approx(tau * math.log(50), rel=1e-5)
    assert r.rise_time == pytest.approx(tau * math.log(9), rel=1e-5)
    assert r.overshoot == 0.0
    assert r.settled and r.final == pytest.approx(1.0, abs=1e-8)


def test_settling_time_is_interpolated_between_coarse_samples():
    tau = 1e-3
    t = np.arange(1, 21) * 1e-3  # one sample per tau
    y = first_order(tau, t)
    ts = response_metrics.settling_time(t, y, 0.0, 0.0, 1.0)
    # Linear interpolation of |error| between 3 ms (5.0 %) and 4 ms (1.8 %).
    e3, e4 = math.exp(-3), math.exp(-4)
    assert ts == pytest.approx(3e-3 + (e3 - 0.02) / (e3 - e4) * 1e-3, rel=1e-12)
    assert abs(ts - tau * math.log(50)) < 0.05e-3


@pytest.mark.parametrize("zeta", [0.1, 0.3, 0.5, 0.7])
def test_second_order_overshoot_is_exp_of_minus_pi_zeta_over_sqrt(zeta):
    wn = 2 * math.pi * 50.0
    t = np.linspace(0, 30 / (zeta * wn), 200001)[1:]
    y = second_order(zeta, wn, t)
    r = response_metrics.step_response(t, y, 0.0, 0.0)
    assert r.overshoot == pytest.approx(
        math.exp(-math.pi * zeta / math.sqrt(1 - zeta**2)), rel=1e-6
    )
    assert r.peak == pytest.approx(1 + r.overshoot, rel=1e-9)
    # The 2 % settling time is bounded by the envelope: exp(-zeta wn t)/sqrt(1-zeta^2) = 0.02.
    envelope = math.log(50 / math.sqrt(1 - zeta**2)) / (zeta * wn)
    assert 0 < r.settling_time <= envelope * (1 + 1e-6)
    assert r.settled


def test_a_step_down_and_an_offset_baseline_are_handled_like_a_step_up():
    tau = 2e-3
    t = np.linspace(0.1, 0.15, 5001)
    y = first_order(tau, t, t0=0.1, y0=5.0, y1=3.0)[1:]
    r = response_metrics.step_response(t[1:], y, 0.1, 5.0)
    assert r.change == pytest.approx(-2.0, abs=1e-8)
    assert r.settling_time == pytest.approx(tau * math.log(50), rel=1e-4)
    assert r.overshoot == 0.0
    # Ringing below the final value of a step down is overshoot.
    ringing = 3.0 - 0.5 * np.exp(-(t[1:] - 0.1) / tau) * np.sin(2e3 * (t[1:] - 0.1))
    assert response_metrics.overshoot(ringing, 5.0, 3.0) > 0.0


def test_a_response_still_moving_at_the_end_of_its_window_is_not_settled():
    tau = 1e-3
    t = np.linspace(0, 4e-3, 401)[1:]  # only 4 tau: still 1.8 % away, and the band is moving
    r = response_metrics.step_response(t, first_order(tau, t), 0.0, 0.0)
    assert not r.settled
    ramp = np.linspace(0, 1, 100)
    r = response_metrics.step_response(np.arange(1, 101) * 1e-3, ramp, 0.0, 0.0)
    assert r.settling_time is None or not r.settled


def test_command_steps_merge_same_time_commands_skip_nan_and_clamp_to_the_stroke():
    t = [0.01, 0.01, 0.02, 0.03, 0.04, 0.05, 0.06]
    c = [1e-6, 0.5e-6, math.nan, 0.5e-6, 5e-6, 2.5e-6, -1.0]
    steps = analysis.command_steps(t, c, initial=0.0, stroke=(0.0, 2e-6))
    assert steps == [Step(0.01, 0.5e-6, 0.0), Step(0.04, 2e-6, 0.5e-6), Step(0.06, 0.0, 2e-6)]


def test_input_steps_find_lagged_and_slewed_moves_of_the_applied_input():
    tau, dt = 1e-3, 1e-4
    t = np.arange(1, 1101) * dt
    u = np.zeros_like(t)
    for t0, y0, y1 in ((0.01, 0.0, 0.5e-6), (0.04, 0.5e-6, 2e-6), (0.08, 2e-6, 0.0)):
        mask = t > t0
        u[mask] = y1 + (y0 - y1) * np.exp(-(t[mask] - t0) / tau)
    steps = analysis.input_steps(t, u)
    assert [round(s.t, 6) for s in steps] == [0.01, 0.04, 0.08]
    assert [s.target for s in steps] == pytest.approx([0.5e-6, 2e-6, 0.0], abs=1e-12)
    assert steps[1].previous == pytest.approx(0.5e-6, abs=1e-12)
    assert analysis.input_steps(t, np.zeros_like(t)) == []


def test_analyse_steps_reports_gain_settling_and_peaks_per_step():
    tau, dt, gain = 1e-3, 1e-4, 27.6
    t = np.arange(1, 801) * dt
    steps = [Step(0.01, 1e-6, 0.0), Step(0.04, 2e-6, 1e-6)]
    u = np.zeros_like(t)
    for s in steps:
        mask = t > s.t
        u[mask] = s.target + (s.previous - s.target) * np.exp(-(t[mask] - s.t) / tau)
    y = gain * u
    force = 2e7 * u + 5.0 * np.gradient(u, t) * 1e-3
    wrench = np.stack([1e-3 * u / 1e-6, -20 * u / 1e-6, 0.1 * u / 1e-6], axis=1)
    results = analysis.analyse_steps(steps, (t, y), drive_input=(t, u), compression=(t, 0.1 * u),
                                     drive_force=(t, force), wrenches={"a": (t, wrench)},
                                     compression_hinge="a")
    assert len(results) == 2
    for r, s in zip(results, steps):
        assert r.settled and r.gain == pytest.approx(gain, rel=1e-9)
        assert r.settling_time == pytest.approx(tau * math.log(50), rel=2e-3)
        assert r.input == s.target and r.input_before == s.previous
        assert r.joint_a_compression == pytest.approx(0.1 * s.target, rel=1e-6)
        assert r.compression_hinge == "a"
        assert r.peak_wrench["a"]["fx"] == pytest.approx(-20 * s.target / 1e-6, rel=1e-6)
        assert r.peak_wrench["a"]["force"] == pytest.approx(
            math.hypot(20, 0.1) * s.target / 1e-6, rel=1e-6
        )
        assert abs(r.peak_drive_force) >= abs(r.drive_force)
    assert results[0].duration == pytest.approx(0.03)
    d = results[0].as_dict()
    for key in (
        "input",
        "gain",
        "settling_time",
        "overshoot",
        "joint_a_compression",
        "peak_drive_force",
    ):
        assert key in d


def test_a_step_cut_short_by_the_next_one_has_no_gain():
    tau, dt = 1e-3, 1e-4
    t = np.arange(1, 201) * dt
    steps = [Step(0.01, 1.0, 0.0), Step(0.0115, 2.0, 1.0)]
    y = np.where(t > 0.01, 1 - np.exp(-(t - 0.01) / tau), 0.0)
    y = np.where(t > 0.0115, y + (1 - np.exp(-(t - 0.0115) / tau)), y)
    results = analysis.analyse_steps(steps, (t, y))
    assert not results[0].settled and results[0].gain is None
    assert "did not settle" in " ".join(results[0].notes)
    assert results[1].settled


def test_wrench_peaks_keep_the_sign_of_the_largest_component():
    w = np.array([[0.1, 1.0, -3.0], [-0.2, -2.0, 0.5]])
    p = analysis.wrench_peaks(w)
    assert p == {"moment": -0.2, "force": pytest.approx(math.hypot(1, 3)), "fx": -2.0, "fy": -3.0}
    with pytest.raises(ValueError, match="w: expected shape"):
        analysis.wrench_peaks(np.zeros((3, 2)))


def test_mismatched_arrays_are_refused_naming_the_argument():
    with pytest.raises(ValueError, match="command"):
        analysis.command_steps([0.0, 1.0], [1.0])
