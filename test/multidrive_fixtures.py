"""
Recordings of mechanisms with several drives or outputs for the tools' tests, without DDS.

The engine stepped tick by tick as the node steps it; each drive's and output's values written
with McapRecorder under the node's topic names (``flexure_sim.topics``: per-drive and
per-output names unless the mechanism has one displacement drive / one output) and the
metadata keys stage_node records (``drives``, ``outputs``, ``drives.<name>.stroke_min``...).
test_tools_multidrive_node.py does the same through the real node.
"""
from __future__ import annotations

from pathlib import Path
from typing import Optional, Sequence

from builtin_interfaces.msg import Time
from rclpy.serialization import serialize_message
from rosgraph_msgs.msg import Clock
from std_msgs.msg import Float64

from flexure_sim import topics
from flexure_sim.engine.mechanism.loader import load_mechanism, resolve_mechanism_path
from flexure_sim.engine.solver.simulation import Simulation
from flexure_sim.recording import McapRecorder


def _stamp(ns: int) -> Time:
    return Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def record_drives_run(
    path: Path,
    mechanism: str,
    schedule: Sequence[tuple[float, str, float]],
    duration: float,
    publish_rate: float = 1000.0,
    sim_step: float = 1e-4,
    namespace: str = "",
    record_command: bool = True,
    mechanism_yaml: Optional[str] = None,
    nan_ticks: Sequence[int] = (),
) -> Simulation:
    """
    Record ``mechanism`` commanded by ``schedule`` ((time s, drive name, value), sorted).

    Each command is applied at the start of the first tick at or after its time and recorded
    with that tick's start as its stamp, as the node does. Returns the simulation (its
    mechanism and model: names, static solves).
    """
    mech = load_mechanism(mechanism)
    sim = Simulation(mech, dt=sim_step, relinearize_tol=1e-4)
    names = list(sim.model.drives.names)
    drives = mech.drives
    single_drive = len(drives) == 1 and drives[0].kind == "displacement"
    single_output = len(mech.all_outputs) == 1
    ns = namespace.rstrip("/")
    floats: list[str] = []
    if single_output:
        floats.append(topics.OUTPUT)
    else:
        floats += [topics.output_displacement(o.name) for o in mech.all_outputs]
    commands = {}
    for d in drives:
        if single_drive:
            floats += [topics.DRIVE_INPUT, topics.DRIVE_FORCE]
            commands[d.name] = topics.COMMAND
        else:
            floats.append(topics.drive_input(d.name))
            floats.append(topics.drive_position(d.name) if d.kind == "force"
                          else topics.drive_force(d.name))
            commands[d.name] = topics.drive_command(d.name, d.kind)
    meta = {
        "mechanism": mechanism, "mechanism_name": mech.name,
        "mechanism_yaml": mechanism_yaml if mechanism_yaml is not None
        else resolve_mechanism_path(mechanism).read_text(),
        "publish_rate": repr(publish_rate), "sim_step": repr(sim_step),
        "time_mode": "lockstep", "node": f"{ns}/stage_node",
        "drives": ",".join(f"{d.name}:{d.kind}" for d in drives),
        "outputs": ",".join(o.name for o in mech.all_outputs),
    }
    if not single_drive:  # declared by the node, unused beside the per-drive limits
        meta.update(stroke_min="0.0", stroke_max="0.0", slew_rate="1.0")
    for d in drives:
        prefix = "" if single_drive else f"drives.{d.name}."
        meta[f"{prefix}stroke_min"] = repr(d.stroke[0])
        meta[f"{prefix}stroke_max"] = repr(d.stroke[1])
    n_steps = round(1.0 / (publish_rate * sim_step))
    period_ns = round(1e9 / publish_rate)
    target = {n: 0.0 for n in names}
    pending = sorted(schedule)
    with McapRecorder(path, chunk_size=1 << 20) as recorder:
        recorder.add_topic("/clock", "rosgraph_msgs/msg/Clock")
        for t in floats:
            recorder.add_topic(f"{ns}/{t}", "std_msgs/msg/Float64")
        if record_command:
            for t in commands.values():
                recorder.add_topic(f"{ns}/{t}", "std_msgs/msg/Float64")
        recorder.add_metadata("flexure_sim", meta)
        stamp, end_ns, tick = 0, round(duration * 1e9), 0
        while stamp < end_ns:
            tick += 1
            while pending and round(pending[0][0] * 1e9) <= stamp:
                _, drive, value = pending.pop(0)
                target[drive] = value
                sim.set_command([target[n] for n in names] if len(names) > 1 else value)
                if record_command:
                    recorder.write(f"{ns}/{commands[drive]}",
                                   serialize_message(Float64(data=value)), stamp)
            sim.step(n_steps)
            snap = sim.snapshot()
            stamp += period_ns
            recorder.write("/clock", serialize_message(Clock(clock=_stamp(stamp))), stamp)
            values = ([snap.output] if single_output
                      else [snap.outputs[o.name] for o in mech.all_outputs])
            for k, d in enumerate(drives):
                values.append(snap.drive_inputs[k])
                values.append(snap.drive_positions[k] if d.kind == "force"
                              else snap.drive_forces[k])
            if tick in nan_ticks:
                values[0] = float("nan")
            for t, v in zip(floats, values):
                recorder.write(f"{ns}/{t}", serialize_message(Float64(data=float(v))), stamp)
    return sim
