"""
The mechanism file's ``damping:`` block (Rayleigh or modal) in the engine (issue 12 item 1).

Expected values come from independent sources: the definition of a damping ratio (the poles of
the exact Jacobian, -Re/|lambda|), the logarithmic decrement of a free decay simulated by the
engine, ln(x_k / x_{k+1}) = 2 pi zeta / sqrt(1 - zeta^2), Chopra's Rayleigh formula
zeta = alpha / (2 omega) + beta omega / 2 (Dynamics of Structures, eq. 11.4.3) with alpha, beta
from its closed-form solution for two targets (eq. 11.4.4), the energy theorem, and numbers the
code before the block produced (a mechanism without the block must not change by one bit).
"""
from __future__ import annotations

import json
import math
import subprocess
import sys

import numpy as np
import pytest
import yaml

from flexure_sim.engine.analysis import linear
from flexure_sim.engine.solver import step_loop as stepping
from flexure_sim.engine.mechanism.loader import (
    ConfigError, load_mechanism, mechanism_from_dict, resolve_mechanism_path,
)
from flexure_sim.engine.solver.state import State
from flexure_sim.engine.solver.simulation import Simulation
from reference_figures import FIRST_MODE_HZ

ZETA = 0.01  # config/microstage_realistic.yaml


def stage_dict(name: str = "microstage") -> dict:
    return yaml.safe_load(resolve_mechanism_path(name).read_text())


def undamped_hinges(damping: dict) -> dict:
    """Return the stage with no hinge damping and the given damping block."""
    data = stage_dict()
    data["defaults"]["damping"] = {"t_char": 0.0}
    data["damping"] = damping
    return data


def oscillatory_poles(A: np.ndarray) -> np.ndarray:
    """Poles of A in the upper half-plane, ascending |pole|."""
    poles = np.linalg.eigvals(A)
    poles = poles[poles.imag > 0]
    return poles[np.argsort(np.abs(poles))]


def rest_jacobian(sim: Simulation) -> np.ndarray:
    """Exact A = dF/dy of the engine's dynamics at rest (command 0)."""
    model = sim.model
    return model.jacobian(model.pack(sim.initial_state()), 0.0, np.zeros(1))


# ------------------------------------------------------------------ microstage_realistic


@pytest.fixture(scope="module")
def realistic():
    return Simulation(load_mechanism("microstage_realistic"))


def test_realistic_stage_has_the_same_mechanism_as_microstage_apart_from_damping():
    # The file is a copy (the loader has no include): pin that only the damping differs.
    base, real = stage_dict("microstage"), stage_dict("microstage_realistic")
    assert real.pop("damping") == {"model": "modal", "ratio": ZETA}
    assert base["defaults"].pop("damping") == {"t_char": 1.0e-3}
    assert real["defaults"].pop("damping") == {"t_char": 0.0}
    for key in ("name", "description", "source"):
        base.pop(key), real.pop(key)
    assert real == base


def test_realistic_first_mode_has_the_configured_ratio_in_the_jacobian_poles(realistic):
    pole = oscillatory_poles(rest_jacobian(realistic))[0]
    assert abs(pole) / (2 * math.pi) == pytest.approx(FIRST_MODE_HZ, rel=1e-3)
    assert -pole.real / abs(pole) == pytest.approx(ZETA, abs=1e-3)
    assert -pole.real / abs(pole) == pytest.approx(ZETA, rel=1e-9)  # exact for modal damping


def test_modes_command_reports_the_configured_ratio(capsys):
    from flexure_sim.cli import main

    assert main(["modes", "microstage_realistic", "--count", "3", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["modes"][0]["frequency_hz"] == pytest.approx(FIRST_MODE_HZ, rel=1e-3)
    assert out["modes"][0]["modal_damping_ratio"] == pytest.approx(ZETA, abs=1e-3)
    first = min((p for p in out["poles"] if p["imag"] > 0), key=lambda p: p["frequency_hz"])
    assert first["damping_ratio"] == pytest.approx(ZETA, abs=1e-3)
    # The book's stage keeps its damping: the first mode stays near critical (0.944).
    assert main(["modes", "microstage", "--count", "1", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["modes"][0]["modal_damping_ratio"] == (
        pytest.approx(0.944, abs=1e-3))


def test_free_decay_has_the_logarithmic_decrement_of_the_configured_ratio(realistic):
    """
    Released from rest displaced 1 um (at the output) along the first mode shape.

    The engine's output is sampled every step (33 samples a period at 300 Hz; peaks refined by
    a parabola through the three samples around each, error ~1e-5 of the amplitude) over 18
    periods. Tolerance 1 %: the stepping integrates the linear part exactly, so what is left
    is the peak refinement and the stage's geometric nonlinearity at 1 um (both far below 1 %;
    measured 1e-5).
    """
    sim = Simulation(realistic.model)
    model = sim.model
    md = linear.modes(linear.linearize(sim, wrenches=False))
    F = model.part.free
    phi = md.shapes[:, 0]
    z = model.z0.copy()
    z[F] += 1e-6 / abs(model.output_matrix[0, F] @ phi) * phi
    sim.state = State(0.0, z, np.zeros_like(z), np.zeros(1), np.zeros(1))
    energy = [sim.snapshot().kinetic_energy + sim.snapshot().potential_energy]
    outputs = [sim.snapshot().output]
    powers = [model.rhs(model.pack(sim.state), 0.0, np.zeros(1))[1]]
    for _ in range(600):
        sim.step(1)
        s = sim.snapshot()
        outputs.append(s.output)
        powers.append(model.rhs(model.pack(sim.state), s.t, np.zeros(1))[1])
    y = np.array(outputs)
    peaks = []
    for i in range(1, len(y) - 1):
        if y[i] > 0 and y[i] > y[i - 1] and y[i] >= y[i + 1]:
            d = 0.5 * (y[i - 1] - y[i + 1]) / (y[i - 1] - 2 * y[i] + y[i + 1])
            peaks.append(y[i] - 0.25 * (y[i - 1] - y[i + 1]) * d)
    assert len(peaks) >= 17
    decrement = math.log(peaks[0] / peaks[-1]) / (len(peaks) - 1)
    zeta = decrement / math.sqrt(4 * math.pi**2 + decrement**2)
    assert zeta == pytest.approx(ZETA, rel=1e-2)
    # The dissipated power (v^T C v, the kernel's AUX_DISSIPATION) integrates to the energy
    # lost (the energy theorem: no drive work while the drive holds still); trapezoidal rule
    # over whole periods of a slowly decaying oscillation: 1e-3.
    s = sim.snapshot()
    lost = energy[0] - (s.kinetic_energy + s.potential_energy)
    assert lost > 0.8 * energy[0]  # 18 periods at zeta 0.01: 1 - exp(-4 pi 0.01 18) = 0.9
    p = np.array([a[stepping.AUX_DISSIPATION] for a in powers])
    assert model.dt * (p.sum() - 0.5 * (p[0] + p[-1])) == pytest.approx(lost, rel=1e-3)
    assert s.dissipated == pytest.approx(lost, rel=1e-9)


def test_drive_work_with_modal_damping_converges_in_the_step():
    # Modal damping couples the drive's velocity to the free coordinates (C_FP = C_FF
    # K_FF^-1 K_FP): the drive work over a 1.35 um command step at the shipped 1e-4 s step
    # equals a 1e-6 s run's (the energy budget T + U + dissipated = work closes by definition).
    runs = []
    for dt in (1e-4, 1e-6):
        sim = Simulation(load_mechanism("microstage_realistic"), dt=dt)
        sim.set_command(1.35e-6)
        sim.step(int(round(5e-3 / dt)))
        runs.append(sim.snapshot())
    assert runs[0].drive_work == pytest.approx(runs[1].drive_work, rel=1e-5)
    assert runs[0].dissipated == pytest.approx(runs[1].dissipated, rel=1e-4)
    assert runs[1].dissipated > 0.05 * runs[1].drive_work


# ------------------------------------------------------------------------------ Rayleigh


def chopra_coefficients(z1, w1, z2, w2):
    """Chopra eq. 11.4.4 in closed form: alpha, beta for ratio z1 at w1 and z2 at w2."""
    alpha = 2 * w1 * w2 * (z1 * w2 - z2 * w1) / (w2**2 - w1**2)
    beta = 2 * (z2 * w2 - z1 * w1) / (w2**2 - w1**2)
    return alpha, beta


def test_rayleigh_targets_are_reproduced_by_the_jacobian_poles():
    # Targets at the stage's first and third modes (300.62 Hz, 6189.1 Hz; test_linear.py).
    f1, f3 = 300.62025013, 6189.08262491
    sim = Simulation(mechanism_from_dict(undamped_hinges(
        {"model": "rayleigh", "ratios": [[0.01, f1], [0.03, f3]]})))
    poles = oscillatory_poles(rest_jacobian(sim))
    ratios = -poles.real / np.abs(poles)
    near = [np.argmin(np.abs(np.abs(poles) / (2 * np.pi) - f)) for f in (f1, f3)]
    assert ratios[near[0]] == pytest.approx(0.01, rel=1e-6)
    assert ratios[near[1]] == pytest.approx(0.03, rel=1e-6)
    # Every underdamped mode follows eq. 11.4.3 with eq. 11.4.4's alpha and beta.
    alpha, beta = chopra_coefficients(0.01, 2 * np.pi * f1, 0.03, 2 * np.pi * f3)
    w = np.abs(poles)
    np.testing.assert_allclose(ratios, alpha / (2 * w) + beta * w / 2, rtol=1e-6)
    assert len(poles) >= 8


def test_rayleigh_alpha_beta_given_directly_follow_chopra():
    alpha, beta = 30.0, 2.0e-7
    sim = Simulation(mechanism_from_dict(undamped_hinges(
        {"model": "rayleigh", "alpha": alpha, "beta": beta})))
    poles = oscillatory_poles(rest_jacobian(sim))
    w = np.abs(poles)
    np.testing.assert_allclose(-poles.real / w, alpha / (2 * w) + beta * w / 2, rtol=1e-6)


def test_modal_ratios_per_mode_then_one_for_the_rest():
    sim = Simulation(mechanism_from_dict(undamped_hinges(
        {"model": "modal", "ratios": [0.005, 0.02], "ratio": 0.05})))
    poles = oscillatory_poles(rest_jacobian(sim))
    np.testing.assert_allclose(-poles.real / np.abs(poles),
                               [0.005, 0.02] + [0.05] * (len(poles) - 2), rtol=1e-6)
    assert len(poles) == 12


def test_the_exact_jacobian_with_damping_matches_finite_differences():
    # At a moving state after a command step, so that v_P (the drive lag) and v_F are not zero.
    sim = Simulation(mechanism_from_dict(undamped_hinges(
        {"model": "modal", "ratios": [0.01, 0.02], "ratio": 0.05})))
    model = sim.model
    sim.set_command(1.0e-6)
    sim.step(7)
    y, t = model.pack(sim.state), sim.state.t
    command = np.array([1.0e-6])
    A = model.jacobian(y, t, command)
    fd = np.empty_like(A)
    for j in range(len(y)):
        h = 1e-6 * max(abs(y[j]), 1e-9)
        yp, ym = y.copy(), y.copy()
        yp[j] += h
        ym[j] -= h
        fd[:, j] = (model.rhs_python(yp, t, command)[0] - model.rhs_python(ym, t, command)[0]) / (
            2 * h)
    np.testing.assert_allclose(A, fd, rtol=0, atol=1e-5 * np.abs(A).max())
    # The compiled kernel and the interpreted path give the same forces and power.
    F1, aux1 = model.rhs(y, t, command)
    F2, aux2 = model.rhs_python(y, t, command)
    np.testing.assert_allclose(F1, F2, rtol=1e-12, atol=1e-12 * np.abs(F1).max())
    np.testing.assert_allclose(aux1, aux2, rtol=1e-12)


def test_the_damping_block_has_no_effect_at_rest():
    plain = undamped_hinges({"model": "modal", "ratio": 0.01})
    del plain["damping"]
    damped = Simulation(mechanism_from_dict(undamped_hinges({"model": "modal", "ratio": 0.01})))
    st, st0 = damped.static(1.35e-6), Simulation(mechanism_from_dict(plain)).static(1.35e-6)
    assert st.snapshot.output == st0.snapshot.output
    assert st.snapshot.drive_force == st0.snapshot.drive_force


# ------------------------------------------------------------------------- loader errors


@pytest.mark.parametrize("block,key,words", [
    ({"model": "viscous", "ratio": 0.01}, "damping.model", "unknown damping model 'viscous'"),
    ({"model": "modal", "ratio": -0.01}, "damping.ratio", "must not be negative"),
    ({"model": "modal", "ratios": [0.01, -0.02], "ratio": 0.01}, "damping.ratios[1]",
     "must not be negative"),
    ({"model": "modal", "ratios": [0.01, 0.02, 0.03]}, "damping.ratios",
     "3 ratios for a mechanism with 12 modes"),
    ({"model": "modal", "ratios": [0.01] * 13}, "damping.ratios",
     "13 ratios for a mechanism with 12 modes"),
    ({"model": "modal"}, "damping", "give ratio"),
    ({"model": "modal", "ratio": 0.01, "beta": 1e-6}, "damping.beta", "unknown key"),
    ({"model": "rayleigh", "alpha": -1.0, "beta": 1e-6}, "damping.alpha", "must not be negative"),
    ({"model": "rayleigh", "ratios": [[0.01, 300.0]]}, "damping.ratios", "two [zeta, freq"),
    ({"model": "rayleigh", "ratios": [[0.01, 300.0], [0.02, 300.0]]}, "damping.ratios",
     "must differ"),
    ({"model": "rayleigh", "ratios": [[0.01, 300.0], [0.02, -3.0]]}, "damping.ratios[1][1]",
     "must be positive"),
    ({"model": "rayleigh", "ratios": [[0.05, 300.0], [0.001, 3000.0]]}, "damping.ratios",
     "beta = -"),
    ({"model": "rayleigh", "alpha": 1.0, "ratios": [[0.01, 1.0], [0.02, 2.0]]}, "damping",
     "not both"),
    ("modal", "damping", "expected a mapping"),
])
def test_loader_errors_name_the_bad_key(block, key, words):
    data = stage_dict()
    data["damping"] = block
    with pytest.raises(ConfigError) as err:
        mechanism_from_dict(data, source="stage.yaml")
    message = str(err.value)
    assert message.startswith(f"stage.yaml: {key}: "), message
    assert words in message and "\n" not in message


def test_a_bad_damping_block_ends_the_cli_in_one_line(tmp_path):
    path = tmp_path / "stage.yaml"
    data = stage_dict()
    data["damping"] = {"model": "modal", "ratios": [0.01, 0.02]}
    path.write_text(yaml.safe_dump(data))
    p = subprocess.run([sys.executable, "-m", "flexure_sim.cli", "modes", str(path)],
                       capture_output=True, text=True, timeout=120)
    assert p.returncode == 2, p.stderr
    assert "Traceback" not in p.stderr
    assert f"{path}: damping.ratios: 2 ratios for a mechanism with 12 modes" in p.stderr


def _modes_with_rayleigh(tmp_path, ratios) -> subprocess.CompletedProcess:
    path = tmp_path / "rayleigh.yaml"
    data = undamped_hinges({"model": "rayleigh", "ratios": ratios})
    path.write_text(yaml.safe_dump(data))
    return subprocess.run([sys.executable, "-m", "flexure_sim.cli", "modes", str(path)],
                          capture_output=True, text=True, timeout=120)


@pytest.mark.slow
def test_rayleigh_ratios_needing_a_negative_coefficient_are_refused_naming_them(tmp_path):
    """
    With alpha, beta >= 0, zeta at f2 > f1 lies in [zeta1 f1/f2, zeta1 f2/f1] (Chopra 11.4.3).

    Outside it one coefficient must be negative: negative damping, refused with the ratios,
    the frequencies and the range that can be met.
    """
    for ratios, which, word in (([[0.01, 300.0], [0.0, 3000.0]], "0 at 3000 Hz", "beta"),
                                ([[0.001, 300.0], [0.1, 3000.0]], "0.1 at 3000 Hz", "alpha")):
        p = _modes_with_rayleigh(tmp_path, ratios)
        assert p.returncode == 2 and "Traceback" not in p.stderr, p.stderr
        assert f"damping.ratios: zeta {ratios[0][0]:g} at 300 Hz and {which} need a negative " \
               f"{word}" in p.stderr, p.stderr
        low, high = ratios[0][0] * 0.1, ratios[0][0] * 10
        assert f"gives {low:g} to {high:g} at 3000 Hz" in p.stderr, p.stderr


@pytest.mark.slow
def test_mass_proportional_damping_given_as_two_ratios_is_accepted(tmp_path):
    """
    Accept zeta2 = zeta1 f1 / f2 exactly: beta = 0 (mass-proportional).

    The 2 x 2 solve gives beta as -2.1e-24 s; zeta of each mode is then zeta1 f1 / f (Chopra
    11.4.3 with beta = 0).
    """
    z1, f1, f2 = 0.01, 100.0, 4100.0
    p = _modes_with_rayleigh(tmp_path, [[z1, f1], [z1 * f1 / f2, f2]])
    assert p.returncode == 0, p.stderr
    row = next(line.split() for line in p.stdout.splitlines() if line.split()[:1] == ["1"])
    f, zeta = float(row[1]), float(row[2])
    assert zeta == pytest.approx(z1 * f1 / f, rel=2e-4)  # printed to 4 digits


# ------------------------------------------------------------- without the block: unchanged

#: Produced by the code before the damping block (commit 09aee03) with the same calls, then
#: regenerated once when the stage's inertias became microstage.sci's values to double precision
#: instead of 6 digits (a change of ~1e-6 in them):
#: (output, drive force, compression, dissipated, drive work, theta of body4) every 10 steps of
#: a 1.35 um command step, compiled kernel (microstage) and interpreted path (polynomial law).
BEFORE = {
    "microstage": [
        (2.172842281379288e-05, 16.675384797844252, 1.514561632984246e-07,
         3.201062788995053e-05, 4.6137195229827566e-05, -1.2738387379455194e-06),
        (3.4096944787797036e-05, 24.031511717673315, 1.3625318235656325e-07,
         3.6064336889632624e-05, 5.205829681412202e-05, -2.0147958449488187e-06),
        (3.6862944506934626e-05, 29.144043268774748, 1.5958153810370634e-07,
         3.64261848756083e-05, 5.5139116004757695e-05, -2.1827970521710058e-06),
        (3.726949403197166e-05, 30.33372126068501, 1.780681916346144e-07,
         3.652605916615656e-05, 5.6405429263129436e-05, -2.207872922032841e-06)],
    "config/examples/microstage_polynomial_a.yaml": [
        (2.1729556556389355e-05, 16.674674517388134, 1.514235548841919e-07,
         3.201267497642377e-05, 4.613949153449879e-05, -1.2732354326619104e-06),
        (3.409787538821492e-05, 24.032646328395455, 1.3622527843433485e-07,
         3.606626806059685e-05, 5.206071943481685e-05, -2.014264737554447e-06),
        (3.686395041774371e-05, 29.145007662705407, 1.595502598355364e-07,
         3.642812419328424e-05, 5.514166375845598e-05, -2.1821786478775056e-06),
        (3.7270632325315346e-05, 30.334635669625893, 1.7803315569518696e-07,
         3.652799204328158e-05, 5.640801642068731e-05, -2.2072163861911878e-06)],
}
BEFORE_MODES = ([300.61788445477464, 4634.706250730204, 6189.23219705728],
                [0.9444234855055436, 14.560361876707839, 19.44406656879421])
BEFORE_FRF = [(20.72283049942241 - 14.641409101818253j),
              (0.029036237982303703 - 14.658620672774662j),
              (-1.976454483254533 - 1.2315102365272237j)]


@pytest.mark.parametrize("name", sorted(BEFORE))
def test_without_the_block_the_step_response_is_bit_identical_to_before(name):
    # A regression guard (it passes on the code before the block by construction).
    sim = Simulation(load_mechanism(name))
    assert sim.model.damping is None
    sim.set_command(1.35e-6)
    got = []
    for _ in range(4):
        sim.step(10)
        s = sim.snapshot()
        got.append((s.output, s.drive_force, s.compression, float(s.poses[3, 2])))
    # The energies (fields 3 and 4 of BEFORE) are left out: the step's exact dissipation
    # integral (issue 16 item 8) changed them on purpose; test_energy.py checks them.
    assert got == [row[:3] + row[5:] for row in BEFORE[name]]


def test_without_the_block_modes_and_frf_are_bit_identical_to_before():
    lm = linear.linearize(Simulation(load_mechanism("microstage")), 1.35e-6, wrenches=False)
    md = linear.modes(lm)
    assert (md.frequencies[:3].tolist(), md.modal_damping[:3].tolist()) == BEFORE_MODES
    assert linear.frf(lm, [100.0, 300.0, 1000.0], ["output"])[0].tolist() == BEFORE_FRF


def test_the_realistic_stage_is_a_builtin_of_the_installed_package(tmp_path):
    # setup.py's data_files glob config/*.yaml: a pip install ships it to share/flexure_sim/config
    # (colcon: test_colcon.py); run from elsewhere, so that the installed copy is imported.
    code = ("import sys; "
            "from flexure_sim.engine.mechanism.builtins import builtin_names, find_builtin; "
            "print(sys.prefix); print(find_builtin('microstage_realistic')); "
            "print(' '.join(builtin_names()))")
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120,
                       cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    prefix, path, names = p.stdout.splitlines()
    assert path == f"{prefix}/share/flexure_sim/config/microstage_realistic.yaml"
    assert {"microstage", "microstage_realistic"} <= set(names.split())
