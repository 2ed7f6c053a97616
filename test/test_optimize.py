"""
``flexure-sim optimize``: exact gradients, a known optimum, infeasibility, the optimised file.

Expected values come from elsewhere: central differences of re-evaluated designs, a root of the
gain found with the engine's static solves, dense sweep grids (tools/design/sweep_outputs.py),
and the engine's own static solve, modes, stress and fatigue of the written file.
"""
import json
from pathlib import Path

import numpy as np
import pytest
import scipy.optimize
import yaml

from flexure_sim.cli import main
from flexure_sim.engine.analysis import linear
from flexure_sim.engine.analysis.optimize import solve
from flexure_sim.engine.analysis.optimize_study import load_optimize_study
from flexure_sim.engine.analysis.study import study_from_dict
from flexure_sim.engine.hinges import fatigue, stress
from flexure_sim.engine.mechanism.loader import load_mechanism, mechanism_from_dict
from flexure_sim.engine.mechanism.loader import resolve_mechanism_path
from flexure_sim.engine.solver.simulation import Simulation
from flexure_sim.tools.design.sweep_outputs import OUTPUTS, evaluate_batch

H = {"lower": 1.5e-4, "upper": 4.0e-4}
STAGE_H = [{"name": f"h_{n}", "path": f"hinges.{n}.stiffness.h", **H} for n in "abcdefg"]


def _write(tmp_path: Path, spec: dict, name: str = "study.yaml") -> Path:
    path = tmp_path / name
    path.write_text(yaml.safe_dump(spec, sort_keys=False))
    return path


def _check_gradients(study, designs, rel=1e-3):
    """
    Every column's (and hinge part's) gradient against central differences, to 1e-6.

    Richardson-extrapolated central differences of re-evaluated designs, steps of ``rel`` of
    each variable's range (the drive forces are differences of large hinge forces: smaller
    steps meet their rounding), relative to the largest entry of the difference gradient.
    """
    for x in designs:
        got = study.evaluate(x, True)
        shifted = {}
        for k in range(len(x)):
            h = rel * (study.upper[k] - study.lower[k])
            for s in (1, -1, 2, -2):
                y = np.array(x, dtype=float)
                y[k] += s * h
                shifted[k, s] = study.evaluate(y, False)

        def central(pick):
            out = []
            for k in range(len(x)):
                h = rel * (study.upper[k] - study.lower[k])
                d1 = (pick(shifted[k, 1]) - pick(shifted[k, -1])) / (2 * h)
                d2 = (pick(shifted[k, 2]) - pick(shifted[k, -2])) / (4 * h)
                out.append((4 * d1 - d2) / 3)
            return np.array(out)

        for column, v in got.items():
            fd = central(lambda vals: vals[column].value)
            scale = max(np.abs(fd).max(), 1e-300)
            assert np.abs(v.gradient - fd).max() <= 1e-6 * scale, (column, v.gradient, fd)
            for hinge, (_, g) in v.parts.items():
                fd = central(lambda vals: vals[column].parts[hinge][0])
                assert np.abs(g - fd).max() <= 1e-6 * max(np.abs(fd).max(), 1e-300), (
                    column, hinge, g, fd)


@pytest.mark.slow
def test_stage_gradients_of_every_output_equal_central_differences(tmp_path):
    """Three random designs; variables of every kind: own and shared notch, frame, mass."""
    outputs = ["gain", "output_displacement", "compression", "drive_force", "peak_stress_ratio",
               "fatigue_safety", "fatigue_safety_soderberg", "stroke_limit",
               "infinite_life_stroke"]
    spec = {"mechanism": "microstage", "input": 2e-6, "cycle_from": 0.5e-6,
            "variables": [{"path": "hinges.c.stiffness.h", **H},
                          {"path": "stiffness_models.notch.D", "lower": 2e-3, "upper": 4e-3},
                          {"name": "a_x", "paths": ["hinges.a.a.at.0", "hinges.a.b.at.0"],
                           "offset": True, "lower": -1e-3, "upper": 1e-3},
                          {"path": "bodies.body4.mass", "lower": 0.01, "upper": 0.03}],
            "objective": {"maximize": "first_mode"},
            "constraints": [{"output": o, "min": 0.0} for o in outputs]}
    study = load_optimize_study(_write(tmp_path, spec))
    # hinge c's own copy of the notch still follows the shared D (seeded on both paths)
    assert study.setup.seeds[1] == ("stiffness_models.notch.D", "hinges.c.stiffness.D")
    rng = np.random.default_rng(27)
    designs = study.lower + rng.random((3, 4)) * (study.upper - study.lower)
    _check_gradients(study, designs)


@pytest.mark.slow
def test_xy_stage_gradients_of_the_gain_matrix_coupling_forces_and_fatigue(tmp_path):
    spec = {"mechanism": "xy_stage", "input": {"x": 1e-5, "y": 4e-6},
            "variables": [{"path": "stiffness_models.notch.h", **H},
                          {"path": "stiffness_models.leaf.thickness", "lower": 3e-4,
                           "upper": 7e-4},
                          {"path": "hinges.guide1_x.stiffness.length", "lower": 0.015,
                           "upper": 0.025},
                          {"path": "bodies.platform.mass", "lower": 0.03, "upper": 0.06}],
            "objective": {"minimize": "gain.y.x"},
            "constraints": [{"output": o, "min": -1e9} for o in (
                "gain.x.x", "gain.theta.y", "output_displacement.y", "drive_force.x",
                "drive_force.y", "first_mode", "peak_stress_ratio", "fatigue_safety")]}
    study = load_optimize_study(_write(tmp_path, spec))
    rng = np.random.default_rng(31)
    _check_gradients(study, study.lower + rng.random((3, 4)) * (study.upper - study.lower))


def test_values_are_the_sweeps_columns_at_the_same_design(tmp_path):
    """The optimiser's outputs are the sweep outputs of the same names (one definition each)."""
    names = ["gain", "output_displacement", "compression", "drive_force", "first_mode",
             "peak_stress_ratio", "fatigue_safety", "fatigue_safety_soderberg", "stroke_limit",
             "infinite_life_stroke"]
    spec = {"mechanism": "microstage", "input": 1.5e-6,
            "variables": [{"path": "hinges.c.stiffness.h", **H}],
            "objective": {"maximize": "first_mode"},
            "constraints": [{"output": o, "min": 0.0} for o in names]}
    study = load_optimize_study(_write(tmp_path, spec))
    got = study.evaluate([3.1e-4], False)
    sweep = study_from_dict({"mechanism": "microstage", "input": 1.5e-6, "outputs": names,
                             "parameters": [{"path": "hinges.c.stiffness.h",
                                             "values": [3.1e-4]}]}, "s.yaml", OUTPUTS)
    cols = evaluate_batch(sweep, 0, 1)
    for name in names:
        assert got[name].value == pytest.approx(cols[name][0], rel=1e-9, abs=1e-300), name


def _gain_at(h: float) -> float:
    doc = yaml.safe_load(resolve_mechanism_path("microstage").read_text())
    doc["stiffness_models"]["notch"]["h"] = h
    return Simulation(mechanism_from_dict(doc)).static(2e-6).snapshot.output / 2e-6


def test_known_optimum_the_gain_constraint_decides_the_neck(tmp_path):
    """
    Maximise the first mode over all seven necks together subject to gain >= 27.2.

    Thicker necks raise the first mode and lower the gain, so the optimum is the neck whose gain
    is 27.2: a root of the engine's static gain (brentq). The result must be that neck, at
    least as good as the best feasible point of a dense sweep grid, and satisfy the KKT
    conditions to 1e-6.
    """
    spec = {"name": "one_neck", "mechanism": "microstage", "input": 2e-6,
            "variables": [{"path": "stiffness_models.notch.h", **H}],
            "objective": {"maximize": "first_mode"},
            "constraints": [{"output": "gain", "min": 27.2}]}
    result = solve(load_optimize_study(_write(tmp_path, spec)))
    h_star = scipy.optimize.brentq(lambda h: _gain_at(h) - 27.2, 2.5e-4, 3.5e-4, xtol=1e-16,
                                   rtol=1e-15)
    assert result.status == "optimal"
    assert result.x[0] == pytest.approx(h_star, rel=1e-8)
    assert result.kkt["stationarity_relative"] <= 1e-6
    assert result.kkt["violation"] <= 1e-6 and result.kkt["complementarity"] <= 1e-6
    gain = [c for c in result.constraints if c["output"] == "gain"][0]
    assert gain["active"] and gain["multiplier"] > 0
    grid = np.linspace(H["lower"], H["upper"], 201)
    sweep = study_from_dict({"mechanism": "microstage", "input": 2e-6,
                             "outputs": ["gain", "first_mode"],
                             "parameters": [{"path": "stiffness_models.notch.h",
                                             "values": grid.tolist()}]}, "s.yaml", OUTPUTS)
    cols = evaluate_batch(sweep, 0, len(grid))
    best = cols["first_mode"][cols["gain"] >= 27.2].max()
    assert result.objective >= best * (1 - 1e-12)
    # The multiplier is the trade: relaxing the gain limit by dg buys mu dg of first mode.
    d_gain = -0.01
    spec["constraints"][0]["min"] = 27.2 + d_gain
    relaxed = solve(load_optimize_study(_write(tmp_path, spec, "relaxed.yaml")))
    assert (relaxed.objective - result.objective) / -d_gain == pytest.approx(
        gain["multiplier"], rel=2e-3)


def test_trust_constr_finds_the_same_optimum(tmp_path):
    spec = {"mechanism": "microstage", "input": 2e-6, "method": "trust-constr",
            "variables": [{"path": "stiffness_models.notch.h", **H}],
            "objective": {"maximize": "first_mode"},
            "constraints": [{"output": "gain", "min": 27.2}]}
    result = solve(load_optimize_study(_write(tmp_path, spec)))
    assert result.status == "optimal" and result.method == "trust-constr"
    h_star = scipy.optimize.brentq(lambda h: _gain_at(h) - 27.2, 2.5e-4, 3.5e-4, xtol=1e-16)
    assert result.x[0] == pytest.approx(h_star, rel=1e-7)


@pytest.mark.slow
def test_two_necks_against_a_dense_grid(tmp_path):
    """Hinges c and e, gain and fatigue: at least the best feasible point of a 31 x 31 grid."""
    variables = [{"name": "h_c", "path": "hinges.c.stiffness.h", **H},
                 {"name": "h_e", "path": "hinges.e.stiffness.h", **H}]
    constraints = [{"output": "gain", "min": 27.5}, {"output": "fatigue_safety", "min": 4.3}]
    spec = {"mechanism": "microstage", "input": 2e-6, "variables": variables,
            "objective": {"maximize": "first_mode"}, "constraints": constraints}
    result = solve(load_optimize_study(_write(tmp_path, spec)))
    assert result.status == "optimal" and result.kkt["stationarity_relative"] <= 1e-6
    grid = np.linspace(H["lower"], H["upper"], 31).tolist()
    sweep = study_from_dict({"mechanism": "microstage", "input": 2e-6,
                             "outputs": ["gain", "first_mode", "fatigue_safety"],
                             "parameters": [{"name": "h_c", "path": "hinges.c.stiffness.h",
                                             "values": grid},
                                            {"name": "h_e", "path": "hinges.e.stiffness.h",
                                             "values": grid}]}, "s.yaml", OUTPUTS)
    cols = evaluate_batch(sweep, 0, len(grid) ** 2)
    ok = (cols["gain"] >= 27.5) & (cols["fatigue_safety"] >= 4.3)
    assert ok.any()
    assert result.objective >= cols["first_mode"][ok].max() * (1 - 1e-12)


@pytest.mark.slow
def test_stage_over_its_seven_necks_writes_a_file_whose_figures_are_the_report(tmp_path,
                                                                               capsys):
    spec = {"name": "stage7", "mechanism": "microstage", "input": 2e-6, "variables": STAGE_H,
            "objective": {"maximize": "first_mode"},
            "constraints": [{"output": "gain", "min": 26.0},
                            {"output": "peak_stress_ratio", "max": 0.15},
                            {"output": "fatigue_safety", "min": 4.0}]}
    study = _write(tmp_path, spec)
    assert main(["optimize", str(study), "-o", str(tmp_path / "out")]) == 0
    text = capsys.readouterr().out
    assert "result: optimal" in text and "sensitivities at the optimum" in text
    report = json.loads((tmp_path / "out" / "stage7_report.json").read_text())
    assert report["status"] == "optimal" and report["kkt"]["stationarity_relative"] <= 1e-6
    files = report["files"]
    assert {Path(f).name for f in files.values()} == {
        "stage7.yaml", "stage7_iterations.csv", "stage7_iterations.png", "stage7_report.json"}
    assert len((tmp_path / "out" / "stage7_iterations.csv").read_text().splitlines()) == len(
        report["history"]) + 1
    # The written mechanism, solved by the engine (not the sensitivities), gives the report.
    mech = load_mechanism(files["mechanism"])
    sim = Simulation(mech)
    static = sim.static(2e-6)
    modes = linear.modes(linear.linearize(sim, 2e-6, wrenches=False, static=static))
    table = fatigue.between(mech, sim.static(0.0).snapshot.wrenches, static.snapshot.wrenches)
    engine = {"gain": static.snapshot.output / 2e-6, "first_mode": modes.frequencies[0],
              "peak_stress_ratio": stress.peak_ratio(stress.stress_table(
                  static.snapshot.wrenches, mech))[1],
              "fatigue_safety": fatigue.critical(table)[1]}
    for name, value in engine.items():
        assert report["values"][name] == pytest.approx(value, rel=1e-9), name
    assert [h.stress.dimensions[1] for h in mech.hinges] == report["x"]
    assert report["objective"] > 300.7  # better than the stage as designed (300.6 Hz)
    active = {c["text"] for c in report["constraints"] if c["active"]}
    assert "gain >= 26" in active
    assert main(["simulate", files["mechanism"], "--drive", "step:2e-6", "--static",
                 "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["gain"] == pytest.approx(26.0, rel=1e-9)


def test_an_infeasible_constraint_ends_with_a_message_and_the_least_violating_design(
        tmp_path, capsys):
    """A gain of 40 is beyond even the rigid levers' 36.4: the best is the highest gain."""
    spec = {"name": "too_much", "mechanism": "microstage", "input": 2e-6,
            "variables": STAGE_H[:4], "objective": {"maximize": "first_mode"},
            "constraints": [{"output": "gain", "min": 40.0}]}
    assert main(["optimize", str(_write(tmp_path, spec)), "-o", str(tmp_path / "out")]) == 3
    captured = capsys.readouterr()
    err = captured.err.strip().splitlines()
    assert len(err) == 1 and "Traceback" not in captured.err
    assert "infeasible: no design within the bounds meets every constraint" in err[0]
    assert "gain >= 40: " in err[0] and "short" in err[0]
    path = tmp_path / "out" / "too_much_least_violating.yaml"
    report = json.loads((tmp_path / "out" / "too_much_report.json").read_text())
    gain = Simulation(load_mechanism(path)).static(2e-6).snapshot.output / 2e-6
    assert report["values"]["gain"] == pytest.approx(gain, rel=1e-9)
    # No sampled design in the bounds has a higher gain than the least-violating one.
    rng = np.random.default_rng(5)
    samples = 1.5e-4 + rng.random((40, 4)) * 2.5e-4
    corners = [[a, b, c, d] for a in (1.5e-4, 4e-4) for b in (1.5e-4, 4e-4)
               for c in (1.5e-4, 4e-4) for d in (1.5e-4, 4e-4)]
    sweep = study_from_dict({"mechanism": "microstage", "input": 2e-6, "outputs": ["gain"],
                             "samples": 1, "seed": 0,
                             "parameters": [{"path": f"hinges.{n}.stiffness.h",
                                             "uniform": {"low": 1.5e-4, "high": 4e-4}}
                                            for n in "abcd"]}, "s.yaml", OUTPUTS)
    best = max(Simulation(sweep.mechanism(x)).static(2e-6).snapshot.output / 2e-6
               for x in list(samples) + corners)
    assert gain >= best * (1 - 1e-9)


@pytest.mark.parametrize("change, message", [
    ({"objective": {"maximize": "settling_time"}},
     "objective.maximize: settling_time: no exact gradient"),
    ({"objective": {"maximize": "speed"}}, "objective.maximize: unknown output 'speed'"),
    ({"objective": {"best": "first_mode"}}, "objective: expected {minimize: OUTPUT}"),
    ({"variables": [{"path": "hinges.a.stiffness.h", "lower": 3e-4, "upper": 2e-4}]},
     r"variables\[0\].upper: must be above lower"),
    ({"variables": [{"path": "hinges.a.stiffness.h", "lower": 3e-4, "upper": 4e-4}]},
     r"variables\[0\].start: the file's value \(the default start\) 0.00025 is outside"),
    ({"variables": [{"path": "hinges.a.stiffness.q", **H}]},
     r"variables\[0\].path: .*has no key 'q'"),
    ({"constraints": [{"output": "gain", "least": 3}]}, r"constraints\[0\].least: unknown key"),
    ({"constraints": [{"output": "gain"}]}, r"constraints\[0\]: give min, max or both"),
    ({"method": "newton"}, "method: expected one of SLSQP, trust-constr"),
    ({"starts": 0}, "starts: expected a positive integer"),
    ({"colour": 1}, "colour: unknown key"),
    ({"mechanism": "xy_stage", "input": {"x": 1e-5, "y": 0.0}, "variables": [
        {"path": "stiffness_models.notch.h", **H}], "constraints": [],
      "objective": {"minimize": "gain"}},
     r"objective.minimize: gain has a column per drive or output with 2 drives: name one "
     r"\(gain.x.x, gain.x.y"),
])
def test_a_bad_study_is_one_line_naming_the_key(tmp_path, capsys, change, message):
    import re

    spec = {"mechanism": "microstage", "variables": STAGE_H[:1],
            "objective": {"maximize": "first_mode"},
            "constraints": [{"output": "gain", "min": 27.0}], **change}
    path = _write(tmp_path, spec)
    assert main(["optimize", str(path), "-o", str(tmp_path / "out")]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and re.search(re.escape(str(path)) + ": " + message, err[0]), err
    assert not (tmp_path / "out").exists()


def test_a_design_that_cannot_be_evaluated_is_one_line_naming_it(tmp_path, capsys):
    """A neck of zero thickness at the start: the loader refuses it, the command names it."""
    spec = {"mechanism": "microstage", "variables": [{"name": "h_c",
                                                      "path": "hinges.c.stiffness.h",
                                                      "lower": 0.0, "upper": 4e-4,
                                                      "start": 0.0}],
            "objective": {"maximize": "first_mode"}}
    assert main(["optimize", str(_write(tmp_path, spec)), "-o", str(tmp_path / "out")]) == 1
    captured = capsys.readouterr()
    err = captured.err.strip().splitlines()
    assert len(err) == 1 and "Traceback" not in captured.err
    assert "the design h_c = 0 could not be evaluated: " in err[0]
    assert "hinges[2].stiffness.h: must be positive" in err[0]


def test_a_missing_or_binary_study_file_is_one_line(tmp_path, capsys):
    assert main(["optimize", str(tmp_path / "none.yaml")]) == 1
    assert "none.yaml: cannot read" in capsys.readouterr().err
    (tmp_path / "b.yaml").write_bytes(b"\x00\xff\x00binary")
    assert main(["optimize", str(tmp_path / "b.yaml")]) == 1
    err = capsys.readouterr().err
    assert "b.yaml: " in err and "Traceback" not in err


@pytest.mark.slow
def test_several_starts_on_a_local_dask_cluster(tmp_path, capsys):
    spec = {"name": "multi", "mechanism": "microstage", "input": 2e-6, "starts": 3, "seed": 4,
            "variables": [{"path": "stiffness_models.notch.h", **H}],
            "objective": {"maximize": "first_mode"},
            "constraints": [{"output": "gain", "min": 27.2}]}
    path = _write(tmp_path, spec)
    assert main(["optimize", str(path), "-o", str(tmp_path / "out"), "--workers", "2",
                 "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    starts = report["extra"]["starts"]
    assert len(starts) == 3 and len({s["start"][0] for s in starts}) == 3
    assert all(s["status"] == "optimal" for s in starts)
    h_star = scipy.optimize.brentq(lambda h: _gain_at(h) - 27.2, 2.5e-4, 3.5e-4, xtol=1e-16)
    assert report["x"][0] == pytest.approx(h_star, rel=1e-8)


def test_outputs_the_mechanism_cannot_give_are_refused(tmp_path, capsys):
    """A stage without an output body or a compression hinge: gain and compression by name."""
    text = resolve_mechanism_path("microstage").read_text()
    assert text.count("\noutput: {body: body4, axis: [1.0, 0.0]}\ncompression_hinge: a") == 1
    (tmp_path / "bare.yaml").write_text(text.replace(
        "\noutput: {body: body4, axis: [1.0, 0.0]}\ncompression_hinge: a", ""))
    for output, problem in (("gain", "'microstage' names no output"),
                            ("compression", "'microstage' names no compression_hinge")):
        spec = {"mechanism": "bare.yaml", "variables": STAGE_H[:1],
                "objective": {"maximize": "first_mode"},
                "constraints": [{"output": output, "min": 0.0}]}
        assert main(["optimize", str(_write(tmp_path, spec)), "-o", str(tmp_path / "o")]) == 1
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and f"objective/constraints: {output}: {problem}" in err[0], err
