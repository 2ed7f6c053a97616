"""
How users start the node.

``ros2 run flexure_sim stage_node`` and the ``stage_node`` console script, from the installed
package (``pip install .``; scripts/run_tests.sh reinstalls it).

There is no ``ros2`` CLI on PyPI, so `ros2_run` does what ros2run does: find the prefix on
AMENT_PREFIX_PATH whose ament index registers flexure_sim, then execute
<prefix>/lib/flexure_sim/stage_node directly. PATH deliberately lacks the virtual environment:
the launcher must find its interpreter itself.
"""
from __future__ import annotations

import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest
from geometry_msgs.msg import PoseArray
from std_msgs.msg import Float64

from flexure_sim.recording import read_log

from node_harness import FIRST_START_TIMEOUT, NodeProcess, Peer, next_domain_id, node_env

PACKAGE = "flexure_sim"


def ament_prefix_path() -> str:
    """AMENT_PREFIX_PATH as scripts/venv.sh exports it (the environment's prefix first)."""
    return os.environ.get("AMENT_PREFIX_PATH") or sys.prefix


def ros2_run_lookup(package: str, executable: str, prefix_path: str) -> Path:
    """
    ros2run's lookup.

    <prefix>/lib/<package>/<executable> of the first prefix holding the package marker
    share/ament_index/resource_index/packages/<package>.
    """
    for prefix in prefix_path.split(os.pathsep):
        if (
            prefix
            and (Path(prefix) / "share/ament_index/resource_index/packages" / package).is_file()
        ):
            candidate = Path(prefix) / "lib" / package / executable
            if not (candidate.is_file() and os.access(candidate, os.X_OK)):
                raise LookupError(f"No executable found: {candidate}")
            return candidate
    raise LookupError(f"Package not found: {package} (AMENT_PREFIX_PATH={prefix_path})")


def bare_env(domain: int, cwd: Path) -> dict[str, str]:
    """
    Return an environment like a fresh shell's.

    System PATH, no virtual environment, no PYTHONPATH.
    """
    env = node_env(
        domain,
        AMENT_PREFIX_PATH=ament_prefix_path(),
        PATH="/usr/local/bin:/usr/bin:/bin",
        ROS_LOG_DIR=str(cwd / "ros_log"),
    )
    for key in ("VIRTUAL_ENV", "PYTHONPATH", "PYTHONHOME", "_ROS_WHEELS_BOOTSTRAP_COMPLETE"):
        env.pop(key, None)
    return env


def test_the_package_is_registered_and_its_launcher_installed():
    exe = ros2_run_lookup(PACKAGE, "stage_node", ament_prefix_path())
    assert exe.read_text().startswith("#!/bin/sh")
    prefix = exe.parent.parent.parent
    assert (prefix / "share" / PACKAGE / "package.xml").is_file()
    assert (prefix / "share" / PACKAGE / "config" / "microstage.yaml").is_file()
    with pytest.raises(LookupError):
        ros2_run_lookup("no_such_package", "stage_node", ament_prefix_path())


def test_ros2_run_starts_the_installed_node_with_the_builtin_stage(tmp_path):
    domain = next_domain_id()
    exe = ros2_run_lookup(PACKAGE, "stage_node", ament_prefix_path())
    cwd = tmp_path / "ros2run"
    cwd.mkdir()
    node = NodeProcess(
        cwd,
        domain,
        {"time_mode": "fast", "publish_rate": 200.0},
        command=[str(exe)],
        env=bare_env(domain, cwd),
    )
    peer = Peer(domain)
    peer.watch = node
    try:
        peer.subscribe("/output/displacement", Float64)
        drive = peer.publisher("/drive/displacement", Float64)
        peer.wait_for_publishers(["/output/displacement"], timeout=FIRST_START_TIMEOUT)
        peer.wait_for_subscribers(drive)
        drive.publish(Float64(data=1.35e-6))
        peer.spin_until(
            lambda: peer.last("/output/displacement") is not None
            and peer.last("/output/displacement").data > 30e-6,
            FIRST_START_TIMEOUT,
            "the stage to move",
        )
    finally:
        peer.close()
        rc = node.stop(signal.SIGINT)
    assert rc == 0, node.stderr
    # Default recording: a bag directory in runs/ under the working directory, complete
    # after Ctrl-C (read_log checks its metadata.yaml against the files).
    bags = sorted((cwd / "runs").glob("microstage_*"))
    assert len(bags) == 1 and (bags[0] / "metadata.yaml").is_file(), node.stderr
    # Not decoded: the unpaced run holds ~300k messages, and what is checked is the bag's
    # completeness and counts (decoding them all took 10 s of this test).
    log = read_log(bags[0], decode=False)
    assert log.complete and log.counts["/drive/displacement"] == 1


def test_console_script_runs_another_mechanism_and_stops_on_sigterm(tmp_path):
    domain = next_domain_id()
    script = Path(sys.prefix) / "bin" / "stage_node"
    assert script.is_file(), "pip install . puts the console script in <venv>/bin"
    cwd = tmp_path / "console"
    cwd.mkdir()
    node = NodeProcess(cwd, domain, {"mechanism": "fourbar_cantilever", "time_mode": "fast",
                                     "record": False}, command=[str(script)],
                       env=bare_env(domain, cwd))
    peer = Peer(domain)
    peer.watch = node
    try:
        peer.subscribe("/bodies/poses", PoseArray)
        peer.wait_for_publishers(["/bodies/poses"], timeout=FIRST_START_TIMEOUT)
        peer.spin_until(lambda: len(peer.received["/bodies/poses"]) > 20, FIRST_START_TIMEOUT,
                        "poses")
        assert len(peer.last("/bodies/poses").poses) == 4
    finally:
        peer.close()
        rc = node.stop(signal.SIGTERM)
    assert rc == 0, node.stderr
    assert not node.recordings()


def test_installed_entry_points_report_bad_input_without_a_traceback(tmp_path):
    domain = next_domain_id()
    exe = ros2_run_lookup(PACKAGE, "stage_node", ament_prefix_path())
    env = bare_env(domain, tmp_path)
    help_text = subprocess.run(
        [str(exe), "--help"], env=env, capture_output=True, text=True, timeout=60
    )
    assert help_text.returncode == 0 and "publish_rate" in help_text.stdout
    bad = tmp_path / "bad.yaml"
    bad.write_text("name: [unclosed\n")
    for command in ([str(exe)], [str(Path(sys.prefix) / "bin" / "stage_node")]):
        p = subprocess.run(
            command + ["--ros-args", "-p", f"mechanism:={bad}"],
            env=env,
            cwd=tmp_path,
            capture_output=True,
            text=True,
            timeout=60,
        )
        assert p.returncode == 1
        assert f"{bad}: not valid YAML" in p.stderr and "Traceback" not in p.stderr
    p = subprocess.run(
        [str(exe), "--unknown"], env=env, capture_output=True, text=True, timeout=60
    )
    assert p.returncode == 2 and "unexpected arguments" in p.stderr
