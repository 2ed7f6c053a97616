"""
pi_controller as users start it (`ros2 run flexure_sim pi_controller`, installed).

One command per measurement, the setpoint topic followed, the law's answer (checked against the
pure law), one-line errors. The closed loop with the stage: test_closed_loop.py.
"""
from __future__ import annotations

import math
import signal
import subprocess
import sys

import pytest
from std_msgs.msg import Float64

from flexure_sim.control.pi_notch import PIConfig, PIController

from node_harness import ROOT, NodeProcess, Peer, next_domain_id, node_env
from test_node_launch import PACKAGE, ament_prefix_path, bare_env, ros2_run_lookup


def test_ros2_run_pi_controller_answers_each_measurement_once_and_follows_the_setpoint(tmp_path):
    domain = next_domain_id()
    exe = ros2_run_lookup(PACKAGE, "pi_controller", ament_prefix_path())
    params = {"kp": 0.01, "ki": 20, "measurement_topic": "output/displacement"}
    node = NodeProcess(tmp_path, domain, params, command=[str(exe)],
                       env=bare_env(domain, tmp_path))
    peer = Peer(domain)
    peer.watch = node
    try:
        peer.subscribe("/drive/displacement", Float64)
        measurement = peer.publisher("/output/displacement", Float64)
        setpoint = peer.publisher("/setpoint", Float64)
        peer.wait_for_subscribers(measurement, timeout=30)
        peer.wait_for_subscribers(setpoint, timeout=30)
        setpoint.publish(Float64(data=1.0e-5))
        # The setpoint and the measurements come from two writers: wait for the setpoint's
        # effect (a non-zero command) before counting.
        peer.spin_until(lambda: _answer_to(peer, measurement, 0.0) > 0.0, 30, "the setpoint")
        start = len(peer.received["/drive/displacement"])
        # One at a time: the controller keeps only the newest measurement (keep last 1).
        for y in (2e-6, 4e-6, 6e-6):
            _answer_to(peer, measurement, y)
        peer.spin_for(0.2)  # nothing more arrives: one command per measurement
        commands = [m.data for m in peer.messages("/drive/displacement")]
    finally:
        peer.close()
        rc = node.stop(signal.SIGINT)
    assert rc == 0, node.stderr
    assert len(commands) == start + 3
    # The pure law fed the same inputs: probes answered before the setpoint arrived had zero
    # error (command 0, integral unchanged); those after it had error 1e-5.
    law = PIController(PIConfig(0.01, 20.0, 1e-3, 0.0, 2e-6))
    for c in commands[:start]:
        if c != 0.0:
            assert c == law.update(1.0e-5, 0.0)
    assert commands[start:] == [law.update(1.0e-5, y) for y in (2e-6, 4e-6, 6e-6)]


def _answer_to(peer: Peer, measurement, y: float) -> float:
    """Publish one measurement, return the command that answers it."""
    n = len(peer.received["/drive/displacement"])
    measurement.publish(Float64(data=y))
    peer.spin_until(lambda: len(peer.received["/drive/displacement"]) > n, 30, "a command")
    return peer.last("/drive/displacement").data


def test_invalid_parameters_stop_it_with_one_line(tmp_path):
    domain = next_domain_id()
    exe = ros2_run_lookup(PACKAGE, "pi_controller", ament_prefix_path())
    result = subprocess.run(
        [str(exe), "--ros-args", "-p", "command_min:=1.0e-6", "-p", "command_max:=0.0"],
        env=bare_env(domain, tmp_path), capture_output=True, text=True, timeout=60)
    assert result.returncode == 1
    assert result.stderr.strip().splitlines()[-1] == (
        "pi_controller: error: invalid parameters: command_min 1e-06 exceeds command_max 0.0")
    assert "Traceback" not in result.stderr


def _source_controller(tmp_path, domain: int, params: dict) -> NodeProcess:
    """pi_controller of this checkout (python -m), in its own DDS domain."""
    return NodeProcess(tmp_path, domain, params,
                       command=[sys.executable, "-m", "flexure_sim.node.apps.pi_controller"])


def test_a_nan_setpoint_or_measurement_is_refused_and_the_loop_recovers(tmp_path):
    """
    A NaN or inf on either topic: a WARN naming the topic and value, the last command repeated.

    The commands answering the good measurements equal the PI law stepped by hand over the good
    measurements only (u = kp e + I, I += ki T e; no notch, limits far away): nothing of the
    refused inputs reached the integral.
    """
    domain = next_domain_id()
    kp, ki, period, r = 0.01, 20.0, 1e-3, 1.0e-5
    node = _source_controller(tmp_path, domain, {
        "kp": kp, "ki": ki, "command_max": 1.0, "setpoint": r,
        "measurement_topic": "output/displacement"})
    peer = Peer(domain)
    peer.watch = node
    try:
        peer.subscribe("/drive/displacement", Float64)
        measurement = peer.publisher("/output/displacement", Float64)
        setpoint = peer.publisher("/setpoint", Float64)
        peer.wait_for_subscribers(measurement, timeout=30)
        peer.wait_for_subscribers(setpoint, timeout=30)
        setpoint.publish(Float64(data=math.nan))
        node.wait_for_output("refused a non-finite value nan on /setpoint", timeout=30)
        answers = [_answer_to(peer, measurement, y)
                   for y in (2e-6, math.nan, math.inf, 4e-6, -math.inf, 6e-6)]
        node.wait_for_output("refused a non-finite value nan on /output/displacement",
                             timeout=30)
    finally:
        peer.close()
        rc = node.stop(signal.SIGTERM)  # ends it as SIGINT does (the other tests)
    assert rc == 0, node.stderr
    integral, expected = 0.0, []
    for y in (2e-6, 4e-6, 6e-6):
        e = r - y
        integral += ki * period * e
        expected.append(kp * e + integral)
    good = [answers[0], answers[3], answers[5]]
    assert good == pytest.approx(expected, rel=1e-12, abs=0.0)
    # A refused measurement is answered with the last command (one answer per measurement).
    assert answers[1] == answers[2] == answers[0]
    assert answers[4] == answers[3]
    assert all(math.isfinite(a) for a in answers)


@pytest.mark.parametrize("name, value", [("setpoint", ".nan"), ("kp", ".inf"),
                                         ("command_max", "-.inf"), ("ki", "abc")])
def test_a_non_finite_or_non_numeric_start_parameter_is_refused_by_name(tmp_path, name, value):
    result = subprocess.run(
        [sys.executable, "-m", "flexure_sim.node.apps.pi_controller", "--ros-args",
         "-p", f"{name}:={value}"],
        env=node_env(next_domain_id(), PYTHONPATH=str(ROOT),
                     ROS_LOG_DIR=str(tmp_path / "ros_log")),
        capture_output=True, text=True, timeout=60)
    assert result.returncode == 1, result.stderr
    last = result.stderr.strip().splitlines()[-1]
    assert last.startswith(f"pi_controller: error: invalid parameters: {name} must be "), last
    assert "Traceback" not in result.stderr


@pytest.mark.parametrize("name, value", [("measurement_topic", "a b"),
                                         ("setpoint_topic", "/9x"), ("command_topic", "x//y")])
def test_an_invalid_topic_name_is_refused_naming_the_parameter(tmp_path, name, value):
    result = subprocess.run(
        [sys.executable, "-m", "flexure_sim.node.apps.pi_controller", "--ros-args",
         "-p", f"{name}:={value}"],
        env=node_env(next_domain_id(), PYTHONPATH=str(ROOT),
                     ROS_LOG_DIR=str(tmp_path / "ros_log")),
        capture_output=True, text=True, timeout=60)
    assert result.returncode == 1, result.stderr
    lines = result.stderr.strip().splitlines()
    assert lines[-1].startswith(
        f"pi_controller: error: invalid parameter {name}: {value!r} is not a valid topic "
        "name ("), result.stderr
    assert "Exception" not in result.stderr
