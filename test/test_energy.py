"""
Energy figures after command steps (issue 16 item 8).

The drive work is integrated as exactly as the motion, the actuator's velocity jump is accounted
for, and the budget T + U + dissipated - work - initial closes.
"""
import math

import numpy as np
import pytest
import scipy.integrate
import scipy.linalg
import yaml

from conftest import ROOT
from flexure_sim.engine.solver import step_energy
from flexure_sim.engine.mechanism.loader import load_mechanism, mechanism_from_dict
from flexure_sim.engine.solver.simulation import Simulation
from test_statics import DRIVEN_PLATFORM, KX

PARALLELOGRAM = ROOT / "config" / "examples" / "parallelogram_stage.yaml"


def _budget(sim):
    s = sim.snapshot()
    return (s.kinetic_energy + s.potential_energy + s.dissipated - s.drive_work) / s.drive_work


def _radau_energies(model, command, duration):
    """
    Dissipated energy and drive work after a command step from rest, by scipy's Radau.

    The energies are extra states of the ODE (rtol 1e-8: 1e-9 and 1e-10 change them by less
    than 1e-10, four orders inside the tests' 1e-6, at 15 to 150 times the cost): the
    dissipated power from ``Assembly.forces`` (the NumPy path), the drive's power
    v_P . (M_P a_P - Q_P) with v_P = du ud, a_P = -du ud / tau, ud = (command - u) / tau; plus
    the kinetic energy the actuator's velocity jump gives the driven body, 1/2 m_d (c/tau)^2.
    """
    part, mass = model.part, model.mass
    nF, P, du = len(part.free), part.prescribed, part.du
    tau = model.drive.response_time

    def f(t, Y):
        y = Y[:-2]
        ud = (command - y[2 * nF]) / tau
        z, v = model.z0.copy(), np.zeros_like(model.z0)
        z[part.free], v[part.free] = y[:nF], y[nF:2 * nF]
        z[P], v[P] = model.z0[P] + du * y[2 * nF], du * ud
        hf = model.assembly.forces(z, v)
        F = np.concatenate([y[nF:2 * nF], hf.Q[part.free] / mass[part.free], [ud]])
        power = (mass[P] * (-du * ud / tau) - hf.Q[P]) @ (du * ud)
        return np.concatenate([F, [hf.dissipation.sum(), power]])

    def jac(t, Y):
        J = np.zeros((len(Y), len(Y)))
        J[:-2, :-2] = model.jacobian(Y[:-2], t, np.array([command]))
        return J

    y0 = np.concatenate([model.z0[part.free], np.zeros(nF + 1), [0.0, 0.0]])
    sol = scipy.integrate.solve_ivp(
        f, (0.0, duration), y0, method="Radau", jac=jac, rtol=1e-8, first_step=1e-12,
        atol=np.concatenate([model.atol * 1e-2, [1e-30, 1e-30]]))
    assert sol.success
    jump = 0.5 * float(mass[P] @ (du * du)) * (command / tau) ** 2
    return sol.y[-2, -1], sol.y[-1, -1] + jump


def _stepped(mech, command, dt, duration):
    sim = Simulation(mech, dt=dt)
    sim.set_command(command)
    sim.step(int(round(duration / dt)))
    return sim


def test_stage_energies_at_the_shipped_step_agree_with_radau():
    """
    1.35 um step, 5 ms at 1e-4 s: dissipated energy and work each to 1e-6 of Radau's.

    Measured: dissipated -8.2e-7, work -2.9e-7. The budget closes to 1e-6 with the dissipated
    energy integrated on its own; a trapezoidal dissipated energy (what the step's ends alone
    give) leaves it open: the closure now checks the integration.
    """
    stage = load_mechanism("microstage")
    sim = _stepped(stage, 1.35e-6, 1e-4, 5e-3)
    dissipated, work = _radau_energies(sim.model, 1.35e-6, 5e-3)
    snap = sim.snapshot()
    assert snap.dissipated == pytest.approx(dissipated, rel=1e-6)
    assert snap.drive_work == pytest.approx(work, rel=1e-6)
    assert abs(_budget(sim)) < 1e-6
    # The same run, its dissipated energy by the trapezoidal rule on the step grid.
    sim = Simulation(stage, dt=1e-4)
    sim.set_command(1.35e-6)
    powers = []
    for _ in range(51):
        s = sim.state
        powers.append(sim.assembly.forces(s.z, s.v).dissipation.sum())
        if len(powers) < 51:
            sim.step(1)
    trapezoid = 1e-4 * (sum(powers) - 0.5 * (powers[0] + powers[-1]))
    wrong = sim.snapshot()
    closure = (wrong.kinetic_energy + wrong.potential_energy + trapezoid - wrong.drive_work)
    assert abs(closure / wrong.drive_work) > 1e-3


@pytest.mark.slow
def test_parallelogram_energies_at_the_shipped_step_agree_with_radau():
    """
    5 um step, 1 ms at 1e-4 s: dissipated energy and work each to 1e-6 of Radau's.

    Measured: dissipated -4.7e-11, work 7.8e-11 (this stage is nearly linear).
    """
    mech = load_mechanism(PARALLELOGRAM)
    sim = _stepped(mech, 5e-6, 1e-4, 1e-3)
    dissipated, work = _radau_energies(sim.model, 5e-6, 1e-3)
    assert sim.snapshot().dissipated == pytest.approx(dissipated, rel=1e-6)
    assert sim.snapshot().drive_work == pytest.approx(work, rel=1e-6)
    assert abs(_budget(sim)) < 1e-6


def _rocked_parallelogram():
    """Build the parallelogram stage with a rocker on its platform, turned at a sine rate."""
    data = yaml.safe_load(PARALLELOGRAM.read_text())
    data["bodies"].append({"name": "rocker", "mass": 0.001, "inertia": 1e-8,
                           "pose": [0.0, 0.04, 0.0]})
    data["hinges"].append({"name": "top", "a": {"body": "platform", "at": [0.0, 0.01]},
                           "b": {"body": "rocker", "at": [0.0, -0.01]}, "stiffness": "notch"})
    data["constraints"].append({"type": "sine_rate", "body": "rocker", "coordinate": "theta",
                                "amplitude": 0.01, "frequency": 20.0})
    return mechanism_from_dict(data)


def test_timed_mechanism_budget_closes_after_a_command_step():
    """
    Drive and sine-rate constraint together: T + U + D - W to 1e-6 of W (measured -1.9e-7).

    1e-4 s after a 5 um step, at 1e-5 s steps. Before, the dissipated power and the timed
    constraint's power were integrated by the trapezoidal rule, which misses the stiff
    transient of the command step: the budget was off by 47 times the work.
    """
    sim = Simulation(_rocked_parallelogram(), dt=1e-5)
    sim.set_command(5e-6)
    sim.step(10)
    assert abs(_budget(sim)) < 1e-6
    sim.step(90)
    assert abs(_budget(sim)) < 3e-6     # measured -1.5e-6 at 1 ms: the motion's own error


@pytest.mark.parametrize("name", ["config/fourbar_mixed.yaml", "config/fourbar_cantilever.yaml"])
def test_timed_fourbar_budget_closes_with_independent_dissipation(name):
    """
    Sine-rate driven four-bars, 0.1 s at 1e-5 s: T + U + D - W to 1e-6 of W (measured 1.2e-7).

    Dissipated energy from the step's linear model with the timed rates in the velocities.
    """
    sim = Simulation(load_mechanism(ROOT / name), dt=1e-5)
    sim.step(10000)
    assert abs(_budget(sim)) < 1e-6


def test_work_and_dissipation_of_a_driven_hinge_match_the_closed_form():
    """
    A platform driven on ground through one hinge (twistor law, alpha = 0, p = (u, 0)).

    U = KX u^2 / 2, dissipated power BX u_dot^2 with BX = t_char KX, and the platform's own kinetic
    energy m u_dot^2 / 2, which the actuator supplies at once when the command jumps. With u = c (1
    - e^{-t/tau}): W = m ud^2/2 + KX u^2/2 + BX c^2 (1 - e^{-2t/tau})/(2 tau).
    """
    m, tau, bx, c = 0.01, 1e-3, 1e-3 * KX, 1e-6
    sim = Simulation(mechanism_from_dict(DRIVEN_PLATFORM), dt=1e-4)
    sim.set_command(c)
    for k in (1, 9, 40):
        sim.step(k)
        t = sim.state.t
        u, ud = c * -math.expm1(-t / tau), c / tau * math.exp(-t / tau)
        dissipated = bx * c * c / (2 * tau) * -math.expm1(-2 * t / tau)
        snap = sim.snapshot()
        assert snap.dissipated == pytest.approx(dissipated, rel=1e-9)
        work = 0.5 * m * ud * ud + 0.5 * KX * u * u + dissipated
        assert snap.drive_work == pytest.approx(work, rel=1e-9)


def _work(mech, command, dt, duration):
    sim = Simulation(mech, dt=dt)
    sim.set_command(command)
    sim.step(int(round(duration / dt)))
    return sim.snapshot().drive_work


def test_stage_work_at_the_shipped_step_equals_the_converged_work():
    """
    The work of the 1.35 um step over 5 ms at 1e-4 s agrees with 1e-6 s steps.

    There the old trapezoidal figures differed by 11-19 % and 1.6 %.
    """
    stage = load_mechanism("microstage")
    converged = _work(stage, 1.35e-6, 1e-6, 5e-3)
    assert _work(stage, 1.35e-6, 1e-4, 5e-3) == pytest.approx(converged, rel=1e-6)


def test_weighted_phi_functions_equal_their_integrals():
    """Psi_1, Psi_2 of step_energy against adaptive quadrature of their definitions."""
    rng = np.random.default_rng(3)
    n, h, tau = 4, 0.3, 0.7
    A = rng.normal(size=(n, n)) - 2 * np.eye(n)

    def phis(s):
        aug = np.zeros((3 * n, 3 * n))
        aug[:n, :n], aug[:n, n:2 * n], aug[n:2 * n, 2 * n:] = s * A, np.eye(n), np.eye(n)
        E = scipy.linalg.expm(aug)
        return s * E[:n, n:2 * n], s * E[:n, 2 * n:]     # s phi_1(sA), s phi_2(sA)

    phi1, phi2 = phis(h)
    shifted = np.zeros((2 * n, 2 * n))
    shifted[:n, :n], shifted[:n, n:] = h * A - h / tau * np.eye(n), np.eye(n)
    psi1, psi2 = step_energy.weighted_phi(
        A, phi1, phi2, h, tau, h * scipy.linalg.expm(shifted)[:n, n:])

    def weighted(k):
        return lambda s: math.exp(-s / tau) * (s / h) ** k * phis(s)[k]

    ref1 = scipy.integrate.quad_vec(weighted(0), 0, h, epsrel=1e-12)[0]
    ref2 = scipy.integrate.quad_vec(weighted(1), 0, h, epsrel=1e-12)[0]
    assert psi1 == pytest.approx(ref1, rel=1e-10, abs=1e-12)
    assert psi2 == pytest.approx(ref2, rel=1e-10, abs=1e-12)


@pytest.mark.parametrize("name", ["microstage", "config/fourbar_mixed.yaml"])
def test_without_energy_bookkeeping_the_motion_is_the_same_to_the_bit(name):
    """
    ``energy=False`` (what stage_node runs) skips the energy integrals and nothing else.

    The states after a command step (or the four-bar's sine rate) are bit-identical to a run
    with the energies; dissipated energy and drive work are NaN, never a stale number.
    """
    mech = load_mechanism(ROOT / "config" / f"{name}.yaml" if "/" not in name else ROOT / name)
    runs = [Simulation(mech, energy=energy) for energy in (True, False)]
    for sim in runs:
        if sim.model.drives.n_lags:
            sim.set_command(1.35e-6)
        sim.step(200)
    with_energy, without = runs
    assert np.array_equal(with_energy.state.z, without.state.z)
    assert np.array_equal(with_energy.state.v, without.state.v)
    assert with_energy.stats.linearizations == without.stats.linearizations
    assert math.isfinite(with_energy.snapshot().dissipated)
    snap = without.snapshot()
    assert math.isnan(snap.dissipated) and math.isnan(snap.drive_work)
    assert snap.kinetic_energy == with_energy.snapshot().kinetic_energy
    with pytest.raises(ValueError, match="energy belong to the model"):
        Simulation(without.model, energy=True)
