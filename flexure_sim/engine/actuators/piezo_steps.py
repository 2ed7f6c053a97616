"""
The piezo actuators of a ``Model`` over n steps of a held command, in one compiled call.

The actuators' states do not depend on the stage (actuators/piezo.py: one-way coupling), so under a
held command their whole trajectory over n steps comes first, then the stage's n steps run in one
call of the stepping loop with each step's kernel command (solver/actuation.py). Each step is the
split of solver/actuation.py: the state after the step is `piezo.advance_values` (P2, P4, P5) and
the free stroke the stage sees over it the mean x_h = (x_a(t+) + x_a(t + h)) / 2 of its values
after the start's jump (`piezo.jump_values`, unlimited bandwidth only) and at the end (P6).
The same compiled functions step one actuator in `piezo.advance` and `piezo.jump`: one source.
"""
from __future__ import annotations

import numpy as np

from flexure_sim.engine import jit as kernel_cache
from flexure_sim.engine.actuators import piezo
from flexure_sim.engine.jit import njit
from flexure_sim.engine.actuators.piezo import advance_values, jump_values, stroke_kernel

#: Columns of ``Actuators.numbers``: tau_a (0: no lag), a = alpha d, beta, gamma, d, v_min, s_min.
TAU, A, BETA, GAMMA, GAIN, V_MIN, S_MIN = range(7)


class Actuators:
    """The numbers of a model's actuators (``DriveTable.actuation``) as arrays for `trajectory`."""

    def __init__(self, actuation) -> None:
        specs = [a.spec for a in actuation]
        self.specs = specs
        #: One row per actuator: the columns ``TAU`` .. ``S_MIN``.
        self.numbers = np.array([[s.tau_amplifier, s.alpha * s.gain, s.beta, s.gamma, s.gain,
                                  s.v_min, s.s_min] for s in specs], dtype=float).reshape(-1, 7)
        #: Actuator j's states are offsets[j]:offsets[j + 1] of the stacked state vector.
        self.offsets = np.array([a.states.start for a in actuation]
                                + [actuation[-1].states.stop if actuation else 0], dtype=np.int64)
        #: Creep ratios and taus, aligned with the stacked state (0 and 1 on V_a and h).
        self.ratios = np.zeros(int(self.offsets[-1]))
        self.taus = np.ones(int(self.offsets[-1]))
        for a in actuation:
            ratios, taus = piezo.creep_arrays(a.spec)
            self.ratios[a.states.start + 2:a.states.stop] = ratios
            self.taus[a.states.start + 2:a.states.stop] = taus

    def run(self, n: int, states: np.ndarray, volts: np.ndarray, dt: float):
        """Return (states after n steps, the (n, actuators) held strokes): `trajectory`."""
        if not dt > 0:
            raise ValueError(f"dt: must be positive, got {dt!r}")
        return trajectory(int(n), np.array(states, dtype=float), np.asarray(volts, dtype=float),
                          float(dt), self.numbers, self.offsets, self.ratios, self.taus)


@njit(cache=True)
def trajectory(n, states, volts, dt, numbers, offsets, ratios, taus):
    """
    Return the actuators' states after n steps under the held ``volts`` and each step's strokes.

    Per step and actuator j (numbers[j]: ``TAU`` .. ``S_MIN``): start = the state, after
    `piezo.jump_values` to volts[j] without a lag; after = `piezo.advance_values`; the held
    stroke (x_a(start) + x_a(after)) / 2 (P6, `piezo.stroke_kernel`).
    """
    m = numbers.shape[0]
    strokes = np.empty((n, m))
    x = states.copy()
    for i in range(n):
        for j in range(m):
            lo, hi = offsets[j], offsets[j + 1]
            tau, a, beta = numbers[j, TAU], numbers[j, A], numbers[j, BETA]
            gamma = numbers[j, GAMMA]
            gain, v_min, s_min = numbers[j, GAIN], numbers[j, V_MIN], numbers[j, S_MIN]
            xs = x[lo:hi].copy()
            start = xs if tau > 0.0 else jump_values(xs, volts[j], a, beta, gamma)
            after = advance_values(xs, volts[j], dt, tau, a, beta, gamma, gain, v_min,
                                   ratios[lo + 2:hi], taus[lo + 2:hi])
            strokes[i, j] = 0.5 * (stroke_kernel(start, s_min, gain, v_min)
                                   + stroke_kernel(after, s_min, gain, v_min))
            x[lo:hi] = after
    return x, strokes


# Numba's cache of each kernel is keyed on its own file only (``kernel_cache``).
kernel_cache.revalidate([trajectory], __file__)
