"""
Drive commands in every CDR encoding a ROS 2 publisher may use.

Also the serialize_message fallback of the node's packed CDR (issue 10 item 9).

Payloads are built here from the encapsulation rules (DDS-XTypes 1.3, 7.6.3.1.2 and 7.4.3):
a 2-byte big-endian encapsulation identifier, 2 option bytes, then the body in the byte
order the identifier names; plain CDR aligns a float64 to 8, XCDR2 to 4 (the same offset for
a lone float64); delimited XCDR2 puts a uint32 DHEADER (body size) first.
"""
from __future__ import annotations

import math
import struct

import pytest
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.serialization import deserialize_message, serialize_message
from std_msgs.msg import Float64

from flexure_sim.engine.mechanism.loader import load_mechanism
from flexure_sim.engine.solver.simulation import Simulation
from flexure_sim.node.publish import cdr, diagnostics_msg
from flexure_sim.node.publish import interface as itf
from flexure_sim.node.publish.cdr import packing_applies, parse_float64
from flexure_sim.node.publish.interface import (
    StageInterface, diagnostics_message, encode_diagnostics,
)

from node_harness import NodeProcess, Peer, diagnostics_values, next_domain_id

VALUES = (0.0, 1.35e-6, -2.5, 1e300, math.inf)


def payloads(v: float) -> dict[str, bytes]:
    return {
        "CDR_LE": b"\x00\x01\x00\x00" + struct.pack("<d", v),
        "CDR_BE": b"\x00\x00\x00\x00" + struct.pack(">d", v),
        "CDR2_LE": b"\x00\x07\x00\x00" + struct.pack("<d", v),
        "CDR2_BE": b"\x00\x06\x00\x00" + struct.pack(">d", v),
        "D_CDR2_LE": b"\x00\x09\x00\x00" + struct.pack("<I", 8) + struct.pack("<d", v),
        "D_CDR2_BE": b"\x00\x08\x00\x00" + struct.pack(">I", 8) + struct.pack(">d", v),
    }


@pytest.mark.parametrize("value", VALUES)
def test_every_encoding_of_a_float64_parses_to_its_value(value):
    for name, data in payloads(value).items():
        assert parse_float64(data) == value, name
    for name, data in payloads(math.nan).items():
        assert math.isnan(parse_float64(data)), name  # a NaN sent is a NaN read (then rejected)


def test_another_middleware_reads_commands_with_rclpy():
    for value in VALUES:
        for name in ("CDR_LE", "CDR_BE", "CDR2_LE", "CDR2_BE"):
            assert parse_float64(payloads(value)[name], rmw="rmw_cyclonedds_cpp") == value


@pytest.mark.parametrize("data, problem", [
    (b"", "too short"),
    (b"\x00\x01\x00", "too short"),
    (b"\x00\x01\x00\x00\x00\x00", "needs 12 bytes"),
    (b"\xff\xfe\x00\x00" + bytes(8), "unknown CDR encapsulation ff fe"),
    (b"\x00\x03\x00\x00" + bytes(8), "PL_CDR_LE"),
    (b"\x00\x0b\x00\x00" + struct.pack("<II", 12, 0) + bytes(8), "PL_CDR2_LE"),
    (b"\x00\x07\x00\x00\x01", "CDR2_LE: not a Float64"),
    (b"\x00\x09\x00\x00" + struct.pack("<I", 99) + bytes(8), "DHEADER says 99 bytes"),
])
def test_a_payload_that_is_no_float64_is_refused_by_name(data, problem):
    with pytest.raises(ValueError, match=problem):
        parse_float64(data)


def test_packed_cdr_only_under_fast_dds_and_for_known_layouts(monkeypatch):
    assert packing_applies("geometry_msgs/msg/PoseStamped", rmw="rmw_fastrtps_cpp")
    assert packing_applies("geometry_msgs/msg/PoseStamped", rmw="rmw_fastrtps_dynamic_cpp")
    assert not packing_applies("geometry_msgs/msg/PoseStamped", rmw="rmw_cyclonedds_cpp")
    assert not packing_applies("sensor_msgs/msg/JointState", rmw="rmw_fastrtps_cpp")
    mech = load_mechanism("microstage")
    snap = Simulation(mech).static(1.35e-6).snapshot
    assert StageInterface(mech, "fast").packed  # this machine runs Fast DDS
    monkeypatch.setattr(cdr, "middleware", lambda: "rmw_cyclonedds_cpp")
    serialized = []
    real = itf.serialize_message

    def serialize(msg):  # the real serializer, noting what it was given
        serialized.append(type(msg).__name__)
        return real(msg)

    monkeypatch.setattr(itf, "serialize_message", serialize)
    monkeypatch.setattr(diagnostics_msg, "serialize_message", serialize)
    iface = StageInterface(mech, "fast")
    assert not iface.packed
    stamp = 1_234_567_891
    reference = iface.messages(snap, stamp)
    encoded = iface.encode(snap, stamp)
    assert serialized == [type(m).__name__ for m in reference]
    assert [deserialize_message(b, type(m)) for b, m in zip(encoded, reference)] == reference
    values = [("sim_time", 1.5), ("recording", True)]
    payload = encode_diagnostics(stamp, "n", "h", 1, "m", values)
    assert serialized[-1] == "DiagnosticArray"
    assert deserialize_message(payload, DiagnosticArray) == diagnostics_message(
        stamp, "n", "h", 1, "m", values)


def test_the_node_applies_xcdr2_commands_and_refuses_garbage_without_nan(tmp_path):
    """A real node: raw payloads published by a real peer (rclpy publishes bytes as given)."""
    domain = next_domain_id()
    peer = Peer(domain)
    node = NodeProcess(tmp_path / "node", domain, dict(
        time_mode="realtime", sim_step=5e-4, publish_rate=200.0, slew_rate=1.0,
        record=True, record_path="cmd.mcap"))
    peer.watch = node
    try:
        peer.subscribe("/diagnostics", DiagnosticArray)
        peer.subscribe("/drive/input", Float64, depth=10000)
        drive = peer.publisher("/drive/displacement", Float64)
        peer.wait_for_publishers(["/diagnostics", "/drive/input"])
        peer.wait_for_subscribers(drive)

        def diag() -> dict[str, str]:
            return diagnostics_values(peer.last("/diagnostics"))

        def applied(value: float) -> None:
            peer.spin_until(lambda: peer.last("/diagnostics") is not None
                            and float(diag()["drive_target"]) == value, 20,
                            f"the drive target to become {value}")

        drive.publish(payloads(1.25e-6)["CDR2_LE"])
        applied(1.25e-6)
        drive.publish(payloads(0.75e-6)["CDR2_BE"])
        applied(0.75e-6)
        drive.publish(b"\xff\xfe\x00\x00" + bytes(8))
        drive.publish(b"\x00\x07\x00\x00\x01")  # XCDR2, cut short
        peer.spin_until(lambda: diag()["commands_malformed"] == "2", 20, "2 refused commands")
        d = diag()
        peer.spin_for(0.2)
    finally:
        peer.watch = None
        rc = node.stop()
        peer.close()
    assert rc == 0, node.stderr
    counts = ("commands_received", "commands_accepted", "commands_rejected")
    assert tuple(d[k] for k in counts) == ("4", "2", "2")
    assert float(d["drive_target"]) == 0.75e-6
    inputs = [m.data for m in peer.messages("/drive/input")]
    assert not any(math.isnan(x) for x in inputs)
    assert "unknown CDR encapsulation ff fe" in node.stderr


@pytest.mark.parametrize("data", [b"", b"\x00\x01", bytes(range(13)), b"\xff" * 64])
def test_the_rejected_payload_record_is_what_rclpy_serializes_for_a_uint8_multi_array(data):
    """The node records a payload it cannot read as a UInt8MultiArray holding it."""
    from std_msgs.msg import UInt8MultiArray

    packed = cdr.pack_uint8_array(data)
    assert packed == serialize_message(UInt8MultiArray(data=list(data)))
    assert bytes(deserialize_message(packed, UInt8MultiArray).data) == data
