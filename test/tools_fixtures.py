"""
Recordings for the tools' tests, written without DDS.

The engine stepped as the node steps it, its state turned into the node's messages (rclpy message
classes, serialize_message) and written with McapRecorder under the node's topic names and metadata
keys.

The end-to-end tests (test_tools_e2e.py) use the real node; these files make the unit tests
fast and independent of it.
"""
from __future__ import annotations

import math
import types
from pathlib import Path
from typing import Optional, Sequence

from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import Pose, PoseArray, PoseStamped, TransformStamped, WrenchStamped
from rclpy.serialization import serialize_message
from rosgraph_msgs.msg import Clock
from std_msgs.msg import Float64

from flexure_sim.engine.mechanism.loader import load_mechanism, resolve_mechanism_path
from flexure_sim.recording import McapRecorder
from flexure_sim.engine.solver.simulation import Simulation
from reference_figures import STAGE_GAIN

#: The demo profile of the main job (m): up to the stage's full stroke and back.
DEMO_LEVELS = (0.5e-6, 1.0e-6, 1.5e-6, 2.0e-6, 0.0)


def _stamp(ns: int) -> Time:
    return Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def _quat(q, yaw: float) -> None:
    q.x, q.y, q.z, q.w = 0.0, 0.0, math.sin(0.5 * yaw), math.cos(0.5 * yaw)


def record_stage_run(
    path: Path,
    levels: Sequence[float] = DEMO_LEVELS,
    rest: float = 0.01,
    dwell: float = 0.02,
    publish_rate: float = 1000.0,
    sim_step: float = 1e-4,
    mechanism: str = "microstage",
    record_command: bool = True,
    clock: bool = True,
    namespace: str = "",
    extra_commands: Sequence[tuple[float, float]] = (),
    chunk_size: int = 1 << 20,
    metadata: bool = True,
    wall_clock: Optional[tuple[int, float]] = None,
    mechanism_yaml: bool = True,
) -> dict:
    """
    Record a stage run: at rest for ``rest`` s, then each level for ``dwell`` s.

    Returns what the live run saw: per step the settled (input, output) before the next
    command, for comparing with the analysis. ``wall_clock`` = (offset ns, real-time factor)
    writes log times as ``ros2 bag record`` without ``--use-sim-time`` would: the wall-clock
    time of reception (offset + sim time / factor, 1 us apart within a tick), not sim time.
    ``mechanism_yaml=False`` leaves the mechanism's YAML text out of the metadata (its name
    and path stay).
    """
    mech = load_mechanism(mechanism)
    sim = Simulation(mech, dt=sim_step, relinearize_tol=1e-4)
    n_steps = round(1.0 / (publish_rate * sim_step))
    period_ns = round(1e9 / publish_rate)
    bodies = [b.name for b in mech.bodies]
    hinges = [h.name for h in mech.hinges]
    ns = namespace.rstrip("/")
    topics = []
    if clock:
        topics.append(("/clock", "rosgraph_msgs/msg/Clock"))
    topics.append((f"{ns}/bodies/poses", "geometry_msgs/msg/PoseArray"))
    topics += [(f"{ns}/bodies/{b}/pose", "geometry_msgs/msg/PoseStamped") for b in bodies]
    for h in hinges:
        topics += [(f"{ns}/hinges/{h}/wrench", "geometry_msgs/msg/WrenchStamped"),
                   (f"{ns}/hinges/{h}/deflection", "geometry_msgs/msg/TransformStamped")]
    has_drive = mech.drive is not None
    if has_drive:
        topics += [(f"{ns}/hinges/{mech.compression_hinge}/compression", "std_msgs/msg/Float64"),
                   (f"{ns}/output/displacement", "std_msgs/msg/Float64"),
                   (f"{ns}/drive/input", "std_msgs/msg/Float64"),
                   (f"{ns}/drive/force", "std_msgs/msg/Float64")]
    topics.append((f"{ns}/diagnostics", "diagnostic_msgs/msg/DiagnosticArray"))
    if has_drive and record_command:
        topics.append((f"{ns}/drive/displacement", "std_msgs/msg/Float64"))
    mech_path = resolve_mechanism_path(mechanism).resolve()
    meta = {
        "mechanism": mechanism,
        "publish_rate": repr(publish_rate),
        "sim_step": repr(sim_step),
        "time_mode": "fast" if clock else "realtime",
        "stroke_min": repr(mech.drive.stroke[0]) if has_drive else "0.0",
        "stroke_max": repr(mech.drive.stroke[1]) if has_drive else "0.0",
        "slew_rate": repr(mech.drive.slew_rate) if has_drive else "1.0",
        "record": "true",
        "record_dir": "runs",
        "record_path": str(path),
        "mechanism_name": mech.name,
        "mechanism_path": str(mech_path),
        "mechanism_yaml": mech_path.read_text() if mechanism_yaml else "",
        "node": f"{ns}/stage_node",
        "flexure_sim_version": "0.1.0",
        "steps_per_tick": str(n_steps),
        "relinearize_tol": "0.0001",
        "root_frame": "stage",
        "bodies": ",".join(bodies),
        "hinges": ",".join(hinges),
        "run": "0",
        "sim_time_start": "0.0",
        "started_utc": "2025-01-01T00:00:00+00:00",
    }
    schedule = []
    t_cmd = rest
    for level in levels:
        schedule.append((round(t_cmd * 1e9), level))
        t_cmd += dwell
    schedule += [(round(t * 1e9), v) for t, v in extra_commands]
    schedule.sort(key=lambda x: x[0])
    t_stop_ns = round(t_cmd * 1e9)
    live: list[dict] = []
    last = {"input": 0.0, "output": 0.0}
    seq = [0, -1]

    def log_time(stamp_ns: int) -> int:
        if wall_clock is None:
            return stamp_ns
        seq[0] = seq[0] + 1 if seq[1] == stamp_ns else 0
        seq[1] = stamp_ns
        return wall_clock[0] + round(stamp_ns / wall_clock[1]) + 1000 * seq[0]

    with McapRecorder(path, chunk_size=chunk_size) as recorder:
        for name, type_name in topics:
            recorder.add_topic(name, type_name)
        if metadata:
            recorder.add_metadata("flexure_sim", meta)
        rec = types.SimpleNamespace(
            write=lambda topic, payload, stamp: recorder.write(topic, payload, log_time(stamp)))
        stamp = 0
        k = 0
        while stamp < t_stop_ns:
            # Commands due at this tick's start (the previous tick's stamp), as the node does.
            while k < len(schedule) and schedule[k][0] <= stamp:
                value = schedule[k][1]
                if has_drive:
                    live.append({"t": stamp / 1e9, "command": value, **last})
                    sim.set_command(value)
                    if record_command:
                        rec.write(
                            f"{ns}/drive/displacement",
                            serialize_message(Float64(data=value)),
                            stamp,
                        )
                k += 1
            sim.step(n_steps)
            snap = sim.snapshot()
            stamp += period_ns
            st = _stamp(stamp)
            if clock:
                rec.write("/clock", serialize_message(Clock(clock=st)), stamp)
            poses = []
            for x, y, th in snap.poses.tolist():
                p = Pose()
                p.position.x, p.position.y = x, y
                _quat(p.orientation, th)
                poses.append(p)
            arr = PoseArray()
            arr.header.stamp, arr.header.frame_id, arr.poses = st, "stage", poses
            rec.write(f"{ns}/bodies/poses", serialize_message(arr), stamp)
            for b, p in zip(bodies, poses):
                msg = PoseStamped()
                msg.header.stamp, msg.header.frame_id, msg.pose = st, "stage", p
                rec.write(f"{ns}/bodies/{b}/pose", serialize_message(msg), stamp)
            for h, (m, fx, fy), (a, px, py) in zip(
                hinges, snap.wrenches.tolist(), snap.deflections.tolist()
            ):
                w = WrenchStamped()
                w.header.stamp, w.header.frame_id = st, f"hinge_{h}"
                w.wrench.force.x, w.wrench.force.y, w.wrench.torque.z = fx, fy, m
                rec.write(f"{ns}/hinges/{h}/wrench", serialize_message(w), stamp)
                d = TransformStamped()
                d.header.stamp, d.header.frame_id, d.child_frame_id = (
                    st,
                    f"hinge_{h}_a",
                    f"hinge_{h}",
                )
                d.transform.translation.x, d.transform.translation.y = px, py
                _quat(d.transform.rotation, a)
                rec.write(f"{ns}/hinges/{h}/deflection", serialize_message(d), stamp)
            if has_drive:
                for topic, value in (
                    (f"{ns}/hinges/{mech.compression_hinge}/compression", snap.compression),
                    (f"{ns}/output/displacement", snap.output),
                    (f"{ns}/drive/input", snap.drive_input),
                    (f"{ns}/drive/force", snap.drive_force),
                ):
                    rec.write(topic, serialize_message(Float64(data=float(value))), stamp)
                last = {"input": snap.drive_input, "output": snap.output}
            if stamp % 100_000_000 == 0:
                status = DiagnosticStatus(name="stage_node: simulation", hardware_id=mech.name,
                                          message="running", level=b"\x00",
                                          values=[KeyValue(key="sim_time", value=repr(snap.t)),
                                                  KeyValue(key="real_time_factor", value="1.0")])
                diag = DiagnosticArray(status=[status])
                diag.header.stamp = st
                rec.write(f"{ns}/diagnostics", serialize_message(diag), stamp)
    live.append({"t": stamp / 1e9, "command": None, **last})
    return {"commands": live, "mechanism": mech}


def live_gains(live: dict) -> list[Optional[float]]:
    """Gain of each step from the values seen just before each command (and at the end)."""
    points = live["commands"]
    gains = []
    for before, after in zip(points[:-1], points[1:]):
        du = after["input"] - before["input"]
        gains.append((after["output"] - before["output"]) / du if du else None)
    return gains


def record_long_run(path: Path, seconds: float, publish_rate: float = 1000.0,
                    step_every: float = 0.05, chunk_size: int = 1 << 20) -> int:
    """
    Return a run of the stage's topics (seven bodies and hinges, /clock, diagnostics at 10 Hz).

    ``seconds`` long, written fast: the values are those of a first-order lag (tau 0.5 ms)
    following a command that alternates between 1 and 2 um every ``step_every`` s, scaled by the
    stage's gain, without stepping the engine (all bodies share a pose, all hinges a wrench).
    Returns the number of messages written.
    """
    bodies = [f"body{k}" for k in range(1, 8)]
    hinges = list("abcdefg")
    topics = [("/clock", "rosgraph_msgs/msg/Clock"),
              ("/bodies/poses", "geometry_msgs/msg/PoseArray")]
    topics += [(f"/bodies/{b}/pose", "geometry_msgs/msg/PoseStamped") for b in bodies]
    for h in hinges:
        topics += [(f"/hinges/{h}/wrench", "geometry_msgs/msg/WrenchStamped"),
                   (f"/hinges/{h}/deflection", "geometry_msgs/msg/TransformStamped")]
    scalars = ("/hinges/a/compression", "/output/displacement", "/drive/input", "/drive/force")
    topics += [(t, "std_msgs/msg/Float64") for t in scalars]
    topics += [("/diagnostics", "diagnostic_msgs/msg/DiagnosticArray"),
               ("/drive/displacement", "std_msgs/msg/Float64")]
    period_ns = round(1e9 / publish_rate)
    ticks = round(seconds * publish_rate)
    ticks_per_step = round(step_every * publish_rate)
    tau, gain = 0.5e-3, STAGE_GAIN
    decay = math.exp(-1.0 / (publish_rate * tau))
    u, target, count = 0.0, 0.0, 0
    pose, wrench, deflection = PoseStamped(), WrenchStamped(), TransformStamped()
    pose.header.frame_id = "stage"
    array_msg = PoseArray()
    array_msg.header.frame_id = "stage"
    array_msg.poses = [Pose() for _ in bodies]
    with McapRecorder(path, chunk_size=chunk_size) as recorder:
        for name, type_name in topics:
            recorder.add_topic(name, type_name)
        for k in range(ticks):
            stamp = (k + 1) * period_ns
            if k % ticks_per_step == 0:
                target = 1e-6 if (k // ticks_per_step) % 2 == 0 else 2e-6
                recorder.write("/drive/displacement", serialize_message(Float64(data=target)),
                               k * period_ns)
                count += 1
            u = target + (u - target) * decay
            st = _stamp(stamp)
            recorder.write("/clock", serialize_message(Clock(clock=st)), stamp)
            for i, p in enumerate(array_msg.poses):
                p.position.x = gain * u * i / 7
            array_msg.header.stamp = st
            recorder.write("/bodies/poses", serialize_message(array_msg), stamp)
            pose.header.stamp = deflection.header.stamp = wrench.header.stamp = st
            # One payload per type and tick, shared by the bodies and hinges (fast to write).
            pose.pose.position.x = gain * u
            payload = serialize_message(pose)
            for b in bodies:
                recorder.write(f"/bodies/{b}/pose", payload, stamp)
            wrench.wrench.force.x, wrench.wrench.torque.z = 2e7 * u, 1e3 * u
            deflection.transform.translation.x = u
            wrench_payload = serialize_message(wrench)
            deflection_payload = serialize_message(deflection)
            for h in hinges:
                recorder.write(f"/hinges/{h}/wrench", wrench_payload, stamp)
                recorder.write(f"/hinges/{h}/deflection", deflection_payload, stamp)
            for topic, value in zip(scalars, (0.142 * u, gain * u, u, 2.26e7 * u)):
                recorder.write(topic, serialize_message(Float64(data=value)), stamp)
            count += 1 + 1 + len(bodies) + 2 * len(hinges) + len(scalars)
            if k % round(publish_rate / 10) == 0:
                diag = DiagnosticArray(status=[DiagnosticStatus(
                    name="stage_node: simulation", message="running", level=b"\x00",
                    values=[KeyValue(key="sim_time", value=repr(stamp / 1e9))])])
                diag.header.stamp = st
                recorder.write("/diagnostics", serialize_message(diag), stamp)
                count += 1
    return count
