"""
The stage node's parameters as data (pure Python, no side effects).

The node declares each `ParamSpec` with a ``ParameterDescriptor`` (description, range,
read-only), validates every change with `param_checks.validate` in its on-set callback, and
applies accepted changes in its post-set callback.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Optional

from flexure_sim.engine.solver.simulation import DEFAULT_STEP

#: Largest relative mismatch between publish period and steps_per_tick * sim_step.
DIVISION_TOLERANCE = 1e-6
MAX_PUBLISH_RATE = 10000.0
MAX_SIM_STEP = 1e-2
#: Values of ``command_reliability``.
COMMAND_RELIABILITIES = ("reliable", "best_effort")
#: Default of ``command_depth``: one second of a 10 kHz command flood, so ticks down to 1 Hz
#: (fast mode) or a one-second stall lose nothing of it (docs/node.md, "Drive commands").
COMMAND_DEPTH = 10000
#: Values of ``space``.
SPACES = ("auto", "2d", "3d")
#: Values of ``record_format``.
RECORD_FORMATS = ("bag", "mcap")
#: Default of ``wake_spin``: see its description and docs/node.md, "Time" (BENCHMARKS.md).
WAKE_SPIN_S = 2e-4
#: Default of ``stepping_nice``: see its description (measured in BENCHMARKS.md).
STEPPING_NICE = -10
#: Default of ``cpu_latency_us``: see its description (measured in BENCHMARKS.md).
CPU_LATENCY_US = -1
#: Default of ``stepping_priority``: see its description (measured in BENCHMARKS.md).
STEPPING_PRIORITY = 0


@dataclass(frozen=True)
class ParamSpec:
    """
    One parameter.

    name, default, Python type (float, int, bool or str), unit, read-only, numeric range [low,
    high] (None if unbounded) and description.
    """

    name: str
    default: Any
    type: type
    unit: str
    read_only: bool
    low: Optional[float]
    high: Optional[float]
    description: str


#: Placeholders of the defaults the mechanism's drive gives (`parameter_specs`).
DRIVE_MIN, DRIVE_MAX, DRIVE_SLEW = "drive stroke_min", "drive stroke_max", "drive slew_rate"
_DRIVE = (DRIVE_MIN, DRIVE_MAX, DRIVE_SLEW)

#: Every parameter, in declaration order: the fields of `ParamSpec` (name, default, type,
#: unit, read-only, low, high, description). docs/node.md, "Parameters", is this table for users.
TABLE: tuple[tuple[Any, ...], ...] = (
    ("mechanism", "microstage", str, "", True, None, None,
     "Built-in mechanism name (a file of the package's config/, e.g. microstage, xy_stage, "
     "tiptilt_stage; an unknown name lists them all) or path of a mechanism YAML file."),
    ("space", "auto", str, "", True, None, None,
     "auto: the mechanism file's own engine (planar, or the spatial engine for a file with "
     "space: 3d); 3d: a planar file opened in space, with its out-of-plane freedoms (poses, "
     "wrenches, markers and TF in 3-D); 2d: planar (refused for a space: 3d file). Read-only."),
    ("publish_rate", 1000.0, float, "Hz", False, 1.0, MAX_PUBLISH_RATE,
     "Ticks per second: each tick advances the simulation by 1/publish_rate s and publishes "
     "every topic once (diagnostics at ~10 Hz). 1/publish_rate must be a whole multiple of "
     "sim_step."),
    ("monitor_rate", 0.0, float, "Hz", False, 0.0, MAX_PUBLISH_RATE,
     "Rate of the monitoring topics (body poses, hinge wrenches and deflections): published "
     "and recorded every round(publish_rate / monitor_rate)-th tick, while the control topics "
     "(output, output/measured, drive, compression, /clock) keep every tick. 0: every tick."),
    ("sim_step", DEFAULT_STEP, float, "s", True, 0.0, MAX_SIM_STEP,
     "Fixed engine step, in (0, 0.01] s; must divide the publish period. Read-only."),
    ("time_mode", "realtime", str, "", True, None, None,
     "realtime: ticks paced by a steady clock; fast: as fast as possible, publishes /clock; "
     "lockstep: one tick per ~/step call, publishes /clock. Read-only."),
    ("stroke_min", DRIVE_MIN, float, "m", False, None, None,
     "Lower end of the actuator stroke; commands below it are clamped."),
    ("stroke_max", DRIVE_MAX, float, "m", False, None, None,
     "Upper end of the actuator stroke; commands above it are clamped."),
    ("slew_rate", DRIVE_SLEW, float, "m/s", False, 0.0, None,
     "Actuator speed limit (> 0): the commanded target moves towards each new command at most "
     "this fast."),
    ("wake_spin", WAKE_SPIN_S, float, "s", False, 0.0, 1.0,
     "Real-time mode: the last part of the wait for each tick that is busy-waited instead of "
     "slept. The default sleeps most of a 1 kHz period and leaves that core to the "
     "controller, the recorder and the middleware; at 4 kHz it spins the whole period. A "
     "sleeping core can take long to wake, above all on virtual machines; publish_rate's "
     "period or more: the stepping thread never sleeps (one busy core)."),
    ("merge_late_ticks", 0, int, "ticks", False, 0, 1000,
     "Real-time mode: a loop late by this many tick periods or more merges the ticks it is "
     "late for into the next one, which steps the engine through all their periods and "
     "publishes once (simulated time stays with wall time; the merged ticks are not published,"
     " and are counted). 0: never, every tick is published and late ones run back to back."),
    ("stepping_nice", STEPPING_NICE, int, "", True, -20, 19,
     "Niceness asked for the stepping thread at start-up (Linux), and for the ROS middleware's"
     " threads, whose locks it waits on. Below the other processes' it gets a shared core "
     "first, which keeps real-time ticks on time next to busy nodes. Needs CAP_SYS_NICE or an "
     "RLIMIT_NICE allowing it; if refused, the node says so once and runs unchanged. "
     "Read-only."),
    ("stepping_priority", STEPPING_PRIORITY, int, "", True, 0, 99,
     "Real-time mode: 1-99 runs the stepping thread under the kernel's real-time policy "
     "SCHED_FIFO at this priority, so that it preempts every normally scheduled process "
     "(niceness is weighed against other processes, not absolute); 0, the default: normal "
     "scheduling with stepping_nice. The thread must then sleep part of every tick: wake_spin "
     "at most half the tick period (1e-4 s is a good start). Needs CAP_SYS_NICE or an "
     "RLIMIT_RTPRIO allowing it; if refused, the node says so once and runs unchanged. "
     "Read-only."),
    ("cpu_latency_us", CPU_LATENCY_US, int, "us", True, -1, 100000,
     "Real-time mode: CPU wake-up latency asked of the kernel while the stage steps (Linux PM "
     "QoS, /dev/cpu_dma_latency; 0: idle CPUs poll instead of halting, so a thread woken on "
     "one runs at once; -1, the default: no request). Needs write access to "
     "/dev/cpu_dma_latency; if refused, the node says so once and runs unchanged. Read-only."),
    ("command_reliability", "reliable", str, "", True, None, None,
     "Reliability of the drive command subscription: reliable (only reliable publishers are "
     "heard) or best_effort (reliable and best-effort publishers alike; a command lost on the "
     "wire is not resent). A publisher that does not match gets a warning and a diagnostics "
     "count. Read-only."),
    ("command_depth", COMMAND_DEPTH, int, "commands", True, 1, 1000000,
     "History depth of each drive command subscription: commands that wait for the next tick "
     "(the stepping thread takes them all, up to this many, at each tick). When more arrive "
     "between two ticks the middleware replaces the oldest; the node counts those from the "
     "gaps in the publishers' sequence numbers (diagnostics commands_lost, a warning). "
     "Read-only."),
    ("frame_prefix", "", str, "", True, None, None,
     "Put in front of every frame id the node publishes (root stage, body and hinge frames; "
     "headers, child frames, markers, TF), e.g. stage1/, so two stages can share one TF tree "
     "and one view. No leading slash. Read-only."),
    ("display_rate", 30.0, float, "Hz", False, 0.0, MAX_PUBLISH_RATE,
     "Rate of the markers (and TF) in simulated time: every round(publish_rate / display_rate)"
     " ticks, at most every tick; 0 turns them off. In real-time mode that is wall time too; "
     "in fast mode it is display_rate times the real-time factor."),
    ("display_scale", 1.0, float, "", False, 0.0, None,
     "Magnification of the displacements drawn by the markers about the rest pose (micrometre "
     "motions are invisible at 1); published poses, wrenches and TF stay true. At 1 the "
     "outlines sit on the TF body frames."),
    ("record", True, bool, "", False, None, None,
     "Record every published topic and the received drive commands to MCAP (same as ~/record)."),
    ("record_dir", "runs", str, "", False, None, None,
     "Directory of the recordings (relative to the working directory), created if missing; "
     "recordings are named <mechanism>_<namespace_node>_<UTC time> (a bag directory, or that "
     ".mcap file), with _1, _2, ... when the name is taken (names are claimed atomically)."),
    ("record_path", "", str, "", False, None, None,
     "Explicit bag directory (or, ending in .mcap, file) for the next recording (later ones "
     "get _1, _2, ... or the next free one); empty: a new name in record_dir. Existing "
     "recordings are never overwritten."),
    ("record_format", "bag", str, "", False, None, None,
     "bag: a rosbag2 bag directory per recording (metadata.yaml + <name>_0.mcap, split by "
     "record_max_bytes / record_max_duration), as ros2 bag record writes; mcap: one MCAP file."
     " A record_path ending in .mcap is one file either way. Applies from the next recording."),
    ("record_max_bytes", 0, int, "B", False, 0, None,
     "Bag format: start a new file of the bag once the current one holds this many bytes of "
     "messages (before MCAP framing and compression); 0: no limit."),
    ("record_max_duration", 0.0, float, "s", False, 0.0, None,
     "Bag format: start a new file once the current one spans this much simulated time; 0: no "
     "limit."),
)


def parameter_specs(
    drive_defaults: Optional[tuple[float, float, float]] = None,
    unused_because: str = "the mechanism has no drive",
) -> list[ParamSpec]:
    """
    Return every parameter of `TABLE`, the drive's defaults filled in.

    ``drive_defaults`` = (stroke_min, stroke_max, slew_rate) of the mechanism's drive, or None when
    it has no drive (the limits are then unused, ``unused_because`` says why).
    """
    values = dict(zip(_DRIVE, drive_defaults if drive_defaults is not None else (0.0, 0.0, 1.0)))
    unused = "" if drive_defaults is not None else f" Unused: {unused_because}."
    out = []
    for name, default, kind, unit, read_only, low, high, text in TABLE:
        if default in values:
            default, text = values[default], text + unused
        out.append(ParamSpec(name, default, kind, unit, read_only, low, high, text))
    return out


def as_declared_type(spec: Optional[ParamSpec], value: Any) -> Any:
    """
    Return a value for a double parameter given as an integer or a numeric string, as a float.

    ``ros2 param set`` guesses a value's type with YAML 1.1, which reads ``2`` as an integer
    and ``1e-6`` (an exponent without a dot) as a string; rclpy would refuse either for a
    double parameter. Anything else (other parameters, non-numeric text) is returned as is,
    for the usual type check and `validate`.
    """
    if spec is None or spec.type is not float or isinstance(value, (bool, float)):
        return value
    if isinstance(value, int):
        return float(value)
    if isinstance(value, str):
        try:
            return float(value)
        except ValueError:
            return value
    return value
