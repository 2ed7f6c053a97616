"""
The tools on runs with several drives or outputs (issue 13, item 4), written without DDS.

Recordings from engine runs (multidrive_fixtures) and step-response arrays with textbook
answers: the gain matrix against the engine's static solve at the same inputs (a second
method: Newton on the static equations, not the dynamic run); settling time and overshoot
against the first- and second-order formulas; a force drive against Euler-Bernoulli.
test_tools_multidrive_node.py checks the real node's recording against simulate --static.
"""
from __future__ import annotations

import csv
import json
import math

import numpy as np
import pytest

from flexure_sim import cli
from flexure_sim.tools.run.step_analysis import Step
from flexure_sim.tools.run.gain_matrix import analyse_drive_steps, gain_pairs, matrix
from flexure_sim.tools.run.plot import figure_title

from multidrive_fixtures import record_drives_run
from test_node_multidrive import LEAF_ROTOR
from reference_figures import STAGE_GAIN

U = 1e-6
#: x steps at 10 ms, y at 60 ms, each held 50 ms (fifty actuator time constants).
SCHEDULE = [(0.01, "x", U), (0.06, "y", U)]


def flexure_sim(capsys, *args) -> tuple[int, str, str]:
    code = cli.main([str(a) for a in args])
    out, err = capsys.readouterr()
    return code, out, err


@pytest.fixture(scope="module")
def xy(tmp_path_factory):
    path = tmp_path_factory.mktemp("xy") / "xy.mcap"
    sim = record_drives_run(path, "xy_stage", SCHEDULE, 0.11)
    return path, sim


def test_gain_matrix_of_an_xy_run_equals_the_static_solve_at_the_same_inputs(capsys, xy):
    path, sim = xy
    code, out, err = flexure_sim(capsys, "analyse", path, "--json")
    assert code == 0, err
    result = json.loads(out)
    names = list(sim.model.output_names)

    def outputs(ux: float, uy: float) -> np.ndarray:
        snap = sim.static({"x": ux, "y": uy}).snapshot
        return np.array([snap.outputs[o] for o in names])

    # Secant gains of the two steps: x 0 -> U (y at 0), then y 0 -> U (x held at U).
    expected = np.column_stack([(outputs(U, 0.0) - outputs(0.0, 0.0)) / U,
                                (outputs(U, U) - outputs(U, 0.0)) / U])
    gm = result["gain_matrix"]
    assert gm["drives"] == ["x", "y"] and gm["outputs"] == names == ["x", "y", "theta"]
    measured = np.array(gm["matrix"], dtype=float)
    np.testing.assert_allclose(measured, expected, rtol=0, atol=1e-6 * np.abs(expected).max())
    # The secant over a 1 um step is not the gain at rest: the platform's rotation is
    # nonlinear (2e-3 of the largest gain per um), which is why the node test steps 10 nm.
    at_rest = np.array(result["static_gain_matrix"]["matrix"])
    np.testing.assert_allclose(at_rest, sim.static_gain(), rtol=1e-12)
    assert abs(measured[2, 0] - at_rest[2, 0]) > 1e-3 * np.abs(at_rest).max()
    # Per step, the static solve at the same inputs is reported beside the measured gain.
    for s in result["steps"]:
        for o in names:
            r = s["outputs"][o]
            assert r["gain"] == pytest.approx(r["static_gain"], rel=1e-5, abs=1e-9)
    assert [(p["drive"], p["output"], p["unit"]) for p in result["pairs"]][:3] == [
        ("x", "x", "m/m"), ("x", "y", "m/m"), ("x", "theta", "rad/m")]
    code, out, err = flexure_sim(capsys, "analyse", path)
    assert code == 0, err
    assert "gain matrix" in out and "theta [rad]" in out and "per pair" in out


# ---------------------------------------------------------------- textbook responses
def test_gain_settling_and_overshoot_per_pair_of_textbook_responses():
    dt, tau, zeta, wn = 1e-5, 1e-3, 0.3, 2 * math.pi * 500
    t = np.arange(1, 30001) * dt                       # 0.3 s
    t1, t2 = 0.1, 0.2

    def lag(t0: float) -> np.ndarray:  # first-order lag step response, 0 before t0
        return np.where(t > t0, 1.0 - np.exp(-(t - t0) / tau), 0.0)

    def second(t0: float) -> np.ndarray:  # second-order (zeta < 1) step response
        s = np.clip(t - t0, 0.0, None)
        wd = wn * math.sqrt(1 - zeta**2)
        y = 1 - np.exp(-zeta * wn * s) * (np.cos(wd * s) + zeta / math.sqrt(1 - zeta**2)
                                          * np.sin(wd * s))
        return np.where(t > t0, y, 0.0)

    ux, uy = 2e-6 * lag(t1), 1e-6 * lag(t2)
    inputs = {"x": (t, ux), "y": (t, uy)}
    outputs = {"a": (t, 3.0 * ux - 0.5 * uy),          # gains 3 and -0.5, lag-shaped
               "b": (t, 4e-6 * second(t1)),             # 2 per m of x, second order
               "c": (t, np.zeros_like(t))}              # coupled to nothing
    steps = {"x": [Step(t1, 2e-6, 0.0)], "y": [Step(t2, 1e-6, 0.0)]}
    result = analyse_drive_steps(steps, inputs, outputs, float(t[-1]))
    pairs = gain_pairs(result, ["x", "y"], ["a", "b", "c"])
    g = np.array(matrix(pairs, ["x", "y"], ["a", "b", "c"]), dtype=float)
    np.testing.assert_allclose(g, [[3.0, -0.5], [2.0, 0.0], [0.0, 0.0]], rtol=1e-9, atol=1e-12)
    by = {(p.drive, p.output): p for p in pairs}
    # A first-order lag settles to 2 % in tau ln 50 and does not overshoot.
    assert by["x", "a"].settling_time == pytest.approx(tau * math.log(50), rel=1e-3)
    assert by["x", "a"].overshoot == 0.0
    # A second-order system overshoots by exp(-pi zeta / sqrt(1 - zeta^2)).
    assert by["x", "b"].overshoot == pytest.approx(
        math.exp(-math.pi * zeta / math.sqrt(1 - zeta**2)), rel=1e-4)
    assert by["x", "c"].settling_time is None and by["x", "c"].steps == 1
    assert all(s.clean and s.input_settled for s in result)


def test_a_step_while_another_drive_moves_measures_no_gain():
    t = np.arange(1, 2001) * 1e-4
    ux = np.where(t > 0.05, 1e-6, 0.0)
    uy = np.where(t > 0.05, 1e-6, 0.0) + np.where(t > 0.12, 1e-6 * (t - 0.12), 0.0)
    inputs = {"x": (t, ux), "y": (t, uy)}
    outputs = {"a": (t, ux + uy)}
    steps = {"x": [Step(0.05, 1e-6, 0.0), Step(0.1, 1e-6 + 1e-9, 1e-6)],
             "y": [Step(0.05, 1e-6, 0.0)]}
    result = analyse_drive_steps(steps, inputs, outputs, float(t[-1]))
    assert [(s.drive, s.clean) for s in result] == [("x", False), ("y", False), ("x", False)]
    assert "stepped at the same time" in result[0].notes[0]
    assert any("drive y did not hold" in n for n in result[2].notes)
    assert matrix(gain_pairs(result, ["x", "y"], ["a"]), ["x", "y"], ["a"]) == [[None, None]]


# ---------------------------------------------------------------- a force drive
@pytest.fixture(scope="module")
def rotor(tmp_path_factory):
    work = tmp_path_factory.mktemp("rotor")
    yaml_path = work / "leaf_rotor.yaml"
    yaml_path.write_text(LEAF_ROTOR)
    path = work / "rotor.mcap"
    record_drives_run(path, str(yaml_path), [(0.01, "torquer", 2e-5)], 0.6)
    return path


def test_a_force_drives_gain_is_the_leafs_compliance_in_rad_per_newton_metre(capsys, rotor):
    # A leaf under an end moment M turns by M L / (E I) (Euler-Bernoulli).
    k_bend = 69.0e9 * (0.01 * 0.0005**3 / 12) / 0.02
    code, out, err = flexure_sim(capsys, "analyse", rotor, "--json", "--no-static")
    assert code == 0, err
    result = json.loads(out)
    assert result["drives"][0]["command"] == "/drive/torquer/force"
    assert result["outputs"] == [{"name": "angle", "unit": "rad",
                                  "topic": "/output/displacement"}]
    assert result["gain_matrix"]["matrix"][0][0] == pytest.approx(1 / k_bend, rel=1e-6)
    assert result["pairs"][0]["unit"] == "rad/(N m)"
    code, out, err = flexure_sim(capsys, "info", rotor, "--json")
    assert code == 0, err
    info = json.loads(out)
    assert info["drives"] == [{
        "name": "torquer", "kind": "force", "unit": "N m", "command": "/drive/torquer/force",
        "command_unit": "N m", "input": "/drive/torquer/input",
        "response": "/drive/torquer/position",
        "response_unit": "rad", "stroke_min": "-0.001", "stroke_max": "0.001",
        "slew_rate": None}]
    assert info["outputs"] == [{"name": "angle", "unit": "rad", "topic": "/output/displacement"}]
    # The single drive's limits, recorded but unused beside the per-drive ones, are not shown.
    assert info["parameters"] == {"mechanism": info["parameters"]["mechanism"],
                                  "time_mode": "lockstep", "publish_rate": "1000.0",
                                  "sim_step": "0.0001"}
    code, out, err = flexure_sim(capsys, "info", rotor)
    assert "stroke_max" not in out.split("Drives:")[0]
    assert "Drives:       torquer (force, N m; stroke [-0.001, 0.001] N m): command " \
        "/drive/torquer/force, input /drive/torquer/input, /drive/torquer/position [rad]" in out


def test_export_signals_names_every_drive_and_output_column(capsys, rotor, tmp_path):
    code, out, err = flexure_sim(capsys, "export", rotor, "--csv", tmp_path, "--signals")
    assert code == 0, err
    assert "signals.csv" in out
    with (tmp_path / "signals.csv").open() as f:
        rows = list(csv.DictReader(f))
    assert list(rows[0]) == ["time", "drive/torquer/force", "drive/torquer/input",
                             "drive/torquer/position", "output/displacement"]
    assert len(rows) == 600 and rows[0]["time"] == "0.001000000"
    # The command is held from the tick it was applied at; before it, no command.
    assert rows[8]["drive/torquer/force"] == "" and float(rows[9]["drive/torquer/force"]) == 2e-5
    assert float(rows[-1]["drive/torquer/position"]) == pytest.approx(
        float(rows[-1]["output/displacement"]), rel=1e-12)


def _recorded_floats(path) -> tuple[dict[str, tuple[np.ndarray, np.ndarray]], float]:
    """
    Return every Float64 topic of a run as (log time s, value), and the last log time (s).

    Read with the mcap library and rclpy's deserializer, not with the tools' Run.
    """
    from mcap.reader import make_reader
    from rclpy.serialization import deserialize_message
    from std_msgs.msg import Float64

    found: dict[str, tuple[list, list]] = {}
    last = 0
    with open(path, "rb") as f:
        for schema, channel, message in make_reader(f).iter_messages(log_time_order=True):
            last = max(last, message.log_time)
            if schema.name == "std_msgs/msg/Float64":
                t, v = found.setdefault(channel.topic, ([], []))
                t.append(message.log_time / 1e9)
                v.append(deserialize_message(message.data, Float64).data)
    return {k: (np.array(t), np.array(v)) for k, (t, v) in found.items()}, last / 1e9


def _data_lines(ax) -> dict:
    """Return the labelled lines of an axis by label (the step markers are unlabelled)."""
    return {ln.get_label(): ln for ln in ax.get_lines() if not ln.get_label().startswith("_")}


def _assert_line(line, t_s, values, factor: float) -> None:
    """Assert a line draws (t_s, values) in ms and ``factor`` units (to conversion rounding)."""
    np.testing.assert_allclose(np.asarray(line.get_xdata(), float), np.asarray(t_s) * 1e3,
                               rtol=1e-14, atol=0)
    np.testing.assert_allclose(np.asarray(line.get_ydata(), float), np.asarray(values) * factor,
                               rtol=1e-14, atol=0)


def test_plot_draws_every_drive_and_output_with_names_and_units(capsys, xy, tmp_path):
    import matplotlib.pyplot as plt

    from flexure_sim.tools.run.plot import plot_run
    from flexure_sim.tools.run.runlog import load_run

    path, _ = xy
    code, out, err = flexure_sim(capsys, "plot", path, "-o", tmp_path)
    assert code == 0, err
    assert figure_title(tmp_path / "drives_outputs.png") == "Drives and outputs"
    assert figure_title(tmp_path / "drive_forces.png") == "Drive forces"
    assert not (tmp_path / "input_output.png").exists()
    assert not (tmp_path / "body_poses.png").exists()
    # The same figures built in-process and left open: every line against the recording.
    figures: dict = {}
    written = plot_run(load_run(path), tmp_path / "kept", figures=figures)
    try:
        assert sorted(figures) == sorted(p.stem for p, _ in written) == [
            "drive_forces", "drives_outputs"]
        rec, t_end = _recorded_floats(path)
        assert t_end == pytest.approx(0.11)
        # The 0.11 s run is plotted in ms; displacements in um, the rotation in urad.
        fig = figures["drives_outputs"]
        assert [ax.get_ylabel() for ax in fig.axes] == [
            "drive x [µm]", "drive y [µm]", "output x [µm]", "output y [µm]",
            "output theta [µrad]"]
        assert fig.axes[-1].get_xlabel() == "simulation time [ms]"
        steps = sorted(t for t, _, _ in SCHEDULE)
        for ax, name in zip(fig.axes, ("x", "y")):
            lines = _data_lines(ax)
            labels = [f"drive {name}: applied input", f"drive {name}: command"]
            assert sorted(lines) == sorted(labels)
            assert [t.get_text() for t in ax.get_legend().get_texts()] == labels
            t_u, u = rec[f"/drive/{name}/input"]
            assert len(t_u) == 110
            _assert_line(lines[labels[0]], t_u, u, 1e6)
            # The command, held from the recorded command on, the rest input before it.
            (t_c,), (c,) = rec[f"/drive/{name}/displacement"]
            assert c == U and u[0] == 0.0
            _assert_line(lines[labels[1]], [t_u[0], t_c, t_c, t_end], [u[0], u[0], c, c], 1e6)
            assert lines[labels[1]].get_linestyle() == "--"
            # The steps the analysis found are marked where the commands were recorded.
            marks = sorted(ln.get_xdata()[0] for ln in ax.get_lines()
                           if ln.get_label().startswith("_"))
            np.testing.assert_allclose(marks, np.array(steps) * 1e3, rtol=1e-12)
        for ax, (name, factor) in zip(fig.axes[2:], (("x", 1e6), ("y", 1e6), ("theta", 1e6))):
            lines = _data_lines(ax)
            assert list(lines) == [f"output {name}"]
            assert [t.get_text() for t in ax.get_legend().get_texts()] == [f"output {name}"]
            _assert_line(lines[f"output {name}"], *rec[f"/output/{name}/displacement"], factor)
        # Drive forces: one panel per drive, one line each, its recorded actuator force.
        fig = figures["drive_forces"]
        assert [ax.get_ylabel() for ax in fig.axes] == ["drive x [N]", "drive y [N]"]
        for ax, name in zip(fig.axes, ("x", "y")):
            lines = _data_lines(ax)
            assert list(lines) == [f"drive {name}: actuator force"]
            _assert_line(lines[f"drive {name}: actuator force"],
                         *rec[f"/drive/{name}/force"], 1.0)
        # Each drive's data differ, so a swapped or repeated line could not pass.
        assert not np.array_equal(rec["/drive/x/force"][1], rec["/drive/y/force"][1])
        assert not np.array_equal(rec["/output/x/displacement"][1],
                                  rec["/output/y/displacement"][1])
    finally:
        for f in figures.values():
            plt.close(f)


def test_a_namespaced_run_of_drive_and_output_topics_only_is_found(capsys, tmp_path):
    path = tmp_path / "ns.mcap"
    record_drives_run(path, "xy_stage", SCHEDULE, 0.11, namespace="/left")
    code, out, err = flexure_sim(capsys, "analyse", path, "--json", "--no-static")
    assert code == 0, err
    result = json.loads(out)
    assert result["outputs"][0]["topic"] == "/left/output/x/displacement"
    assert result["gain_matrix"]["matrix"][0][0] == pytest.approx(6.8725, rel=1e-4)


def test_non_finite_output_samples_are_ignored_and_counted(capsys, xy, tmp_path):
    path = tmp_path / "nan.mcap"
    record_drives_run(path, "xy_stage", SCHEDULE, 0.11, nan_ticks=(30, 80, 110))
    code, out, err = flexure_sim(capsys, "analyse", path, "--json", "--no-static")
    assert code == 0, err
    assert "/output/x/displacement: 3 non-finite sample(s) ignored" in err
    clean = json.loads(flexure_sim(capsys, "analyse", xy[0], "--json", "--no-static")[1])
    # The last sample (tick 110) is the settled value of the y step: the one before it is
    # taken, equal to it to the settling of the 50 ms dwell.
    np.testing.assert_allclose(np.array(json.loads(out)["gain_matrix"]["matrix"], dtype=float),
                               np.array(clean["gain_matrix"]["matrix"], dtype=float),
                               rtol=0, atol=1e-9)


def test_one_drive_with_two_outputs_keeps_the_drives_topics_and_gets_a_column(capsys, tmp_path):
    from flexure_sim.engine.mechanism.loader import resolve_mechanism_path

    text = resolve_mechanism_path("microstage").read_text().replace(
        "output: {body: body4, axis: [1.0, 0.0]}",
        "outputs:\n  - {name: x, body: body4, axis: [1.0, 0.0]}\n"
        "  - {name: yaw, body: body4, coordinate: theta}")
    assert "outputs:" in text
    (tmp_path / "stage2.yaml").write_text(text)
    path = tmp_path / "stage2.mcap"
    sim = record_drives_run(path, str(tmp_path / "stage2.yaml"), [(0.01, "drive", 1e-6)], 0.04)
    code, out, err = flexure_sim(capsys, "analyse", path, "--json")
    assert code == 0, err
    result = json.loads(out)
    assert result["drives"][0]["command"] == "/drive/displacement"
    assert [o["topic"] for o in result["outputs"]] == ["/output/x/displacement",
                                                       "/output/yaw/displacement"]
    snap = sim.static(1e-6).snapshot
    expected = [[snap.outputs["x"] / 1e-6], [snap.outputs["yaw"] / 1e-6]]
    np.testing.assert_allclose(result["gain_matrix"]["matrix"], expected, rtol=1e-6,
                               atol=1e-6 * abs(expected[0][0]))
    assert result["gain_matrix"]["matrix"][0][0] == pytest.approx(STAGE_GAIN, rel=1e-4)


def _volts_copy(src, dst, volts_per_metre: float) -> None:
    """Copy a run, its displacement commands turned into drive/<name>/voltage in V."""
    from mcap.reader import make_reader
    from rclpy.serialization import deserialize_message, serialize_message
    from std_msgs.msg import Float64

    from flexure_sim.recording import McapRecorder

    with open(src, "rb") as f, McapRecorder(dst) as rec:
        reader = make_reader(f)
        summary = reader.get_summary()
        rename = {}
        for ch in summary.channels.values():
            name = ch.topic
            if name.startswith("/drive/") and name.endswith("/displacement"):
                name = name[: -len("displacement")] + "voltage"
            rename[ch.topic] = name
            rec.add_topic(name, summary.schemas[ch.schema_id].name)
        for m in reader.iter_metadata():
            if m.name == "flexure_sim":
                meta = dict(m.metadata)
                for d in ("x", "y"):
                    meta[f"drives.{d}.stroke_min"], meta[f"drives.{d}.stroke_max"] = "0.0", "150.0"
                rec.add_metadata(m.name, meta)
        for _, ch, msg in reader.iter_messages(log_time_order=True):
            data = msg.data
            if rename[ch.topic] != ch.topic:
                value = deserialize_message(data, Float64).data * volts_per_metre
                data = serialize_message(Float64(data=value))
            rec.write(rename[ch.topic], data, msg.log_time)


def test_a_drive_commanded_in_volts_is_stepped_on_its_voltage_topic(capsys, xy, tmp_path):
    path = tmp_path / "volts.mcap"
    _volts_copy(xy[0], path, 1e7)                     # 1 um <-> 10 V
    code, out, err = flexure_sim(capsys, "analyse", path, "--json", "--no-static")
    assert code == 0, err
    result = json.loads(out)
    assert [(d["command"], d["command_unit"], d["unit"], d["steps_from"])
            for d in result["drives"]] == [
        ("/drive/x/voltage", "V", "m", "/drive/x/voltage"),
        ("/drive/y/voltage", "V", "m", "/drive/y/voltage")]
    assert [(s["input_before"], s["input"]) for s in result["steps"]] == [(0.0, 10.0)] * 2
    clean = json.loads(flexure_sim(capsys, "analyse", xy[0], "--json", "--no-static")[1])
    assert result["gain_matrix"] == clean["gain_matrix"]
    code, out, err = flexure_sim(capsys, "info", path)
    assert "x (displacement, m; stroke [0.0, 150.0] V): command /drive/x/voltage [V], " in out
    code, out, err = flexure_sim(capsys, "plot", path, "-o", tmp_path / "plots")
    assert code == 0, err
    assert figure_title(tmp_path / "plots" / "drives_outputs.png") == "Drives and outputs"


def test_drives_stepped_together_give_no_gain_and_say_why(capsys, tmp_path):
    path = tmp_path / "together.mcap"
    record_drives_run(path, "xy_stage", [(0.01, "x", U), (0.01, "y", U)], 0.04)
    code, out, err = flexure_sim(capsys, "analyse", path)
    assert code == 0, err
    assert "no measured gain to compare (no clean, settled step)" in out
    assert "step 1: drive(s) y stepped at the same time: no gain" in out
    assert "! another drive moved during the step: not in the gain matrix" in out


def test_export_signals_of_a_single_drive_run_uses_its_topics(capsys, tmp_path):
    from tools_fixtures import record_stage_run

    path = tmp_path / "stage.mcap"
    record_stage_run(path, levels=(1e-6,), dwell=0.02)
    code, out, err = flexure_sim(capsys, "export", path, "--csv", tmp_path / "csv", "--signals")
    assert code == 0, err
    with (tmp_path / "csv" / "signals.csv").open() as f:
        rows = list(csv.DictReader(f))
    assert list(rows[0]) == ["time", "drive/displacement", "drive/input", "drive/force",
                             "output/displacement"]
    with (tmp_path / "csv" / "output.displacement.csv").open() as f:
        outputs = [r["data"] for r in csv.DictReader(f)]
    assert [r["output/displacement"] for r in rows] == outputs


@pytest.mark.slow
def test_analyse_shows_an_input_that_decayed_to_a_denormal_as_zero(tmp_path):
    """
    A step back to 0 held 0.95 s: the lag's output decays as exp(-t / 1 ms) into denormals.

    `flexure-sim analyse` (a subprocess, as a user runs it) reads both ends of the step in the
    unit of the larger and to 6 digits of it: the command's own values, 10 um and 0.
    """
    import subprocess
    import sys

    from conftest import ROOT
    from flexure_sim.recording import read_log

    path = tmp_path / "down.mcap"
    record_drives_run(path, "xy_stage", [(0.01, "x", 10 * U), (0.05, "x", 0.0)], 1.0,
                      publish_rate=200.0, sim_step=5e-4)
    last = read_log(path).messages_on("/drive/x/input")[-1].message.data
    assert 0.0 < last < 1e-300  # what was recorded: a denormal
    p = subprocess.run([sys.executable, "-m", "flexure_sim.cli", "analyse", str(path)],
                       cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert p.returncode == 0, p.stderr
    rows = [line.split() for line in p.stdout.splitlines()
            if line.split()[:2] in (["1", "x"], ["2", "x"])]
    assert [r[3:7] for r in rows] == [["0", "um", "->", "10"], ["10", "um", "->", "0"]], rows
