"""
The package as a ROS 2 user builds, runs and tests it.

``colcon build`` in a workspace, the built ``stage_node`` (directly and through ``ros2 run``),
``ros2 topic pub``/``ros2 param set`` against it, and ``colcon test``.

colcon comes from PyPI (requirements.txt); the ros2 command-line tools are not on PyPI and come
as wheels from ``../shared/ros2cli`` (FLEXURE_ROS2CLI overrides; scripts/venv.sh installs
them). The workspace is built once per module in a Python environment without the pip copy
of flexure_sim (see ros_workspace.py), so nothing can come from that copy.
"""
from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from rcl_interfaces.msg import ParameterType
from rcl_interfaces.srv import GetParameters
from std_msgs.msg import Float64

from node_harness import FIRST_START_TIMEOUT, NodeProcess, Peer, next_domain_id
from ros_workspace import ROS2CLI_DIR, build_workspace, fresh_shell_env

#: Gain of the stage at small inputs (reference/README.md: 27.8 at 1.35 um); the checks only
#: need "clearly moved by the command", so half of it.
MIN_GAIN = 27.8 / 2
#: The built-in stage file of an install under ``prefix``.
MICROSTAGE = Path("share/flexure_sim/config/microstage.yaml")


@pytest.fixture(scope="module")
def workspace(tmp_path_factory):
    return build_workspace(tmp_path_factory.mktemp("colcon"))


def ros_env(workspace, cwd: Path, **extra: str) -> dict[str, str]:
    """Return a shell that sourced the workspace, on a DDS domain of its own."""
    return workspace.shell_env(ROS_DOMAIN_ID=str(next_domain_id()),
                               ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST",
                               ROS_LOG_DIR=str(cwd / "ros_log"), **extra)


def recording_facts(path: Path) -> tuple[bool, dict[str, str], list[float]]:
    """(has a summary with statistics, the node's metadata, drive commands) read by mcap."""
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        summary = reader.get_summary()
        complete = summary is not None and summary.statistics is not None
        meta = {m.name: dict(m.metadata) for m in reader.iter_metadata()}.get("flexure_sim", {})
        commands = [msg.data for _, _, _, msg in
                    reader.iter_decoded_messages(topics=["/drive/displacement"])]
    return complete, meta, commands


def test_colcon_build_installs_the_package_for_ros2_run_without_a_pip_copy(workspace):
    install = workspace.install
    exe = install / "lib" / "flexure_sim" / "stage_node"
    assert exe.is_file() and os.access(exe, os.X_OK), workspace.log[-2000:]
    index = install / "share" / "ament_index" / "resource_index"
    assert (index / "packages" / "flexure_sim").is_file()
    assert (install / "share" / "flexure_sim" / "config" / "microstage.yaml").is_file()
    assert (install / "share" / "flexure_sim" / "config" / "microstage_realistic.yaml").is_file()
    # The environment that built it cannot import a flexure_sim of its own.
    bare = subprocess.run([str(workspace.python), "-c", "import flexure_sim"], capture_output=True,
                          text=True, env=fresh_shell_env(workspace.python), timeout=60,
                          cwd=workspace.root)
    assert "No module named 'flexure_sim'" in bare.stderr


def test_built_flexure_sim_simulates_a_builtin_from_the_workspace(workspace):
    exe = workspace.install / "lib" / "flexure_sim" / "flexure-sim"
    p = subprocess.run([str(exe), "simulate", "microstage", "--static", "--drive", "step:1.35e-6",
                        "--json"], capture_output=True, text=True, env=workspace.shell_env(),
                       cwd=workspace.root, timeout=FIRST_START_TIMEOUT)
    assert p.returncode == 0, p.stderr
    out = json.loads(p.stdout)
    assert Path(out["mechanism_file"]) == workspace.install / MICROSTAGE
    assert out["gain"] > MIN_GAIN
    # The material table is package data of the colcon install too (engine/hinges/materials.py).
    assert out["hinge_stress"]["c"]["material"] == "6061-T6"
    assert out["fatigue"]["critical"]["goodman"]["hinge"] == "c"


def test_built_stage_node_runs_the_builtin_stage_and_stops_on_sigint(workspace, tmp_path):
    env = ros_env(workspace, tmp_path)
    domain = int(env["ROS_DOMAIN_ID"])
    exe = workspace.install / "lib" / "flexure_sim" / "stage_node"
    node = NodeProcess(tmp_path, domain, {"publish_rate": 200.0}, command=[str(exe)], env=env)
    peer = Peer(domain)
    peer.watch = node
    try:
        peer.subscribe("/output/displacement", Float64)
        peer.spin_until(lambda: peer.last("/output/displacement") is not None, FIRST_START_TIMEOUT,
                        "the first output message")
        # The stepping thread can publish before the main thread logs the start-up line.
        node.wait_for_output("mechanism microstage (", timeout=FIRST_START_TIMEOUT)
    finally:
        peer.close()
        rc = node.stop(signal.SIGINT)
    assert rc == 0, node.stderr
    used = workspace.install / MICROSTAGE
    assert f"mechanism microstage ({used})" in node.stderr
    bags = sorted((tmp_path / "runs").glob("microstage_*"))  # a rosbag2 bag directory
    assert len(bags) == 1 and (bags[0] / "metadata.yaml").is_file(), node.stderr
    files = sorted(bags[0].glob("*.mcap"))
    assert len(files) == 1, node.stderr
    complete, meta, _ = recording_facts(files[0])
    assert complete and meta["mechanism_path"] == str(used)


def test_colcon_installed_code_reads_its_own_builtins_when_a_pip_copy_is_indexed_first(workspace):
    """
    The test's virtual environment holds a pip copy and registers it in the ament index.

    Put it first on AMENT_PREFIX_PATH and the workspace's code first on PYTHONPATH: the code that
    runs (the workspace's) must read the workspace's files, and the pip copy its own.
    """
    site = next(workspace.install.glob("lib/python*/site-packages"))
    probe = ("from flexure_sim.engine.mechanism.loader import resolve_mechanism_path; "
             "import flexure_sim; print(flexure_sim.__file__); "
             "print(resolve_mechanism_path('microstage'))")
    both = os.pathsep.join([sys.prefix, str(workspace.install)])
    env = fresh_shell_env(Path(sys.executable), AMENT_PREFIX_PATH=both, PYTHONPATH=str(site))
    code, data = subprocess.run([sys.executable, "-c", probe], env=env, capture_output=True,
                                text=True, timeout=60, check=True, cwd="/").stdout.split()
    assert Path(code).is_relative_to(workspace.install)
    assert Path(data) == workspace.install / MICROSTAGE
    env = fresh_shell_env(Path(sys.executable), AMENT_PREFIX_PATH=os.pathsep.join(
        [str(workspace.install), sys.prefix]))
    code, data = subprocess.run([sys.executable, "-c", probe], env=env, capture_output=True,
                                text=True, timeout=60, check=True, cwd="/").stdout.split()
    assert Path(code).is_relative_to(sys.prefix) and Path(data) == Path(sys.prefix) / MICROSTAGE


def test_colcon_test_runs_pytest_and_reports_failures(workspace):
    done = workspace.colcon("test", "--packages-select", "flexure_sim", "--pytest-args",
                            "test/test_kinematics.py")
    assert done.returncode == 0, done.stdout + done.stderr
    xml = workspace.root / "build" / "flexure_sim" / "pytest.xml"
    assert xml.is_file(), "colcon ran pytest (its junit file)"
    result = workspace.colcon("test-result", "--all")
    assert result.returncode == 0, result.stdout
    tests = int(result.stdout.split("Summary:")[1].split("tests")[0])
    assert tests > 0 and "0 errors, 0 failures" in result.stdout, result.stdout
    # A failing test module makes colcon test-result report the failure.
    failing = workspace.source / "test" / "test_deliberately_failing.py"
    failing.write_text("def test_fails():\n    assert 1 == 2\n")
    try:
        done = workspace.colcon("test", "--packages-select", "flexure_sim", "--pytest-args",
                                "test/test_deliberately_failing.py")
        result = workspace.colcon("test-result")
    finally:
        failing.unlink()
    assert "1 failure" in result.stdout and result.returncode != 0, result.stdout


def ros2_cli() -> str:
    """
    Return the ``ros2`` command.

    Skips (only) when neither it nor the folder of its wheels exists.
    """
    found = shutil.which("ros2")
    if found:
        return found
    if not ROS2CLI_DIR.is_dir():
        pytest.skip(f"needs the ros2 command-line tools: no `ros2` on PATH and no wheels in "
                    f"{ROS2CLI_DIR} (see its README; FLEXURE_ROS2CLI names another folder)")
    pytest.fail(f"{ROS2CLI_DIR} holds the ros2 wheels but `ros2` is not installed: "
                "source scripts/venv.sh (it installs them)")


class Ros2:
    """
    Runs ``ros2 VERB ...`` in the sourced workspace.

    It runs without the ros2 daemon (which would outlive the test).
    """

    def __init__(self, exe: str, env: dict[str, str], cwd: Path) -> None:
        self.exe, self.env, self.cwd = exe, env, cwd

    def __call__(self, *args: str, timeout: float = 60) -> subprocess.CompletedProcess:
        return subprocess.run([self.exe, *args], env=self.env, cwd=self.cwd, capture_output=True,
                              text=True, timeout=timeout)

    def until(self, args: tuple[str, ...], done,
              timeout: float = 60) -> subprocess.CompletedProcess:
        """
        Repeat a discovery-dependent command until ``done(result)``, at most ``timeout`` s.

        Each try waits for discovery itself (--spin-time).
        """
        deadline = time.monotonic() + timeout
        while True:
            result = self(*args)
            if done(result) or time.monotonic() > deadline:
                return result


def test_ros2_run_topic_pub_and_param_set_against_the_built_node(workspace, tmp_path):
    ros2 = Ros2(ros2_cli(), ros_env(workspace, tmp_path), tmp_path)
    domain = int(ros2.env["ROS_DOMAIN_ID"])
    listing = ros2("pkg", "executables", "flexure_sim")
    assert "flexure_sim stage_node" in listing.stdout.splitlines(), listing
    log = open(tmp_path / "ros2_run.log", "wb")  # noqa: SIM115
    # Its own session, so that SIGINT reaches ros2 run and the node as Ctrl-C in a terminal does.
    run = subprocess.Popen([ros2.exe, "run", "flexure_sim", "stage_node", "--ros-args", "-p",
                            "publish_rate:=200.0"], cwd=tmp_path, env=ros2.env, stdout=log,
                           stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
                           start_new_session=True)
    peer = Peer(domain)
    try:
        peer.subscribe("/output/displacement", Float64)
        peer.spin_until(lambda: peer.last("/output/displacement") is not None, FIRST_START_TIMEOUT,
                        "output")
        # --keep-alive: the publisher outlives the reliable delivery of its one message.
        pub = ros2("topic", "pub", "--once", "--keep-alive", "1", "drive/displacement",
                   "std_msgs/msg/Float64", "{data: 1.0e-6}")
        assert pub.returncode == 0, pub
        peer.spin_until(lambda: peer.last("/output/displacement").data > MIN_GAIN * 1e-6, 60,
                        "the output to follow the command published by ros2 topic pub")
        echo = ros2("topic", "echo", "--once", "--no-daemon", "output/displacement",
                    "std_msgs/msg/Float64")
        assert float(echo.stdout.split("data:")[1].split()[0]) > MIN_GAIN * 1e-6, echo
        # ros2param reads values as YAML 1.1, where 1e-6 (no dot) is a string and 2 an integer:
        # the node takes either for its double parameters (other text: test_node_params).
        # (2 m is no stroke the stage can follow, which the node refuses: the integer goes to
        # slew_rate, 2 m/s.)
        answers = {}
        for name, text in (("stroke_max", "1e-6"), ("slew_rate", "2")):
            set_ = ros2.until(("param", "set", "--no-daemon", "--spin-time", "1", "/stage_node",
                               name, text), lambda r: "Set" in r.stdout + r.stderr)
            value = peer.call(GetParameters, "/stage_node/get_parameters",
                              GetParameters.Request(names=[name])).values[0]
            answers[text] = ((set_.stdout + set_.stderr).split(":")[0].strip(), value.type,
                             value.double_value)
        assert answers == {
            "1e-6": ("Set parameter successful", ParameterType.PARAMETER_DOUBLE, 1.0e-6),
            "2": ("Set parameter successful", ParameterType.PARAMETER_DOUBLE, 2.0),
        }
    finally:
        peer.close()
        if run.poll() is None:
            os.killpg(run.pid, signal.SIGINT)
        try:
            rc = run.wait(60)
        finally:
            log.close()
    text = (tmp_path / "ros2_run.log").read_text()
    assert rc == 0, text
    bags = sorted((tmp_path / "runs").glob("microstage_*"))  # a rosbag2 bag directory
    assert len(bags) == 1 and (bags[0] / "metadata.yaml").is_file(), text
    files = sorted(bags[0].glob("*.mcap"))
    assert len(files) == 1, text
    complete, meta, commands = recording_facts(files[0])
    assert complete and commands == [1.0e-6], text
    assert meta["mechanism_path"] == str(workspace.install / MICROSTAGE)
