"""
Profile of one stage_node tick: where its time goes, in this process and without DDS traffic.

Engine steps, snapshot, CDR packing against rclpy message building + serialize_message,
publish and recording, per tick, next to the tick's budget at the publish rate. The front end
is ``python -m flexure_sim.tools.bench.measure --profile``.
"""
from __future__ import annotations

import random
import tempfile
import time
from pathlib import Path


def profile(
    rate: float, sim_step: float, ticks: int = 300, mechanism: str = "microstage"
) -> dict[str, float]:
    """
    Where one tick's time goes, in this process and without DDS traffic.

    Engine steps, snapshot, CDR packing vs rclpy message building + serialize_message, publish,
    record.
    """
    import rclpy
    from rclpy.context import Context
    from rclpy.serialization import serialize_message

    from flexure_sim.engine.mechanism.loader import load_mechanism
    from flexure_sim.recording import McapRecorder
    from flexure_sim.engine.solver.simulation import Simulation
    from flexure_sim.node.publish.interface import StageInterface, stream_qos
    from flexure_sim.node.params.checks import steps_per_tick
    from flexure_sim.node.record.process import ProcessRecording, RecorderProcess
    from flexure_sim.node.stage.stepping_thread import RELINEARIZE_TOL

    n, problem = steps_per_tick(rate, sim_step)
    if problem:
        raise ValueError(problem)
    mech = load_mechanism(mechanism)
    sim = Simulation(mech, dt=sim_step, relinearize_tol=RELINEARIZE_TOL, energy=False)
    if sim.drive is not None:
        sim.set_command(1.35e-6)
    itf = StageInterface(mech, "fast")
    perf = time.perf_counter
    out: dict[str, float] = {"steps_per_tick": n, "topics_per_tick": len(itf.tick_topics)}
    sim.step(n)
    t = perf()
    for _ in range(ticks):
        sim.step(n)
    out["engine_us"] = (perf() - t) / ticks * 1e6
    t = perf()
    for _ in range(ticks):
        snap = sim.snapshot()
    out["snapshot_us"] = (perf() - t) / ticks * 1e6
    t = perf()
    for k in range(ticks):
        payloads = itf.encode(snap, k)
    out["cdr_pack_us"] = (perf() - t) / ticks * 1e6
    t = perf()
    for k in range(ticks // 10):
        msgs = itf.messages(snap, k)
    out["rclpy_build_us"] = (perf() - t) / (ticks // 10) * 1e6
    t = perf()
    for k in range(ticks // 10):
        for m in msgs:
            serialize_message(m)
    out["rclpy_serialize_us"] = (perf() - t) / (ticks // 10) * 1e6
    context = Context()
    rclpy.init(context=context, domain_id=random.randint(1, 100))
    node = rclpy.create_node("stage_node_profile", context=context)
    try:
        pubs = [
            node.create_publisher(s.msg_type, f"/profile{i}", stream_qos())
            for i, s in enumerate(itf.tick_topics)
        ]
        t = perf()
        for _ in range(ticks):
            for p, data in zip(pubs, payloads):
                p.publish(data)
        out["publish_bytes_us"] = (perf() - t) / ticks * 1e6
        t = perf()
        for _ in range(ticks // 10):
            for p, m in zip(pubs, msgs):
                p.publish(m)
        out["publish_msg_objects_us"] = (perf() - t) / (ticks // 10) * 1e6
    finally:
        node.destroy_node()
        rclpy.try_shutdown(context=context)
    with tempfile.TemporaryDirectory() as tmp:
        # In-process recorder (its writer thread shares the GIL) vs the node's recorder process.
        recorder = McapRecorder(Path(tmp) / "p.mcap")
        names = [f"/t{i}" for i in range(len(payloads))]
        for name, spec in zip(names, itf.tick_topics):
            recorder.add_topic(name, spec.type_name)
        t = perf()
        for k in range(ticks):
            for name, data in zip(names, payloads):
                recorder.write(name, data, k)
        out["record_in_process_write_us"] = (perf() - t) / ticks * 1e6
        t = perf()
        recorder.close()
        out["record_in_process_drain_us"] = (perf() - t) / ticks * 1e6
        process = RecorderProcess()
        try:
            topics = [
                (name, spec.type_name, stream_qos()) for name, spec in zip(names, itf.tick_topics)
            ]
            recording = ProcessRecording(process, Path(tmp) / "q.mcap", topics, {}, "flexure_sim",
                                         lossless=False)  # the real-time hand-off: never waits
            t = perf()
            for k in range(ticks):
                recording.write_batch(list(enumerate(payloads)), k)
            out["record_batch_to_process_us"] = (perf() - t) / ticks * 1e6
            recording.close()
        finally:
            process.quit()
    out["tick_total_us"] = (out["engine_us"] + out["snapshot_us"] + out["cdr_pack_us"]
                            + out["publish_bytes_us"] + out["record_batch_to_process_us"])
    out["tick_budget_us"] = 1e6 / rate
    return out
