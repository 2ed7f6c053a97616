"""
The status at the stop is recorded however the stepping thread's ticks ended.

A signal shuts rclpy's context down before the node stops its stepping thread: the thread's
next call into rclpy (its graph check between ticks) raises. The recording must still end
with a status that holds the run's final counters (``analyse`` reads it), as it does after a
clean stop. Real parts: a real rclpy context, node and diagnostics publisher, a real recorder
process writing MCAP, read back with mcap's reader.
"""
from __future__ import annotations

import threading

import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from mcap.reader import make_reader
from rclpy.serialization import deserialize_message

from flexure_sim.engine.mechanism.loader import load_mechanism
from flexure_sim.engine.solver.simulation import Simulation
from flexure_sim.node.publish.diagnostics import DiagnosticsPort
from flexure_sim.node.publish.interface import StageInterface
from flexure_sim.node.publish.qos_profiles import stream_qos
from flexure_sim.node.record.session import RecordingSession
from flexure_sim.node.stage.loop_parts import LoopParts, LoopSettings
from flexure_sim.node.stage.stepping_thread import RELINEARIZE_TOL, SteppingLoop

from test_node_stepping import Discard, Log

DT = 1.0e-4
RATE = 1000.0


def test_a_context_shut_down_under_the_ticks_still_records_the_final_status(tmp_path, domain):
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=domain)
    node = rclpy.create_node("stop_status", context=context)
    diag_pub = node.create_publisher(DiagnosticArray, "/diagnostics", 10)
    stage = load_mechanism("microstage")
    sim = Simulation(stage, dt=DT, relinearize_tol=RELINEARIZE_TOL)
    interface = StageInterface(stage, "fast")
    session = RecordingSession(Log())
    n = len(interface.tick_topics)
    failures: list[BaseException] = []
    ended: list[bool] = []
    done = threading.Event()
    graph_checks = [0]

    def check_graph() -> None:  # as a signal's shutdown meets the node's graph check
        graph_checks[0] += 1
        if graph_checks[0] == 2:
            context.try_shutdown()
        node.get_publishers_info_by_topic("/drive/displacement")

    def on_failure(exc: BaseException) -> bool:
        failures.append(exc)
        return context.ok()  # the node's rule: an error while shutting down is no failure

    loop = SteppingLoop(LoopParts(
        LoopSettings("fast", RATE, DT), sim, interface, [Discard() for _ in range(n)], session,
        Log(), graph_check=check_graph,
        diagnostics=DiagnosticsPort(diag_pub, n, "stop_status", stage.name)))
    qos = stream_qos()
    topics = [("/" + t.name.lstrip("/"), t.type_name, qos) for t in interface.tick_topics]
    topics.append(("/diagnostics", interface.diagnostics.type_name, qos))
    values = {"record_format": "mcap", "record_path": "run.mcap", "record_dir": str(tmp_path),
              "record_max_bytes": 0, "record_max_duration": 0.0}
    path = session.start(values, stage.name, "/stop_status", topics, {})
    try:
        loop.start(lambda ok: (ended.append(ok), done.set()), on_failure)
        assert done.wait(120.0), "the stepping thread did not end"
        loop.stop(60.0)
    finally:
        session.close()
        node.destroy_node()
        context.try_shutdown()
    # The thread ended on rclpy's error, not as asked, and that was no failure.
    assert len(failures) == 1 and "context is invalid" in str(failures[0])
    assert ended == [True] and loop.failure is None
    with open(path, "rb") as f:
        reader = make_reader(f)
        statuses = [(m.log_time, deserialize_message(m.data, DiagnosticArray))
                    for _, channel, m in reader.iter_messages(topics=["/diagnostics"])]
        last_tick = max(m.log_time for _, _, m in reader.iter_messages(topics=["/clock"]))
    assert statuses, "no status recorded"
    log_time, last = statuses[-1]
    values_at_stop = {kv.key: kv.value for kv in last.status[0].values}
    # The last status is the stop's: at the last tick, with every tick counted.
    assert loop.ticks >= 2 and values_at_stop["ticks"] == str(loop.ticks)
    assert log_time == last_tick == round(loop.sim.state.t * 1e9)
