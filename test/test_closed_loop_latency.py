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


def test_late_ticks_are_counted_from_the_answered_reading_to_the_applying_tick(tmp_path):
    readings = [1.1e-9, -0.7e-9, 2.3e-9, 0.4e-9, -1.9e-9]  # at the ends of ticks 1..5
    # Answers to readings 1..4: on time, on time, one tick late, on time.
    applied = [1 * MS, 2 * MS, 4 * MS, 4 * MS]
    path = tmp_path / "run.mcap"
    with McapRecorder(path) as rec:
        rec.add_topic("/output/measured", "std_msgs/msg/Float64")
        rec.add_topic("/drive/displacement", "std_msgs/msg/Float64")
        for k, y in enumerate(readings, start=1):
            rec.write("/output/measured", serialize_message(Float64(data=y)), k * MS)
        for t in applied:
            rec.write("/drive/displacement", serialize_message(Float64(data=1e-7)), t)
    trace = tmp_path / "trace.txt"
    traced = readings[:4] + [9e-9]  # the last command never reached the recording
    trace.write_text("".join(f"{i} {y!r} 1e-07 0\n" for i, y in enumerate(traced, 1)))
    r = command_latency(path, trace, 1e-3)
    assert r["commands_traced"] == 5 and r["commands_recorded"] == 4
    assert r["commands_matched"] == 4 and r["commands_unmatched"] == 0
    assert r["applied_next_tick_fraction"] == 0.75
    assert r["late_ticks_max"] == 1 and r["late_ticks_min"] == 0
    assert r["late_ticks_mean"] == 0.25


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
