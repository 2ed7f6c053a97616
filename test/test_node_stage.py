"""
stage_node as a real subprocess, talked to over DDS on loopback by real rclpy test nodes.

Each test gets its own ROS domain (node_harness.next_domain_id). The node runs the source
tree; test_node_launch.py covers the installed console script and the ros2-run launcher.
"""
from __future__ import annotations

import math
import os
import signal
import time
from pathlib import Path

import pytest
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseArray, PoseStamped, TransformStamped, WrenchStamped
from rcl_interfaces.msg import Parameter as ParameterMsg
from rcl_interfaces.msg import ParameterType, ParameterValue
from rcl_interfaces.srv import GetParameters, SetParameters
from rosgraph_msgs.msg import Clock
from rclpy.executors import TimeoutException
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from std_msgs.msg import Bool, Float64
from std_srvs.srv import SetBool, Trigger
from visualization_msgs.msg import MarkerArray

from flexure_sim.engine.mechanism.loader import ConfigError, load_mechanism, resolve_mechanism_path
from flexure_sim.recording import CorruptLogError, log_info, read_log
from flexure_sim.engine.solver.simulation import Simulation
from flexure_sim.node.stage.cpu_latency import DEVICE, latency_in_effect

from node_harness import NodeProcess, Peer, diagnostics_values, next_domain_id, thread_stats
from reference_figures import STAGE_GAIN

STEP = 1.35e-6
STAGE_TOPICS = (
    ["/bodies/poses"] + [f"/bodies/body{i}/pose" for i in range(1, 7)]
    + [f"/hinges/{h}/{kind}" for h in "abcdefg" for kind in ("wrench", "deflection")]
    + ["/drive/wrench", "/hinges/a/compression", "/output/displacement", "/drive/input",
       "/drive/force"]
)
TYPES = {
    "/bodies/poses": PoseArray,
    "/hinges/a/compression": Float64,
    "/output/displacement": Float64,
    "/drive/input": Float64,
    "/drive/force": Float64,
    "/drive/wrench": WrenchStamped,
    "/diagnostics": DiagnosticArray,
    "/clock": Clock,
    "/markers": MarkerArray,
    **{f"/bodies/body{i}/pose": PoseStamped for i in range(1, 7)},
    **{f"/hinges/{h}/wrench": WrenchStamped for h in "abcdefg"},
    **{f"/hinges/{h}/deflection": TransformStamped for h in "abcdefg"},
}


@pytest.fixture(scope="module")
def engine_static():
    """Return the engine's static answer at 1.35 um (no ROS)."""
    sim = Simulation(load_mechanism("microstage"))
    return sim.static(STEP).snapshot


def start(tmp_path: Path, domain: int, peer: Peer | None = None, **params) -> NodeProcess:
    node = NodeProcess(tmp_path / "node", domain, params)
    if peer is not None:
        peer.watch = node
    return node


def stamp_ns(msg) -> int:
    return msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec


def latest_diagnostics(peer: Peer) -> dict[str, str]:
    return diagnostics_values(peer.last("/diagnostics"))


def thread_nices(pid: int) -> list[tuple[str, int]]:
    """(name, niceness) of every thread of process ``pid``, its main thread first."""
    return [(name, int(fields[16])) for name, fields in thread_stats(pid)]  # field 19: nice


def stop_cleanly(node: NodeProcess, sig: int = signal.SIGINT) -> None:
    rc = node.stop(sig)
    assert rc == 0, f"exit code {rc}\n{node.stderr}"


# ------------------------------------------------------------------------------ acceptance
def test_step_response_settles_to_the_engines_static_gain_and_compression(
    tmp_path, domain, peer, engine_static
):
    node = start(
        tmp_path, domain, peer, time_mode="fast", sim_step=1e-4, publish_rate=200.0, record=False
    )
    try:
        for topic in (
            "/output/displacement",
            "/hinges/a/compression",
            "/drive/input",
            "/drive/force",
            "/bodies/body4/pose",
            "/hinges/a/wrench",
            "/hinges/a/deflection",
            "/diagnostics",
        ):
            peer.subscribe(topic, TYPES[topic])
        drive = peer.publisher("/drive/displacement", Float64)
        peer.wait_for_publishers(["/output/displacement"])
        peer.wait_for_subscribers(drive)
        peer.spin_until(lambda: len(peer.received["/output/displacement"]) > 5, 20, "outputs")
        assert abs(peer.last("/output/displacement").data) < 1e-15  # at rest
        drive.publish(Float64(data=STEP))
        # Settled: the actuator lag is 1 ms, the hinge modes are faster still; wait for
        # 0.2 s of simulated time after the input reached the command.
        peer.spin_until(
            lambda: peer.last_data("/drive/input") == pytest.approx(STEP, rel=1e-12),
            30,
            "the actuator to reach the command",
        )
        count = len(peer.received["/output/displacement"])
        peer.spin_until(
            lambda: len(peer.received["/output/displacement"]) > count + 40, 30, "settling"
        )
        gain = peer.last("/output/displacement").data / STEP
        engine_gain = engine_static.output / STEP
        assert gain == pytest.approx(engine_gain, rel=1e-4)
        assert gain == pytest.approx(STAGE_GAIN, rel=1e-4)
        assert peer.last("/hinges/a/compression").data == pytest.approx(
            engine_static.compression, rel=1e-4
        )
        assert peer.last("/drive/force").data == pytest.approx(engine_static.drive_force, rel=1e-4)
        # Frames and units as documented.
        pose = peer.last("/bodies/body4/pose")
        assert pose.header.frame_id == "stage"
        assert pose.pose.position.x == pytest.approx(engine_static.poses[3, 0], rel=1e-6)
        assert pose.pose.position.z == 0.0 and pose.pose.orientation.x == 0.0
        yaw = 2 * math.atan2(pose.pose.orientation.z, pose.pose.orientation.w)
        assert yaw == pytest.approx(engine_static.poses[3, 2], rel=1e-4, abs=1e-12)
        wrench = peer.last("/hinges/a/wrench")
        assert wrench.header.frame_id == "hinge_a"
        m, fx, fy = engine_static.wrenches[0]
        assert wrench.wrench.torque.z == pytest.approx(m, rel=1e-4)
        assert wrench.wrench.force.x == pytest.approx(fx, rel=1e-4)
        assert wrench.wrench.force.y == pytest.approx(fy, rel=1e-4)
        deflection = peer.last("/hinges/a/deflection")
        assert (deflection.header.frame_id, deflection.child_frame_id) == ("hinge_a_a", "hinge_a")
        assert deflection.transform.translation.x == pytest.approx(
            engine_static.deflections[0, 1], rel=1e-4
        )
        # Stamps are simulated time, on the tick grid (5 ms).
        stamps = [stamp_ns(m) for m in peer.messages("/bodies/body4/pose")]
        off_grid = [s for s in stamps if s % 5_000_000]
        assert (
            not off_grid
        ), f"stamps off the 5 ms tick grid (ns): {off_grid[:10]} of {len(stamps)}"
        # In order; a subscriber slower than the unpaced fast mode may miss ticks (the
        # publishers keep the last 100), the recording keeps them all
        # (test_node_recording.py: a slow recorder loses nothing in fast mode).
        assert all(b > a for a, b in zip(stamps, stamps[1:]))
        diag = latest_diagnostics(peer)
        assert diag["commands_received"] == "1" and diag["commands_accepted"] == "1"
        assert diag["time_mode"] == "fast" and float(diag["real_time_factor"]) > 0
    finally:
        stop_cleanly(node)


# ------------------------------------------------------------------------------ bad input
def test_bad_commands_are_rejected_clamped_rate_limited_and_counted_and_a_flood_does_not_stall(
        tmp_path, domain, peer):
    node = start(tmp_path, domain, peer, time_mode="realtime", sim_step=5e-4, publish_rate=200.0,
                 slew_rate=1e-4, record=True, record_path="bad.mcap")
    try:
        for topic in ("/drive/input", "/output/displacement", "/hinges/a/wrench", "/diagnostics"):
            peer.subscribe(topic, TYPES[topic], depth=10000)
        drive = peer.publisher("/drive/displacement", Float64, depth=1000)
        peer.wait_for_publishers(["/diagnostics"])
        peer.wait_for_subscribers(drive)
        peer.spin_for(0.3)

        def diag_after(settle: float = 0.3) -> dict[str, str]:
            n = len(peer.received["/diagnostics"])
            peer.spin_for(settle)
            # two diagnostics periods; the bound only ends a hang on a busy machine
            peer.spin_until(lambda: len(peer.received["/diagnostics"]) > n + 1, 60, "diagnostics")
            return latest_diagnostics(peer)

        for bad in (math.nan, math.inf, -math.inf):
            drive.publish(Float64(data=bad))
        d = diag_after()
        assert (d["commands_received"], d["commands_rejected"], d["commands_accepted"]) == (
            "3",
            "3",
            "0",
        )
        assert d["drive_target"] == "0.0"
        drive.publish(Float64(data=5e-6))      # above the 2 um stroke
        d = diag_after()
        assert d["commands_clamped"] == "1" and float(d["drive_target"]) == 2e-6
        assert d["commands_rate_limited"] == "1"    # 2 um at 1e-4 m/s takes 20 ms > 5 ms tick
        drive.publish(Float64(data=-1e-6))     # below
        d = diag_after()
        assert d["commands_clamped"] == "2" and float(d["drive_target"]) == 0.0
        assert d["commands_rate_limited"] == "2"
        drive.publish(Float64(data=1.0e-6))
        d = diag_after(0.5)
        assert float(d["drive_applied"]) == 1.0e-6 and d["commands_rate_limited"] == "3"
        # The engine followed the ramp: the actuator output approached 1 um without overshoot.
        inputs = [m.data for m in peer.messages("/drive/input")]
        assert max(inputs) <= 2e-6 * (1 + 1e-9) and min(inputs) >= -1e-15
        assert inputs[-1] == pytest.approx(1.0e-6, rel=1e-3)
        before = latest_diagnostics(peer)

        # Flood: 10,000 commands at up to 10 kHz (1 s, or longer if this process is slower),
        # every 100th NaN, the others valid.
        sent = nan_sent = 0
        t0 = time.perf_counter()
        while sent < 10_000:
            now = time.perf_counter()
            while sent < 10_000 and sent * 1e-4 <= now - t0:  # catch up with the schedule
                if sent % 100 == 99:
                    drive.publish(Float64(data=math.nan))
                    nan_sent += 1
                else:
                    drive.publish(Float64(data=1e-6 + 1e-8 * (sent % 50)))
                sent += 1
            time.sleep(0.0005)
        wall = time.perf_counter() - t0
        drive.publish(Float64(data=1.5e-6))
        sent += 1
        d = diag_after(1.0)
        assert node.alive()
        received = int(d["commands_received"]) - int(before["commands_received"])
        rejected = int(d["commands_rejected"]) - int(before["commands_rejected"])
        # The stepping thread empties the reader (1000 deep: 100 ms of flood) every 5 ms tick:
        # every command arrives, none is lost to the reader's history.
        assert received == sent, (received, sent)
        assert rejected == nan_sent
        # Stepping went on during the flood: every diagnostics window (20 ticks) advanced
        # simulated time (how closely it kept pace with the wall clock under a flood is the
        # benchmark's figure: `flexure-sim bench --node`, flood_missed_tick_fraction).
        n_before = next(i for i, m in enumerate(peer.messages("/diagnostics"))
                        if diagnostics_values(m)["sim_time"] == before["sim_time"])
        flood = [diagnostics_values(m) for m in peer.messages("/diagnostics")[n_before + 1:]]
        sim_times = [float(before["sim_time"])] + [float(v["sim_time"]) for v in flood]
        assert len(sim_times) > 2 and all(b > a for a, b in zip(sim_times, sim_times[1:]))
        assert float(d["drive_target"]) == pytest.approx(1.5e-6, rel=1e-12)
        # Outputs stayed finite throughout.
        for topic in ("/drive/input", "/output/displacement"):
            assert all(math.isfinite(m.data) for m in peer.messages(topic))
        assert all(math.isfinite(m.wrench.force.x) and math.isfinite(m.wrench.torque.z)
                   for m in peer.messages("/hinges/a/wrench"))
        print(
            f"flood: {sent} sent in {wall:.2f} s, {received} received, sim time advanced "
            f"{sim_times[-1] - float(before['sim_time']):.2f} s, missed ticks "
            f"{d.get('missed_ticks')}"
        )
    finally:
        stop_cleanly(node)
    # Every received command is in the recording, NaN included, in order.
    log = read_log(node.cwd / "bad.mcap")
    assert log.complete
    commands = [m.message.data for m in log.messages_on("/drive/displacement")]
    assert len(commands) == int(d["commands_received"])
    assert (
        sum(1 for c in commands if math.isnan(c)) == int(d["commands_rejected"]) - 2
    )  # inf, -inf
    assert math.isnan(commands[0]) and commands[1] == math.inf and commands[2] == -math.inf
    assert commands[3:6] == [5e-6, -1e-6, 1e-6] and commands[-1] == 1.5e-6


# ------------------------------------------------------------------------------ signals
def read_with_mcap(path: Path) -> tuple[dict[str, int], int, dict]:
    """Count per topic from mcap + mcap-ros2-support, decoding every message."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    counts: dict[str, int] = {}
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        summary = reader.get_summary()
        assert summary is not None and summary.statistics is not None
        metadata = {m.name: dict(m.metadata) for m in reader.iter_metadata()}
        for schema, channel, message, decoded in reader.iter_decoded_messages():
            assert schema.encoding == "ros2msg" and channel.message_encoding == "cdr"
            assert "offered_qos_profiles" in channel.metadata and \
                channel.metadata["topic_type_hash"].startswith("RIHS01_")
            assert message.log_time == message.publish_time
            assert decoded is not None
            counts[channel.topic] = counts.get(channel.topic, 0) + 1
        total = summary.statistics.message_count
    return counts, total, metadata


def read_with_rosbags(path: Path) -> dict[str, int]:
    from rosbags.highlevel import AnyReader

    counts: dict[str, int] = {}
    with AnyReader([path]) as reader:
        for connection, _, raw in reader.messages():
            reader.deserialize(raw, connection.msgtype)
            counts[connection.topic] = counts.get(connection.topic, 0) + 1
    return counts


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_signal_leaves_a_complete_recording_matching_what_was_received(
    tmp_path, domain, peer, sig
):
    ticks = 25
    node = start(tmp_path, domain, peer, time_mode="lockstep", sim_step=1e-4, publish_rate=100.0,
                 record=True, record_path="run.mcap")
    try:
        topics = ["/clock"] + STAGE_TOPICS + ["/diagnostics", "/markers"]
        for topic in topics:
            peer.subscribe(topic, TYPES[topic])
        drive = peer.publisher("/drive/displacement", Float64)
        peer.wait_for_publishers(topics)
        peer.wait_for_subscribers(drive)
        drive.publish(Float64(data=STEP))
        peer.publish_acked(drive, Float64(data=math.nan))
        for k in range(ticks):
            answer = peer.call(Trigger, "/stage_node/step")
            assert answer.success, answer.message
        peer.spin_until(
            lambda: all(len(peer.received[t]) >= ticks for t in ["/clock"] + STAGE_TOPICS)
            and len(peer.received["/diagnostics"]) >= 2
            and len(peer.received["/markers"]) >= 9,
            20,
            "every tick's messages",
        )
        peer.spin_for(0.3)
    finally:
        stop_cleanly(node, sig)
    received = {t: len(peer.received[t]) for t in topics}
    assert received["/bodies/poses"] == ticks and received["/diagnostics"] == ticks // 10  # 10 Hz
    assert received["/markers"] == 9  # display_rate 30 Hz: every 3rd of the 100 Hz ticks
    received["/drive/displacement"] = 2
    # One status more than the peer took while it listened: the stop's, written with the
    # run's final counters (the 5 ticks after the last periodic one).
    expected = dict(received, **{"/diagnostics": received["/diagnostics"] + 1})
    path = node.cwd / "run.mcap"
    counts, total, metadata = read_with_mcap(path)
    assert counts == expected, node.stderr
    assert total == sum(expected.values())
    assert read_with_rosbags(path) == expected
    last_status = read_log(path).messages_on("/diagnostics")[-1]
    assert last_status.log_time_ns == ticks * 10_000_000  # the last tick's time
    assert diagnostics_values(last_status.message)["ticks"] == str(ticks)
    meta = metadata["flexure_sim"]
    assert meta["mechanism"] == "microstage" and meta["mechanism_name"] == "microstage"
    assert meta["time_mode"] == "lockstep" and meta["publish_rate"] == "100.0"
    assert (
        meta["sim_step"] == "0.0001"
        and meta["record"] == "true"
        and meta["steps_per_tick"] == "100"
    )
    assert "bodies:" in meta["mechanism_yaml"]
    assert "rosbag2" in metadata
    # The bytes received are the bytes recorded; log time = header stamp.
    log = read_log(path)
    recorded = log.messages_on("/hinges/c/wrench")
    assert [m.data for m in recorded] == [raw for _, raw in peer.received["/hinges/c/wrench"]]
    assert all(m.log_time_ns == stamp_ns(m.message) for m in recorded)
    clocks = [
        m.message.clock.sec * 10**9 + m.message.clock.nanosec for m in log.messages_on("/clock")
    ]
    assert clocks == [k * 10_000_000 for k in range(1, ticks + 1)]
    commands = log.messages_on("/drive/displacement")
    assert commands[0].message.data == STEP and math.isnan(commands[1].message.data)
    assert [c.log_time_ns for c in commands] == [0, 0]  # applied at the first tick, t = 0


# ------------------------------------------------------------------------------ time
def test_fast_mode_publishes_clock_and_a_use_sim_time_node_follows_it(tmp_path, domain):
    follower = Peer(domain, name="sim_time_follower", use_sim_time=True)
    node = start(tmp_path, domain, follower, time_mode="fast", sim_step=1e-4, publish_rate=1000.0,
                 record=False)
    try:
        follower.subscribe("/clock", Clock, depth=100000)
        follower.subscribe("/bodies/body4/pose", PoseStamped, depth=100000)
        follower.wait_for_publishers(["/clock", "/bodies/body4/pose"])
        follower.spin_until(
            lambda: len(follower.received["/bodies/body4/pose"]) > 300, 30, "poses"
        )
        during = follower.node.get_clock().now().nanoseconds
        # Its clock moves on while the node runs (a /clock after `during` reached it), so that
        # it cannot stay at `during` when the node stops right after that reading.
        follower.spin_until(lambda: follower.node.get_clock().now().nanoseconds > during, 30,
                            "the follower's clock to move past its reading")
        follower.watch = None
        stop_cleanly(node)
        # The node has exited. Once its writers have left the graph nothing more can arrive,
        # and what reached this process waits in its readers' queues: take all of it. (A
        # reliable writer that is gone resends nothing: unpaced, the node published thousands
        # of ticks a second, more than this process takes on a busy machine, so each topic's
        # last messages can be lost, each topic's differently.)
        follower.spin_until(
            lambda: not any(follower.node.count_publishers(t)
                            for t in ("/clock", "/bodies/body4/pose")),
            120, "the stage's writers to leave the graph")
        taken = -1
        while taken:  # rounds of rclpy's wait, each taking one message per ready reader
            taken = 0
            try:
                while True:  # the round ends with TimeoutException (timeout 0)
                    handler, _, _ = follower.executor.wait_for_ready_callbacks(timeout_sec=0.0)
                    handler()
                    taken += 1
            except TimeoutException:
                pass  # a round that took nothing: every queue is empty
        now = follower.node.get_clock().now().nanoseconds
        active = follower.node.get_clock().ros_time_is_active
        clocks = [m.clock.sec * 10**9 + m.clock.nanosec for m in follower.messages("/clock")]
        stamps = [stamp_ns(m) for m in follower.messages("/bodies/body4/pose")]
    finally:
        follower.close()
        if node.alive():
            stop_cleanly(node)
    # /clock advances tick by tick (a follower slower than the unpaced fast mode misses some:
    # the publishers keep the last 100), and every pose carries the simulated time of a tick,
    # the ticks /clock carried.
    assert all(b > a and (b - a) % 1_000_000 == 0 for a, b in zip(clocks, clocks[1:])), \
        "/clock advances tick by tick"
    assert len(stamps) > 300 and all(s % 1_000_000 == 0 for s in stamps)
    assert set(stamps) & set(clocks)
    # The follower's ROS clock is simulated time: it followed /clock (taken best effort by
    # rclpy's TimeSource, the newest only) past where it was while the node ran, to a tick.
    # (The TimeSource's reader and this test's /clock reader each lose their own messages: a
    # subscription that joins an unpaced run misses its first ticks, and a slow reader of a
    # writer that keeps the last 100 its last ones. So `during` need not lie within `clocks`.)
    assert active and now > during and now % 1_000_000 == 0
    assert during % 1_000_000 == 0


def test_lockstep_runs_are_deterministic_and_reset_restarts_time(tmp_path, domain, peer):
    node = start(tmp_path, domain, peer, time_mode="lockstep", sim_step=1e-4, publish_rate=1000.0,
                 record=True, record_path="det.mcap")
    try:
        drive = peer.connect_drive({"/output/displacement": Float64,
                                    "/hinges/b/wrench": WrenchStamped})
        peer.spin_for(0.5)

        def run() -> tuple[list[float], list[tuple[int, float, float, float]]]:
            start_out = len(peer.received["/output/displacement"])
            start_w = len(peer.received["/hinges/b/wrench"])
            for command, steps in ((1.0e-6, 4), (1.8e-6, 3), (0.3e-6, 3)):
                peer.publish_acked(drive, Float64(data=command))
                for _ in range(steps):
                    assert peer.call(Trigger, "/stage_node/step").success
            peer.spin_until(
                lambda: len(peer.received["/output/displacement"]) == start_out + 10, 10, "outputs"
            )
            peer.spin_until(
                lambda: len(peer.received["/hinges/b/wrench"]) == start_w + 10, 10, "wrenches"
            )
            outs = [m.data for m in peer.messages("/output/displacement")[start_out:]]
            wrenches = [(stamp_ns(m), m.wrench.torque.z, m.wrench.force.x, m.wrench.force.y)
                        for m in peer.messages("/hinges/b/wrench")[start_w:]]
            return outs, wrenches

        first = run()
        answer = peer.call(Trigger, "/stage_node/reset")
        assert answer.success and "det_1.mcap" in answer.message, answer.message
        second = run()
    finally:
        stop_cleanly(node)
    assert first == second  # bit for bit, stamps included (time restarts at 0 after reset)
    assert first[1][0][0] == 1_000_000 and first[0][-1] != 0.0
    # Both files complete; each holds its run's commands at the ticks they were applied.
    logs = [read_log(node.cwd / name) for name in ("det.mcap", "det_1.mcap")]
    times = [
        [(m.log_time_ns, m.message.data) for m in log.messages_on("/drive/displacement")]
        for log in logs
    ]
    assert times[0] == times[1] == [(0, 1.0e-6), (4_000_000, 1.8e-6), (7_000_000, 0.3e-6)]


# ------------------------------------------------------------------------------ recording
def test_realtime_run_records_what_it_publishes_and_kill_9_leaves_readable_chunks(
    tmp_path, domain, peer
):
    custom = tmp_path / "my_stage.yaml"
    custom.write_text(resolve_mechanism_path("microstage").read_text())
    realtime = dict(time_mode="realtime", sim_step=5e-4, publish_rate=200.0)
    # The two nodes killed below start with the first, each on a domain of its own (nothing
    # of theirs reaches the peer): their start-ups overlap its run instead of following it.
    node = start(tmp_path, domain, peer, mechanism=str(custom), **realtime, record=True,
                 record_path="rt.mcap")
    killed = NodeProcess(tmp_path / "killed", next_domain_id(),
                         dict(realtime, record_path="k.mcap"))
    crashed = NodeProcess(tmp_path / "crashed", next_domain_id(),
                          dict(realtime, record_path="c.mcap"))
    try:
        _realtime_run_and_kill_9(peer, node, custom, killed, crashed)
    finally:
        for left in (killed, crashed):  # never left behind when a check fails
            for pid in left.children():
                os.kill(pid, signal.SIGKILL)
            left.kill()


def _realtime_run_and_kill_9(peer, node, custom, killed, crashed):
    try:
        peer.subscribe("/bodies/poses", PoseArray, depth=10000)
        peer.subscribe("/diagnostics", DiagnosticArray)
        peer.wait_for_publishers(["/bodies/poses"])
        peer.spin_until(
            lambda: len(peer.received["/diagnostics"]) >= 25, 60, "25 diagnostics windows"
        )
        d = latest_diagnostics(peer)
    finally:
        stop_cleanly(node)
    # Real time: the node stepped and counted what it was late for. How closely simulated time
    # keeps pace with the wall clock depends on the machine: `flexure-sim bench --node`
    # measures it (real-time factor, missed ticks); here only what holds on any machine.
    assert float(d["sim_time"]) > 0 and float(d["real_time_factor"]) > 0
    assert 0 <= int(d["missed_ticks"]) <= int(d["paced_ticks"])
    log = read_log(node.cwd / "rt.mcap")
    assert log.complete and log.metadata["flexure_sim"]["mechanism_path"] == str(custom.resolve())
    stamps = [m.log_time_ns for m in log.messages_on("/bodies/poses")]
    # A late tick is stepped late, not skipped (merge_late_ticks is 0): every tick from the
    # first to the last is in the file, in order, once; or the recorder counted what it dropped.
    missing = (stamps[-1] - stamps[0]) // 5_000_000 + 1 - len(stamps)
    assert stamps == sorted(set(stamps)) and all(s % 5_000_000 == 0 for s in stamps)
    assert missing <= int(log_info(node.cwd / "rt.mcap").dropped_messages or 0), missing
    recorded = set(stamps)
    got = [stamp_ns(m) for m in peer.messages("/bodies/poses")]
    # Everything received was recorded; the recording has nothing the subscriber missed between
    # its first and last message (it may hold more before matching and in flight at the end).
    assert set(got) <= recorded
    assert sorted(t for t in recorded if got[0] <= t <= got[-1]) == got

    # kill -9 of the node: its recorder process sees the pipe close and finishes the file.
    node = killed
    peer.watch = node
    path = node.cwd / "k.mcap"
    peer.spin_until(
        lambda: path.exists() and path.stat().st_size > 200_000, 30, "a few chunks on disk"
    )
    (recorder,) = node.children()
    peer.watch = None
    node.kill()
    peer.spin_until(lambda: not Path(f"/proc/{recorder}").exists(), 30, "the recorder to finish")
    log = read_log(path)
    assert log.complete and log.message_count > 1000

    # kill -9 of node and recorder alike: the chunks already written are readable.
    node = crashed
    peer.watch = node
    path = node.cwd / "c.mcap"
    peer.spin_until(
        lambda: path.exists() and path.stat().st_size > 200_000, 30, "a few chunks on disk"
    )
    peer.watch = None
    for pid in node.children():
        os.kill(pid, signal.SIGKILL)
    node.kill()
    with pytest.raises(CorruptLogError, match="recover=True"):
        read_log(path)  # no summary: not complete
    recovered = read_log(path, recover=True)
    assert not recovered.complete and recovered.message_count > 1000
    assert all(m.message is not None for m in recovered.messages)
    # Independently: mcap's streaming reader decodes every message of the complete chunks.
    from mcap.reader import NonSeekingReader
    from mcap_ros2.decoder import DecoderFactory

    decoded = 0
    with open(path, "rb") as f:
        reader = NonSeekingReader(f, decoder_factories=[DecoderFactory()])
        try:
            for _, _, _, msg in reader.iter_decoded_messages(log_time_order=False):
                decoded += 1
        except Exception:  # noqa: BLE001 - the file ends mid-chunk
            pass
    assert decoded == recovered.message_count
    print(f"kill -9: {path.stat().st_size} bytes on disk, {decoded} messages recovered")


def test_record_and_reset_services_close_complete_files(tmp_path, domain, peer):
    node = start(tmp_path, domain, peer, time_mode="realtime", sim_step=5e-4, publish_rate=200.0,
                 record=True, record_path="svc.mcap")
    try:
        peer.subscribe("/bodies/poses", PoseArray, depth=10000)
        peer.wait_for_publishers(["/bodies/poses"])
        peer.spin_until(lambda: len(peer.received["/bodies/poses"]) > 40, 10, "poses")
        answer = peer.call(SetBool, "/stage_node/record", SetBool.Request(data=False))
        assert answer.success and "svc.mcap" in answer.message
        assert read_log(node.cwd / "svc.mcap").complete  # complete as soon as the service answers
        answer = peer.call(SetBool, "/stage_node/record", SetBool.Request(data=False))
        assert answer.success and answer.message == "not recording"
        values = peer.call(GetParameters, "/stage_node/get_parameters",
                           GetParameters.Request(names=["record"])).values
        assert values[0].bool_value is False  # the parameter follows the service
        answer = peer.call(SetBool, "/stage_node/record", SetBool.Request(data=True))
        assert answer.success and "svc_1.mcap" in answer.message
        peer.spin_for(0.5)
        t_before = stamp_ns(peer.last("/bodies/poses"))
        answer = peer.call(Trigger, "/stage_node/reset")
        assert (
            answer.success
            and "closed svc_1.mcap" in answer.message
            and "svc_2.mcap" in answer.message
        )
        assert read_log(node.cwd / "svc_1.mcap").complete
        n = len(peer.received["/bodies/poses"])
        peer.spin_until(
            lambda: len(peer.received["/bodies/poses"]) > n + 20, 10, "poses after reset"
        )
        after = [stamp_ns(m) for m in peer.messages("/bodies/poses")[n:]]
        assert min(after) < t_before and min(after) <= 200_000_000  # time restarted at 0
        answer = peer.call(Trigger, "/stage_node/step")
        assert not answer.success and "lockstep" in answer.message
    finally:
        stop_cleanly(node)
    log = read_log(node.cwd / "svc_2.mcap")
    assert log.complete and log.metadata["flexure_sim"]["run"] == "1"
    assert min(m.log_time_ns for m in log.messages_on("/bodies/poses")) == 5_000_000


# ------------------------------------------------------------------------------ parameters
def _set(peer: Peer, name: str, value) -> tuple[bool, str]:
    msg = ParameterMsg(name=name)
    if isinstance(value, bool):
        msg.value = ParameterValue(type=ParameterType.PARAMETER_BOOL, bool_value=value)
    elif isinstance(value, float):
        msg.value = ParameterValue(type=ParameterType.PARAMETER_DOUBLE, double_value=value)
    elif isinstance(value, int):
        msg.value = ParameterValue(type=ParameterType.PARAMETER_INTEGER, integer_value=value)
    else:
        msg.value = ParameterValue(type=ParameterType.PARAMETER_STRING, string_value=value)
    answer = peer.call(
        SetParameters, "/stage_node/set_parameters", SetParameters.Request(parameters=[msg])
    )
    result = answer.results[0]
    return result.successful, result.reason


def test_parameters_are_validated_with_reasons_and_applied_live(tmp_path, domain, peer):
    # stepping_nice 5: raising niceness is always permitted, so the request is granted.
    node = start(
        tmp_path,
        domain,
        peer,
        time_mode="realtime",
        sim_step=5e-4,
        publish_rate=200.0,
        record=False,
        stepping_nice=5,
        cpu_latency_us=13,
    )
    # The PM QoS request is granted where this process could make it (root here).
    granted = os.access(DEVICE, os.W_OK)
    try:
        peer.subscribe("/diagnostics", DiagnosticArray)
        peer.subscribe("/bodies/poses", PoseArray, depth=10000)
        peer.wait_for_publishers(["/diagnostics"])
        ok, reason = _set(peer, "publish_rate", 150.0)
        assert not ok and "does not divide" in reason
        ok, reason = _set(peer, "publish_rate", 20000.0)
        assert not ok
        ok, reason = _set(peer, "stroke_max", -1e-6)
        assert not ok and "stroke_min" in reason
        ok, reason = _set(peer, "slew_rate", 0.0)
        assert not ok and "slew_rate" in reason
        ok, reason = _set(peer, "time_mode", "fast")
        assert not ok and "read-only" in reason.lower() or "read only" in reason.lower()
        ok, reason = _set(peer, "stepping_nice", 0)
        assert not ok and "read-only" in reason.lower() or "read only" in reason.lower()
        ok, reason = _set(peer, "wake_spin", -1e-3)
        assert not ok and "wake_spin" in reason
        ok, reason = _set(peer, "publish_rate", 100.0)
        assert ok, reason
        ok, reason = _set(peer, "stroke_max", 1e-6)
        assert ok, reason
        ok, reason = _set(peer, "wake_spin", 2e-3)
        assert ok, reason
        n = len(peer.received["/bodies/poses"])
        peer.spin_for(1.0)
        stamps = [stamp_ns(m) for m in peer.messages("/bodies/poses")[n + 2:]]
        assert {b - a for a, b in zip(stamps, stamps[1:])} == {10_000_000}  # 100 Hz now
        drive = peer.publisher("/drive/displacement", Float64)
        peer.wait_for_subscribers(drive)
        drive.publish(Float64(data=1.5e-6))
        peer.spin_for(0.5)
        d = latest_diagnostics(peer)
        assert d["publish_rate"] == "100.0" and d["steps_per_tick"] == "20"
        assert float(d["wake_spin_us"]) == pytest.approx(2000.0)
        assert d["stepping_nice"] == "5"
        # The middleware's threads serve the stepping thread's takes and publishes: they run
        # at its niceness (a priority inversion otherwise), the executor's thread does not.
        nices = thread_nices(node.proc.pid)
        dds = [nice for name, nice in nices if name.startswith("dds.")]
        assert dds and set(dds) == {5}, nices
        # the main thread (the executor) keeps the niceness the node started with: this
        # process's (0, or the suite's own under `nice`)
        assert nices[0][1] == os.getpriority(os.PRIO_PROCESS, 0), nices
        assert sum(nice == 5 for _, nice in nices) == int(d["middleware_threads"]) + 1, nices
        assert d["cpu_latency_us"] == ("13" if granted else "-1")
        if granted:  # the kernel holds the node's request while it steps in real time ...
            assert latency_in_effect() == 13
        assert d["commands_clamped"] == "1" and float(d["drive_target"]) == 1e-6
    finally:
        stop_cleanly(node)
    assert latency_in_effect() != 13  # ... and not once it has stopped


def test_invalid_startup_parameters_and_bad_mechanisms_stop_with_the_reason(tmp_path, domain):
    broken = tmp_path / "broken.yaml"
    broken.write_text(
        "name: broken\nbodies: [{name: body1, mass: -1, inertia: 1, pose: [0, 0, 0]}]\n"
        "hinges: []\nconstraints: []\n"
    )
    with pytest.raises(ConfigError) as loader:
        load_mechanism(str(broken))
    cases = {
        "bad_file": (dict(mechanism=str(broken)), str(loader.value)),
        "missing_file": (dict(mechanism=str(tmp_path / "nope.yaml")), "no such mechanism file"),
        "unknown_builtin": (dict(mechanism="no_such_stage"), "no such built-in mechanism"),
        "step": (dict(sim_step=3e-4), "does not divide"),
        "zero_step": (dict(sim_step=0.0), "sim_step"),
        "mode": (dict(time_mode="slow"), "time_mode"),
        "range": (dict(publish_rate=20000.0),
                  "invalid parameter publish_rate: 20000.0 is outside its range [1, 10000] Hz"),
        "int_range": (dict(stepping_priority=150),
                      "invalid parameter stepping_priority: 150 is outside its range [0, 99]"),
        "stroke": (dict(stroke_min=3e-6), "stroke_min"),
    }
    nodes = {
        name: NodeProcess(tmp_path / name, domain, params) for name, (params, _) in cases.items()
    }
    for name, node in nodes.items():
        rc = node.wait(60)
        assert rc != 0, name
        assert cases[name][1] in node.stderr, (name, node.stderr)
        assert "Traceback" not in node.stderr, node.stderr
        assert not node.recordings()


def test_fourbar_runs_without_drive_topics(tmp_path, domain, peer):
    node = start(
        tmp_path,
        domain,
        peer,
        mechanism="fourbar_mixed",
        time_mode="fast",
        sim_step=1e-4,
        publish_rate=1000.0,
        record=True,
        record_path="fb.mcap",
    )
    try:
        peer.subscribe("/hinges/B/deflection", TransformStamped)
        peer.subscribe("/bodies/poses", PoseArray)
        peer.wait_for_publishers(["/hinges/B/deflection"])
        peer.spin_until(lambda: len(peer.received["/hinges/B/deflection"]) > 50, 30, "deflections")
        names = {name for name, _ in peer.node.get_topic_names_and_types()}
        assert "/drive/input" not in names and "/output/displacement" not in names
        assert peer.node.count_subscribers("/drive/displacement") == 0
        d = peer.last("/hinges/B/deflection")
        assert (d.header.frame_id, d.child_frame_id) == ("hinge_B_a", "hinge_B")
        assert len(peer.last("/bodies/poses").poses) == 4
    finally:
        stop_cleanly(node)
    log = read_log(node.cwd / "fb.mcap")
    assert (
        log.complete
        and "/bodies/link2/pose" in log.topics
        and "/drive/displacement" not in log.topics
    )


def test_reset_restarts_the_pacing_counters_with_ticks(tmp_path, domain, peer):
    """After ``~/reset`` missed_ticks, paced_ticks, slips count the new run, like ticks."""
    node = start(tmp_path, domain, peer, time_mode="realtime", publish_rate=200.0, record=False)
    try:
        peer.subscribe("/diagnostics", DiagnosticArray)
        peer.wait_for_publishers(["/diagnostics"], timeout=60)
        peer.spin_until(lambda: len(peer.received["/diagnostics"]) > 0
                        and int(latest_diagnostics(peer)["paced_ticks"]) >= 100, 60,
                        "100 paced ticks")
        before = latest_diagnostics(peer)
        assert peer.call(Trigger, "/stage_node/reset").success
        n = len(peer.received["/diagnostics"])
        # The first report of the new run: fewer ticks than the old run had already run.
        peer.spin_until(lambda: any(
            int(diagnostics_values(m)["ticks"]) < int(before["ticks"])
            for m in peer.messages("/diagnostics")[n:]), 60, "diagnostics of the new run")
        after = next(d for d in map(diagnostics_values, peer.messages("/diagnostics")[n:])
                     if int(d["ticks"]) < int(before["ticks"]))
    finally:
        stop_cleanly(node)
    paced = int(after["paced_ticks"])
    assert paced < int(before["paced_ticks"])
    assert paced <= int(after["ticks"]) + int(after["merged_ticks"]) + 1
    assert int(after["missed_ticks"]) <= paced
    assert int(after["slips"]) <= paced


def test_ready_is_latched_true_once_the_loop_runs(tmp_path, domain, peer):
    """
    ``~/ready`` (transient local): a driver subscribing late still gets ``true``.

    Subscribed only after the node's diagnostics show ticks: the message was published before
    this reader existed, so it arrives only because it is latched.
    """
    node = start(tmp_path, domain, peer, record=False)
    try:
        peer.subscribe("/diagnostics", DiagnosticArray)
        peer.spin_until(lambda: len(peer.received["/diagnostics"]) > 0
                        and int(latest_diagnostics(peer)["ticks"]) > 0, 60, "ticks")
        latched = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1,
                             reliability=ReliabilityPolicy.RELIABLE,
                             durability=DurabilityPolicy.TRANSIENT_LOCAL)
        peer.subscribe("/stage_node/ready", Bool, qos=latched)
        peer.spin_until(lambda: len(peer.received["/stage_node/ready"]) > 0, 60, "ready")
    finally:
        stop_cleanly(node)
    assert [m.data for m in peer.messages("/stage_node/ready")] == [True]
