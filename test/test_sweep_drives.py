"""
Sweeps of mechanisms with several drives (issue 13 item 1; docs/sweeps.md, "Several drives").

Each design's values against the engine called directly on a mechanism built here from the
YAML document (not through the study's paths), the gain matrix against central differences
of static solves, the step outputs against a time run stepped here, bad inputs refused at
load with the key, single-drive columns unchanged, and the command on the shipped XY grid.
"""
import copy
import functools
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest
import yaml

from flexure_sim.engine.mechanism.loader import (
    ConfigError, mechanism_from_dict, resolve_mechanism_path,
)
from flexure_sim.engine.solver.simulation import Simulation
from flexure_sim.engine.analysis.study import StudyError, load_study, study_from_dict
from flexure_sim.engine.mechanism.yaml_files import read_yaml
from flexure_sim.tools.run import response_metrics
from flexure_sim.tools.design.sweep_outputs import OUTPUTS, columns, evaluate_batch
from reference_figures import STAGE_GAIN

ROOT = Path(__file__).resolve().parent.parent
XY_GRID = ROOT / "config" / "studies" / "xy_stage_grid.yaml"
XY_OUTPUTS = ("x", "y", "theta")


def _xy_doc() -> dict:
    return copy.deepcopy(read_yaml(resolve_mechanism_path("xy_stage"), ConfigError))


def _xy_study(values, input={"x": 2.0e-6, "y": 1.0e-6}, outputs=("gain", "output_displacement",
              "drive_force"), **over):
    """Hinge pivot_x's own notch thickness over ``values`` (the other hinges keep theirs)."""
    data = {"mechanism": "xy_stage", "input": input, "outputs": list(outputs),
            "parameters": [{"name": "h_pivot_x", "path": "hinges.pivot_x.stiffness.h",
                            "values": list(values)}], **over}
    return study_from_dict(data, "xy.yaml", OUTPUTS)


def _direct_pivot_x(h: float) -> Simulation:
    """Return the XY stage with hinge pivot_x's notch h set by hand (its own copy of notch)."""
    doc = _xy_doc()
    hinge = next(x for x in doc["hinges"] if x["name"] == "pivot_x")
    hinge["stiffness"] = {**doc["stiffness_models"]["notch"], "h": h}
    return Simulation(mechanism_from_dict(doc, "xy_stage (by hand)"))


# ------------------------------------------------------------------------------ values
def test_each_designs_columns_equal_the_engine_called_directly():
    """
    gain.<o>.<d> is Simulation.static_gain, the rest a static solve at the study's input.

    For a thinner, the nominal and a thicker pivot_x; the mechanism is built here, not by the
    study. The x chain's hinge changes the x column of the gain matrix and leaves y's.
    """
    hs = (2.2e-4, 2.5e-4, 2.8e-4)
    study = _xy_study(hs)
    cols = evaluate_batch(study, 0, len(hs))
    assert cols["status"] == ["ok"] * 3
    for r, h in enumerate(hs):
        sim = _direct_pivot_x(h)
        G = sim.static_gain()
        for i, o in enumerate(XY_OUTPUTS):
            for k, d in enumerate(("x", "y")):
                assert cols[f"gain.{o}.{d}"][r] == G[i, k]
        snap = sim.static({"x": 2.0e-6, "y": 1.0e-6}).snapshot
        for o in XY_OUTPUTS:
            assert cols[f"output_displacement.{o}"][r] == snap.outputs[o]
        assert [cols["drive_force.x"][r], cols["drive_force.y"][r]] == list(snap.drive_forces)
    # pivot_x is in the x chain: x/x rises with its thickness (less of the lever's motion
    # lost to its compliance) by percents, y/y moves by ~1e-6 only (through the platform).
    assert cols["gain.x.x"][0] < cols["gain.x.x"][1] - 0.1 < cols["gain.x.x"][2] - 0.2
    np.testing.assert_allclose(cols["gain.y.y"], cols["gain.y.y"][1], rtol=1e-5)


def test_gain_matrix_is_the_slope_of_static_solves_central_differences():
    """
    A second method: (y(+du) - y(-du)) / 2 du of static solves about rest, drive by drive.

    With du = 1 nm the central difference agrees with the exact linearisation to ~3e-9
    (direct gains, rotation) and ~2e-6 (the cross-coupling, 1000 times smaller) relative.
    """
    cols = evaluate_batch(_xy_study([2.5e-4], outputs=("gain",)), 0, 1)
    sim, du = _direct_pivot_x(2.5e-4), 1e-9
    for d in ("x", "y"):
        plus = sim.static({"x": du if d == "x" else 0.0, "y": du if d == "y" else 0.0})
        minus = sim.static({"x": -du if d == "x" else 0.0, "y": -du if d == "y" else 0.0})
        for o in XY_OUTPUTS:
            slope = (plus.snapshot.outputs[o] - minus.snapshot.outputs[o]) / (2 * du)
            assert cols[f"gain.{o}.{d}"][0] == pytest.approx(slope, rel=1e-5)
    assert cols["gain.x.x"][0] == pytest.approx(6.8725, rel=1e-4)  # config/xy_stage.yaml
    assert cols["gain.y.x"][0] == pytest.approx(5.8015e-3, rel=1e-4)


def test_step_outputs_are_those_of_every_drive_stepped_together_per_output():
    """
    settling_time.<o> and overshoot.<o>: the step of both drives to the input, stepped here.

    The time run ends, 50 ms later, at the static solution (a second method for its end).
    """
    study = _xy_study([2.5e-4], outputs=("settling_time", "overshoot"))
    cols = evaluate_batch(study, 0, 1)
    sim = Simulation(_direct_pivot_x(2.5e-4).mechanism, dt=1e-4)  # the study's step.dt
    sim.set_command({"x": 2.0e-6, "y": 1.0e-6})
    y = []
    for _ in range(500):
        sim.step()
        y.append(sim.snapshot().outputs)
    t = 1e-4 * np.arange(1, 501)
    static = sim.static({"x": 2.0e-6, "y": 1.0e-6}).snapshot.outputs
    for o in XY_OUTPUTS:
        yo = np.array([s[o] for s in y])
        assert yo[-1] == pytest.approx(static[o], rel=1e-6)
        r = response_metrics.step_response(t, yo, 0.0, 0.0, band=0.02)
        assert cols[f"settling_time.{o}"][0] == r.settling_time
        assert cols[f"overshoot.{o}"][0] == r.overshoot
    assert 1e-3 < cols["settling_time.x"][0] < 1e-2  # a few actuator time constants (1 ms)


def test_a_force_drive_takes_newtons_and_reports_its_commanded_force(tmp_path):
    """Drive y made a force drive (N): input, stroke and units in newtons; values as static."""
    doc = _xy_doc()
    doc["constraints"][2] = {"type": "force", "name": "y", "body": "piezo_y", "axis": [0, 1],
                             "response_time": 1e-3, "stroke": [-5.0, 5.0], "slew_rate": 1e3}
    (tmp_path / "xy_force.yaml").write_text(yaml.safe_dump(doc))
    data = {"mechanism": "xy_force.yaml", "input": {"x": 2.0e-6, "y": 0.5},
            "outputs": ["gain", "output_displacement", "drive_force"],
            "parameters": [{"path": "stiffness_models.leaf.thickness", "values": [5e-4]}]}
    study = study_from_dict(data, str(tmp_path / "s.yaml"), OUTPUTS, base_dir=tmp_path)
    units = {c.name: c.unit for c in columns(study)}
    assert units["gain.x.y"] == "m/N" and units["gain.theta.y"] == "rad/N"
    assert units["drive_force.y"] == "N"
    cols = evaluate_batch(study, 0, 1)
    sim = Simulation(mechanism_from_dict(doc, "by hand"))
    snap = sim.static({"x": 2.0e-6, "y": 0.5}).snapshot
    assert cols["drive_force.y"][0] == 0.5
    assert cols["drive_force.x"][0] == snap.drive_forces[0]
    assert cols["output_displacement.y"][0] == snap.outputs["y"]
    assert cols["gain.y.y"][0] == sim.static_gain()[1, 1]
    with pytest.raises(StudyError, match=r"s.yaml: input.y: 6.0 N is outside drive y's "
                       r"stroke \[-5.0, 5.0\] N"):
        study_from_dict({**data, "input": {"x": 2.0e-6, "y": 6.0}}, str(tmp_path / "s.yaml"),
                        OUTPUTS, base_dir=tmp_path)


# ------------------------------------------------------------------------------ refused
@pytest.mark.parametrize("change, message", [
    ({"input": 1.0e-6}, "xy.yaml: input: one number for the 2 drives of 'xy_stage' (x, y): give "
     "one value per drive by name, e.g. input: {x: 1e-06, y: 0.0}"),
    ({"input": {"x": 1.0e-6}}, "xy.yaml: input: no value for drive y: give every drive's input "
     "(x, y)"),
    ({"input": {"x": 1.0e-6, "y": 0.0, "z": 0.0}},
     "xy.yaml: input.z: unknown drive 'z' (drives of 'xy_stage': x, y)"),
    ({"input": {"x": "ten", "y": 0.0}}, "xy.yaml: input.x: expected a finite number, got 'ten'"),
    ({"input": {"x": 1.0e-6, "y": 2.0e-5}},  # the second drive's stroke is checked too
     "xy.yaml: input.y: 2e-05 m is outside drive y's stroke [0.0, 1.5e-05] m"),
    ({"input": {"x": -1.0e-6, "y": 0.0}},
     "xy.yaml: input.x: -1e-06 m is outside drive x's stroke [0.0, 1.5e-05] m"),
    ({"input": [1.0e-6, 0.0]}, "xy.yaml: input: expected a number (one drive) or a mapping drive "
     "name -> value (drives of 'xy_stage': x, y), got [1e-06, 0.0]"),
])
def test_a_bad_several_drive_study_is_refused_at_load_naming_the_key(change, message):
    with pytest.raises(StudyError) as err:
        _xy_study([2.5e-4], **change)
    assert str(err.value).startswith(message), str(err.value)


def test_a_parameter_named_like_an_output_column_is_refused():
    with pytest.raises(StudyError, match=r"parameters\[0\].name: column 'gain.x.x' is named like "
                       "a column of the output gain"):
        study_from_dict({"mechanism": "xy_stage", "input": {"x": 0.0, "y": 0.0},
                         "outputs": ["gain"], "parameters": [
                             {"name": "gain.x.x", "path": "stiffness_models.notch.h",
                              "values": [2.5e-4]}]}, "xy.yaml", OUTPUTS)


# ------------------------------------------------------------------------------ one drive
def test_a_single_drive_study_keeps_its_columns_and_takes_its_drive_by_name():
    """
    The stage's columns are the outputs' names; {drive: u} equals u, to the bit.

    Gain 27.628 at 1.35 um (README reference figure, docs/sweeps.md "Checks").
    """
    base = {"mechanism": "microstage", "outputs": ["gain", "output_displacement", "compression",
                                                   "drive_force", "settling_time", "overshoot"],
            "parameters": [{"name": "h", "path": "stiffness_models.notch.h", "values": [2.5e-4]}]}
    by_number = study_from_dict({**base, "input": 1.35e-6}, "s.yaml", OUTPUTS)
    by_name = study_from_dict({**base, "input": {"drive": 1.35e-6}}, "s.yaml", OUTPUTS)
    assert by_name.input == by_number.input == 1.35e-6
    assert by_name.fingerprint() == by_number.fingerprint()
    assert [c.name for c in columns(by_number)] == base["outputs"]
    a, b = evaluate_batch(by_number, 0, 1), evaluate_batch(by_name, 0, 1)
    assert list(a) == ["sample", "h", *base["outputs"], "status", "error"]
    for name in base["outputs"]:
        assert a[name][0] == b[name][0]
    assert a["gain"][0] == pytest.approx(STAGE_GAIN, rel=1e-4)
    with pytest.raises(StudyError, match=r"s.yaml: input.drive: 3e-06 m is outside drive "
                       r"drive's stroke \[0.0, 2e-06\] m"):
        study_from_dict({**base, "input": {"drive": 3e-6}}, "s.yaml", OUTPUTS)


# ------------------------------------------------------------------------------ the command
def _cli(*args, cwd: Path) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(ROOT), "MPLBACKEND": "Agg"}
    return subprocess.run([sys.executable, "-m", "flexure_sim.cli", "sweep", *map(str, args)],
                          cwd=cwd, env=env, capture_output=True, text=True, timeout=300)


@pytest.mark.slow
def test_the_command_on_a_small_xy_grid_writes_the_engines_values(tmp_path):
    """
    The shipped XY grid cut to two notch thicknesses: columns, units, values, summary.

    Each row's gain matrix and static outputs equal the engine's on the design built here.
    """
    data = yaml.safe_load(XY_GRID.read_text())
    data["parameters"] = [{"name": "notch_h", "path": "stiffness_models.notch.h",
                           "values": [2.0e-4, 3.0e-4]}]
    study = tmp_path / "xy.yaml"
    study.write_text(yaml.safe_dump(data))
    res = _cli(study, "-o", tmp_path / "xy.parquet", "--workers", "1", "--json", "--no-plots",
               cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    summary = json.loads(res.stdout)
    assert summary["failed"] == 0 and summary["outputs"]["gain.theta.x"]["unit"] == "rad/m"
    table = pq.read_table(tmp_path / "xy.parquet")
    about = json.loads(table.schema.metadata[b"flexure_sim.study"])
    assert about["drives"] == ["x", "y"] and about["input"] == {"x": 1.0e-5, "y": 0.0}
    assert about["units"]["drive_force.y"] == "N" and about["units"]["gain.y.x"] == "m/m"
    rows = table.to_pydict()
    assert [n for n in rows if n.startswith("gain.")] == [
        f"gain.{o}.{d}" for o in XY_OUTPUTS for d in ("x", "y")]
    # Equal to rounding, not to the bit: the Dask worker runs BLAS on one thread, this process on
    # several, and some OpenBLAS builds (NumPy 1.26's wheel) round differently with thread count.
    same = functools.partial(pytest.approx, rel=1e-12, abs=0.0)
    for r, h in enumerate((2.0e-4, 3.0e-4)):
        doc = _xy_doc()
        doc["stiffness_models"]["notch"]["h"] = h
        sim = Simulation(mechanism_from_dict(doc, "by hand"))
        G = sim.static_gain()
        assert rows["gain.y.x"][r] == same(G[1, 0]) and rows["gain.theta.y"][r] == same(G[2, 1])
        snap = sim.static({"x": 1.0e-5, "y": 0.0}).snapshot
        assert rows["output_displacement.y"][r] == same(snap.outputs["y"])
        assert rows["drive_force.x"][r] == same(snap.drive_forces[0])
    # a number for the two drives: one line naming the key, before any work
    data["input"] = 1.0e-5
    study.write_text(yaml.safe_dump(data))
    res = _cli(study, "-o", tmp_path / "bad.parquet", "--workers", "1", cwd=tmp_path)
    assert res.returncode == 1
    assert res.stderr.strip().splitlines() == [
        f"flexure-sim sweep: error: {study}: input: one number for the 2 drives of 'xy_stage' "
        "(x, y): give one value per drive by name, e.g. input: {x: 1e-05, y: 0.0}"]


def test_the_shipped_xy_grid_loads_with_its_gain_matrix_columns():
    study = load_study(XY_GRID, OUTPUTS)
    assert study.samples == 9 and study.input == {"x": 1.0e-5, "y": 0.0}
    names = [c.name for c in columns(study)]
    assert names[:6] == [f"gain.{o}.{d}" for o in XY_OUTPUTS for d in ("x", "y")]
    assert "drive_force.y" in names and "settling_time.theta" in names


def test_first_mode_of_an_xy_design_is_what_the_modes_command_reports():
    """
    first_mode and its damping ratio with two drives: `flexure-sim modes xy_stage --input x=,y=`.

    The command run as a user runs it, at the study's input (the linear model with one input
    per drive, docs/analyses.md "Several drives").
    """
    cols = evaluate_batch(_xy_study([2.5e-4], outputs=("first_mode", "first_mode_damping")), 0, 1)
    out = subprocess.run([sys.executable, "-m", "flexure_sim.cli", "modes", "xy_stage",
                          "--input", "x=2e-6,y=1e-6", "--json"], capture_output=True, text=True,
                         env={**os.environ, "PYTHONPATH": str(ROOT)}, timeout=120, check=True)
    modes = json.loads(out.stdout)
    assert cols["status"][0] == "ok"
    assert cols["first_mode"][0] == modes["undamped_frequencies_hz"][0]
    assert cols["first_mode_damping"][0] == modes["modal_damping_ratios"][0]


def test_first_mode_of_a_mechanism_with_a_piezo_stack_is_refused_at_load():
    path = ROOT / "config" / "examples" / "piezo_stage.yaml"
    with pytest.raises(StudyError, match=r"s.yaml: outputs: first_mode: the linear model "
                       r"\(engine/analysis/linear.py, flexure-sim modes\) takes no drive with a "
                       r"piezo stack \(actuator: block\)"):
        study_from_dict({"mechanism": str(path), "outputs": ["first_mode"], "parameters": [
            {"path": "stiffness_models.leaf.thickness", "values": [1.0e-3]}]}, "s.yaml", OUTPUTS)
