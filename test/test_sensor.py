"""
The output sensor (engine/actuators/sensor.py) without ROS, against closed forms.

The first-order step response 1 - exp(-t/tau), exact latency, quantisation, seeded noise; and the
``sensor:`` block's validation.
"""
from __future__ import annotations

import math

import numpy as np
import pytest
import yaml

from flexure_sim.engine.mechanism.loader import (
    ConfigError, mechanism_from_dict, resolve_mechanism_path,
)
from flexure_sim.engine.actuators.sensor import Sensor, SensorSpec

T = 1e-3


def run(spec: SensorSpec, xs, period: float = T) -> np.ndarray:
    sensor = Sensor(spec, period)
    return np.array([sensor.sample(float(x)) for x in xs])


def test_bandwidth_step_response_is_the_continuous_first_order_response_at_each_tick():
    f_c = 150.0
    tau = 1.0 / (2.0 * math.pi * f_c)
    j = 5
    xs = np.r_[np.zeros(j), np.ones(60)]
    y = run(SensorSpec(bandwidth=f_c), xs)
    assert np.all(y[:j] == 0.0)
    t = (np.arange(len(xs) - j) + 1) * T  # the end of each tick since the step
    np.testing.assert_allclose(y[j:], 1.0 - np.exp(-t / tau), rtol=0, atol=1e-14)


def test_bandwidth_follows_a_new_period():
    sensor = Sensor(SensorSpec(bandwidth=100.0), T)
    sensor.sample(0.0)
    sensor.set_period(2e-3)
    expected = 1.0 - math.exp(-2e-3 * 2 * math.pi * 100.0)
    assert sensor.sample(1.0) == pytest.approx(expected, abs=1e-15)


def test_latency_delays_by_exactly_that_many_ticks():
    xs = np.arange(1.0, 21.0)
    y = run(SensorSpec(latency=3), xs)
    assert list(y) == [1.0, 1.0, 1.0] + list(xs[:-3])
    assert list(run(SensorSpec(latency=0), xs)) == list(xs)


def test_resolution_rounds_to_the_nearest_multiple():
    q = 1e-9
    xs = np.linspace(-5e-9, 5e-9, 1001)
    y = run(SensorSpec(resolution=q), xs)
    k = y / q
    assert np.all(np.abs(k - np.round(k)) < 1e-9)
    assert np.all(np.abs(y - xs) <= q / 2 * (1 + 1e-9))


def test_noise_is_seeded_gaussian_and_reset_restarts_it():
    spec = SensorSpec(noise_rms=2e-9, seed=11)
    zeros = np.zeros(20000)
    a = run(spec, zeros)
    b = run(spec, zeros)
    assert a.tobytes() == b.tobytes()
    assert run(SensorSpec(noise_rms=2e-9, seed=12), zeros[:10]).tobytes() != a[:10].tobytes()
    sensor = Sensor(spec, T)
    first = [sensor.sample(0.0) for _ in range(10)]
    sensor.reset()
    assert [sensor.sample(0.0) for _ in range(10)] == first == list(a[:10])
    # Sample RMS of N normal draws: relative standard deviation 1/sqrt(2N) (0.5 % here);
    # the bound is 5 of them.
    rms = math.sqrt(float(np.mean(a**2)))
    assert abs(rms / 2e-9 - 1.0) < 5 / math.sqrt(2 * len(a))


def stage(sensor) -> dict:
    data = yaml.safe_load(resolve_mechanism_path("microstage").read_text())
    data["sensor"] = sensor
    return data


def test_sensor_block_is_parsed_and_bad_values_name_the_key():
    block = {"noise_rms": 1e-9, "latency": 2, "bandwidth": 5000.0}
    mech = mechanism_from_dict(stage(block), "s.yaml")
    assert mech.sensor == SensorSpec(noise_rms=1e-9, latency=2, bandwidth=5000.0)
    assert mechanism_from_dict(stage({}), "s.yaml").sensor == SensorSpec()
    for bad, message in [
        ({"latency": 1.5}, "s.yaml: sensor.latency: expected an integer >= 0, got 1.5"),
        ({"seed": -1}, "s.yaml: sensor.seed: expected an integer >= 0, got -1"),
        ({"noise_rms": -1e-9}, "s.yaml: sensor.noise_rms: must not be negative"),
        ({"bandwidth": float("nan")}, "s.yaml: sensor.bandwidth: must be finite"),
        ({"resolution": "fine"}, "s.yaml: sensor.resolution: expected a number"),
        ({"gain": 2}, "s.yaml: sensor.gain: unknown key"),
        ([1, 2], "s.yaml: sensor: expected a mapping"),
    ]:
        with pytest.raises(ConfigError) as info:
            mechanism_from_dict(stage(bad), "s.yaml")
        assert str(info.value).startswith(message), str(info.value)
    no_output = stage({"noise_rms": 1e-9})
    del no_output["output"], no_output["compression_hinge"]
    with pytest.raises(ConfigError, match="s.yaml: sensor: needs an output"):
        mechanism_from_dict(no_output, "s.yaml")
