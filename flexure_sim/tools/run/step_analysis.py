"""
Step detection and step-response metrics: pure functions on NumPy arrays (no files, no ROS).

Definitions (used by ``flexure-sim analyse`` and documented in docs/tools.md):

- A **step** is a change of the drive *command* (`command_steps`): non-finite commands are
  ignored (the node rejects them), commands outside the stroke count as clamped to it, and
  commands that leave the target unchanged are no step. Without a recorded command the steps
  are found in the applied drive input instead (`input_steps`).
- A step's **window** runs from its onset ``t0`` to the next step's onset (or the end of the
  run). Samples stamped ``t <= t0`` are before the step: the node applies a command at the
  start of a tick and stamps the tick's messages at its end.
- **Settled values**: before the step, the last sample at or before ``t0``; after it, the
  last sample of the window.
- **Settling time** (band 2 %): time from ``t0`` until the signal enters, for good, the band
  of +-2 % of its change around its final value; the crossing is interpolated linearly
  between samples (the value at ``t0`` is the settled value before the step). A first-order
  lag settles in tau ln 50 = 3.912 tau.
- **Overshoot**: largest excursion beyond the final value, in the direction of the change,
  as a fraction of the change (0 if none); exp(-pi zeta / sqrt(1 - zeta^2)) for a
  second-order system.
- **Rise time**: 10 % to 90 % of the change (tau ln 9 for a first-order lag).
- A response is **settled** when it entered the band and stayed in it for at least the last
  ``hold`` fraction (default 20 %) of its window; only then is a gain reported.
- **Gain** of a step: (output change) / (input change), both between settled values.
- **Peaks**: the signed sample of largest magnitude in the window (transients included).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Mapping, Optional, Sequence

import numpy as np

from flexure_sim.tools.run.response_metrics import (
    DEFAULT_BAND, DEFAULT_HOLD, peak, sample_arrays, step_response,
)


@dataclass(frozen=True)
class Step:
    """
    One step of the drive.

    Onset time ``t`` (s), command ``target`` after it and the target before it (m).
    """

    t: float
    target: float
    previous: float


# ---------------------------------------------------------------------------- step detection
def command_steps(
    t: Sequence[float],
    command: Sequence[float],
    initial: float = 0.0,
    stroke: Optional[tuple[float, float]] = None,
    tolerance: float = 0.0,
) -> list[Step]:
    """
    Step of a command signal (times ``t``, values ``command``).

    ``initial``: the target before the first command. ``stroke``: (min, max) the commands
    are clamped to. A command changes the target when it differs from it by more than
    ``tolerance``; several commands at one time count as the last of them.
    """
    t, c = sample_arrays(t, command, "command")
    steps: list[Step] = []
    target = float(initial)
    i, n = 0, t.shape[0]
    while i < n:
        j = i
        while j + 1 < n and t[j + 1] == t[i]:
            j += 1
        value = None
        for k in range(i, j + 1):
            if math.isfinite(c[k]):
                value = float(c[k])
        i = j + 1
        if value is None:
            continue
        if stroke is not None:
            value = min(max(value, stroke[0]), stroke[1])
        if abs(value - target) > tolerance:
            steps.append(Step(float(t[j]), value, target))
            target = value
    return steps


def input_steps(t: Sequence[float], u: Sequence[float], rel_tolerance: float = 1e-4) -> list[Step]:
    """
    Step recovered from the applied drive input when the command was not recorded.

    A step starts where the input moves by more than ``rel_tolerance`` of its range between
    two samples (its onset is the sample before), and ends where it stops moving; the target
    is the value it comes to rest at. A steady ramp counts as one step.
    """
    t, u = sample_arrays(t, u, "u")
    if t.shape[0] < 2:
        return []
    span = float(np.max(u) - np.min(u))
    if span == 0.0:
        return []
    tol = rel_tolerance * span
    du = np.abs(np.diff(u))
    steps: list[Step] = []
    k, n = 0, du.shape[0]
    level = float(u[0])
    while k < n:
        if du[k] <= tol:
            level = float(u[k + 1])
            k += 1
            continue
        start = k
        while k < n and du[k] > tol:
            k += 1
        # k: first quiet difference after the move (or the end); the input rests at u[k].
        steps.append(Step(float(t[start]), float(u[k]), level))
        level = float(u[k])
    # The target of a step is where the input is just before the next one (a lag creeps on
    # below the tolerance after the move).
    out: list[Step] = []
    previous = float(u[0])
    for i, s in enumerate(steps):
        t_next = steps[i + 1].t if i + 1 < len(steps) else float(t[-1])
        k = int(np.searchsorted(t, t_next, side="right")) - 1
        out.append(Step(s.t, float(u[k]), previous))
        previous = float(u[k])
    return out


# ---------------------------------------------------------------------------- per-step analysis
@dataclass
class StepMetrics:
    """Everything reported for one step (SI units; times in s from the step's onset)."""

    index: int
    t: float
    input: float
    input_before: float
    duration: float
    samples: int
    applied_input_before: Optional[float] = None
    applied_input: Optional[float] = None
    input_change: Optional[float] = None
    output_before: Optional[float] = None
    output: Optional[float] = None
    output_change: Optional[float] = None
    gain: Optional[float] = None
    settling_time: Optional[float] = None
    overshoot: Optional[float] = None
    rise_time: Optional[float] = None
    input_settling_time: Optional[float] = None
    joint_a_compression: Optional[float] = None
    compression_hinge: Optional[str] = None
    drive_force: Optional[float] = None
    peak_drive_force: Optional[float] = None
    peak_wrench: dict[str, dict[str, float]] = field(default_factory=dict)
    settled: bool = False
    notes: list[str] = field(default_factory=list)

    def as_dict(self) -> dict:
        return {k: (dict(v) if isinstance(v, dict) else list(v) if isinstance(v, list) else v)
                for k, v in self.__dict__.items()}


Signal = tuple[np.ndarray, np.ndarray]


def _before(sig: Signal, t0: float) -> Optional[float]:
    t, y = sig
    k = int(np.searchsorted(t, t0, side="right")) - 1
    return float(y[k]) if k >= 0 else None


def _window(sig: Signal, t0: float, t1: float) -> Signal:
    t, y = sig
    lo = int(np.searchsorted(t, t0, side="right"))
    hi = int(np.searchsorted(t, t1, side="right"))
    return t[lo:hi], y[lo:hi]


def analyse_steps(
    steps: Sequence[Step],
    output: Signal,
    drive_input: Optional[Signal] = None,
    compression: Optional[Signal] = None,
    drive_force: Optional[Signal] = None,
    wrenches: Optional[Mapping[str, Signal]] = None,
    t_end: Optional[float] = None,
    compression_hinge: Optional[str] = None,
    band: float = DEFAULT_BAND,
    hold: float = DEFAULT_HOLD,
) -> list[StepMetrics]:
    """
    Metrics of every step.

    Signals are (t, values) with t increasing; wrenches hold (n, 3) arrays of (moment, f_x, f_y).
    ``t_end``: end of the run (default: last output).
    """
    out_t, out_y = sample_arrays(*output, name="output")
    if out_t.shape[0] == 0:
        return []
    end = float(out_t[-1]) if t_end is None else float(t_end)
    results: list[StepMetrics] = []
    for i, step in enumerate(steps):
        t0 = step.t
        t1 = steps[i + 1].t if i + 1 < len(steps) else end
        wt, wy = _window((out_t, out_y), t0, t1)
        m = StepMetrics(
            index=i + 1,
            t=t0,
            input=step.target,
            input_before=step.previous,
            duration=t1 - t0,
            samples=int(wt.shape[0]),
            compression_hinge=compression_hinge,
        )
        results.append(m)
        if wt.shape[0] == 0:
            m.notes.append("no samples after the step")
            continue
        y0 = _before((out_t, out_y), t0)
        in_change = step.target - step.previous
        in_ok = True
        if drive_input is not None and drive_input[0].shape[0]:
            u0 = _before(drive_input, t0)
            ut, uy = _window(drive_input, t0, t1)
            if u0 is not None and ut.shape[0]:
                r_in = step_response(ut, uy, t0, u0, t1, band, hold)
                m.applied_input_before, m.applied_input = u0, r_in.final
                m.input_settling_time = r_in.settling_time
                in_change = r_in.change
                in_ok = r_in.settled
                if not in_ok:
                    m.notes.append("the drive input did not settle before the next step")
            else:
                in_ok = False
        m.input_change = in_change
        if y0 is None:
            m.notes.append("no samples before the step")
            m.output = float(wy[-1])
        else:
            r = step_response(wt, wy, t0, y0, t1, band, hold)
            m.output_before, m.output, m.output_change = y0, r.final, r.change
            m.settling_time, m.overshoot, m.rise_time = r.settling_time, r.overshoot, r.rise_time
            m.settled = r.settled and in_ok
            if not r.settled:
                m.notes.append("the output did not settle before the next step")
            if m.settled and in_change != 0.0:
                m.gain = r.change / in_change
            elif in_change == 0.0:
                m.notes.append("the applied input did not change (clamped to the stroke?)")
        if compression is not None and compression[0].shape[0]:
            ct, cy = _window(compression, t0, t1)
            if ct.shape[0]:
                m.joint_a_compression = float(cy[-1])
        if drive_force is not None and drive_force[0].shape[0]:
            ft, fy = _window(drive_force, t0, t1)
            if ft.shape[0]:
                m.drive_force = float(fy[-1])
                m.peak_drive_force = peak(fy)
        for name, sig in (wrenches or {}).items():
            st, sv = _window(sig, t0, t1)
            if st.shape[0]:
                m.peak_wrench[name] = wrench_peaks(sv)
    return results


def wrench_peaks(w: np.ndarray) -> dict[str, float]:
    """
    Peaks of (n, 3) wrench samples (moment, f_x, f_y).

    Signed moment, f_x, f_y of largest magnitude, and the largest in-plane force magnitude |f|.
    """
    w = np.asarray(w, dtype=float)
    if w.ndim != 2 or w.shape[1] != 3:
        raise ValueError(f"w: expected shape (n, 3), got {w.shape}")
    return {
        "moment": peak(w[:, 0]),
        "force": float(np.max(np.hypot(w[:, 1], w[:, 2]))),
        "fx": peak(w[:, 1]),
        "fy": peak(w[:, 2]),
    }
