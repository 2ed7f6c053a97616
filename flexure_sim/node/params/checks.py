"""
Checks of the stage node's parameter values (pure Python, no side effects).

`validate` is what the node's on-set callback runs on a complete set of values (start-up and
every live change); a numeric parameter whose only rule is its declared type and range is
checked against its `params.ParamSpec` (`range_problem`), so the range has one definition.
`steps_per_tick` and `monitor_every` are the tick arithmetic the checks and the stepping loop
share.
"""
from __future__ import annotations

import math
from typing import Any, Mapping, Optional

from flexure_sim.topics import frame_prefix_problem
from flexure_sim.node.inputs.command_checks import limits_problem
from flexure_sim.node.publish.interface import TIME_MODES
from flexure_sim.node.params.table import (
    COMMAND_RELIABILITIES, DIVISION_TOLERANCE, MAX_PUBLISH_RATE, MAX_SIM_STEP, RECORD_FORMATS,
    SPACES, ParamSpec, parameter_specs,
)


def steps_per_tick(publish_rate: float, sim_step: float) -> tuple[int, Optional[str]]:
    """
    Engine steps per tick.

    round(1 / (publish_rate * sim_step)), and the reason why the pair is invalid (None when valid).
    """
    if not (isinstance(publish_rate, (int, float)) and math.isfinite(publish_rate)
            and 1.0 <= publish_rate <= MAX_PUBLISH_RATE):
        return 0, f"publish_rate: must be in [1, {MAX_PUBLISH_RATE:g}] Hz, got {publish_rate!r}"
    if not (isinstance(sim_step, (int, float)) and math.isfinite(sim_step)
            and 0.0 < sim_step <= MAX_SIM_STEP):
        return 0, f"sim_step: must be in (0, {MAX_SIM_STEP:g}] s, got {sim_step!r}"
    ratio = 1.0 / (publish_rate * sim_step)
    n = round(ratio)
    if n < 1 or abs(ratio - n) > DIVISION_TOLERANCE * max(n, 1):
        return 0, (
            f"sim_step {sim_step:g} s does not divide the publish period {1.0 / publish_rate:g} s "
            f"(publish_rate {publish_rate:g} Hz): the period is {ratio:.6g} steps; choose "
            f"sim_step = period / n or a publish_rate of 1 / (n * sim_step)"
        )
    return n, None


def monitor_every(publish_rate: float, monitor_rate: float) -> int:
    """
    Ticks per publication of the monitoring topics.

    round(publish_rate / monitor_rate), 1 for monitor_rate 0.
    """
    return 1 if monitor_rate <= 0 else max(1, round(publish_rate / monitor_rate))


def range_problem(spec: ParamSpec, value: Any) -> Optional[str]:
    """
    Why ``value`` is not of ``spec``'s numeric type within its range [low, high], or None.

    The declared range is the one definition: the ParameterDescriptor shows it, this checks it
    (also for values given at start-up, which rclpy does not check against the range).
    """
    integer = spec.type is int
    if isinstance(value, bool) or not (
            isinstance(value, int) if integer
            else isinstance(value, (int, float)) and math.isfinite(value)):
        ok = False
    else:
        ok = ((spec.low is None or value >= spec.low)
              and (spec.high is None or value <= spec.high))
    if ok:
        return None
    kind = "an integer" if integer else "a finite number"
    unit = f" {spec.unit}" if spec.unit else ""
    bounds = (f"in [{spec.low:g}, {spec.high:g}]{unit}" if spec.high is not None
              else f">= {spec.low:g}{unit}")
    return f"{spec.name}: must be {kind} {bounds}, got {value!r}"


#: Numeric parameters whose whole check is their declared type and range (`range_problem`).
_RANGED = ("wake_spin", "merge_late_ticks", "stepping_nice", "stepping_priority",
           "cpu_latency_us", "command_depth", "display_rate", "display_scale", "record_max_bytes",
           "record_max_duration")
#: Largest wake_spin, as a fraction of the tick period, with a real-time stepping thread.
FIFO_MAX_SPIN_FRACTION = 0.5
_SPECS = {spec.name: spec for spec in parameter_specs()}


def validate(values: Mapping[str, Any]) -> Optional[str]:
    """Why this complete set of parameter values is invalid, or None."""
    _, problem = steps_per_tick(values["publish_rate"], values["sim_step"])
    if problem:
        return problem
    if values["time_mode"] not in TIME_MODES:
        return f"time_mode: expected one of {', '.join(TIME_MODES)}, got {values['time_mode']!r}"
    if values.get("space", "auto") not in SPACES:
        return f"space: expected one of {', '.join(SPACES)}, got {values['space']!r}"
    problem = limits_problem(values["stroke_min"], values["stroke_max"], values["slew_rate"])
    if problem:
        return problem
    monitor = values["monitor_rate"]
    if not (isinstance(monitor, (int, float)) and math.isfinite(monitor)
            and 0.0 <= monitor <= values["publish_rate"]):
        return (f"monitor_rate: must be 0 (every tick) or in (0, publish_rate "
                f"{values['publish_rate']:g}] Hz, got {monitor!r}")
    for name in _RANGED:
        problem = range_problem(_SPECS[name], values[name])
        if problem:
            return problem
    problem = fifo_spin_problem(values)
    if problem:
        return problem
    if values["command_reliability"] not in COMMAND_RELIABILITIES:
        return (f"command_reliability: expected one of {', '.join(COMMAND_RELIABILITIES)}, "
                f"got {values['command_reliability']!r}")
    problem = frame_prefix_problem(values["frame_prefix"])
    if problem:
        return problem
    if not isinstance(values["mechanism"], str) or not values["mechanism"].strip():
        return "mechanism: expected a built-in name or a YAML path, got an empty string"
    if not isinstance(values["record_dir"], str) or not values["record_dir"].strip():
        return "record_dir: expected a directory path, got an empty string"
    if values["record_format"] not in RECORD_FORMATS:
        return (f"record_format: expected one of {', '.join(RECORD_FORMATS)}, "
                f"got {values['record_format']!r}")
    if not isinstance(values["record_path"], str):
        return f"record_path: expected a string, got {values['record_path']!r}"
    return None


def fifo_spin_problem(values: Mapping[str, Any]) -> Optional[str]:
    """
    Why ``wake_spin`` is too long for a real-time (SCHED_FIFO) stepping thread, or None.

    A SCHED_FIFO thread that busy-waits the whole period never yields its core, and the kernel
    then throttles it (by default 50 ms of every second, sched_rt_runtime_us): a trial with
    the default wake_spin (the whole 1 ms period) missed 6.6 % of the ticks (BENCHMARKS.md).
    """
    priority, rate = values["stepping_priority"], values["publish_rate"]
    if not priority or values["time_mode"] != "realtime":
        return None
    limit = FIFO_MAX_SPIN_FRACTION / rate
    if values["wake_spin"] > limit:
        return (f"stepping_priority {priority} (SCHED_FIFO) needs the stepping thread to sleep "
                f"part of every tick: wake_spin must be at most {limit:g} s (half the tick "
                f"period at publish_rate {rate:g} Hz), got {values['wake_spin']:g} s; 1e-4 s "
                "is a good start")
    return None
