"""
stage_node on mechanisms in space: the tip-tilt stage, and the microstage opened in 3-D.

Real node processes in lockstep mode, real DDS peers, real recordings read back with rosbags'
AnyReader and ``flexure-sim analyse``. Expected values come from another path than the node's
stepped dynamics: the spatial engine's statics (``SpatialSimulation.static_snapshot``,
Newton on the exact stiffness) and ``static_gain`` (its exact linearisation), rigid-body
equilibrium of the platform written here with SciPy's rotations, and the planar engine.
"""
from __future__ import annotations

import json
import math
import signal

import numpy as np
import pytest
from rosgraph_msgs.msg import Clock
from scipy.spatial.transform import Rotation
from std_msgs.msg import Float64

from node_harness import NodeProcess

DRIVES = ("p1", "p2", "p3")
OUTPUTS = ("tip", "tilt", "piston")
#: Steps from -U to +U about rest (least squares over -U, +U, 0: the gain at rest exactly to
#: second order in U).
U = 2e-6
INPUTS = [f"/drive/{d}/input" for d in DRIVES]
HINGES = ("wire1", "wire2", "wire3", "guide1", "guide2", "guide3")
BODIES = ("base", "platform", "cap1", "cap2", "cap3")


def read_bag(path) -> dict[str, list]:
    """Every message of a recording by topic: (log time, decoded), rosbags' AnyReader."""
    from rosbags.highlevel import AnyReader

    out: dict[str, list] = {}
    with AnyReader([path]) as reader:
        for connection, log_time, raw in reader.messages():
            out.setdefault(connection.topic, []).append(
                (log_time, reader.deserialize(raw, connection.msgtype)))
    return out


def before(series: list, t: float):
    """Return the last message of ``series`` logged before time ``t`` (ns)."""
    return [m for time, m in series if time < t][-1]


def xyzw(q) -> np.ndarray:
    return np.array([q.x, q.y, q.z, q.w])


def vec(v) -> np.ndarray:
    return np.array([v.x, v.y, v.z])


@pytest.mark.slow
def test_tiptilt_node_settles_at_the_engines_statics_and_analyse_gives_its_static_gain(
        tmp_path, domain, peer, capsys):
    from flexure_sim.engine.mechanism.spatial_loader import load_spatial
    from flexure_sim.engine.solver.spatial_simulation import SpatialSimulation

    node = NodeProcess(tmp_path / "node", domain, {
        "mechanism": "tiptilt_stage", "time_mode": "lockstep", "sim_step": 1e-4,
        "publish_rate": 20.0, "display_rate": 20.0, "record_path": "tt.mcap",
        **{f"drives.{d}.stroke_min": -1.5e-5 for d in DRIVES}})
    peer.watch = node
    try:
        commands = peer.connect_drives(DRIVES, INPUTS)
        for k, drive in enumerate(DRIVES):
            for level in (-U, U, 0.0):
                commands[drive].publish(Float64(data=level))
                # The 0.1 ms actuator lag and the modes (6-12 kHz, ~2 % damped: 1.3 ms decay)
                # settle within the 50 ms tick; three more ticks at rest for analyse.
                peer.tick_until(lambda: abs(peer.last(INPUTS[k]).data - level) < 1e-12 * U,
                                f"drive {drive} at {level:g} m", INPUTS)
                for _ in range(3):
                    peer.tick(INPUTS)
    finally:
        assert node.stop(signal.SIGINT) == 0, node.stderr
    assert "tiptilt_stage" in node.stderr and "28 topics per tick" in node.stderr
    path = node.cwd / "tt.mcap"
    bag = read_bag(path)
    sent = sorted(t for d in DRIVES for t, _ in bag[f"/drive/{d}/displacement"])
    assert len(sent) == 9
    # The end of p1's +U level: p1 = U, p2 = p3 = 0, against the engine's static equilibrium.
    end = sent[2]
    sim = SpatialSimulation(load_spatial("tiptilt_stage"))
    static = sim.static_snapshot({"p1": U, "p2": 0.0, "p3": 0.0})
    poses = {b: before(bag[f"/bodies/{b}/pose"], end) for b in BODIES}
    for i, b in enumerate(BODIES):
        msg = poses[b]
        assert msg.header.frame_id == "stage"
        q = xyzw(msg.pose.orientation)
        assert abs(np.linalg.norm(q) - 1.0) < 1e-12
        expected_q = static.quaternions[i][[1, 2, 3, 0]]
        assert np.max(np.abs(q - expected_q)) < 1e-6 * 65.8 * U  # of the tip, 1.3e-4 rad
        assert np.max(np.abs(vec(msg.pose.position) - static.positions[i])) < 1e-6 * U
    platform = poses["platform"].pose
    # The quaternion is the output's rotation: its rotation vector is (tip, tilt, rz).
    phi = Rotation.from_quat(xyzw(platform.orientation)).as_rotvec()
    tip = before(bag["/output/tip/displacement"], end).data
    tilt = before(bag["/output/tilt/displacement"], end).data
    assert tip == pytest.approx(static.outputs["tip"], rel=1e-6)
    assert abs(phi[0] - tip) < 1e-9 * abs(tip) and abs(phi[1] - tilt) < 1e-9 * abs(tip)
    # Wrenches: all six components, in frame b, as the engine's statics; the platform (body B
    # of every hinge) is in equilibrium under them, summed in the root frame about its centre.
    mech = sim.mechanism
    r_platform = Rotation.from_quat(xyzw(platform.orientation))
    force_sum, torque_sum, scale = np.zeros(3), np.zeros(3), 0.0
    for h, hinge in enumerate(mech.hinges):
        msg = before(bag[f"/hinges/{hinge.name}/wrench"], end)
        assert msg.header.frame_id == f"hinge_{hinge.name}" and hinge.b.body == "platform"
        f, m = vec(msg.wrench.force), vec(msg.wrench.torque)
        expected = static.wrenches[h]
        size = np.max(np.abs(expected))
        assert np.max(np.abs(np.concatenate([m, f]) - expected)) < 1e-6 * size
        w, x, y, z = hinge.b.quaternion
        r_b = r_platform * Rotation.from_quat([x, y, z, w])
        arm = r_platform.apply(hinge.b.position)
        force_sum += r_b.apply(f)
        torque_sum += np.cross(arm, r_b.apply(f)) + r_b.apply(m)
        scale = max(scale, np.linalg.norm(f), np.linalg.norm(m) / 0.015)
        deflection = before(bag[f"/hinges/{hinge.name}/deflection"], end)
        assert deflection.header.frame_id == f"hinge_{hinge.name}_a"
        assert deflection.child_frame_id == f"hinge_{hinge.name}"
        assert abs(np.linalg.norm(xyzw(deflection.transform.rotation)) - 1.0) < 1e-12
    assert np.linalg.norm(force_sum) < 1e-6 * scale
    assert np.linalg.norm(torque_sum) < 1e-6 * scale * 0.015
    # Under tip the wires bend about x: torque out of the plane of a planar model, non-zero.
    wire1 = before(bag["/hinges/wire1/wrench"], end).wrench.torque
    assert math.hypot(wire1.x, wire1.y) > 1e-6
    # Markers in 3-D: a sphere per hinge at its frame b on the (unmagnified) platform.
    markers = before(bag["/markers"], end + 1).markers
    spheres = {mk.text: mk for mk in markers if mk.ns == "hinges"}
    assert set(spheres) == set(HINGES) and all(mk.type == 2 for mk in spheres.values())
    at = vec(spheres["wire1"].pose.position)
    expected_at = vec(platform.position) + r_platform.apply(mech.hinges[0].b.position)
    assert np.max(np.abs(at - expected_at)) < 1e-12
    assert {mk.header.frame_id for mk in markers} == {"stage"}
    # The platform's outline: a star from its origin out to each of its hinge frames and back.
    (star,) = [mk for mk in markers if mk.ns == "bodies" and mk.text == "platform"]
    points = np.array([vec(p) for p in star.points])
    assert np.max(np.abs(points[0::2] - vec(platform.position))) < 1e-12
    tips = vec(platform.position) + r_platform.apply([h.b.position for h in mech.hinges])
    assert points.shape == (13, 3) and np.max(np.abs(points[1::2] - tips)) < 1e-12
    # analyse: the gain matrix from the recording's steps is the engine's exact static gain.
    from flexure_sim.cli import main
    assert main(["analyse", str(path), "--json"]) == 0
    result = json.loads(capsys.readouterr().out)
    gm = result["gain_matrix"]
    assert gm["drives"] == list(DRIVES) and gm["outputs"] == list(OUTPUTS)
    measured = np.array(gm["matrix"], dtype=float)
    exact = sim.static_gain()
    error = np.max(np.abs(measured - exact)) / np.max(np.abs(exact))
    print(f"gain matrix from the recording:\n{measured}\nstatic_gain:\n{exact}\n"
          f"largest difference / largest entry: {error:.2e}")
    assert error < 1e-6
    units = {p["output"]: p["unit"] for p in result["pairs"]}
    assert units["tip"] == "rad/m" and units["piston"] == "m/m"
    # plot: the drives and outputs, and the hinge wrenches with all six components.
    assert main(["plot", str(path), "-o", str(tmp_path / "plots")]) == 0
    written = capsys.readouterr().out
    for figure in ("drives_outputs.png", "drive_forces.png", "hinge_wrenches.png"):
        assert figure in written and (tmp_path / "plots" / figure).stat().st_size > 0
    # Diagnostics of the 3-D node: OK, every tick's engine steps counted.
    status = bag["/diagnostics"][-1][1].status[0]
    values = {kv.key: kv.value for kv in status.values}
    assert status.level == 0 and status.hardware_id == "tiptilt_stage"
    assert int(values["engine_steps"]) == 500 * int(values["ticks"])
    assert values["hinge_colour"] == "|wrench| / peak" and values["engine_failures"] == "0"


@pytest.mark.slow
def test_a_planar_stage_in_3d_under_its_in_plane_drive_has_no_out_of_plane_motion(
        tmp_path, domain, peer, capsys):
    from flexure_sim.engine.mechanism.loader import load_mechanism
    from flexure_sim.engine.solver.simulation import Simulation

    node = NodeProcess(tmp_path / "node", domain, {
        "mechanism": "microstage", "space": "3d", "time_mode": "lockstep", "sim_step": 1e-4,
        "publish_rate": 20.0, "record_path": "micro3d.mcap"})
    peer.watch = node
    u = 1e-6
    try:
        peer.subscribe("/clock", Clock)
        peer.subscribe("/drive/input", Float64)
        command = peer.publisher("/drive/displacement", Float64)
        peer.wait_for_publishers(["/drive/input"])
        peer.wait_for_subscribers(command)
        for _ in range(2):  # at rest first: analyse sees the step
            peer.tick(["/drive/input"])
        command.publish(Float64(data=u))
        peer.tick_until(lambda: abs(peer.last("/drive/input").data - u) < 1e-12 * u,
                        "the drive at 1 um", ["/drive/input"])
        for _ in range(3):
            peer.tick(["/drive/input"])
    finally:
        assert node.stop(signal.SIGINT) == 0, node.stderr
    bag = read_bag(node.cwd / "micro3d.mcap")
    # The spatial engine ran (the planar one publishes the drive's wrench and the compression).
    assert "spatial engine (3-D)" in node.stderr
    assert "/drive/wrench" not in bag and "/hinges/a/compression" not in bag
    from flexure_sim.recording import read_log
    assert read_log(node.cwd / "micro3d.mcap").metadata["flexure_sim"]["space"] == "3d"
    planar = Simulation(load_mechanism("microstage")).static(u).snapshot
    names = [f"body{i}" for i in range(1, 7)]
    for i, b in enumerate(names):
        pose = bag[f"/bodies/{b}/pose"][-1][1].pose
        # Out of the plane: exactly nothing.
        assert (pose.position.z, pose.orientation.x, pose.orientation.y) == (0.0, 0.0, 0.0)
        # In the plane: the planar engine's statics.
        x, y, theta = planar.poses[i]
        assert abs(pose.position.x - x) < 1e-6 * u and abs(pose.position.y - y) < 1e-6 * u
        yaw = 2.0 * math.atan2(pose.orientation.z, pose.orientation.w)
        assert abs(yaw - theta) < 1e-6 * u / 0.01
    moved = 0.0
    for h in ("a", "b", "c", "d", "e", "f", "g"):
        wrench = bag[f"/hinges/{h}/wrench"][-1][1].wrench
        assert (wrench.force.z, wrench.torque.x, wrench.torque.y) == (0.0, 0.0, 0.0)
        moved = max(moved, abs(wrench.force.x), abs(wrench.force.y))
    assert moved > 0.1  # the hinges are loaded in the plane
    output = bag["/output/displacement"][-1][1].data
    assert output == pytest.approx(planar.output, rel=1e-6)
    # analyse of the 3-D recording: the step's gain, and the spatial engine's static solve at
    # the same inputs, are the planar engine's static gain.
    from flexure_sim.cli import main
    assert main(["analyse", str(node.cwd / "micro3d.mcap"), "--json"]) == 0
    (step,) = json.loads(capsys.readouterr().out)
    assert step["gain"] == pytest.approx(planar.output / u, rel=1e-6)
    assert step["static_gain"] == pytest.approx(planar.output / u, rel=1e-9)


def test_spatial_messages_pack_as_rclpy_serializes_them():
    from rclpy.serialization import serialize_message

    from flexure_sim.engine.mechanism.spatial_loader import load_spatial
    from flexure_sim.engine.solver.spatial_simulation import SpatialSimulation
    from flexure_sim.node.publish.spatial_messages import SpatialInterface

    mech = load_spatial("tiptilt_stage")
    sim = SpatialSimulation(mech)
    sim.set_command([3e-6, -1e-6, 2e-6])
    sim.step(7)  # mid-transient: every component of poses, wrenches, deflections moves
    snap = sim.snapshot()
    itf = SpatialInterface(mech, "lockstep", "s1/")
    names = [t.name for t in itf.tick_topics]
    assert names[:3] == ["/clock", "bodies/poses", "bodies/base/pose"]
    assert "drive/p1/wrench" not in names and "hinges/wire1/wrench" in names
    assert [c.name for c in itf.commands] == [f"drive/{d}/displacement" for d in DRIVES]
    units = {t.name: t.unit for t in itf.tick_topics}
    assert units["output/tip/displacement"] == "rad" and units["output/piston/displacement"] == "m"
    packed = itf.encode(snap, 1_234_567_890)
    reference = [serialize_message(m) for m in itf.messages(snap, 1_234_567_890)]
    assert len(packed) == len(reference) == len(names)
    # Byte for byte outside the alignment padding (serialize_message leaves it uninitialised).
    for payload, ref, packer in zip(packed, reference, itf.packers()):
        ref = bytearray(ref)
        for i in getattr(packer, "padding", ()):
            ref[i] = payload[i]
        assert payload == bytes(ref)
    wrench = itf.messages(snap, 0)[names.index("hinges/guide1/wrench")].wrench
    assert wrench.torque.x != 0.0 and wrench.torque.y != 0.0 and wrench.force.z != 0.0
    assert itf.messages(snap, 0)[1].header.frame_id == "s1/stage"


@pytest.mark.parametrize("space, words", [
    ("2d", ("tiptilt_stage", "space 2d", "space auto or 3d")),
    ("4d", ("space", "expected one of auto, 2d, 3d", "'4d'")),
])
def test_a_space_the_mechanism_cannot_run_in_stops_start_up_naming_it(tmp_path, domain, space,
                                                                      words):
    node = NodeProcess(tmp_path / "node", domain, {"mechanism": "tiptilt_stage",
                                                   "space": space, "record": False})
    rc = node.wait(120)
    lines = [line for line in node.stderr.splitlines() if line.strip()]
    assert rc == 1 and len(lines) == 1 and "Traceback" not in node.stderr, node.stderr
    assert lines[0].startswith("stage_node: error: ")
    for word in words:
        assert word in lines[0], (word, lines[0])


def test_tf_chain_through_the_bodies_gives_each_hinges_deflection():
    """
    TF in 3-D: stage -> body -> hinge frames, composed here with SciPy.

    At a deflected static state, frame a (through body A) and frame b (through body B) differ
    by the hinge's deflection the engine reports, and every fixed body is on /tf_static.
    """
    from flexure_sim.engine.mechanism.spatial_loader import load_spatial
    from flexure_sim.engine.solver.spatial_simulation import SpatialSimulation
    from flexure_sim.node.publish.spatial_display import SpatialDisplay
    from flexure_sim.topics import Frames

    mech = load_spatial("tiptilt_stage")
    snap = SpatialSimulation(mech).static_snapshot({"p1": 1e-5, "p2": 3e-6, "p3": 0.0})
    display = SpatialDisplay(mech, Frames("t/"), 1.0)
    static, moving = display.static(), display.moving(snap)
    assert [t.child for t in moving] == ["t/platform", "t/cap1", "t/cap2", "t/cap3"]
    assert [t.child for t in static if t.parent == "t/stage"] == ["t/base"]
    tree = {t.child: t for t in static + moving}
    assert len(tree) == len(static) + len(moving)

    def in_root(frame: str) -> tuple[np.ndarray, Rotation]:
        p, r = np.zeros(3), Rotation.identity()
        while frame != "t/stage":
            t = tree[frame]
            step = Rotation.from_quat(t.rotation)
            p, r = np.array(t.translation) + step.apply(p), step * r
            frame = t.parent
        return p, r

    largest = 0.0
    for h, hinge in enumerate(mech.hinges):
        pa, ra = in_root(f"t/hinge_{hinge.name}_a")
        pb, rb = in_root(f"t/hinge_{hinge.name}")
        phi, p = snap.deflections[h, :3], snap.deflections[h, 3:]
        assert np.max(np.abs(ra.inv().apply(pb - pa) - p)) < 1e-15
        assert np.max(np.abs((ra.inv() * rb).as_rotvec() - phi)) < 1e-12
        largest = max(largest, float(np.max(np.abs(phi))))
    assert largest > 1e-5  # the hinges are deflected: the check has something to find
