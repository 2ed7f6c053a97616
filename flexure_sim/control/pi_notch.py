"""
A discrete PI controller with an optional notch filter and anti-windup.

One update per sample of period T (the stage's tick).

Per sample k, with error e_k = setpoint - measurement:

1. notch (optional) at f_0 Hz: the biquad N(z) obtained from
       N(s) = (s^2 + 2 d zeta w0 s + w0^2) / (s^2 + 2 zeta w0 s + w0^2),  w0 = 2 pi f_0,
   by the bilinear transform s = K (z - 1) / (z + 1) with K = w0 / tan(w0 T / 2) (pre-warped,
   so the notch sits exactly at f_0). zeta sets the width (the -3 dB band is about
   2 zeta f_0 wide), d the depth: |N| at f_0 is exactly d (0: a full notch, 1: no notch).
   |N| is 1 at DC and towards Nyquist. Implemented in transposed direct form II.
2. PI on the filtered error f_k: I_k = I_{k-1} + ki T f_k (backward-Euler integral),
   u_k = kp f_k + I_k; in z: C(z) = kp + ki T z / (z - 1).
3. limits and anti-windup (clamped integration): if the unclamped u_k lies beyond u_max and
   f_k > 0, the integral becomes max(I_{k-1}, u_max - kp f_k) -- it integrates up to the limit
   and no further (likewise at u_min with f_k < 0, min); the command is u_k clipped into
   [u_min, u_max]. Without saturation the law is exactly C(z) N(z).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from flexure_sim.errors import FlexureSimError


@dataclass(frozen=True)
class PIConfig:
    """
    Gains and limits.

    kp: command per error (m/m of output); ki: 1/s; period: T (s); u_min, u_max: command limits
    (m); notch_frequency: Hz (0: no notch), below the Nyquist frequency 1 / (2 T); notch_damping:
    zeta > 0; notch_depth: d in [0, 1].
    """

    kp: float
    ki: float
    period: float
    u_min: float
    u_max: float
    notch_frequency: float = 0.0
    notch_damping: float = 0.1
    notch_depth: float = 0.0

    def problem(self) -> str:
        """Why this configuration cannot be used ("" if it can)."""
        for name, value in (("kp", self.kp), ("ki", self.ki), ("period", self.period),
                            ("command_min", self.u_min), ("command_max", self.u_max),
                            ("notch_frequency", self.notch_frequency),
                            ("notch_damping", self.notch_damping),
                            ("notch_depth", self.notch_depth)):
            if not math.isfinite(value):
                return f"{name} must be finite, got {value!r}"
        if self.period <= 0.0:
            return f"period must be positive, got {self.period!r}"
        if self.kp < 0.0 or self.ki < 0.0:
            return "kp and ki must not be negative"
        if self.u_min > self.u_max:
            return f"command_min {self.u_min!r} exceeds command_max {self.u_max!r}"
        if self.notch_frequency < 0.0 or self.notch_frequency >= 0.5 / self.period:
            return (f"notch_frequency must be in [0, {0.5 / self.period:g}) Hz (0: off; below "
                    f"the Nyquist frequency of the {self.period:g} s period), got "
                    f"{self.notch_frequency!r}")
        if self.notch_damping <= 0.0:
            return f"notch_damping must be positive, got {self.notch_damping!r}"
        if not 0.0 <= self.notch_depth <= 1.0:
            return f"notch_depth must be in [0, 1], got {self.notch_depth!r}"
        return ""


Coefficients = tuple[float, float, float]


class NonFiniteInput(FlexureSimError, ValueError):
    """A setpoint or measurement is NaN or infinite (refused; the state is untouched)."""


def notch_coefficients(frequency: float, damping: float, depth: float,
                       period: float) -> tuple[Coefficients, Coefficients]:
    """(b, a) of the pre-warped bilinear transform of N(s) (module docstring), a[0] = 1."""
    w0 = 2.0 * math.pi * frequency
    k = w0 / math.tan(0.5 * w0 * period)
    kk, ww = k * k, w0 * w0
    bz, az = 2.0 * depth * damping * w0 * k, 2.0 * damping * w0 * k
    a0 = kk + az + ww
    b = ((kk + bz + ww) / a0, 2.0 * (ww - kk) / a0, (kk - bz + ww) / a0)
    a = (1.0, 2.0 * (ww - kk) / a0, (kk - az + ww) / a0)
    return b, a


class Biquad:
    """
    y_k = b0 x_k + b1 x_{k-1} + b2 x_{k-2} - a1 y_{k-1} - a2 y_{k-2} (transposed direct form II).

    Starting at rest.
    """

    def __init__(self, b: Coefficients, a: Coefficients) -> None:
        self.b, self.a = b, a
        self.reset()

    def reset(self) -> None:
        self._s1 = self._s2 = 0.0

    def __call__(self, x: float) -> float:
        b0, b1, b2 = self.b
        _, a1, a2 = self.a
        y = b0 * x + self._s1
        self._s1 = b1 * x - a1 * y + self._s2
        self._s2 = b2 * x - a2 * y
        return y


class PIController:
    """The law of the module docstring; `update` once per sample, `reset` for a new run."""

    def __init__(self, config: PIConfig) -> None:
        problem = config.problem()
        if problem:
            raise ValueError(problem)
        self.config = config
        self.notch: Biquad | None = None
        if config.notch_frequency > 0.0:
            self.notch = Biquad(*notch_coefficients(config.notch_frequency, config.notch_damping,
                                                    config.notch_depth, config.period))
        self.reset()

    def reset(self) -> None:
        self.integral = 0.0
        if self.notch is not None:
            self.notch.reset()

    def rest_command(self) -> float:
        """Return the command at rest (zero, clipped into the limits)."""
        return min(max(0.0, self.config.u_min), self.config.u_max)

    def update(self, setpoint: float, measurement: float) -> float:
        """
        Return the command for this sample, given the setpoint and the measurement (m).

        A non-finite setpoint or measurement raises `NonFiniteInput` before any state changes:
        the integral and the notch never hold a NaN, so the next finite sample gives a finite
        command.
        """
        for name, value in (("setpoint", setpoint), ("measurement", measurement)):
            if not math.isfinite(value):
                raise NonFiniteInput(f"{name} {value!r} is not finite")
        c = self.config
        f = setpoint - measurement
        if self.notch is not None:
            f = self.notch(f)
        integral = self.integral + c.ki * c.period * f
        u = c.kp * f + integral
        # Anti-windup: integrate only up to the limit, never further out than before.
        if u > c.u_max and f > 0.0:
            integral = max(self.integral, c.u_max - c.kp * f)
            u = c.kp * f + integral
        elif u < c.u_min and f < 0.0:
            integral = min(self.integral, c.u_min - c.kp * f)
            u = c.kp * f + integral
        self.integral = integral
        return min(max(u, c.u_min), c.u_max)
