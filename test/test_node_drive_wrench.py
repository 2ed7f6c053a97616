"""
The stage node publishes and records each drive's full wrench (issue 30 item 4), over DDS.

``drive/wrench`` (``drive/<name>/wrench`` with several drives): force x, y and moment the drive
applies to its body, in the body's frame. Checked against what the node publishes besides:
along the axis it is ``drive/force``; in full it balances hinge a's wrench on body6 (published on
``hinges/a/wrench``, in hinge a's frame b, moved here to body6's origin) once the 1 ms lag has
settled; the recording holds every published message. The existing topics' bytes are those of
the golden recording (test_golden_recording.py).
"""
from __future__ import annotations

import signal

import numpy as np
import pytest
import yaml
from geometry_msgs.msg import WrenchStamped
from std_msgs.msg import Float64
from std_srvs.srv import Trigger

from conftest import ROOT
from flexure_sim.engine.mechanism.loader import load_mechanism
from flexure_sim.node.publish.interface import StageInterface
from flexure_sim.recording import read_log

from node_harness import NodeProcess, Peer, next_domain_id

TICKS = 40      # 40 ms at 1 kHz: the lag has settled to e^-40


def test_the_stage_node_publishes_and_records_the_full_drive_wrench(tmp_path):
    domain = next_domain_id()
    node = NodeProcess(tmp_path / "node", domain, dict(
        time_mode="lockstep", publish_rate=1000.0, record=True, record_path="w.mcap"))
    peer = Peer(domain)
    peer.watch = node
    try:
        for topic, kind in (("/drive/wrench", WrenchStamped), ("/hinges/a/wrench", WrenchStamped),
                            ("/drive/force", Float64)):
            peer.subscribe(topic, kind)
        drive = peer.publisher("/drive/displacement", Float64)
        peer.wait_for_publishers(["/drive/wrench", "/hinges/a/wrench", "/drive/force"])
        peer.wait_for_subscribers(drive)
        peer.publish_acked(drive, Float64(data=1.35e-6))
        for _ in range(TICKS):
            assert peer.call(Trigger, "/stage_node/step").success
        peer.spin_until(lambda: len(peer.received["/drive/wrench"]) == TICKS
                        and len(peer.received["/hinges/a/wrench"]) == TICKS
                        and len(peer.received["/drive/force"]) == TICKS, 20, "every tick")
        peer.watch = None
        wrenches = peer.messages("/drive/wrench")
        hinge = peer.last("/hinges/a/wrench")
        forces = peer.messages("/drive/force")
    finally:
        peer.close()
        assert node.stop(signal.SIGINT) == 0, node.stderr
    last = wrenches[-1]
    assert last.header.frame_id == "body6"
    assert [w.wrench.force.x for w in wrenches] == [f.data for f in forces]
    hinge_a = next(h for h in yaml.safe_load((ROOT / "config" / "microstage.yaml").read_text())
                   ["hinges"] if h["name"] == "a")
    at = hinge_a["b"]["at"]           # frame b on body6, unrotated
    fx, fy, m = hinge.wrench.force.x, hinge.wrench.force.y, hinge.wrench.torque.z
    moved = np.array([m + at[0] * fy - at[1] * fx, fx, fy])
    got = np.array([last.wrench.torque.z, last.wrench.force.x, last.wrench.force.y])
    np.testing.assert_allclose(got, -moved, rtol=1e-9, atol=1e-12 * abs(fx))
    assert abs(got[2]) > 1e-3 and abs(got[0]) > 1e-6
    assert (last.wrench.force.z, last.wrench.torque.x, last.wrench.torque.y) == (0.0, 0.0, 0.0)
    log = read_log(node.cwd / "w.mcap")
    recorded = log.messages_on("/drive/wrench")
    assert len(recorded) == TICKS
    assert recorded[-1].message.wrench.torque.z == last.wrench.torque.z
    assert recorded[-1].message.header.frame_id == "body6"


def test_several_drives_each_have_their_wrench_topic_in_their_body_frame():
    itf = StageInterface(load_mechanism("xy_stage"), "fast", frame_prefix="xy/")
    table = {t.name: t for t in itf.tick_topics}
    for name, body in (("x", "piezo_x"), ("y", "piezo_y")):
        spec = table[f"drive/{name}/wrench"]
        assert spec.type_name == "geometry_msgs/msg/WrenchStamped"
        assert spec.frame_id == f"xy/{body}" and spec.unit == "N, N m"
    assert "drive/wrench" not in table
    assert "drive/x/wrench" not in [itf.tick_topics[i].name for i in itf.control_indices]


@pytest.mark.parametrize("name", ["microstage", "xy_stage"])
def test_the_packed_drive_wrench_is_the_reference_message(name):
    from rclpy.serialization import deserialize_message

    from flexure_sim.engine.solver.simulation import Simulation
    mech = load_mechanism(name)
    itf = StageInterface(mech, "lockstep")
    sim = Simulation(mech)
    sim.set_command(1e-6 if len(mech.drives) == 1 else [1e-6, 2e-6])
    sim.step(20)
    snap = sim.snapshot()
    names = [t.name for t in itf.tick_topics]
    packed, reference = itf.encode(snap, 9_000_000), itf.messages(snap, 9_000_000)
    for k, d in enumerate(mech.drives):
        i = names.index("drive/wrench" if name == "microstage" else f"drive/{d.name}/wrench")
        msg = deserialize_message(packed[i], WrenchStamped)
        assert msg == reference[i]
        assert (msg.wrench.torque.z, msg.wrench.force.x, msg.wrench.force.y) == tuple(
            snap.drive_wrenches[k])
        assert msg.header.frame_id == d.body and msg.header.stamp.nanosec == 9_000_000
