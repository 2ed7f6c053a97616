"""
How stage_node ends: bad start-up input (issue 16.6) and signals at any moment (issue 18.4).

Real node processes. Every ending is one line on stderr and the documented exit code: 1 when
the node cannot start, 2 for bad arguments, 0 after SIGINT/SIGTERM (the recording finished),
never a traceback. Signals are sent at moments found by waiting on the node's own output
lines, never after sleeps.
"""
from __future__ import annotations

import signal
from pathlib import Path

import pytest

from flexure_sim.engine.mechanism.loader import resolve_mechanism_path
from flexure_sim.recording import read_log

from node_harness import NodeProcess, next_domain_id

STAGE_YAML = resolve_mechanism_path("microstage").read_text()


def error_lines(node: NodeProcess) -> list[str]:
    return [line for line in node.stderr.splitlines() if line.strip()]


def assert_one_line_error(node: NodeProcess, code: int, *words: str) -> None:
    rc = node.wait(120)
    lines = error_lines(node)
    assert rc == code, (rc, node.stderr)
    assert "Traceback" not in node.stderr and len(lines) == 1, node.stderr
    assert lines[0].startswith("stage_node: error: "), lines
    for word in words:
        assert word in lines[0], (word, lines[0])


def bad_files(tmp_path: Path) -> dict[str, Path]:
    files = {
        "binary": bytes(range(256)) * 4,
        "latin1": ("# r\xe9glage fin\n" + STAGE_YAML).encode("latin-1"),
        "unhashable_hinge": STAGE_YAML.replace("compression_hinge: a",
                                               "compression_hinge: [a]").encode(),
    }
    assert b"compression_hinge: [a]" in files["unhashable_hinge"]
    paths = {}
    for name, data in files.items():
        paths[name] = tmp_path / f"{name}.yaml"
        paths[name].write_bytes(data)
    return paths


# ------------------------------------------------------------------------ start-up input
def test_an_empty_mechanism_parameter_is_named(tmp_path):
    node = NodeProcess(tmp_path / "empty", next_domain_id(), {"mechanism": "''", "record": False})
    assert_one_line_error(node, 1, "parameter mechanism", "''")


@pytest.mark.parametrize("kind", ["binary", "latin1", "unhashable_hinge"])
def test_a_mechanism_file_that_does_not_load_gives_one_line_and_exit_1(tmp_path, kind):
    path = bad_files(tmp_path)[kind]
    node = NodeProcess(tmp_path / kind, next_domain_id(), {"mechanism": str(path),
                                                           "record": False})
    assert_one_line_error(node, 1, f"{path}: ")
    assert not node.recordings()


def test_malformed_ros_arguments_are_a_usage_error(tmp_path):
    node = NodeProcess(tmp_path / "args", next_domain_id(),
                       extra_args=["--ros-args", "-p", "mechanism:="])
    assert_one_line_error(node, 2, "parse", "--help")


# ------------------------------------------------------------------------ signals
@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_a_signal_while_a_start_up_error_is_reported_keeps_the_message_and_exit_1(tmp_path, sig):
    broken = tmp_path / "broken.yaml"
    broken.write_text("name: broken\nbodies: [{name: body1, mass: -1, inertia: 1, "
                      "pose: [0, 0, 0]}]\nhinges: []\nconstraints: []\n")
    domain = next_domain_id()
    for attempt in range(4):
        node = NodeProcess(tmp_path / f"run{attempt}", domain, {"mechanism": str(broken)})
        node.wait_for_output("stage_node: error:")  # the exit has begun
        if node.alive():
            node.send(sig)
            if attempt % 2:
                node.send(sig)  # twice: Ctrl-C pressed again
        assert_one_line_error(node, 1, f"{broken}: bodies[0].mass")


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
@pytest.mark.parametrize("moment", ["recording opened", "running"])
def test_a_signal_during_start_up_or_run_ends_with_one_line_and_exit_0(tmp_path, sig, moment):
    line = "recording to " if moment == "recording opened" else "mechanism microstage"
    node = NodeProcess(tmp_path / "node", next_domain_id(),
                       dict(time_mode="realtime", sim_step=5e-4, publish_rate=200.0))
    node.wait_for_output(line)
    node.send(sig)
    node.send(sig)  # a second signal while the node finishes its recording
    rc = node.wait(60)
    assert rc == 0, node.stderr
    assert "Traceback" not in node.stderr, node.stderr
    last = error_lines(node)[-1]
    assert last.startswith(f"stage_node: stopped by {signal.Signals(sig).name}"), node.stderr
    for path in node.recordings():
        assert read_log(path).complete, path
