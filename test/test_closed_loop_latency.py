"""
The benchmark's command-to-applied latency (tools/closed_loop.command_latency).

On a recording written like the node's (real MCAP, real reader): commands applied at the next
tick count as late 0, each tick later as one more (no timing measured here).
"""
from __future__ import annotations

from rclpy.serialization import serialize_message
from std_msgs.msg import Float64

from flexure_sim.recording.writer import McapRecorder
from flexure_sim.tools.bench.closed_loop import command_latency

MS = 1_000_000


def _run(tmp_path, readings, applied):
    """Write a recording: ``readings`` at the ends of ticks 1, 2, ...; (command, log time)s."""
    path = tmp_path / "run.mcap"
    with McapRecorder(path) as rec:
        rec.add_topic("/output/measured", "std_msgs/msg/Float64")
        rec.add_topic("/drive/displacement", "std_msgs/msg/Float64")
        for k, y in enumerate(readings, start=1):
            rec.write("/output/measured", serialize_message(Float64(data=y)), k * MS)
        for u, t in applied:
            rec.write("/drive/displacement", serialize_message(Float64(data=u)), t)
    return path


def _trace(tmp_path, answers):
    """Write the controller's trace: a line (number, reading, command, wall ns) per answer."""
    trace = tmp_path / "trace.txt"
    trace.write_text("".join(f"{i} {y!r} {u!r} 0\n" for i, (y, u) in enumerate(answers, 1)))
    return trace


def test_late_ticks_are_counted_from_the_answered_reading_to_the_applying_tick(tmp_path):
    readings = [1.1e-9, -0.7e-9, 2.3e-9, 0.4e-9, -1.9e-9]  # at the ends of ticks 1..5
    commands = [1.01e-7, 1.02e-7, 1.03e-7, 1.04e-7, 1.05e-7]
    # Answers to readings 1..4: on time, on time, one tick late, on time.
    applied = [1 * MS, 2 * MS, 4 * MS, 4 * MS]
    path = _run(tmp_path, readings, list(zip(commands, applied)))
    # The last command never reached the recording.
    trace = _trace(tmp_path, list(zip(readings[:4] + [9e-9], commands)))
    r = command_latency(path, trace, 1e-3)
    assert r["commands_traced"] == 5 and r["commands_recorded"] == 4
    assert r["commands_matched"] == 4 and r["commands_unmatched"] == 0
    assert r["applied_next_tick_fraction"] == 0.75
    assert r["late_ticks_max"] == 1 and r["late_ticks_min"] == 0
    assert r["late_ticks_mean"] == 0.25


def test_commands_lost_before_the_node_took_them_shift_no_other(tmp_path):
    """
    The first two answers were sent before the node's subscription matched: not recorded.

    Each later command is still paired with the reading it answers (by value, not by its place
    in the trace); pairing by place made every command two ticks late.
    """
    readings = [1.1e-9, -0.7e-9, 2.3e-9, 0.4e-9, -1.9e-9, 0.8e-9]
    commands = [2.01e-7, 2.02e-7, 2.03e-7, 2.04e-7, 2.05e-7, 2.06e-7]
    kept = [(commands[i], (i + 1) * MS) for i in range(2, 6)]   # answers 3..6, all on time
    path = _run(tmp_path, readings, kept)
    trace = _trace(tmp_path, list(zip(readings, commands)))
    r = command_latency(path, trace, 1e-3)
    assert r["commands_traced"] == 6 and r["commands_recorded"] == 4
    assert r["commands_matched"] == 4 and r["commands_unmatched"] == 0
    assert r["applied_next_tick_fraction"] == 1.0
    assert r["late_ticks_max"] == 0


def test_the_benchmarks_cpu_hog_is_busy_at_niceness_19_until_stopped():
    """`closed_loop.Hog`: a CPU-bound process that only takes time nobody else wants."""
    import os
    import time

    from flexure_sim.tools.bench.closed_loop import Hog
    from node_harness import proc_stat

    def stat(pid):
        _, fields = proc_stat(f"/proc/{pid}/stat")
        return int(fields[16]), int(fields[11]) + int(fields[12])  # nice; utime + stime

    hog = Hog()
    try:
        deadline = time.monotonic() + 30.0
        while True:  # until it has used 0.2 s of CPU at niceness 19
            nice, cpu_ticks = stat(hog.proc.pid)
            if nice == 19 and cpu_ticks >= 20:
                break
            assert time.monotonic() < deadline, f"the hog: niceness {nice}, {cpu_ticks} ticks"
            assert hog.proc.poll() is None
        assert os.sched_getscheduler(hog.proc.pid) == os.SCHED_OTHER
    finally:
        hog.stop()
    assert hog.proc.returncode is not None
