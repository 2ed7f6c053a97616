"""The node's recorder helper process, driven directly (no ROS): a real child process writes
a real MCAP file that the recording layer reads back."""
import os
import struct
from pathlib import Path

from flexure_sim.node.record_process import RECORDER_NICE, ProcessRecording, RecorderProcess
from flexure_sim.recording import QosDescription, read_log


def float64_cdr(value: float) -> bytes:
    return b"\x00\x01\x00\x00" + struct.pack("<d", value)


def test_recorder_process_runs_below_the_node_priority_and_writes_every_batch(tmp_path: Path) -> None:
    process = RecorderProcess()
    try:
        # The child lowers its own priority once it starts: wait for its first answer.
        path = tmp_path / "batches.mcap"
        topics = [("/a", "std_msgs/msg/Float64", QosDescription()),
                  ("/b", "std_msgs/msg/Float64", QosDescription())]
        recording = ProcessRecording(process, path, topics, {"k": "v"}, "meta")
        own = os.getpriority(os.PRIO_PROCESS, 0)
        assert os.getpriority(os.PRIO_PROCESS, process.proc.pid) == min(own + RECORDER_NICE, 19)
        for k in range(200):
            assert recording.write_batch([(0, float64_cdr(k)), (1, float64_cdr(-k))], 1_000_000 * k)
        stats = recording.close()
    finally:
        process.quit()
    assert process.proc.returncode == 0
    assert stats["accepted"] == 400 and stats["dropped"] == 0
    log = read_log(path)
    assert log.complete
    a = [(m.log_time_ns, m.message.data) for m in log.messages_on("/a")]
    b = [m.message.data for m in log.messages_on("/b")]
    assert a == [(1_000_000 * k, float(k)) for k in range(200)]
    assert b == [-float(k) for k in range(200)]
    assert log.metadata["meta"] == {"k": "v"}
