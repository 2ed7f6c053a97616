"""
A displacement sensor on the mechanism's output (a capacitive gauge).

bandwidth, noise, resolution and latency, sampled once per publish tick.

The chain, per tick k of period T (the true output x_k is the value at the end of the tick):

1. bandwidth: a first-order low-pass, tau dy/dt = x - y, with tau = 1 / (2 pi f_c) (f_c the
   -3 dB bandwidth, Hz). Discretised exactly for an input held over the tick (zero-order
   hold): y_k = a y_{k-1} + (1 - a) x_k, a = exp(-T / tau). The filter starts settled at the
   first sample (y_{-1} = x_0); a unit step from tick j on (x_k = 0 before, 1 from j) gives
   y_k = 1 - exp(-(k - j + 1) T / tau): the continuous step response at the tick's end.
   ``bandwidth`` 0: no filter.
2. noise: y_k + n_k, n_k ~ N(0, noise_rms^2) independent per tick, drawn from NumPy's PCG64
   generator seeded with ``seed`` (same seed, same sequence; `reset` restarts it). The noise
   is the sensor's output noise within its bandwidth, so it is added after the filter.
3. resolution: quantised to the nearest multiple of ``resolution`` q (mid-tread rounding, the
   error within +-q/2); 0: not quantised.
4. latency: the reading of tick k is published at tick k + L (``latency`` L ticks); before
   tick L the first reading is repeated. The delay line holds the readings not yet published,
   at most L + 1 (it grows with the ticks run, not with L), and L is at most ``MAX_LATENCY``.

Pure NumPy, no ROS: the node calls `Sensor.sample` once per tick.
"""
from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass
from typing import Optional

import numpy as np

#: Longest latency (ticks): 1000 s at 1 kHz; its delay line holds ~32 MB of readings.
MAX_LATENCY = 1_000_000


@dataclass(frozen=True)
class SensorSpec:
    """
    Configuration of the output sensor (mechanism file block ``sensor:``).

    noise_rms: m, >= 0; resolution: m, >= 0 (0: none); bandwidth: Hz, >= 0 (0: unlimited);
    latency: ticks, integer >= 0; seed: integer >= 0 of the noise generator.
    """

    noise_rms: float = 0.0
    resolution: float = 0.0
    bandwidth: float = 0.0
    latency: int = 0
    seed: int = 0


def lowpass_pole(bandwidth: float, period: float) -> float:
    """
    Return the pole a = exp(-T / tau), tau = 1 / (2 pi f_c).

    It is the exact zero-order-hold discretisation of a first-order low-pass of bandwidth f_c
    (Hz) at sample period T (s). 0 when f_c is 0 (no filter: y_k = x_k).
    """
    if bandwidth <= 0.0:
        return 0.0
    return math.exp(-2.0 * math.pi * bandwidth * period)


class Sensor:
    """The stateful sensor of one run: `sample` once per tick, `reset` for a new run."""

    def __init__(self, spec: SensorSpec, period: float) -> None:
        if not period > 0.0:
            raise ValueError(f"period: must be positive, got {period!r}")
        self.spec = spec
        self.set_period(period)
        self.reset()

    def set_period(self, period: float) -> None:
        """Take a new tick period (publish rate changed): the filter's pole follows."""
        self.period = period
        self._a = lowpass_pole(self.spec.bandwidth, period)

    def reset(self) -> None:
        """Back to the state before the first sample (the noise sequence restarts)."""
        self._rng = np.random.Generator(np.random.PCG64(self.spec.seed))
        self._y: Optional[float] = None
        self._delay: deque[float] = deque()

    def sample(self, x: float) -> float:
        """Return the reading published at this tick, for the true output ``x`` (m) at its end."""
        spec = self.spec
        a = self._a
        y = x if self._y is None else a * self._y + (1.0 - a) * x
        self._y = y
        if spec.noise_rms > 0.0:
            y = y + spec.noise_rms * float(self._rng.standard_normal())
        if spec.resolution > 0.0:
            y = spec.resolution * round(y / spec.resolution)
        delay = self._delay
        delay.append(y)
        if len(delay) > spec.latency:
            return delay.popleft()
        return delay[0]  # before tick L: the first reading
