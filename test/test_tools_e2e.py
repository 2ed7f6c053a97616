"""
The tools on a run recorded through the real node, and replay to real rclpy subscribers.

A stage_node subprocess (lockstep mode, 2 kHz ticks) is driven by the demo driver
(``python -m flexure_sim.node.apps.demo_drive --record``), a real rclpy node that advances it with
~/step, publishes the demo profile and reports the gain it saw live; then ``flexure-sim
analyse / plot / export / info`` run on the recording and ``replay`` publishes it again to a
real subscriber. Each test gets its own ROS domain (node_harness).
"""
from __future__ import annotations

import csv
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.serialization import deserialize_message
from std_msgs.msg import Float64

from flexure_sim import cli
from flexure_sim.engine.mechanism.loader import load_mechanism
from flexure_sim.recording import log_info, read_log
from flexure_sim.recording.bag import bag_files
from flexure_sim.engine.solver.simulation import Simulation
from flexure_sim.tools.run.export import csv_name
from flexure_sim.tools.run.plot import figure_title
from flexure_sim.node.apps.replay import _message_class

from node_harness import ROOT, NodeProcess, Peer, diagnostics_values, next_domain_id, node_env
from reference_figures import STAGE_GAIN

LEVELS_UM = (0.5, 1.0, 1.5, 2.0, 0.0)
RATE = 2000.0


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    """Return a demo run through the real node: (recording, what the driver saw live, work dir)."""
    work = tmp_path_factory.mktemp("node_run")
    domain = next_domain_id()
    # The recording is a rosbag2 bag directory split into several files (every 40 ms of
    # simulated time): every tool reads it as one run.
    node = NodeProcess(
        work,
        domain,
        {
            "time_mode": "lockstep",
            "publish_rate": RATE,
            "record": False,
            "record_path": str(work / "stage"),
            "record_max_duration": 0.04,
        },
    )
    try:
        env = node_env(domain, PYTHONPATH=str(ROOT), ROS_LOG_DIR=str(work / "ros_log"))
        proc = subprocess.run(
            [
                sys.executable,
                "-m",
                "flexure_sim.node.apps.demo_drive",
                "--record",
                "--json",
                "--timeout",
                "60",
            ],
            capture_output=True,
            text=True,
            env=env,
            cwd=work,
            timeout=180,
        )
        assert proc.returncode == 0, proc.stderr + node.stderr
        live = json.loads(proc.stdout)
    finally:
        rc = node.stop(signal.SIGINT)
    assert rc == 0, node.stderr
    path = work / "stage"
    assert live["recording"] == str(path)
    assert len(bag_files(path)) >= 3
    return path, live, work


def flexure_sim(capsys, *args) -> tuple[int, str, str]:
    code = cli.main([str(a) for a in args])
    out, err = capsys.readouterr()
    return code, out, err


# ------------------------------------------------------------------------------ analysis
def test_analyse_gives_the_gain_of_the_live_run_and_of_the_engines_statics(capsys, recorded):
    path, live, _ = recorded
    code, out, err = flexure_sim(capsys, "analyse", path, "--json")
    assert code == 0, err
    steps = json.loads(out)
    assert [round(s["input"] * 1e6, 9) for s in steps] == list(LEVELS_UM)
    assert len(live["steps"]) == len(steps)
    sim = Simulation(load_mechanism("microstage"))
    for s, seen in zip(steps, live["steps"]):
        assert s["settled"], s["notes"]
        assert s["t"] == pytest.approx(
            seen["t"], abs=1e-12
        )  # applied at the tick after it was sent
        assert s["gain"] == pytest.approx(seen["gain"], rel=1e-4)
        assert s["gain"] == pytest.approx(s["static_gain"], rel=1e-6)
        assert s["gain"] == pytest.approx(STAGE_GAIN, rel=1e-4)
        assert s["output"] == pytest.approx(seen["output"], rel=1e-9, abs=1e-15)
        static = sim.static(s["applied_input"]).snapshot
        assert s["joint_a_compression"] == pytest.approx(static.compression, rel=1e-5, abs=1e-14)
        assert s["drive_force"] == pytest.approx(static.drive_force, rel=1e-5, abs=1e-6)
        assert 1e-3 < s["settling_time"] < 6e-3
        assert abs(s["peak_drive_force"]) >= abs(s["drive_force"])
        assert set(s["peak_wrench"]) == set("abcdefg")
    code, out, _ = flexure_sim(capsys, "analyse", path)
    assert code == 0 and f"{STAGE_GAIN:.3f}" in out


def test_info_shows_the_mechanism_and_the_nodes_parameters(capsys, recorded):
    path, _, _ = recorded
    code, out, err = flexure_sim(capsys, "info", path, "--json")
    assert code == 0, err
    info = json.loads(out)
    assert info["complete"] and info["mechanism"]["name"] == "microstage"
    assert info["mechanism"]["hinges"] == list("abcdefg")
    assert info["parameters"]["time_mode"] == "lockstep"
    assert float(info["parameters"]["publish_rate"]) == RATE
    assert {"/drive/displacement", "/output/displacement", "/hinges/a/wrench", "/clock"} <= {
        t["name"] for t in info["topics"]}
    assert info["duration"] == pytest.approx(0.1095, abs=2e-3)
    assert any(c.get("record") == "true" for c in info["parameter_changes"])


def test_plot_writes_the_four_figures(capsys, recorded, tmp_path):
    path, _, _ = recorded
    code, out, err = flexure_sim(capsys, "plot", path, "-o", tmp_path / "plots")
    assert code == 0, err
    titles = {p.name: figure_title(p) for p in (tmp_path / "plots").glob("*.png")}
    assert titles == {
        "input_output.png": "Input and output displacement",
        "joint_a.png": "Joint a displacement on body2 and body6",
        "hinge_wrenches.png": "Hinge wrenches",
        "drive_force.png": "Drive force",
    }
    assert all((tmp_path / "plots" / name).stat().st_size > 10_000 for name in titles)


def test_export_rows_equal_message_counts(capsys, recorded, tmp_path):
    path, _, _ = recorded
    code, _, err = flexure_sim(capsys, "export", path, "--csv", tmp_path / "csv")
    assert code == 0, err
    info = log_info(path)
    assert len(list((tmp_path / "csv").glob("*.csv"))) == len(info.topics)
    for topic, t in info.topics.items():
        with open(tmp_path / "csv" / csv_name(topic), newline="") as f:
            assert sum(1 for _ in csv.DictReader(f)) == t.message_count, topic


# ------------------------------------------------------------------------------ other nodes' input
def test_a_malformed_command_is_kept_on_a_channel_of_its_own_that_every_reader_decodes(
    capsys, tmp_path
):
    """
    A 2-byte payload on drive/displacement is rejected, counted and recorded on its own channel.

    rclpy publishes raw bytes as they are. The command channel then holds only Float64s and the
    payload is on ``/drive/displacement/rejected`` as a std_msgs/UInt8MultiArray: rosbags and
    mcap-ros2-support decode every message of every channel, and the tools read the run
    without a note (``--strict`` too).
    """
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory
    from rosbags.highlevel import AnyReader

    domain = next_domain_id()
    bag = tmp_path / "malformed"
    garbage = bytes.fromhex("0001")
    node = NodeProcess(tmp_path / "node", domain, {"time_mode": "realtime", "publish_rate": 200.0,
                                                   "record": True, "record_path": str(bag)})
    peer = Peer(domain)
    peer.watch = node
    try:
        peer.subscribe("/diagnostics", DiagnosticArray)
        drive = peer.publisher("/drive/displacement", Float64)
        peer.wait_for_subscribers(drive)
        for k, command in enumerate((Float64(data=1.0e-6), garbage, Float64(data=0.5e-6)),
                                    start=1):
            drive.publish(command)  # one at a time: each lands on a tick of its own
            peer.spin_until(lambda: peer.last("/diagnostics") is not None and diagnostics_values(
                peer.last("/diagnostics")).get("commands_received") == str(k), 20,
                f"{k} command(s) received")
        d = diagnostics_values(peer.last("/diagnostics"))
    finally:
        peer.close()
        rc = node.stop(signal.SIGINT)
    assert rc == 0, node.stderr
    assert (d["commands_rejected"], d["commands_malformed"], d["commands_accepted"]) == (
        "1", "1", "2")
    # Every message of every channel decodes, with rosbags and with mcap-ros2-support.
    with AnyReader([bag]) as reader:
        topics = {c.topic: c.msgtype for c in reader.connections}
        decoded = [(c.topic, reader.deserialize(raw, c.msgtype))
                   for c, _, raw in reader.messages()]
    assert topics["/drive/displacement/rejected"] == "std_msgs/msg/UInt8MultiArray"
    assert [m.data for t, m in decoded if t == "/drive/displacement"] == [1.0e-6, 0.5e-6]
    # What arrived (the transport pads a payload to a multiple of 4 bytes), verbatim.
    rejected = [bytes(m.data) for t, m in decoded if t == "/drive/displacement/rejected"]
    assert same_payloads(rejected, [garbage]), rejected
    assert len(decoded) > 10
    assert {t for t, _ in decoded} >= {"/diagnostics", "/output/displacement"}
    files = bag_files(bag)
    mcap_messages = []
    for path in files:
        with open(path, "rb") as f:
            mcap_messages += [(c.topic, m) for _, c, _, m in make_reader(
                f, decoder_factories=[DecoderFactory()]).iter_decoded_messages()]
    assert len(mcap_messages) == len(decoded)
    assert [bytes(m.data) for t, m in mcap_messages
            if t == "/drive/displacement/rejected"] == rejected
    # The tools read the run without a note, strict or not.
    for tool in (("analyse", "--json", "--no-static"), ("info",),
                 ("export", "--csv", tmp_path / "csv")):
        for strict in ((), ("--strict",)):
            code, out, err = flexure_sim(capsys, tool[0], bag, *tool[1:], *strict)
            assert code == 0 and "undecodable" not in err + out, (tool, strict, err)
            if tool[0] == "analyse":
                assert [round(s["input"] * 1e6, 9) for s in json.loads(out)] == [1.0, 0.5]
    with open(tmp_path / "csv" / "drive.displacement.csv", newline="") as f:
        assert [float(r["data"]) for r in csv.DictReader(f)] == [1.0e-6, 0.5e-6]


# ------------------------------------------------------------------------------ replay
def same_payloads(received: list[bytes], recorded: list[bytes]) -> bool:
    """
    Return whether the received and recorded CDR payloads are equal.

    The transport may pad a payload with up to 3 bytes to a multiple of 4.
    """
    return len(received) == len(recorded) and all(
        r[:len(d)] == d and len(r) - len(d) < 4 and not any(r[len(d):])
        for r, d in zip(received, recorded)
    )


def _subscribe_all(peer: Peer, log, topics) -> None:
    for topic in topics:
        peer.subscribe(topic, _message_class(log.topics[topic].type), depth=5000)


def _replay(domain: int, work: Path, *args: str, command=None, env=None) -> subprocess.Popen:
    env = env or node_env(domain, PYTHONPATH=str(ROOT), ROS_LOG_DIR=str(work / "ros_log"))
    cmd = command or [sys.executable, "-m", "flexure_sim.node.apps.replay"]
    return subprocess.Popen([*cmd, *args], env=env, cwd=work, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)


def _spin_until_done(
    peer: Peer, proc: subprocess.Popen, expected: dict[str, int], timeout: float = 60
) -> None:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        peer.executor.spin_once(timeout_sec=0.01)
        if proc.poll() is not None and all(
            len(peer.received[t]) >= n for t, n in expected.items()
        ):
            # Drain what is still in flight, then stop.
            peer.spin_for(0.3)
            return
    raise AssertionError(
        f"replay did not deliver everything in {timeout} s: "
        f"{ {t: (len(peer.received[t]), n) for t, n in expected.items()} } "
        f"rc={proc.poll()} {proc.stderr.read() if proc.poll() is not None else ''}"
    )


def test_replay_delivers_every_message_in_order_and_the_recorded_clock(recorded):
    path, _, work = recorded
    log = read_log(path)
    domain = next_domain_id()
    peer = Peer(domain, name="replay_listener", use_sim_time=True)
    try:
        _subscribe_all(peer, log, log.topics)
        # A twentieth of recorded speed (2.2 s for this 0.11 s run): 26 topics at 2 kHz outrun
        # a Python subscriber on a slow, loaded machine, and the keep-last-100 histories then
        # drop the oldest unread messages (a quarter of it lost /clock messages on one).
        proc = _replay(domain, work, str(path), "--wait-for-subscribers", "30", "--rate", "0.05")
        _spin_until_done(peer, proc, {t: i.message_count for t, i in log.topics.items()})
        out, err = proc.communicate(timeout=30)
        assert proc.returncode == 0, err
        assert "/clock as recorded" in out and "Traceback" not in err
        for topic in log.topics:
            # Every message, in order, with the recorded content.
            assert same_payloads([raw for _, raw in peer.received[topic]],
                                 [m.data for m in log.messages_on(topic)]), topic
            cls = _message_class(log.topics[topic].type)
            assert peer.messages(topic) == [
                deserialize_message(m.data, cls) for m in log.messages_on(topic)
            ]
        clock = [c.clock.sec * 10**9 + c.clock.nanosec for c in peer.messages("/clock")]
        times = [m.log_time_ns for m in log.messages]
        assert clock[0] <= min(times) and clock[-1] >= max(times)
        # A use_sim_time node follows the replayed clock.
        assert peer.node.get_clock().now().nanoseconds == clock[-1]
    finally:
        peer.close()


def test_replay_generates_clock_honours_the_topic_filter_offset_and_rate(recorded):
    path, _, work = recorded
    log = read_log(path)
    topics = ["/output/displacement", "/hinges/a/wrench"]
    offset = 0.05
    first = min(m.log_time_ns for m in log.messages)
    expected = {
        t: [m for m in log.messages_on(t) if m.log_time_ns >= first + offset * 1e9] for t in topics
    }
    domain = next_domain_id()
    peer = Peer(domain, name="filtered_listener")
    try:
        _subscribe_all(peer, log, topics + ["/clock"])
        peer.subscribe("/bodies/poses", _message_class("geometry_msgs/msg/PoseArray"))
        t0 = time.monotonic()
        proc = _replay(domain, work, str(path), "--topics", *topics, "--start-offset", str(offset),
                       "--rate", "0.5", "--wait-for-subscribers", "30")
        _spin_until_done(peer, proc, {t: len(v) for t, v in expected.items()})
        wall = time.monotonic() - t0
        out, err = proc.communicate(timeout=30)
        assert proc.returncode == 0, err
        assert "/clock generated" in out
        for t in topics:
            assert same_payloads(
                [raw for _, raw in peer.received[t]], [m.data for m in expected[t]]
            )
        assert not peer.received["/bodies/poses"]  # filtered out
        clock = [c.clock.sec * 10**9 + c.clock.nanosec for c in peer.messages("/clock")]
        played = sorted({m.log_time_ns for v in expected.values() for m in v})
        assert clock == sorted(clock)
        assert clock[0] == played[0] and clock[-1] == played[-1]
        assert set(played) <= set(clock)
        # Half speed: 0.0595 s of log time take about 0.12 s of wall time.
        span = (played[-1] - played[0]) / 1e9
        assert wall > span / 0.5
    finally:
        peer.close()


def test_replay_loops_until_interrupted_and_stops_cleanly(recorded):
    path, _, work = recorded
    log = read_log(path)
    n = log.topics["/drive/force"].message_count
    domain = next_domain_id()
    peer = Peer(domain, name="loop_listener")
    try:
        _subscribe_all(peer, log, ["/drive/force"])
        proc = _replay(domain, work, str(path), "--topics", "/drive/force", "--loop",
                       "--wait-for-subscribers", "30")
        peer.spin_until(
            lambda: len(peer.received["/drive/force"]) >= 2 * n + 10, 60, "a second pass"
        )
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=30)
        assert proc.returncode == 0, err
        assert "Traceback" not in err
        data = [raw for _, raw in peer.received["/drive/force"]]
        recorded_bytes = [m.data for m in log.messages_on("/drive/force")]
        assert same_payloads(data[:n], recorded_bytes) and same_payloads(
            data[n:2 * n], recorded_bytes
        )
    finally:
        peer.close()


def test_ros2_run_replay_finds_the_installed_launcher(recorded, tmp_path):
    """
    `ros2 run flexure_sim replay` executes <prefix>/lib/flexure_sim/replay.

    Run it as ros2run would, from a shell without the virtual environment on PATH.
    """
    path, _, _ = recorded
    prefix = None
    for p in (os.environ.get("AMENT_PREFIX_PATH") or sys.prefix).split(os.pathsep):
        if p and (Path(p) / "share/ament_index/resource_index/packages/flexure_sim").is_file():
            prefix = Path(p)
            break
    assert prefix is not None, "flexure_sim is not installed (scripts/run_tests.sh installs it)"
    exe = prefix / "lib" / "flexure_sim" / "replay"
    assert exe.is_file() and os.access(exe, os.X_OK)
    log = read_log(path)
    domain = next_domain_id()
    env = node_env(
        domain, PATH="/usr/local/bin:/usr/bin:/bin", ROS_LOG_DIR=str(tmp_path / "ros_log")
    )
    for key in ("VIRTUAL_ENV", "PYTHONPATH", "PYTHONHOME"):
        env.pop(key, None)
    peer = Peer(domain, name="launcher_listener")
    try:
        _subscribe_all(peer, log, ["/output/displacement"])
        proc = _replay(domain, tmp_path, str(path), "--topics", "/output/displacement",
                       "--wait-for-subscribers", "30", "--ros-args", "--log-level", "warn",
                       command=[str(exe)], env=env)
        _spin_until_done(
            peer, proc, {"/output/displacement": log.topics["/output/displacement"].message_count}
        )
        out, err = proc.communicate(timeout=30)
        assert proc.returncode == 0, err
        assert same_payloads([raw for _, raw in peer.received["/output/displacement"]],
                             [m.data for m in log.messages_on("/output/displacement")])
        # Bad input: a message and exit code 1, no traceback.
        bad = tmp_path / "bad.mcap"
        bad.write_bytes(bag_files(path)[0].read_bytes()[:1000])
        proc = subprocess.run(
            [str(exe), str(bad)], env=env, capture_output=True, text=True, timeout=60
        )
        assert (
            proc.returncode == 1 and "Traceback" not in proc.stderr and "truncated" in proc.stderr
        )
    finally:
        peer.close()
