"""
The node measuring harness behind `python -m flexure_sim.tools.bench.benchmarks --node`.

It is tested on a short real run (a real stage_node subprocess, Fast DDS on loopback, a real
recording read back).
"""
import subprocess
import sys
from pathlib import Path

import pytest

from flexure_sim.node.publish.diagnostics import TICK_PARTS
from flexure_sim.tools.bench import closed_loop, measure

from node_harness import next_domain_id


def test_measure_reports_pacing_cpu_and_a_complete_recording(tmp_path):
    r = measure.run_node("realtime", 2.0, 200.0, 1e-4, True, False, warmup=1.0,
                         domain_id=next_domain_id(), keep_dir=tmp_path,
                         params={"wake_spin": "0.0005", "stepping_nice": "3"})
    assert r["exit_code"] == 0
    assert r["params"] == {"wake_spin": "0.0005", "stepping_nice": "3"}
    assert r["wake_spin_s"] == pytest.approx(5e-4)  # the parameters reached the node's pacer
    assert r["stepping_nice"] == 3  # and its stepping thread
    assert r["middleware_threads"] > 0  # and the threads ROS started in its process
    assert r["steps_per_tick"] == 50 and r["topics_per_tick"] == 26
    # The figures are measured and reported; their values are the machine's (the benchmark
    # prints them: `flexure-sim bench --node`). Here what holds on any machine: the window
    # stepped, its late ticks are counted among the paced ones, and the recording is complete
    # with every tick's 26 topics.
    assert r["real_time_factor"] > 0 and r["ticks"] > 0
    assert 0 <= r["missed_ticks"] <= r["paced_ticks"] and r["paced_ticks"] > 0
    assert 0 < r["node_cpu_cores"] < 2.5
    assert r["recording_complete"] and r["recording_dropped"] == 0
    assert r["recorded_messages"] >= 26 * r["ticks"]  # the window's ticks, and warm-up's more
    assert (tmp_path / "measure.mcap").is_file()
    # The tick's parts as the node timed them add up to its whole (each window's means).
    parts = [r[f"{part}_time_mean_us"] for part in TICK_PARTS]
    assert all(p >= 0 for p in parts) and r["engine_time_mean_us"] > 0
    assert sum(parts) == pytest.approx(r["tick_time_mean_us"], rel=1e-6)


def test_measure_refuses_a_malformed_param():
    with pytest.raises(SystemExit):
        measure.main(["--param", "wake_spin=0.001"])


def test_the_ping_pong_floor_counts_every_paced_tick_and_the_answers_it_takes():
    """A real echo process: every tick paced and counted, answers taken at later ticks only."""
    from flexure_sim.tools.bench import pingpong

    r = pingpong.run(500.0, 1.0, warmup=0.5, domain_id=next_domain_id())
    assert r["paced_ticks"] == 500
    assert 0 <= r["missed_ticks"] <= r["paced_ticks"]
    assert 0 < r["answers"] <= r["paced_ticks"]
    assert r["answers"] + r["unanswered"] == r["paced_ticks"]
    assert r["late_ticks_max"] >= r["late_ticks_p99"] >= 0  # never before the next tick
    assert 0 <= r["applied_next_tick_fraction"] <= 1


class _StuckCompanion:
    """A companion (`run_node`) whose stop fails; it notes the node's process when started."""

    def __init__(self, env, workdir):
        # The node runs in workdir (its recording's relative path): find it by its cwd.
        self.node_pid = None
        here = Path(workdir).resolve()
        for proc in Path("/proc").iterdir():
            try:
                if (proc.name.isdigit() and (proc / "cwd").resolve() == here
                        and b"stage_node" in (proc / "cmdline").read_bytes()):
                    self.node_pid = int(proc.name)
            except OSError:
                continue

    def stop(self):
        raise RuntimeError("the companion would not stop")


def test_a_companion_that_fails_to_stop_still_leaves_no_node_running(tmp_path):
    made = []

    def start(env, workdir):
        made.append(_StuckCompanion(env, workdir))
        return made[-1]

    with pytest.raises(RuntimeError, match="would not stop"):
        measure.run_node("realtime", 0.5, 200.0, 1e-4, False, False, warmup=0.2,
                         domain_id=next_domain_id(), keep_dir=tmp_path, companion=start)
    assert made and made[0].node_pid is not None, "the node was not found while it ran"
    # run_node waited for it (SIGINT, wait): the process is gone, not merely signalled.
    assert not Path(f"/proc/{made[0].node_pid}").exists()


def test_a_controller_that_ignores_sigint_is_killed_and_that_raised(tmp_path, monkeypatch):
    monkeypatch.setattr(closed_loop, "STOP_TIMEOUT_S", 0.5)
    ignore = ("import signal, sys, time; signal.signal(signal.SIGINT, signal.SIG_IGN); "
              "print('ready', flush=True); time.sleep(600)")
    controller = closed_loop.ControllerProcess.__new__(closed_loop.ControllerProcess)
    controller.proc = subprocess.Popen([sys.executable, "-c", ignore], stdout=subprocess.PIPE,
                                       text=True)
    controller._log = open(tmp_path / "controller.stderr", "wb")  # noqa: SIM115
    assert controller.proc.stdout.readline().strip() == "ready"  # SIGINT is ignored from here
    with pytest.raises(RuntimeError, match="did not end within 0.5 s of SIGINT: killed"):
        controller.stop()
    assert controller.proc.poll() is not None and controller._log.closed
    controller.proc.stdout.close()


def test_the_tick_profile_times_every_part_of_ticks_that_send_their_status():
    """``measure --profile``: a real node ticked in this process, its statuses falling due."""
    from flexure_sim.tools.bench import tick_profile

    r = tick_profile.profile(1000.0, 1e-4, ticks=250)  # two statuses (10 Hz) fall due
    parts = [r[f"{part}_us"] for part in TICK_PARTS]
    assert all(p >= 0 for p in parts) and r["engine_us"] > 0
    assert sum(parts) == pytest.approx(r["tick_us"], rel=1e-6)
    assert r["steps_per_tick"] == 10 and r["topics_per_tick"] == 26
    steps = r["steps_per_tick"] * r["engine_step_us_reference"]
    assert r["overhead_factor"] == pytest.approx(r["tick_us"] / steps)
    assert r["engine_ratio"] == pytest.approx(r["engine_us"] / steps)
