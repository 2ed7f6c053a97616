"""
Live parameters and commands the engine cannot follow never stop stage_node (issue 16.10).

A real node process; real ``set_parameters`` calls and drive commands from a real rclpy peer.
Strokes without a static equilibrium are refused with the engine's reason; a step that fails
anyway holds the last good state (ERROR in the diagnostics, counted, logged), publishes no
non-finite value, and the node goes on following later commands. A parameter change is in
force when ``set_parameters`` answers: the next command meets the new limits.
"""
from __future__ import annotations

import math
import signal

from diagnostic_msgs.msg import DiagnosticArray
from rcl_interfaces.msg import Parameter as ParameterMsg
from rcl_interfaces.msg import ParameterType, ParameterValue
from rcl_interfaces.srv import SetParameters
from std_msgs.msg import Float64

from flexure_sim.engine.mechanism.loader import load_mechanism
from flexure_sim.engine.solver.simulation import Simulation, SolverError

from node_harness import NodeProcess, Peer, diagnostics_values

import pytest


def set_double(peer: Peer, name: str, value: float) -> tuple[bool, str]:
    msg = ParameterMsg(name=name, value=ParameterValue(type=ParameterType.PARAMETER_DOUBLE,
                                                       double_value=value))
    answer = peer.call(SetParameters, "/stage_node/set_parameters",
                       SetParameters.Request(parameters=[msg]))
    return answer.results[0].successful, answer.results[0].reason


def test_a_stroke_without_static_equilibrium_is_refused_with_the_reason(tmp_path, peer_and_domain):
    peer, domain = peer_and_domain
    # Independent of the node: the engine has no equilibrium of the stage at 1 cm.
    with pytest.raises(SolverError):
        Simulation(load_mechanism("microstage")).static(0.01)
    node = NodeProcess(tmp_path / "node", domain, dict(time_mode="realtime", sim_step=1e-4,
                                                       publish_rate=200.0, record=False))
    peer.watch = node
    try:
        peer.subscribe("/diagnostics", DiagnosticArray)
        peer.wait_for_publishers(["/diagnostics"])
        ok, reason = set_double(peer, "stroke_max", 0.01)
        assert not ok and "stroke_max" in reason and "no static equilibrium" in reason, reason
        ok, reason = set_double(peer, "slew_rate", 100.0)
        assert ok, reason
        ok, reason = set_double(peer, "stroke_max", 1e-5)  # within the engine's reach
        assert ok, reason
    finally:
        rc = node.stop(signal.SIGINT)
    assert rc == 0, node.stderr
    # Refused at start-up too, with the same reason and exit code 1.
    bad = NodeProcess(tmp_path / "start", domain, dict(stroke_max=0.01, record=False))
    assert bad.wait(60) == 1
    assert "stroke_max" in bad.stderr and "no static equilibrium" in bad.stderr
    assert "Traceback" not in bad.stderr


def test_a_command_sent_after_set_parameters_answered_meets_the_new_stroke(
        tmp_path, peer_and_domain):
    # At 2 Hz the stepping thread serves its queue once every 0.5 s. The microstage's own
    # stroke ends at 2 um (config), so the node's default stroke_max clamps a 3 um command.
    peer, domain = peer_and_domain
    assert load_mechanism("microstage").drives[0].stroke[1] == pytest.approx(2e-6)
    node = NodeProcess(tmp_path / "node", domain, dict(time_mode="realtime", sim_step=5e-4,
                                                       publish_rate=2.0, record=False))
    peer.watch = node
    try:
        drive = peer.connect_drive({"/drive/input": Float64, "/diagnostics": DiagnosticArray})
        assert set_double(peer, "stroke_max", 4e-6) == (True, "")
        drive.publish(Float64(data=3e-6))
        peer.spin_until(lambda: any(m.data != 0.0 for m in peer.messages("/drive/input")), 20,
                        "the actuator to move")
        first = next(m.data for m in peer.messages("/drive/input") if m.data != 0.0)
        assert first == pytest.approx(3e-6, rel=1e-9)  # 2e-6 when clamped to the old stroke
        peer.spin_until(lambda: peer.last("/diagnostics") is not None, 20, "the diagnostics")
        assert int(diagnostics_values(peer.last("/diagnostics"))["commands_clamped"]) == 0
    finally:
        rc = node.stop(signal.SIGINT)
    assert rc == 0, node.stderr
    assert "clamped" not in node.stderr


def test_a_step_the_engine_cannot_take_holds_the_state_and_the_node_goes_on(
        tmp_path, peer_and_domain):
    peer, domain = peer_and_domain
    # Independently: at a 5e-4 s step the engine cannot follow a 20 um jump of the command.
    sim = Simulation(load_mechanism("microstage"), dt=5e-4)
    sim.static(2e-5)  # ... though the stage has an equilibrium there
    sim.set_command(2e-5)
    with pytest.raises(SolverError):
        sim.step(10)
    node = NodeProcess(tmp_path / "node", domain, dict(time_mode="realtime", sim_step=5e-4,
                                                       publish_rate=200.0, record=True,
                                                       record_path="held.mcap"))
    peer.watch = node
    try:
        for topic, kind in (("/diagnostics", DiagnosticArray), ("/drive/input", Float64),
                            ("/output/displacement", Float64)):
            peer.subscribe(topic, kind, depth=10000)
        drive = peer.publisher("/drive/displacement", Float64)
        peer.wait_for_publishers(["/diagnostics", "/output/displacement"])
        peer.wait_for_subscribers(drive)
        assert set_double(peer, "stroke_max", 2e-5) == (True, "")
        assert set_double(peer, "slew_rate", 100.0) == (True, "")
        drive.publish(Float64(data=2e-5))

        def failed() -> bool:
            msg = peer.last("/diagnostics")
            return msg is not None and int(diagnostics_values(msg)["engine_failures"]) > 0

        peer.spin_until(failed, 20, "the engine failure in the diagnostics")
        status = peer.last("/diagnostics").status[0]
        values = diagnostics_values(peer.last("/diagnostics"))
        assert status.level == bytes([2]) and "engine failures" in status.message
        assert "reduce the step" in values["engine_error"]
        # The node goes on: a command the engine can follow is applied.
        drive.publish(Float64(data=1e-6))
        peer.spin_until(lambda: peer.last("/drive/input") is not None
                        and peer.last("/drive/input").data == pytest.approx(1e-6, rel=1e-6),
                        20, "the actuator to reach 1 um")
        n = len(peer.received["/diagnostics"])
        peer.spin_until(lambda: len(peer.received["/diagnostics"]) > n + 2, 20, "more diagnostics")
        later = peer.last("/diagnostics")
        assert later.status[0].level != bytes([2])  # the failure was in an earlier window
        assert float(diagnostics_values(later)["sim_time"]) > float(values["sim_time"])
        assert node.alive()
    finally:
        rc = node.stop(signal.SIGINT)
    assert rc == 0, node.stderr
    assert "the engine failed" in node.stderr and "state held" in node.stderr
    assert "Traceback" not in node.stderr
    for topic in ("/drive/input", "/output/displacement"):
        assert all(math.isfinite(m.data) for m in peer.messages(topic))
