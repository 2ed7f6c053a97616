"""
The engine's tick report (engine/solver/tick_report.py) is the Snapshot, in one compiled call.

Every number the stage node publishes comes from the report now; the Snapshot's own code
(``snapshot.snapshot`` on the Model) is the reference. They are compared to the bit along runs
of every kind of mechanism the loader knows: one displacement drive with a compression hinge
(the stage), two drives (the XY stage), hinge damping and a damping matrix, a force drive,
a rotational drive and output, prescribed-displacement drives (``response_time: 0``) following
programs (alone and next to a lagged drive), and a piezo actuator (reported through the Snapshot
itself). The drives' full wrenches are among the parts compared.
"""
from __future__ import annotations

import copy

import numpy as np
import pytest
import yaml

from flexure_sim.engine.hinges.stress import stress_table
from flexure_sim.engine.mechanism.builtins import builtin_dir
from flexure_sim.engine.mechanism.loader import load_mechanism
from flexure_sim.engine.solver.simulation import Program, Simulation
from flexure_sim.engine.solver.tick_report import ReportView, TickReport
from test_multidrive import _microstage_doc, mechanism_from_dict, rotor
from test_prescribed_drive import PARALLELOGRAM, _prescribed


def force_drive_stage():
    doc, source = _microstage_doc()
    doc = copy.deepcopy(doc)
    doc["constraints"][1] = {"type": "force", "name": "push", "body": "body6", "axis": [1, 0],
                             "response_time": 1e-3, "stroke": [-10, 10], "slew_rate": 1e3}
    doc.pop("compression_hinge")
    return mechanism_from_dict(doc, source)


def turning_rotor():
    return rotor({"type": "drive", "name": "turn", "body": "disc", "axis": "theta",
                  "response_time": 1e-3, "stroke": [-0.01, 0.01], "slew_rate": 1.0},
                 [{"name": "angle", "body": "disc", "coordinate": "theta"}])


def xy_one_prescribed():
    """Return the XY stage with its first drive a prescribed displacement, the other lagged."""
    doc = yaml.safe_load((builtin_dir() / "xy_stage.yaml").read_text())
    drive = next(c for c in doc["constraints"] if c["type"] == "drive")
    drive["response_time"] = 0.0
    return mechanism_from_dict(doc, str(builtin_dir() / "xy_stage.yaml"))


MECHANISMS = {
    "microstage": lambda: load_mechanism("microstage"),
    "microstage_realistic": lambda: load_mechanism("microstage_realistic"),
    "xy_stage": lambda: load_mechanism("xy_stage"),
    "fourbar_mixed": lambda: load_mechanism("fourbar_mixed"),
    "parallelogram": lambda: load_mechanism(builtin_dir() / "examples"
                                            / "parallelogram_stage.yaml"),
    "piezo": lambda: load_mechanism(builtin_dir() / "examples" / "piezo_stage.yaml"),
    "force_drive": force_drive_stage,
    "rotor": turning_rotor,
    "prescribed": lambda: _prescribed(PARALLELOGRAM),
    "xy_prescribed": xy_one_prescribed,
}


def snapshot_values(sim, snap):
    """Return the Snapshot's numbers by report part (the reference)."""
    model = sim.model
    return {"poses": snap.poses.ravel(), "deflections": snap.deflections.ravel(),
            "wrenches": snap.wrenches.ravel(), "drive_inputs": snap.drive_inputs,
            "drive_forces": snap.drive_forces, "drive_positions": snap.drive_positions,
            "drive_wrenches": snap.drive_wrenches.ravel(),
            "outputs": np.array([snap.outputs[n] for n in model.output_names]),
            "compression": np.array([np.nan if snap.compression is None
                                     else snap.compression])}


def commands(model, k):
    """Return a command per drive at step k of a run: a sine, back to 0 now and then."""
    out = []
    for j, d in enumerate(model.drives):
        span = 0.4 * (d.stroke[1] - d.stroke[0]) if d.actuator is None else 40.0
        out.append(span * (0.5 + 0.5 * np.sin(0.7 * k + j)) if k % 9 else 0.0)
    return out[0] if len(out) == 1 else out


@pytest.mark.parametrize("name", sorted(MECHANISMS))
def test_the_report_is_the_snapshot_to_the_bit_along_a_run(name):
    sim = Simulation(MECHANISMS[name](), energy=False)
    report = TickReport(sim.model)
    assert report.compiled == (name != "piezo")  # a piezo actuator: through the Snapshot
    for k in range(25):
        if sim.model.drives:
            sim.set_command(commands(sim.model, k))
        sim.step(1 + k % 4)
        for values in (report.fill_data(sim.data), report.fill(sim.state)):
            want = snapshot_values(sim, sim.snapshot())
            for part, expected in want.items():
                np.testing.assert_array_equal(values[report.index[part]], expected,
                                              err_msg=f"{name}, {part}, step {k}")
            assert report.finite
    if len(sim.model.output_names) == 1:
        assert values[report.index["outputs"]][0] == sim.snapshot().output


def assert_report_is_snapshot(sim, report, values, what):
    """Assert the report ``values`` are the Snapshot's numbers of ``sim``'s state, to the bit."""
    for part, expected in snapshot_values(sim, sim.snapshot()).items():
        np.testing.assert_array_equal(values[report.index[part]], expected,
                                      err_msg=f"{what}, {part}")
    assert report.finite


@pytest.mark.parametrize("name", ["prescribed", "xy_prescribed"])
def test_the_report_is_the_snapshot_along_programs_and_their_ends(name):
    """
    Prescribed drives along programs, through the pieces' starts and ends on the step grid.

    A cycloid of 2 ms and a ramp of 1.5 ms on the prescribed drive, a sine on a lagged one:
    the report reads each prescribed drive's displacement from the piece its last step held.
    """
    sim = Simulation(MECHANISMS[name](), energy=False)
    drives = sim.model.drives
    prescribed = drives.names[drives.prescribed[0]]
    lagged = [drives.names[k] for k in drives.lagged]
    report = TickReport(sim.model)
    assert report.compiled
    programs = {prescribed: Program("cycloid", 2e-6, duration=2e-3, start=5e-4)}
    if lagged:
        programs[lagged[0]] = Program("sine", 1e-6, frequency=300.0, start=2e-4)
    sim.set_programs(programs)
    for k in range(45):
        if k == 30:
            sim.set_programs({prescribed: Program("ramp", -1e-6, duration=1.5e-3,
                                                  start=sim.state.t, initial=2e-6)})
        sim.step(1 + k % 2)
        for values in (report.fill_data(sim.data), report.fill(sim.state)):
            assert_report_is_snapshot(sim, report, values, f"{name}, step {k}")


def test_a_command_set_after_the_step_is_the_one_reported():
    """fill_data after set_command: the new command's drive force, not the last step's."""
    sim = Simulation(load_mechanism("microstage"), energy=False)
    report = TickReport(sim.model)
    sim.set_command(1e-6)
    sim.step(3)
    report.fill_data(sim.data)
    before = report.values[report.index["drive_forces"]].copy()
    sim.set_command(4e-6)
    values = report.fill_data(sim.data)
    assert_report_is_snapshot(sim, report, values, "after set_command")
    assert values[report.index["drive_forces"]][0] != before[0]


@pytest.mark.parametrize("name", ["microstage", "xy_stage"])
def test_stress_ratios_are_the_stress_tables(name):
    """The report's sigma / sigma_y against the engine's hinge-by-hinge stress table."""
    mech = MECHANISMS[name]()
    sim = Simulation(mech, energy=False)
    sim.set_command(commands(sim.model, 3))
    sim.step(40)
    report = TickReport(sim.model)
    ratios = report.fill(sim.state)[report.index["stress_ratios"]]
    table = stress_table(sim.snapshot().wrenches, mech)
    for k, hinge in enumerate(mech.hinges):
        expected = table[hinge.name]["ratio"]
        if expected is None:
            assert np.isnan(ratios[k])
        else:
            assert ratios[k] == pytest.approx(expected, rel=1e-12)
    view = report.view()
    np.testing.assert_array_equal(view.stress_ratios, ratios)
    np.testing.assert_array_equal(ReportView.from_snapshot(sim.snapshot(), mech).stress_ratios,
                                  ratios)
    assert view.drive_force == sim.snapshot().drive_force
    np.testing.assert_array_equal(view.poses, sim.snapshot().poses)


def test_a_non_finite_state_is_reported_as_such():
    """A state the engine could not have produced: NaN in a velocity, then in a pose."""
    sim = Simulation(load_mechanism("microstage"), energy=False)
    sim.set_command(1e-6)
    sim.step(5)
    report = TickReport(sim.model)
    report.fill(sim.state)
    assert report.finite
    state = sim.state.copy()
    state.v[4] = np.nan
    report.fill(state)
    assert not report.finite
    state = sim.state.copy()
    state.z[10] = np.inf
    report.fill(state)
    assert not report.finite
    report.fill(sim.state)
    assert report.finite
