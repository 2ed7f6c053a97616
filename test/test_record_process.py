"""
The node's recorder helper process, driven directly (no ROS).

A real child process writes a real MCAP file that the recording layer reads back.
"""
import os
import struct
import subprocess
import sys
from pathlib import Path

import pytest

from flexure_sim.node.record.process import (
    MAX_BACKLOG_ENV,
    RECORDER_NICE,
    WRITE_DELAY_ENV,
    ProcessRecording,
    RecorderProcess,
)
from flexure_sim.recording import QosDescription, read_log


def float64_cdr(value: float) -> bytes:
    return b"\x00\x01\x00\x00" + struct.pack("<d", value)


def test_recorder_process_runs_below_the_node_priority_and_writes_every_batch(
        tmp_path: Path) -> None:
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
            assert recording.write_batch([(0, float64_cdr(k)), (1, float64_cdr(-k))],
                                         1_000_000 * k)
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


# ------------------------------------------------------------- a recorder slower than the node
TOPICS = [(f"/t{c:02d}", "std_msgs/msg/String", QosDescription()) for c in range(26)]
TICKS = 2000
DISK_DELAY_S = "0.2"  # per write to the file descriptor: a ~1 MiB chunk waits 0.2 s


def string_cdr(text: str) -> bytes:
    """
    Return std_msgs/String as little-endian CDR, written from the CDR rules, not by the package.

    Encapsulation 00 01 00 00; uint32 length counting the terminating NUL; the bytes; NUL.
    """
    data = text.encode() + b"\0"
    return b"\x00\x01\x00\x00" + struct.pack("<I", len(data)) + data


def tick(k: int) -> list[tuple[int, bytes]]:
    return [(c, string_cdr(f"{k}:{c}:" + "x" * 120)) for c in range(len(TOPICS))]


@pytest.mark.slow
def test_a_slow_recorder_loses_nothing_when_the_node_may_wait(tmp_path, monkeypatch) -> None:
    """Fast mode (the default of ProcessRecording): back-pressure, never a drop."""
    monkeypatch.setenv(WRITE_DELAY_ENV, DISK_DELAY_S)
    process = RecorderProcess()
    try:
        path = tmp_path / "slow_disk.mcap"
        recording = ProcessRecording(process, path, TOPICS, {"k": "v"}, "meta")
        accepted = [recording.write_batch(tick(k), 1_000_000 * k) for k in range(TICKS)]
        stats = recording.close()
    finally:
        process.quit()
    assert all(accepted) and recording.dropped_count == 0
    assert stats["dropped"] == 0 and stats["accepted"] == TICKS * len(TOPICS)
    log = read_log(path)
    assert log.complete and log.message_count == TICKS * len(TOPICS)
    assert log.bag_metadata["custom_data"]["flexure_sim.dropped_messages"] == "0"
    for c, (name, _, _) in enumerate(TOPICS):
        got = [(m.log_time_ns, m.message.data) for m in log.messages_on(name)]
        assert got == [(1_000_000 * k, f"{k}:{c}:" + "x" * 120) for k in range(TICKS)]


@pytest.mark.slow
def test_a_slow_recorder_in_real_time_counts_every_message_it_drops(tmp_path, monkeypatch) -> None:
    """
    Real-time mode.

    The node never waits; whole ticks the pipe cannot take are dropped, and the file's metadata,
    the recording's count and `flexure-sim info` all say how many.
    """
    monkeypatch.setenv(WRITE_DELAY_ENV, DISK_DELAY_S)
    monkeypatch.setenv(MAX_BACKLOG_ENV, str(256 << 10))
    process = RecorderProcess()
    try:
        path = tmp_path / "rt_slow_disk.mcap"
        recording = ProcessRecording(process, path, TOPICS, {"k": "v"}, "meta", lossless=False)
        accepted = [recording.write_batch(tick(k), 1_000_000 * k) for k in range(TICKS)]
        recording.close()
    finally:
        process.quit()
    log = read_log(path)
    assert log.complete
    sent_ticks = [k for k, ok in enumerate(accepted) if ok]
    missing = TICKS * len(TOPICS) - log.message_count
    assert missing == accepted.count(False) * len(TOPICS) > 0
    assert recording.dropped_count == missing
    assert log.bag_metadata["custom_data"]["flexure_sim.dropped_messages"] == str(missing)
    for name, _, _ in TOPICS:  # whole ticks: every topic holds exactly the accepted ticks
        assert [m.log_time_ns for m in log.messages_on(name)] == [
            1_000_000 * k for k in sent_ticks]
    info = subprocess.run([sys.executable, "-m", "flexure_sim.cli", "info", str(path)],
                          capture_output=True, text=True, timeout=120)
    assert info.returncode == 0, info.stderr
    assert f"Dropped:      {missing} message(s) could not be recorded" in info.stdout


def test_the_recorder_polls_its_pipe_and_reads_frames_split_anywhere_up_to_its_end():
    """`child.PolledInput`: never blocks in read; bytes in order however written; EOF: None."""
    import threading

    from flexure_sim.node.record.child import PolledInput

    read_end, write_end = os.pipe()
    with os.fdopen(read_end, "rb", buffering=0) as stream:
        polled = PolledInput(stream, poll_s=0.001)
        assert not os.get_blocking(read_end)  # a write never has a blocked reader to wake
        data = bytes(range(256)) * 40  # 10240 bytes, written in uneven pieces
        cuts = [0, 1, 7, 300, 301, 5000, 10000, len(data)]

        def write() -> None:
            for a, b in zip(cuts, cuts[1:]):
                os.write(write_end, data[a:b])
            os.write(write_end, b"xyz")  # a frame cut short by the writer's end
            os.close(write_end)

        writer = threading.Thread(target=write)
        writer.start()
        sizes = [5, 1, 4000, 2, 6232]
        got = [polled.read_exact(n) for n in sizes]
        writer.join()
        assert b"".join(got) == data and [len(g) for g in got] == sizes
        assert polled.read_exact(4) is None  # 3 bytes left, then the end
