"""
The stage node's diagnostics report the largest hinge stress ratio sigma / sigma_y.

With the hinge, WARN above 1: a real node in fast mode against the engine's static stress
table.
"""
from pathlib import Path

import pytest
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from std_msgs.msg import Float64

from flexure_sim.engine.mechanism.loader import load_mechanism, resolve_mechanism_path
from flexure_sim.engine.solver.simulation import Simulation
from flexure_sim.engine.hinges.stress import peak_ratio, stress_table
from node_harness import NodeProcess, Peer, diagnostics_values, next_domain_id

FULL_STROKE = 2.0e-6


def _weak_stage(tmp_path: Path) -> Path:
    """
    microstage.yaml with a yield strength of 20 MPa instead of 6061-T6's 276 MPa.

    Full stroke (about 33 MPa in the most loaded hinge) is beyond it.
    """
    text = resolve_mechanism_path("microstage").read_text()
    assert text.count("material: 6061-T6}") == 1
    path = tmp_path / "weak_stage.yaml"  # the file's own sigma_y overrides the material's
    path.write_text(text.replace("material: 6061-T6}", "material: 6061-T6, sigma_y: 20.0e6}"))
    return path


def _first_stressed(messages) -> float | None:
    """Sim time of the first diagnostics with a stress ratio off rest (None: none yet)."""
    for msg in messages:
        values = diagnostics_values(msg)
        if float(values.get("stress_ratio_max", 0.0)) > 1e-9:
            return float(values["sim_time"])
    return None


def test_diagnostics_warn_when_full_stroke_exceeds_yield_with_the_engines_ratio(tmp_path):
    mech_file = _weak_stage(tmp_path)
    expected_hinge, expected = peak_ratio(stress_table(
        Simulation(load_mechanism(mech_file)).static(FULL_STROKE).snapshot.wrenches,
        load_mechanism(mech_file)))
    assert expected > 1.2  # the premise: full stroke is well beyond this yield strength
    domain = next_domain_id()
    peer = Peer(domain)
    node = NodeProcess(tmp_path / "node", domain, dict(
        mechanism=str(mech_file), time_mode="fast", sim_step=1e-4, publish_rate=200.0,
        record=False))
    peer.watch = node
    try:
        drive = peer.connect_drive({"/diagnostics": DiagnosticArray, "/drive/input": Float64})
        peer.spin_until(lambda: len(peer.received["/diagnostics"]) > 1, 30, "diagnostics")
        at_rest = peer.last("/diagnostics").status[0]
        values = diagnostics_values(peer.last("/diagnostics"))
        assert float(values["stress_ratio_max"]) < 1e-9 and at_rest.level == DiagnosticStatus.OK
        drive.publish(Float64(data=FULL_STROKE))
        at_full = pytest.approx(FULL_STROKE, rel=1e-12)
        peer.spin_until(lambda: peer.last_data("/drive/input") == at_full, 30,
                        "the actuator to reach full stroke")
        # When the stage started to move, from the diagnostics alone (one topic arrives in
        # order; the last diagnostics received with /drive/input can be older than it).
        peer.spin_until(lambda: _first_stressed(peer.messages("/diagnostics")) is not None, 60,
                        "diagnostics of the stressed stage")
        reached = _first_stressed(peer.messages("/diagnostics"))
        # Settled: 0.2 s of simulated time after the input started to follow the command
        # (actuator lag 1 ms, the modes faster still), as the node's step-response test.
        peer.spin_until(
            lambda: float(diagnostics_values(peer.last("/diagnostics"))["sim_time"])
            > reached + 0.2, 60, "settling")
        msg = peer.last("/diagnostics")
        values = diagnostics_values(msg)
        status = msg.status[0]
    finally:
        rc = node.stop()
        peer.close()
    assert rc == 0, node.stderr
    assert status.level == DiagnosticStatus.WARN
    assert f"hinge {expected_hinge} above its yield strength" in status.message
    assert values["stress_ratio_hinge"] == expected_hinge
    assert float(values["stress_ratio_max"]) == pytest.approx(expected, rel=1e-4)


def test_no_stress_values_for_a_mechanism_without_yield_strengths(tmp_path):
    """fourbar_mixed has no sigma_y: no stress values, and no warning for them."""
    domain = next_domain_id()
    peer = Peer(domain)
    node = NodeProcess(tmp_path / "node", domain, dict(
        mechanism="fourbar_mixed", time_mode="fast", sim_step=1e-4, publish_rate=200.0,
        record=False))
    peer.watch = node
    try:
        peer.subscribe("/diagnostics", DiagnosticArray)
        peer.wait_for_publishers(["/diagnostics"])
        peer.spin_until(lambda: len(peer.received["/diagnostics"]) > 2, 30, "diagnostics")
        values = diagnostics_values(peer.last("/diagnostics"))
    finally:
        rc = node.stop()
        peer.close()
    assert rc == 0, node.stderr
    assert "stress_ratio_max" not in values and "sim_time" in values
