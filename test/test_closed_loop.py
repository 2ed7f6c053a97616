"""
The stage closed by the example controller (pi_controller).

Both real processes, in the stage's lockstep mode: deterministic, and the step response settles to
the setpoint.

Handshake (docs/controller_guide.md): the test calls the stage's
``~/step`` for tick k + 1 only after the controller's ``~/answered`` reached k; the controller
(``handshake:=true``) publishes that count only once every reliable reader of its command --
the stage's -- acknowledged it, so the command is in the stage before the tick that applies
it. The recording proves it: each command applied at the tick after the measurement it
answers. (The controller runs with the shipped Fast DDS profile of 1 ms heartbeats.)
"""
from __future__ import annotations

import subprocess
import sys

import numpy as np
import yaml
from std_msgs.msg import UInt64
from std_srvs.srv import Trigger

from flexure_sim.engine.mechanism.loader import resolve_mechanism_path
from flexure_sim.recording import read_log

from node_harness import ROOT, NodeProcess, Peer, node_env
from node_harness import reliable as reliable_qos

SETPOINT = 2.0e-5
TICKS = 100
SENSOR = {"noise_rms": 1.0e-9, "resolution": 1.0e-9, "bandwidth": 2000.0, "latency": 1, "seed": 3}


def test_lockstep_closed_loop_settles_to_the_setpoint_and_runs_are_bit_identical(tmp_path, domain):
    data = yaml.safe_load(resolve_mechanism_path("microstage").read_text())
    data["sensor"] = SENSOR
    (tmp_path / "stage.yaml").write_text(yaml.safe_dump(data))
    stage = NodeProcess(tmp_path / "stage", domain, dict(
        mechanism=str(tmp_path / "stage.yaml"), time_mode="lockstep", publish_rate=1000.0,
        sim_step=1e-4, record=True, record_path="loop.mcap"))
    controller = NodeProcess(
        tmp_path / "controller", domain, dict(setpoint=SETPOINT, period=1e-3, handshake=True),
        command=[sys.executable, "-m", "flexure_sim.node.apps.pi_controller"],
        env=node_env(domain, PYTHONPATH=str(ROOT), ROS_LOG_DIR=str(tmp_path / "ros_log"),
                     FASTRTPS_DEFAULT_PROFILES_FILE=str(ROOT / "config/fastdds_fast_ack.xml")))
    peer = Peer(domain)
    answered: list[int] = []
    try:
        peer.node.create_subscription(UInt64, "/pi_controller/answered",
                                      lambda m: answered.append(m.data), reliable_qos())
        peer.watch = stage
        peer.spin_until(lambda: peer.node.count_subscribers("/output/measured") > 0
                        and peer.node.count_subscribers("/drive/displacement") > 0
                        and peer.node.count_publishers("/drive/displacement") > 0
                        and peer.node.count_publishers("/pi_controller/answered") > 0,
                        30, "the stage and the controller")

        stepper = peer.node.create_client(Trigger, "/stage_node/step")
        peer.spin_until(stepper.service_is_ready, 30, "the stage's ~/step")

        def step() -> None:
            future = stepper.call_async(Trigger.Request())
            peer.spin_until(future.done, 30, "the answer of ~/step")
            assert future.result().success

        def answered_count(n: int) -> None:
            peer.spin_until(lambda: bool(answered) and answered[-1] >= n, 20,
                            f"the controller's answer {n}")

        # Probe until the measurement path is matched end to end (ticks before the
        # controller's reader matched the stage's writer are not answered), then start the
        # run afresh: both reset.
        for _ in range(50):
            step()
            try:
                peer.spin_until(lambda: bool(answered), 1.0, "a first answer")
                break
            except AssertionError:
                continue
        assert answered, "the controller never answered"

        def run() -> None:
            assert peer.call(Trigger, "/stage_node/reset").success
            assert peer.call(Trigger, "/pi_controller/reset").success
            answered.clear()
            for k in range(1, TICKS + 1):
                step()
                answered_count(k)

        run()
        run()
    finally:
        peer.watch = None
        peer.close()
        codes = []
        for process in (controller, stage):  # both stopped before either is checked
            try:
                # The bound only ends a hang: the controller exits 0.2 s after SIGINT on a
                # quiet machine, and once took over 30 s on a heavily loaded one.
                codes.append(process.stop(timeout=120))
            except subprocess.TimeoutExpired:
                process.kill()
                codes.append(None)
        assert codes[0] == 0, controller.stderr
        assert codes[1] == 0, stage.stderr
    runs = []
    for name in ("loop_1.mcap", "loop_2.mcap"):
        log = read_log(stage.cwd / name)
        out = [(m.log_time_ns, m.message.data) for m in log.messages_on("/output/displacement")]
        meas = [(m.log_time_ns, m.message.data) for m in log.messages_on("/output/measured")]
        cmds = [(m.log_time_ns, m.message.data) for m in log.messages_on("/drive/displacement")]
        runs.append((out, meas, cmds))
    assert runs[0] == runs[1]  # bit for bit, times included
    out, meas, cmds = runs[0]
    assert len(out) == len(meas) == TICKS
    # Each command answered the measurement of tick k and was applied at tick k + 1: it is
    # recorded at the start of tick k + 1, the time of tick k's measurement.
    assert [t for t, _ in cmds] == [t for t, _ in meas[:-1]]
    y = np.array([v for _, v in out])
    # Settled: the last 50 ms within 1 % of the setpoint, the mean within 0.1 %.
    assert np.all(np.abs(y[-50:] - SETPOINT) < 0.01 * SETPOINT), y[-50:]
    assert abs(np.mean(y[-50:]) - SETPOINT) < 1e-3 * SETPOINT
    assert y[0] < 0.2 * SETPOINT  # it did start from rest
