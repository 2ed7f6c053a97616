"""
The node measuring harness behind `python -m flexure_sim.tools.bench.benchmarks --node`.

It is tested on a short real run (a real stage_node subprocess, Fast DDS on loopback, a real
recording read back).
"""

import pytest

from flexure_sim.tools.bench import measure

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
    assert r["steps_per_tick"] == 50 and r["topics_per_tick"] == 25
    # The figures are measured and reported; their values are the machine's (the benchmark
    # prints them: `flexure-sim bench --node`). Here what holds on any machine: the window
    # stepped, its late ticks are counted among the paced ones, and the recording is complete
    # with every tick's 25 topics.
    assert r["real_time_factor"] > 0 and r["ticks"] > 0
    assert 0 <= r["missed_ticks"] <= r["paced_ticks"] and r["paced_ticks"] > 0
    assert 0 < r["node_cpu_cores"] < 2.5
    assert r["recording_complete"] and r["recording_dropped"] == 0
    assert r["recorded_messages"] >= 25 * r["ticks"]  # the window's ticks, and warm-up's more
    assert (tmp_path / "measure.mcap").is_file()


def test_measure_refuses_a_malformed_param():
    with pytest.raises(SystemExit):
        measure.main(["--param", "wake_spin=0.001"])
