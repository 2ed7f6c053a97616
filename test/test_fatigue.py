"""Fatigue: Goodman and Soderberg safety factors, the critical hinge, the infinite-life stroke."""
import json

import numpy as np
import pytest

from flexure_sim.cli import main
from flexure_sim.engine.hinges import fatigue, stress
from flexure_sim.engine.hinges.stress import StressGeometry
from flexure_sim.engine.mechanism.loader import load_mechanism
from flexure_sim.engine.solver.simulation import Simulation

#: A 6061-T6 leaf 20 mm x 0.5 mm x 10 mm (length, thickness, width).
LEAF = StressGeometry("cantilever", (0.02, 0.0005, 0.01), 276e6, 310e6, 96.5e6, 5e8, "6061-T6")


def test_goodman_and_soderberg_against_a_hand_computation():
    """
    Leaf cycling between no load and 0.01 N m with 1 N of tension.

    By hand: section modulus w T^2 / 6 = 0.01 * 0.25e-6 / 6 = 4.1667e-10 m^3, bending
    0.01 / 4.1667e-10 = 24 MPa, axial 1 / (0.01 * 0.0005) = 0.2 MPa; the top fibre goes 0 ->
    24.2 MPa: amplitude = mean = 12.1 MPa. Goodman 1/n = 12.1/96.5 + 12.1/310 = 0.125389 +
    0.039032 = 0.164421, n = 6.08194; Soderberg 1/n = 0.125389 + 12.1/276 = 0.125389 + 0.043841
    = 0.169230, n = 5.90912 (Shigley 10th ed. Sec. 6-12).
    """
    w0, w1 = np.zeros(3), np.array([0.01, 0.0, 1.0])
    amplitude, mean = fatigue.cycle(LEAF, w0, w1)
    k = int(np.argmax(fatigue.utilisations(LEAF, amplitude, mean)["goodman"]))
    assert amplitude[k] == pytest.approx(12.1e6, rel=1e-12)
    assert mean[k] == pytest.approx(12.1e6, rel=1e-12)
    table = fatigue.table([("l", LEAF, (amplitude, mean))])
    assert table["l"]["goodman"] == pytest.approx(1 / (12.1 / 96.5 + 12.1 / 310), rel=1e-12)
    assert table["l"]["goodman"] == pytest.approx(6.08194, rel=1e-5)
    assert table["l"]["soderberg"] == pytest.approx(5.90912, rel=1e-5)


def test_a_compressive_mean_leaves_the_amplitude_alone():
    """Axial compression 10 N cycled: every fibre between 0 and -2 MPa: 1/n = 1 / 96.5."""
    amplitude, mean = fatigue.cycle(LEAF, np.zeros(3), np.array([0.0, 0.0, -10.0]))
    u = fatigue.utilisations(LEAF, amplitude, mean)
    assert np.all(mean < 0)
    np.testing.assert_allclose(u["goodman"], 1e6 / 96.5e6, rtol=1e-12)
    np.testing.assert_allclose(u["soderberg"], u["goodman"], rtol=0)


@pytest.mark.parametrize("geometry", [
    StressGeometry("notch", (0.003, 0.00025, 0.02)), StressGeometry("cantilever",
                                                                    (0.02, 0.0005, 0.01))])
def test_the_fibres_peak_is_the_peak_stress_to_the_bit(geometry):
    """One set of section terms: the largest fibre magnitude is the peak stress formula."""
    w = np.random.default_rng(3).normal(size=(200, 3)) * [0.05, 10.0, 10.0]
    np.testing.assert_array_equal(np.abs(geometry.fibres(w)).max(axis=-1), geometry.stress(w))


def test_the_stage_cycled_to_its_infinite_life_input_has_a_safety_factor_of_one():
    """Independent static solves at the input found give Goodman n = 1 at hinge c."""
    mech = load_mechanism("microstage")
    sim = Simulation(mech)
    report = fatigue.static_report(sim, 0.0, 2e-6)
    crit = report["critical"]["goodman"]
    hinges = report["hinges"]
    assert crit["hinge"] == min(hinges, key=lambda h: hinges[h]["goodman"]) == "c"
    assert crit["safety"] == pytest.approx(4.4514, rel=1e-4)
    assert hinges["c"]["soderberg"] < hinges["c"]["goodman"]  # S_y < S_u: more conservative
    for criterion in ("goodman", "soderberg"):
        life = report["infinite_life"][criterion]
        rest = Simulation(mech).static(0.0).snapshot.wrenches
        at = Simulation(mech).static(life["input"]).snapshot.wrenches
        found = fatigue.critical(fatigue.between(mech, rest, at), criterion)
        assert found == (life["hinge"], pytest.approx(1.0, abs=1e-8))
    # Stress grows nearly linearly with the input: 2 um times the safety factor.
    assert report["infinite_life"]["goodman"]["input"] == pytest.approx(2e-6 * 4.4514, rel=2e-3)
    # Fatigue, not yield, sets the stroke: 8.9 um against 16.7 um to yield.
    assert report["infinite_life"]["goodman"]["input"] < stress.stroke_limit(sim)[0] / 1.8


def test_simulate_static_and_stroke_limit_report_fatigue(capsys):
    assert main(["simulate", "microstage", "--drive", "step:2e-6", "--static", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    f = out["fatigue"]
    assert f["cycle"] == [0.0, 2e-6] and f["critical"]["goodman"]["hinge"] == "c"
    assert set(f["hinges"]) == set("abcdefg") and f["note"] is None
    assert f["hinges"]["c"]["material"] == "6061-T6" and f["hinges"]["c"]["cycles"] == 5e8
    assert main(["simulate", "microstage", "--drive", "step:2e-6", "--static",
                 "--cycle-from", "1e-6", "--json"]) == 0
    half = json.loads(capsys.readouterr().out)["fatigue"]
    # From 1 um the amplitude halves while the mean grows: a larger safety factor.
    assert half["hinges"]["c"]["amplitude"] == pytest.approx(f["hinges"]["c"]["amplitude"] / 2,
                                                             rel=1e-3)
    assert half["critical"]["goodman"]["safety"] > f["critical"]["goodman"]["safety"]
    assert main(["simulate", "microstage", "--drive", "step:2e-6", "--static"]) == 0
    text = capsys.readouterr().out
    assert "critical hinge (Goodman): c, n = 4.451; infinite life up to 8.9" in text
    assert main(["simulate", "microstage", "--stroke-limit", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["infinite_life"]["goodman"]["input"] == pytest.approx(
        f["infinite_life"]["goodman"]["input"], rel=1e-8)
    assert main(["simulate", "microstage", "--static", "--cycle-from", "nan"]) == 2


def test_analyse_reports_each_steps_fatigue_from_the_recorded_wrenches(tmp_path, capsys):
    """
    A recorded stage run: per step, each fibre between its extremes over the step's samples.

    Against the engine stepped here on the same schedule, with every tick's snapshot.
    """
    from tools_fixtures import DEMO_LEVELS, record_stage_run

    path = tmp_path / "stage.mcap"
    record_stage_run(path)  # rest 10 ms, then each level for 20 ms, 1 kHz ticks of 10 steps
    assert main(["analyse", str(path), "--json"]) == 0
    steps = json.loads(capsys.readouterr().out)
    mech = load_mechanism("microstage")
    sim = Simulation(mech, dt=1e-4, relinearize_tol=1e-4)
    samples = [[] for _ in DEMO_LEVELS]
    for tick in range(110):
        if tick >= 10 and (tick - 10) % 20 == 0:
            sim.set_command(DEMO_LEVELS[(tick - 10) // 20])
        sim.step(10)
        if tick >= 10:
            samples[(tick - 10) // 20].append(sim.snapshot().wrenches)
    for s, window in zip(steps, samples):
        w = np.array(window)  # (ticks, hinges, 3)
        table = fatigue.table((h.name, h.stress, fatigue.envelope(h.stress, w[:, i]))
                              for i, h in enumerate(mech.hinges))
        hinge, n = fatigue.critical(table)
        assert s["fatigue"]["hinge"] == hinge
        assert s["fatigue"]["goodman"] == pytest.approx(n, rel=1e-9)
    assert main(["analyse", str(path)]) == 0
    text = capsys.readouterr().out
    assert "fatigue n" in text and "fatigue over the whole run" in text


def test_sweep_fatigue_and_stroke_outputs_are_the_engines(tmp_path):
    """A grid of two notch thicknesses: each design against fatigue/stress called directly."""
    import yaml

    from flexure_sim.engine.analysis.study import StudyError, study_from_dict
    from flexure_sim.engine.mechanism.loader import mechanism_from_dict, resolve_mechanism_path
    from flexure_sim.tools.design.sweep_outputs import OUTPUTS, evaluate_batch

    names = ["fatigue_safety", "fatigue_safety_soderberg", "infinite_life_stroke", "stroke_limit"]
    spec = {"mechanism": "microstage", "input": 2e-6, "outputs": names,
            "parameters": [{"path": "stiffness_models.notch.h", "values": [2.0e-4, 3.0e-4]}]}
    study = study_from_dict(spec, str(tmp_path / "s.yaml"), OUTPUTS, base_dir=tmp_path)
    cols = evaluate_batch(study, 0, 2)
    assert list(cols["status"]) == ["ok", "ok"]
    base = yaml.safe_load(resolve_mechanism_path("microstage").read_text())
    for k, h in enumerate((2.0e-4, 3.0e-4)):
        base["stiffness_models"]["notch"]["h"] = h
        mech = mechanism_from_dict(base)
        sim = Simulation(mech)
        report = fatigue.static_report(sim, 0.0, 2e-6)
        assert cols["fatigue_safety"][k] == report["critical"]["goodman"]["safety"]
        assert cols["fatigue_safety_soderberg"][k] == report["critical"]["soderberg"]["safety"]
        assert cols["infinite_life_stroke"][k] == report["infinite_life"]["goodman"]["input"]
        assert cols["stroke_limit"][k] == stress.stroke_limit(sim)[0]
    # Refused at load, naming the output and what is missing.
    spec["mechanism"] = "xy_stage"
    spec["input"] = {"x": 1e-5, "y": 0.0}
    spec["parameters"][0]["values"] = [2.5e-4]
    with pytest.raises(StudyError, match="outputs: infinite_life_stroke: a stroke is the input "
                       "of one displacement drive"):
        study_from_dict(spec, "s.yaml", OUTPUTS)
    bare = tmp_path / "bare.yaml"
    bare.write_text(resolve_mechanism_path("microstage").read_text().replace(
        ", material: 6061-T6}", "}"))
    spec.update(mechanism=str(bare), input=2e-6, outputs=["fatigue_safety"])
    with pytest.raises(StudyError, match="outputs: fatigue_safety: no hinge of 'microstage' has "
                       "fatigue strengths: .*add material: NAME .*to stiffness_models.notch"):
        study_from_dict(spec, "s.yaml", OUTPUTS)
