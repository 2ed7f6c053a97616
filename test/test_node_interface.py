"""
The stage node's topic table and its hand-packed CDR, checked against rclpy's serializer.

serialize_message leaves alignment padding uninitialised (whatever its buffer held), so the
packed bytes are compared with it at every byte that is not padding; the packer writes zeros
there, and both deserialize to equal messages.
"""
import math

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseArray, PoseStamped, TransformStamped, WrenchStamped
from rclpy.serialization import deserialize_message, serialize_message
from rosgraph_msgs.msg import Clock
from std_msgs.msg import Float64

from flexure_sim.engine.mechanism.loader import load_mechanism, mechanism_from_dict
from flexure_sim.node.publish.cdr import StampedPacker, pack_diagnostics, split_stamp
from flexure_sim.node.publish.interface import (
    StageInterface,
    check_names,
    diagnostics_message,
    encode_diagnostics,
    yaw_quaternion,
)
from flexure_sim.engine.solver.simulation import Simulation

STAMPS = [0, 1, 999_999_999, 1_000_000_000, 1_234_567_891_011, 2**31 * 1_000_000_000 - 1]


def moving_snapshot(name: str, steps: int = 30):
    """
    Return a snapshot with non-trivial values in every field.

    The static answer at 1.35 um (stage) or at a time when the four-bar's driver has turned the
    linkage.
    """
    mech = load_mechanism(name)
    sim = Simulation(mech)
    result = sim.static(1.35e-6 if sim.drive is not None else 0.0, t=steps * 1e-3)
    return mech, result.snapshot


@pytest.mark.parametrize("name", ["microstage", "fourbar_mixed", "fourbar_cantilever"])
@pytest.mark.parametrize("mode", ["realtime", "fast"])
def test_packed_messages_equal_serialize_message_outside_padding(name, mode):
    mech, snap = moving_snapshot(name)
    itf = StageInterface(mech, mode)
    for stamp in STAMPS:
        packed = itf.encode(snap, stamp)
        reference = itf.messages(snap, stamp)
        packers = itf.packers()
        assert len(packed) == len(reference) == len(packers) == len(itf.tick_topics)
        for spec, data, msg, packer in zip(itf.tick_topics, packed, reference, packers):
            assert isinstance(msg, spec.msg_type), spec.name
            expected = serialize_message(msg)
            assert len(data) == len(expected) == packer.size, spec.name
            padding = set(packer.padding)
            assert all(data[i] == 0 for i in padding), spec.name
            assert bytes(b for i, b in enumerate(data) if i not in padding) == \
                bytes(b for i, b in enumerate(expected) if i not in padding), spec.name
            assert deserialize_message(data, spec.msg_type) == msg, spec.name


def test_stamped_packer_handles_every_frame_id_alignment():
    # frame ids of 0..9 characters shift the float64 block through every alignment.
    for n in range(10):
        frame = "f" * n
        child = "c" * (9 - n)
        packer = StampedPacker(frame, 7, strings=(child,))
        values = [0.1 * k - 0.3 for k in range(7)]
        data = packer.pack(12, 34, *values)
        msg = TransformStamped()
        msg.header.stamp.sec, msg.header.stamp.nanosec = 12, 34
        msg.header.frame_id, msg.child_frame_id = frame, child
        t, r = msg.transform.translation, msg.transform.rotation
        t.x, t.y, t.z, r.x, r.y, r.z, r.w = values
        expected = serialize_message(msg)
        mask = set(packer.padding)
        assert len(data) == len(expected)
        assert [b for i, b in enumerate(data) if i not in mask] == [
            b for i, b in enumerate(expected) if i not in mask
        ]
        assert deserialize_message(data, TransformStamped) == msg


def test_non_ascii_frames_are_packed_as_utf8():
    packer = StampedPacker("stäge", 7)
    msg = PoseStamped()
    msg.header.frame_id = "stäge"
    msg.pose.orientation.w = 1.0
    data = packer.pack(0, 0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0)
    assert deserialize_message(data, PoseStamped) == msg


def test_stage_topic_table_names_types_frames():
    mech = load_mechanism("microstage")
    itf = StageInterface(mech, "fast")
    table = {t.name: t for t in itf.tick_topics}
    assert list(table)[:2] == ["/clock", "bodies/poses"]
    assert len(table) == 27
    assert table["drive/wrench"].msg_type is WrenchStamped
    assert table["drive/wrench"].frame_id == "body6"
    assert (
        table["bodies/poses"].msg_type is PoseArray and table["bodies/poses"].frame_id == "stage"
    )
    assert table["bodies/body6/pose"].msg_type is PoseStamped
    assert (
        table["hinges/a/wrench"].msg_type is WrenchStamped
        and table["hinges/a/wrench"].frame_id == "hinge_a"
    )
    assert "body6" in table["hinges/a/wrench"].description  # the body the wrench acts on
    assert table["hinges/g/deflection"].frame_id == "hinge_g_a"
    assert table["hinges/a/compression"].msg_type is Float64
    assert {"output/displacement", "drive/input", "drive/force"} <= set(table)
    assert (
        table["/clock"].msg_type is Clock
        and table["/clock"].type_name == "rosgraph_msgs/msg/Clock"
    )
    assert itf.command.name == "drive/displacement" and itf.diagnostics.name == "diagnostics"
    assert all(not t.name.startswith("/") for t in itf.tick_topics[1:])
    assert "/clock" not in {t.name for t in StageInterface(mech, "realtime").tick_topics}


def test_fourbar_has_no_drive_output_or_compression_topics():
    itf = StageInterface(load_mechanism("fourbar_mixed"), "realtime")
    names = [t.name for t in itf.tick_topics]
    assert names == ["bodies/poses"] + [f"bodies/link{i}/pose" for i in range(1, 5)] + [
        f"hinges/{h}/{k}" for h in "ABCD" for k in ("wrench", "deflection")]
    assert itf.command is None


def test_values_land_in_the_documented_fields():
    mech, snap = moving_snapshot("microstage", steps=50)
    itf = StageInterface(mech, "realtime")
    msgs = dict(zip((t.name for t in itf.tick_topics), itf.messages(snap, 5_000_000)))
    pose = msgs["bodies/body4/pose"].pose
    assert (pose.position.x, pose.position.y, pose.position.z) == (
        snap.poses[3, 0],
        snap.poses[3, 1],
        0.0,
    )
    assert 2 * math.atan2(pose.orientation.z, pose.orientation.w) == pytest.approx(
        snap.poses[3, 2], abs=1e-15
    )
    w = msgs["hinges/c/wrench"].wrench
    assert (w.torque.z, w.force.x, w.force.y) == tuple(snap.wrenches[2])
    assert (w.torque.x, w.torque.y, w.force.z) == (0.0, 0.0, 0.0)
    d = msgs["hinges/c/deflection"].transform
    assert (d.translation.x, d.translation.y) == tuple(snap.deflections[2, 1:])
    assert msgs["output/displacement"].data == snap.output
    assert msgs["hinges/a/compression"].data == snap.compression
    assert (
        msgs["drive/input"].data == snap.drive_input
        and msgs["drive/force"].data == snap.drive_force
    )
    assert np.allclose(yaw_quaternion(0.3), (0, 0, math.sin(0.15), math.cos(0.15)))
    assert split_stamp(1_500_000_001) == (1, 500_000_001)


def test_clashing_frame_names_are_refused():
    mech = load_mechanism("microstage")
    data = {
        "name": "clash",
        "defaults": {"damping": {"t_char": 1e-3}},
        "bodies": [
            {"name": "stage", "mass": 1.0, "inertia": 1.0, "pose": [0, 0, 0]},
            {"name": "b", "mass": 1.0, "inertia": 1.0, "pose": [0, 0, 0]},
        ],
        "hinges": [
            {
                "name": "h",
                "a": {"body": "stage", "at": [0, 0]},
                "b": {"body": "b", "at": [0, 0]},
                "stiffness": {"model": "matrix", "K": np.eye(3).tolist()},
            }
        ],
        "constraints": [{"type": "fixed", "body": "stage"}],
    }
    clash = mechanism_from_dict(data)
    with pytest.raises(ValueError, match="clashes with the root frame"):
        check_names(clash)
    check_names(mech)


@pytest.mark.parametrize("level", [0, 1, 2, 3])
def test_packed_diagnostics_equal_serialize_message_outside_padding(level):
    # Names and values of 0..5 bytes (and a 2-byte UTF-8 character) walk every alignment.
    for shift in range(6):
        values = [
            (f"k{'x' * ((shift + i) % 5)}", 1.5 * i if i % 2 else "é" * (i % 3)) for i in range(9)
        ]
        values += [("flag", True), ("count", 7), ("empty", "")]
        args = (
            1_234_567_891_011 + shift,
            "n" * shift,
            "hw" * shift,
            level,
            "m" * (5 - shift),
            values,
        )
        msg = diagnostics_message(*args)
        expected = serialize_message(msg)
        data = encode_diagnostics(*args)
        padding: list[int] = []
        sec, nsec = split_stamp(args[0])
        again = pack_diagnostics(
            sec,
            nsec,
            level,
            args[1],
            args[4],
            args[2],
            [(kv.key, kv.value) for kv in msg.status[0].values],
            padding=padding,
        )
        assert again == data
        mask = set(padding)
        assert len(data) == len(expected)
        assert all(data[i] == 0 for i in mask)
        assert [b for i, b in enumerate(data) if i not in mask] == \
            [b for i, b in enumerate(expected) if i not in mask]
        assert deserialize_message(data, DiagnosticArray) == msg
