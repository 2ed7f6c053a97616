"""
monitor_rate.

The monitoring topics (poses, wrenches, deflections) every n-th tick, the control topics every
tick, published and recorded alike (a real node in lockstep mode).
"""
from __future__ import annotations

from geometry_msgs.msg import PoseArray
from rclpy.serialization import serialize_message
from std_msgs.msg import Float64
from std_srvs.srv import Trigger

from flexure_sim.engine.mechanism.loader import load_mechanism
from flexure_sim.engine.solver.simulation import Simulation
from flexure_sim.node.publish.interface import StageInterface
from flexure_sim.recording import read_log

from node_harness import NodeProcess, Peer, next_domain_id


def test_control_only_encoding_is_the_control_subset_of_the_full_one():
    mech = load_mechanism("microstage")
    snap = Simulation(mech).static(1.35e-6).snapshot
    itf = StageInterface(mech, "lockstep")
    names = [itf.tick_topics[i].name for i in itf.control_indices]
    assert names == ["/clock", "hinges/a/compression", "output/displacement", "drive/input",
                     "drive/force"]
    full = itf.encode(snap, 7_000_000)
    assert itf.encode(snap, 7_000_000, monitor=False) == [full[i] for i in itf.control_indices]
    reference = itf.messages(snap, 7_000_000)
    assert full[itf.control_indices[2]] == serialize_message(reference[itf.control_indices[2]])


def test_monitoring_topics_at_a_quarter_of_the_tick_rate(tmp_path):
    domain = next_domain_id()
    node = NodeProcess(tmp_path / "node", domain, dict(
        time_mode="lockstep", publish_rate=1000.0, monitor_rate=250.0, record=True,
        record_path="m.mcap"))
    peer = Peer(domain)
    peer.watch = node
    try:
        peer.subscribe("/output/displacement", Float64)
        peer.subscribe("/bodies/poses", PoseArray)
        peer.wait_for_publishers(["/output/displacement", "/bodies/poses"])
        for _ in range(8):
            assert peer.call(Trigger, "/stage_node/step").success
        peer.spin_until(lambda: len(peer.received["/output/displacement"]) == 8, 20, "outputs")
        peer.spin_until(lambda: len(peer.received["/bodies/poses"]) == 2, 20, "poses")
        peer.watch = None
    finally:
        peer.close()
        assert node.stop() == 0, node.stderr
    log = read_log(node.cwd / "m.mcap")
    outputs = [m.log_time_ns for m in log.messages_on("/output/displacement")]
    poses = [m.log_time_ns for m in log.messages_on("/bodies/poses")]
    wrenches = [m.log_time_ns for m in log.messages_on("/hinges/c/wrench")]
    assert outputs == [k * 1_000_000 for k in range(1, 9)]
    assert poses == wrenches == [1_000_000, 5_000_000]  # ticks 0 and 4 of the run
    assert log.metadata["flexure_sim"]["monitor_rate"] == "250.0"


def test_monitor_rate_above_the_publish_rate_is_refused(tmp_path):
    node = NodeProcess(tmp_path, next_domain_id(), dict(publish_rate=100.0, monitor_rate=200.0,
                                                        record=False))
    assert node.wait(60) == 1
    assert "monitor_rate: must be 0 (every tick) or in (0, publish_rate 100] Hz" in node.stderr
