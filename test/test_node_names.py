"""
Recording names of stage_node processes started together, as a launch file does (issue 16.4).

Real node processes on one DDS domain share one directory; each must get its own file (node
namespace and name in the default name, ``_1``, ``_2`` when taken), none may fail or
overwrite. The atomic claim itself is tested with racing processes in test_node_params.py.
"""
from __future__ import annotations

import signal

from flexure_sim.recording import read_log

from node_harness import NodeProcess, next_domain_id

LOCKSTEP = dict(time_mode="lockstep", sim_step=1e-4, publish_rate=100.0, record=True)


def test_nodes_started_together_on_one_directory_each_get_their_own_file(tmp_path):
    domain = next_domain_id()
    shared = tmp_path / "shared"
    explicit = shared / "run.mcap"
    nodes = [
        # Two nodes of the same name asking for the same explicit file: one gets run_1.mcap.
        NodeProcess(tmp_path / "a", domain, dict(LOCKSTEP, record_path=str(explicit))),
        NodeProcess(tmp_path / "b", domain, dict(LOCKSTEP, record_path=str(explicit))),
        # Two namespaced nodes on one record_dir: the namespace is in the name.
        NodeProcess(tmp_path / "left", domain, dict(LOCKSTEP, record_dir=str(shared)),
                    extra_args=["--ros-args", "-r", "__ns:=/left"]),
        NodeProcess(tmp_path / "right", domain, dict(LOCKSTEP, record_dir=str(shared)),
                    extra_args=["--ros-args", "-r", "__ns:=/right"]),
    ]
    try:
        lines = [node.wait_for_output("recording to ", timeout=120) for node in nodes]
    finally:
        codes = [node.stop(signal.SIGINT) for node in nodes]
    assert codes == [0, 0, 0, 0], "\n".join(node.stderr for node in nodes)
    paths = [line.rsplit("recording to ", 1)[1].split(" instead")[0].strip() for line in lines]
    taken = [line for line in lines[:2] if "instead" in line]
    assert len(taken) == 1 and f"{explicit} exists" in taken[0] and "[WARN]" in taken[0]
    assert sorted(paths[:2]) == [str(explicit), str(shared / "run_1.mcap")]
    assert "microstage_left_stage_node_" in paths[2] and "microstage_right_stage_node_" in paths[3]
    files = sorted(shared.iterdir())
    assert len(files) == 4 and sorted(str(f) for f in files) == sorted(paths)
    for path in files:
        log = read_log(path)
        assert log.complete
    nodes_meta = sorted(read_log(p).metadata["flexure_sim"]["node"] for p in files)
    assert nodes_meta == ["/left/stage_node", "/right/stage_node", "/stage_node", "/stage_node"]
