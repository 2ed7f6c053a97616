"""
The output sensor in a real stage_node.

`output/measured` published and recorded per tick next to the true `output/displacement`, measured
back from the recording (fast mode).

Statistical tolerances: the sample RMS s of N independent normal draws of RMS sigma has a
relative standard deviation of 1/sqrt(2N) (var(s^2) = 2 sigma^4 / N, delta method); the
bounds below are 5 of those. Quantisation error of a signal whose noise sigma is twice the
step q is uniform on [-q/2, q/2] to within exp(-2 pi^2 sigma^2 / q^2) ~ 1e-34 (Widrow's
quantisation theorem), independent of the noise, so measured - true has variance
sigma^2 + q^2 / 12.
"""
from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
import yaml
from rclpy.serialization import serialize_message
from scipy import signal
from std_msgs.msg import Float64

from flexure_sim.engine.mechanism.loader import load_mechanism, resolve_mechanism_path
from flexure_sim.engine.actuators.sensor import SensorSpec
from flexure_sim.node.publish.interface import StageInterface
from flexure_sim.engine.solver.simulation import Simulation
from flexure_sim.recording.reader import open_reader

from node_harness import NodeProcess, Peer

TICKS = 3000


def stage_file(path, sensor: dict) -> str:
    data = yaml.safe_load(resolve_mechanism_path("microstage").read_text())
    data["sensor"] = sensor
    path.write_text(yaml.safe_dump(data))
    return str(path)


def recorded_run(tmp_path, domain, sensor: dict, command: float = 1.0e-6,
                 after_step: int | None = None):
    """
    Return output/displacement and output/measured of one fast-mode run.

    With a drive step early on, from the node's recording, as arrays aligned by log time. The
    run lasts TICKS ticks, or (``after_step``) until the measurement has shown the step and
    ``after_step`` more ticks were received.
    """
    mech = stage_file(tmp_path / "stage.yaml", sensor)
    node = NodeProcess(tmp_path / "node", domain, dict(
        mechanism=mech, time_mode="fast", publish_rate=1000.0, sim_step=1e-4, record=True,
        record_path="run.mcap"))
    peer = Peer(domain)
    peer.watch = node
    try:
        peer.subscribe("/output/measured", Float64, depth=100000)
        drive = peer.publisher("/drive/displacement", Float64)
        peer.wait_for_publishers(["/output/measured"])
        peer.wait_for_subscribers(drive)
        drive.publish(Float64(data=command))
        if after_step is None:
            peer.spin_until(lambda: len(peer.received["/output/measured"]) > TICKS, 120,
                            "measurements")
        else:
            received = peer.received["/output/measured"]
            moved: list[int] = []  # index of the first reading that differs from the first

            def settled_after_step() -> bool:
                if not moved:
                    moved.extend(k for k, (m, _) in enumerate(received)
                                 if abs(m.data - received[0][0].data) > 1e-15)
                    del moved[1:]
                # (TICKS at the most: a subscriber that missed the step's start still ends.)
                return (bool(moved) and len(received) > moved[0] + after_step
                        or len(received) > TICKS)

            peer.spin_until(settled_after_step, 120, f"the step and {after_step} ticks after it")
        peer.watch = None
        assert node.stop() == 0, node.stderr
    finally:
        peer.close()
        node.kill()
    # Only the two topics are decoded (the run's other ~30 topics per tick took 10 s to decode).
    true, meas = {}, {}
    by_topic = {"/output/displacement": true, "/output/measured": meas}
    for m in open_reader(node.cwd / "run.mcap").messages(lambda t: t.name in by_topic):
        by_topic[m.topic][m.log_time_ns] = m.message.data
    assert sorted(true) == sorted(meas)  # one reading per tick, at the tick's time
    times = sorted(true)
    assert len(times) >= (TICKS if after_step is None else after_step)
    return np.array([true[t] for t in times]), np.array([meas[t] for t in times])


def test_interface_publishes_measured_after_output_packed_like_serialize_message():
    mech = dataclasses.replace(load_mechanism("microstage"), sensor=SensorSpec(noise_rms=1e-9))
    snap = Simulation(mech).static(1.35e-6).snapshot
    itf = StageInterface(mech, "fast")
    names = [t.name for t in itf.tick_topics]
    assert names.index("output/measured") == names.index("output/displacement") + 1
    packed = itf.encode(snap, 12_345, measured=3.25e-6)
    reference = itf.messages(snap, 12_345, measured=3.25e-6)
    i = names.index("output/measured")
    assert reference[i] == Float64(data=3.25e-6)
    assert packed[i] == serialize_message(reference[i])
    plain = StageInterface(load_mechanism("microstage"))
    assert "output/measured" not in [t.name for t in plain.tick_topics]


def test_recorded_latency_is_exact_and_bandwidth_is_the_zoh_first_order_filter(tmp_path, domain):
    f_c, latency = 200.0, 3
    # 200 ticks after the step: 250 filter time constants, the stage settled long before.
    true, meas = recorded_run(tmp_path, domain, {"bandwidth": f_c, "latency": latency},
                              after_step=200)
    assert true[-1] > 1e-5  # the stage moved
    # Independent reference: scipy's zero-order-hold discretisation of 1 / (tau s + 1).
    tau = 1.0 / (2 * math.pi * f_c)
    num, den, _ = signal.cont2discrete(([1.0], [tau, 1.0]), 1e-3, method="zoh")
    # scipy: y_k = -a1 y_{k-1} + b1 x_{k-1}; the sensor filters x_k, the value at the end of
    # tick k (held over it), so drop the leading zero of num. Started settled at x_0.
    b = np.ravel(num)[1:]
    zi = signal.lfiltic(b, den, y=[true[0]])
    reference = signal.lfilter(b, den, true, zi=zi)[0]
    expected = np.r_[np.full(latency, reference[0]), reference[:-latency]]
    np.testing.assert_allclose(meas, expected, rtol=0, atol=1e-12 * abs(true).max())
    # The step's first visible change comes exactly `latency` ticks after the true one.
    first_true = int(np.argmax(np.abs(true - true[0]) > 1e-12))
    first_meas = int(np.argmax(np.abs(meas - meas[0]) > 1e-15))
    assert first_meas == first_true + latency


def test_recorded_noise_rms_and_quantisation_equal_the_configured_values(tmp_path, domain):
    sigma, q = 2.0e-9, 1.0e-9
    true, meas = recorded_run(tmp_path, domain, {"noise_rms": sigma, "resolution": q, "seed": 5})
    k = meas / q
    assert np.all(np.abs(k - np.round(k)) < 1e-6)  # every reading a multiple of q
    err = meas - true
    n = len(err)
    expected = math.sqrt(sigma**2 + q**2 / 12)
    rms = math.sqrt(float(np.mean(err**2)))
    assert abs(rms / expected - 1.0) < 5 / math.sqrt(2 * n), (rms, expected)
    assert abs(float(np.mean(err))) < 5 * expected / math.sqrt(n)
    # The quantisation step seen in the data: the smallest non-zero difference of readings.
    steps = np.abs(np.diff(meas))
    assert np.min(steps[steps > 0]) == pytest.approx(q, rel=1e-6)
