"""
stage_node with several drives (issue 13): the XY stage as a real node process.

One command topic per drive, per-drive inputs and forces, one topic per output, per-drive
parameters, counters and warnings. Acceptance: the gain matrix measured from the node's
recording (output change per drive step) equals ``flexure-sim simulate xy_stage --static``'s
to 1e-4.
"""
from __future__ import annotations

import json
import math
import signal
import subprocess

import numpy as np
import pytest
from rcl_interfaces.msg import Parameter as ParameterMsg
from rcl_interfaces.msg import ParameterType, ParameterValue
from rcl_interfaces.srv import SetParameters
from std_msgs.msg import Float64
from diagnostic_msgs.msg import DiagnosticArray
from rosgraph_msgs.msg import Clock

from flexure_sim.recording import read_log

from node_harness import NodeProcess, Peer, diagnostics_values

DRIVES = ("x", "y")
OUTPUTS = ("x", "y", "theta")
#: Steps from -U to +U about rest: the gain at rest to second order (test_multidrive_stepping).
U = 1e-6
INPUTS = [f"/drive/{d}/input" for d in DRIVES]
FORCES = [f"/drive/{d}/force" for d in DRIVES]
OUTPUT_TOPICS = [f"/output/{o}/displacement" for o in OUTPUTS]


def start(tmp_path, domain, peer, **params) -> NodeProcess:
    node = NodeProcess(tmp_path / "node", domain, {
        "mechanism": "xy_stage", "time_mode": "lockstep", "sim_step": 1e-4,
        "publish_rate": 20.0, **params})
    peer.watch = node
    return node


def step_until(peer: Peer, predicate, what: str, limit: int = 50, topics=INPUTS) -> None:
    """Lockstep ticks until ``predicate`` holds (e.g. the node has taken a command)."""
    peer.tick_until(predicate, what, topics, limit)


def static_gain_matrix() -> np.ndarray:
    out = subprocess.run(["flexure-sim", "simulate", "xy_stage", "--static", "--json"],
                         capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    gm = json.loads(out.stdout)["gain_matrix"]
    assert gm["drives"] == list(DRIVES) and gm["outputs"] == list(OUTPUTS)
    return np.array(gm["matrix"])


def test_xy_stage_node_gain_matrix_equals_simulate_static(tmp_path, domain, peer):
    node = start(tmp_path, domain, peer, record=True, record_path="xy.mcap",
                 **{f"drives.{d}.stroke_min": -1.5e-5 for d in DRIVES})
    try:
        for topic in ["/clock"] + INPUTS + FORCES + OUTPUT_TOPICS:
            peer.subscribe(topic, Float64 if topic != "/clock" else Clock)
        commands = {d: peer.publisher(f"/drive/{d}/displacement", Float64) for d in DRIVES}
        peer.wait_for_publishers(INPUTS + OUTPUT_TOPICS)
        for pub in commands.values():
            peer.wait_for_subscribers(pub)
        for k, drive in enumerate(DRIVES):
            for level in (-U, U, 0.0):
                commands[drive].publish(Float64(data=level))
                # Taken at a tick: then the 1 ms actuator lag and the hinge modes settle
                # within the 50 ms tick; two more ticks show the state at rest.
                step_until(peer, lambda: abs(peer.last(INPUTS[k]).data - level) < 1e-12 * U,
                           f"drive {drive} at {level:g} m")
                step_until(peer, lambda: True, "one more tick")
                step_until(peer, lambda: True, "one more tick")
    finally:
        assert node.stop(signal.SIGINT) == 0, node.stderr
    log = read_log(node.cwd / "xy.mcap")
    assert log.complete
    series = {t: [(m.log_time_ns, m.message.data) for m in log.messages_on(t)]
              for t in INPUTS + FORCES + OUTPUT_TOPICS}
    for d in DRIVES:
        recorded = [m.message.data for m in log.messages_on(f"/drive/{d}/displacement")]
        assert recorded == [-U, U, 0.0]
    # The settled values just before each next command (the last tick of each level).
    times = sorted(m.log_time_ns for d in DRIVES
                   for m in log.messages_on(f"/drive/{d}/displacement"))[1:] + [math.inf]

    def settled(topic: str, before: float) -> float:
        return [v for t, v in series[topic] if t < before][-1]

    gain = np.zeros((len(OUTPUTS), len(DRIVES)))
    for k in range(len(DRIVES)):
        low, high = times[3 * k], times[3 * k + 1]   # ends of the -U and +U levels
        du = settled(INPUTS[k], high) - settled(INPUTS[k], low)
        assert du == pytest.approx(2 * U, rel=1e-12)
        # The other drive is at rest (its actuator lag's exponential tail has died out).
        assert abs(settled(INPUTS[1 - k], high)) < 1e-12 * U
        assert abs(settled(INPUTS[1 - k], low)) < 1e-12 * U
        for j, topic in enumerate(OUTPUT_TOPICS):
            gain[j, k] = (settled(topic, high) - settled(topic, low)) / du
    expected = static_gain_matrix()
    error = np.max(np.abs(gain - expected)) / np.max(np.abs(expected))
    print(f"gain matrix from the recording:\n{gain}\nsimulate --static:\n{expected}\n"
          f"largest difference / largest entry: {error:.2e}")
    assert error < 1e-4
    # Every drive's command, input and force, every output: recorded, and named in the metadata.
    assert {f"/drive/{d}/{t}" for d in DRIVES for t in ("displacement", "input", "force")} \
        | set(OUTPUT_TOPICS) <= set(log.topics)
    meta = log.metadata["flexure_sim"]
    assert meta["drives"] == "x:displacement,y:displacement" and meta["outputs"] == "x,y,theta"


def test_each_drive_has_its_own_limits_counters_and_warnings(tmp_path, domain, peer):
    node = start(tmp_path, domain, peer, record=False, **{"drives.y.slew_rate": 1e-5})
    try:
        peer.subscribe("/clock", Clock)
        for topic in INPUTS:
            peer.subscribe(topic, Float64)
        peer.subscribe("/diagnostics", DiagnosticArray)
        commands = {d: peer.publisher(f"/drive/{d}/displacement", Float64) for d in DRIVES}
        peer.wait_for_publishers(INPUTS)
        for pub in commands.values():
            peer.wait_for_subscribers(pub)
        commands["x"].publish(Float64(data=1.0))        # far beyond x's 15 um stroke
        commands["y"].publish(Float64(data=math.nan))   # refused
        step_until(peer, lambda: abs(peer.last_data(INPUTS[0]) - 1.5e-5) < 1e-17, "x clamped")
        commands["y"].publish(Float64(data=1e-5))       # ramps at y's own 10 um/s
        step_until(peer, lambda: peer.last_data(INPUTS[1]) > 0, "y moving")
        assert peer.last(INPUTS[1]).data <= 1e-5 * 0.05 * (1 + 1e-9)  # one 50 ms tick
        step_until(peer, lambda: len(peer.received["/diagnostics"]) > 0, "diagnostics", 20)
        d = diagnostics_values(peer.last("/diagnostics"))
        assert d["commands_x_clamped"] == "1" and d["commands_x_rejected"] == "0"
        assert d["commands_y_rejected"] == "1" and d["commands_y_clamped"] == "0"
        assert int(d["commands_y_rate_limited"]) >= 1 and d["commands_x_received"] == "1"
        assert float(d["drive_x_target"]) == 1.5e-5
        # The per-drive parameters describe themselves; the single-drive ones say they are unused.
        from rcl_interfaces.srv import DescribeParameters
        names = ["drives.x.stroke_max", "drives.y.slew_rate", "stroke_max"]
        described = peer.call(DescribeParameters, "/stage_node/describe_parameters",
                              DescribeParameters.Request(names=names)).descriptors
        texts = [p.description for p in described]
        assert texts[0].startswith("Drive x: upper end") and texts[0].endswith("[m]")
        assert texts[1].startswith("Drive y: speed limit") and texts[1].endswith("[m/s]")
        assert "Unused: each drive has its own drives.<name>.* limits" in texts[2]
        # A bad per-drive parameter is refused naming the drive.
        request = SetParameters.Request()
        request.parameters = [ParameterMsg(name="drives.x.slew_rate", value=ParameterValue(
            type=ParameterType.PARAMETER_DOUBLE, double_value=-1.0))]
        result = peer.call(SetParameters, "/stage_node/set_parameters", request).results[0]
        assert not result.successful and "drives.x.slew_rate" in result.reason
        # A good one applies live to its drive only: x's stroke shrinks to 10 um.
        request.parameters = [ParameterMsg(name="drives.x.stroke_max", value=ParameterValue(
            type=ParameterType.PARAMETER_DOUBLE, double_value=1e-5))]
        result = peer.call(SetParameters, "/stage_node/set_parameters", request).results[0]
        assert result.successful, result.reason
        commands["x"].publish(Float64(data=1.0))
        step_until(peer, lambda: abs(peer.last(INPUTS[0]).data - 1e-5) < 1e-17, "x at 10 um")
        step_until(peer, lambda: diagnostics_values(peer.last("/diagnostics"))[
            "commands_x_clamped"] == "2", "the second clamp in the diagnostics", 40)
        assert diagnostics_values(peer.last("/diagnostics"))["drive_x_target"] == "1e-05"
    finally:
        assert node.stop(signal.SIGINT) == 0, node.stderr
    err = node.stderr
    assert "drive x command 1 m outside the stroke [0, 1.5e-05] m: clamped" in err
    assert "drive y command nan rejected (not finite)" in err
    assert "drive y command faster than the slew limit (1e-05 m/s): ramping" in err


# ------------------------------------------------------------- the topic table (no process)
def test_topic_names_per_drive_and_output_and_the_single_drive_names_kept():
    from rclpy.serialization import deserialize_message

    from flexure_sim.engine.mechanism.loader import load_mechanism
    from flexure_sim.engine.solver.simulation import Simulation
    from flexure_sim.node.publish.interface import StageInterface
    xy = StageInterface(load_mechanism("xy_stage"), "fast")
    names = [t.name for t in xy.tick_topics]
    floats = ["output/x/displacement", "output/y/displacement", "output/theta/displacement",
              "drive/x/input", "drive/x/force", "drive/y/input", "drive/y/force"]
    assert names[-len(floats):] == floats
    assert not {"drive/input", "drive/force", "output/displacement"} & set(names)
    assert [c.name for c in xy.commands] == ["drive/x/displacement", "drive/y/displacement"]
    assert xy.command is None
    units = {t.name: t.unit for t in xy.tick_topics}
    assert units["output/theta/displacement"] == "rad" and units["drive/x/force"] == "N"
    sim = Simulation(xy.mechanism)
    snap = sim.static({"x": 1e-6, "y": 0.5e-6}).snapshot
    packed = xy.encode(snap, 123)
    reference = xy.messages(snap, 123)
    values = [deserialize_message(p, Float64).data for p in packed[-len(floats):]]
    assert values == [m.data for m in reference[-len(floats):]]
    assert values == [snap.outputs["x"], snap.outputs["y"], snap.outputs["theta"],
                      snap.drive_inputs[0], snap.drive_forces[0], snap.drive_inputs[1],
                      snap.drive_forces[1]]
    stage = StageInterface(load_mechanism("microstage"), "fast")
    assert [c.name for c in stage.commands] == ["drive/displacement"]
    assert [t.name for t in stage.tick_topics][-4:] == [
        "hinges/a/compression", "output/displacement", "drive/input", "drive/force"]


LEAF_ROTOR = """
name: leaf_rotor
defaults: {law: twistor, damping: {t_char: 1.0e-3}}
stiffness_models:
  leaf: {model: cantilever, length: 0.02, thickness: 0.0005, width: 0.01, E: 69.0e9, nu: 0.33}
bodies:
  - {name: base, mass: 1.0, inertia: 1.0, pose: [0, 0, 0]}
  - {name: disc, mass: 0.01, inertia: 1.0e-6, pose: [0, 0.02, 0]}
hinges:
  - {name: leaf, a: {body: base, at: [0, 0.02]}, b: {body: disc, at: [0, 0]}, stiffness: leaf}
constraints:
  - {type: fixed, body: base}
  - {type: force, name: torquer, body: disc, axis: theta, response_time: 1.0e-3,
     stroke: [-0.001, 0.001], slew_rate: 1.0}
outputs:
  - {name: angle, body: disc, coordinate: theta}
"""


def test_a_force_drive_is_commanded_in_newton_metres_and_turns_its_body(
        tmp_path, domain, peer):
    # A leaf spring under an end moment M turns by M L / (E I) (Euler-Bernoulli).
    k_bend = 69.0e9 * (0.01 * 0.0005**3 / 12) / 0.02
    path = tmp_path / "leaf_rotor.yaml"
    path.write_text(LEAF_ROTOR)
    node = start(tmp_path, domain, peer, mechanism=str(path), record=False)
    torque = 2e-5
    try:
        peer.subscribe("/clock", Clock)
        topics = ["/drive/torquer/input", "/drive/torquer/position", "/output/displacement"]
        for topic in topics:
            peer.subscribe(topic, Float64)
        command = peer.publisher("/drive/torquer/force", Float64)
        peer.wait_for_publishers(topics)
        peer.wait_for_subscribers(command)
        command.publish(Float64(data=torque))
        step_until(peer, lambda: peer.last_data(topics[0]) == torque, "the torque applied",
                   topics=topics)
        for _ in range(10):   # 0.5 s: the disc's swing (~180 /s decay) has died out
            step_until(peer, lambda: True, "one more tick", topics=topics)
    finally:
        assert node.stop(signal.SIGINT) == 0, node.stderr
    assert peer.last(topics[1]).data == pytest.approx(torque / k_bend, rel=1e-6)
    assert peer.last(topics[2]).data == pytest.approx(torque / k_bend, rel=1e-6)


# ------------------------------------------------- a drive whose piezo actuator takes volts
PIEZO_STAGE = "config/examples/piezo_stage.yaml"   # actuator: {command: voltage, v_max: 100}


def test_a_voltage_commanded_drive_has_its_command_topic_and_limits_in_volts(tmp_path):
    from flexure_sim.engine.mechanism.loader import load_mechanism
    from flexure_sim.node.inputs.drive_bank import drive_parameter_specs
    from flexure_sim.node.publish.interface import StageInterface
    from node_harness import ROOT as REPO
    one = StageInterface(load_mechanism(str(REPO / PIEZO_STAGE)), "fast")
    assert [(c.name, c.unit) for c in one.commands] == [("drive/voltage", "V")]
    # xy_stage with a 0-150 V stack on drive x: drive/x/voltage, drive y keeps metres.
    text = (REPO / "config" / "xy_stage.yaml").read_text()
    x_line = next(line for line in text.splitlines() if "name: x, body: piezo_x" in line)
    path = tmp_path / "xy_volts.yaml"
    path.write_text(text.replace(x_line, x_line.rstrip()[:-1]
                                 + ", actuator: {command: voltage, v_max: 150.0}}"))
    xy = load_mechanism(str(path))
    assert [(c.name, c.unit) for c in StageInterface(xy, "fast").commands] == [
        ("drive/x/voltage", "V"), ("drive/y/displacement", "m")]
    specs = {s.name: (s.default, s.unit) for s in drive_parameter_specs(xy.drives)}
    # Stroke 15 um over 150 V: d = 1e-7 m/V, so the 0.01 m/s slew limit is 1e5 V/s.
    assert specs["drives.x.stroke_min"] == (0.0, "V") and specs["drives.x.stroke_max"] == (
        150.0, "V")
    assert specs["drives.x.slew_rate"][0] == pytest.approx(0.01 / (1.5e-5 / 150.0), rel=1e-12)
    assert specs["drives.x.slew_rate"][1] == "V/s" and specs["drives.y.stroke_max"] == (
        1.5e-5, "m")


def test_volts_out_of_range_are_clamped_counted_and_warned_in_volts(tmp_path, domain, peer):
    from rcl_interfaces.srv import GetParameters

    from node_harness import ROOT as REPO
    node = start(tmp_path, domain, peer, mechanism=str(REPO / PIEZO_STAGE), record=True,
                 record_path="volts.mcap")

    def diagnostics(key: str, value: str) -> bool:
        last = peer.last("/diagnostics")
        return last is not None and diagnostics_values(last)[key] == value

    try:
        peer.subscribe("/clock", Clock)
        peer.subscribe("/drive/input", Float64)
        peer.subscribe("/diagnostics", DiagnosticArray)
        command = peer.publisher("/drive/voltage", Float64)
        peer.wait_for_publishers(["/drive/input"])
        peer.wait_for_subscribers(command)
        command.publish(Float64(data=150.0))      # above v_max = 100 V: clamped to 100 V
        command.publish(Float64(data=math.nan))   # refused
        step_until(peer, lambda: diagnostics("commands_received", "2"), "diagnostics", 40,
                   topics=["/drive/input"])
        d = diagnostics_values(peer.last("/diagnostics"))
        assert d["commands_clamped"] == "1" and d["commands_rejected"] == "1"
        assert float(d["drive_target"]) == 100.0
        # 100 V is the stroke's end: the actuator pushes the platform by at most 15 um.
        assert 0.0 < peer.last("/drive/input").data <= 1.5e-5 * (1 + 1e-6)
        command.publish(Float64(data=-5.0))       # below v_min = 0 V: clamped to 0 V
        step_until(peer, lambda: diagnostics("commands_clamped", "2"), "the second clamp", 40,
                   topics=["/drive/input"])
        assert float(diagnostics_values(peer.last("/diagnostics"))["drive_target"]) == 0.0
        # The stroke parameters are in volts: 80 V is accepted.
        request = GetParameters.Request(names=["stroke_min", "stroke_max", "slew_rate"])
        got = peer.call(GetParameters, "/stage_node/get_parameters", request).values
        assert [v.double_value for v in got] == pytest.approx([0.0, 100.0, 0.1 / 1.5e-7])
        request = SetParameters.Request()
        request.parameters = [ParameterMsg(name="stroke_max", value=ParameterValue(
            type=ParameterType.PARAMETER_DOUBLE, double_value=80.0))]
        assert peer.call(SetParameters, "/stage_node/set_parameters",
                         request).results[0].successful
    finally:
        assert node.stop(signal.SIGINT) == 0, node.stderr
    assert "drive command 150 V outside the stroke [0, 100] V: clamped" in node.stderr
    log = read_log(node.cwd / "volts.mcap")
    recorded = [m.message.data for m in log.messages_on("/drive/voltage")]
    assert recorded[0] == 150.0 and math.isnan(recorded[1]) and recorded[2:] == [-5.0]


# ----------------------------------------------- the stepping loop's ticks with several drives
def test_ticks_with_new_commands_on_several_drives_reach_the_step_by_step_states():
    """
    The loop's shortcut (one compiled call once every drive's ramp has ended) on `xy_stage`.

    Reference: the drives' definition (docs/node.md: drive commands) stepped one engine step at a
    time, each drive's target moving towards its command by at most its slew_rate * dt.
    """
    from flexure_sim.engine.mechanism.loader import load_mechanism
    from flexure_sim.engine.solver.simulation import Simulation
    from flexure_sim.node.inputs.drive_bank import FilterBank
    from flexure_sim.node.inputs.command_checks import DriveLimits
    from flexure_sim.node.publish.interface import StageInterface
    from flexure_sim.node.record.session import RecordingSession
    from flexure_sim.node.stage.loop_parts import LoopParts, LoopSettings
    from flexure_sim.node.stage.stepping_thread import RELINEARIZE_TOL, SteppingLoop
    from test_node_stepping import DT, N_STEPS, RATE, Discard, Log

    xy = load_mechanism("xy_stage")
    slew = {"x": xy.drives[0].slew_rate, "y": 2e-3}   # y ramps over several steps and ticks
    bank = FilterBank(DRIVES, [DriveLimits(d.stroke[0], d.stroke[1], slew[d.name])
                               for d in xy.drives])
    sim = Simulation(xy, dt=DT, relinearize_tol=RELINEARIZE_TOL)
    itf = StageInterface(xy, "realtime")
    loop = SteppingLoop(LoopParts(LoopSettings("realtime", RATE, DT), sim, itf,
                                  [Discard() for _ in itf.tick_topics], RecordingSession(Log()),
                                  Log(),
                                  filter=bank))
    commands = [(1e-6, 0.0), (1e-6, 5e-7), (1e-6 + 3e-9, 5e-7), (0.0, 1e-6), (0.0, 1e-6),
                (2e-6, 0.0), (2e-6, 0.0)]
    for tick in commands:
        for f, value in zip(bank.filters, tick):
            if value != f.target:
                f.submit_many([value])
        loop._advance_engine()
    ref = Simulation(xy, dt=DT, relinearize_tol=RELINEARIZE_TOL)
    applied = np.zeros(2)
    step = np.array([slew[d] * DT for d in DRIVES])
    for tick in commands:
        for _ in range(N_STEPS):
            applied = applied + np.clip(np.array(tick) - applied, -step, step)
            ref.set_command(applied)
            ref.step(1)
    assert sim.state.t == ref.state.t
    np.testing.assert_array_equal(sim.state.z, ref.state.z)
    np.testing.assert_array_equal(sim.state.v, ref.state.v)
    np.testing.assert_array_equal(sim.state.command, applied)


@pytest.mark.parametrize("override, expected", [
    ("drives.z.slew_rate:=1.0",
     "stage_node: error: invalid parameter drives.z.slew_rate: no such parameter; the drives are "
     "x, y, each with drives.<name>.{stroke_min, stroke_max, slew_rate}"),
    ("drives.x.slew_rat:=1.0",
     "stage_node: error: invalid parameter drives.x.slew_rat: no such parameter; the drives are "
     "x, y, each with drives.<name>.{stroke_min, stroke_max, slew_rate}"),
    ("drives.x.stroke_max:=abc",
     "stage_node: error: invalid parameter drives.x.stroke_max: expected a double (a number), "
     "got string 'abc'"),
])
def test_a_per_drive_parameter_typo_or_wrong_type_stops_start_up_naming_it(
        tmp_path, domain, override, expected):
    node = NodeProcess(tmp_path, domain, extra_args=[
        "--ros-args", "-p", "mechanism:=xy_stage", "-p", "record:=false", "-p", override])
    try:
        rc = node.wait(60)
    finally:
        node.kill()  # a node that accepted the override runs on: never left behind
    assert rc == 1, node.stderr
    assert node.stderr.strip().splitlines()[-1] == expected
    assert "Traceback" not in node.stderr
