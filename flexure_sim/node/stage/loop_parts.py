"""
What a stage node's stepping loop is built from: its parts and its settings (no ROS).

``shell.StageNode`` builds every part (simulation, topic table, publishers, recording,
command intake, display, diagnostics port) and reads the settings from its parameters, then
constructs the ``stepping_thread.SteppingLoop`` from the one `LoopParts` that holds them all.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Callable, Mapping, Optional, Sequence

from flexure_sim.node.inputs.command_checks import WarningThrottle
from flexure_sim.node.publish.diagnostics import DiagnosticsPort
from flexure_sim.node.record.session import RecordingSession


@dataclass(frozen=True)
class LoopSettings:
    """
    The stepping loop's settings, from the node's parameters (docs/node.md, "Parameters").

    ``merge_after``: ``merge_late_ticks``; ``nice``, ``priority``: ``stepping_nice``,
    ``stepping_priority``; the others are the parameters of the same name.
    """

    time_mode: str
    rate: float
    dt: float
    wake_spin: float = 0.0
    nice: int = 0
    monitor_rate: float = 0.0
    merge_after: int = 0
    cpu_latency_us: int = -1
    priority: int = 0
    display_rate: float = 0.0

    @classmethod
    def from_values(cls, values: Mapping[str, Any]) -> "LoopSettings":
        """Read the settings from the node's parameter values (by name)."""
        return cls(values["time_mode"], float(values["publish_rate"]),
                   float(values["sim_step"]), float(values["wake_spin"]),
                   int(values["stepping_nice"]), float(values["monitor_rate"]),
                   int(values["merge_late_ticks"]), int(values["cpu_latency_us"]),
                   int(values["stepping_priority"]), float(values["display_rate"]))


@dataclass
class LoopParts:
    """
    What a stepping loop works with, all built before it.

    ``settings``: the loop's `LoopSettings`; ``sim``: the simulation; ``interface``: its topic
    table (``publish.interface``); ``publishers``: one per tick topic, in its order;
    ``session``: the recording; ``log``: a logger; ``filter``: the drives' command filter
    (None without a drive); ``intake``: the command intake (``command_intake``, None without a
    drive); ``diagnostics``: where the diagnostics go (None: none); ``display``: markers and
    TF (``display.DisplayOutput``, None: none); ``graph_check``: a check of the ROS graph run
    between ticks every GRAPH_CHECK_PERIOD_S (``qos_watch``); ``throttle``: the warnings'
    rate limit, shared with the intake; ``report``: None for the planar engine (the loop
    builds its compiled ``TickReport``), a ``spatial_report.SpatialReport`` for a mechanism
    in space.
    """

    settings: LoopSettings
    sim: Any  # a Simulation, or a SpatialSimulation with a SpatialReport as ``report``
    interface: Any
    publishers: Sequence[Any]
    session: RecordingSession
    log: Any
    filter: Any = None
    intake: Any = None
    diagnostics: Optional[DiagnosticsPort] = None
    display: Any = None
    graph_check: Optional[Callable[[], Any]] = None
    throttle: WarningThrottle = field(default_factory=lambda: WarningThrottle(1.0))
    report: Any = None
