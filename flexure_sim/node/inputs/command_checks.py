"""
Validation of the piezo drive commands the stage node receives (pure Python, no ROS).

A command is a target displacement (m) of the actuator along the mechanism's drive axis.
Before the simulation sees it, `CommandFilter`

1. **rejects** NaN and +-Inf (the target stays where it was);
2. **clamps** it into the actuator's stroke ``[stroke_min, stroke_max]``;
3. **rate-limits** it: the target handed to the engine (`CommandFilter.applied`) moves
   towards the accepted command at no more than ``slew_rate`` (m/s), engine step by engine
   step (`CommandFilter.advance`).

Every event is counted (`CommandCounters`) and `WarningThrottle` turns floods of bad
commands into at most one warning per kind and interval, naming how many were affected.

All decisions depend only on the order of the commands and on simulated time, never on
the wall clock, so identical command sequences applied at identical ticks give identical
outputs.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, fields
from enum import Enum
from typing import Any, Callable, Optional, Sequence


class CommandStatus(Enum):
    """What happened to one command."""

    ACCEPTED = "accepted"
    CLAMPED = "clamped"
    REJECTED = "rejected"


@dataclass(frozen=True)
class DriveLimits:
    """Actuator limits: stroke [stroke_min, stroke_max] (m) and slew rate (m/s, > 0)."""

    stroke_min: float
    stroke_max: float
    slew_rate: float

    def __post_init__(self) -> None:
        problem = self.problem()
        if problem is not None:
            raise ValueError(problem)

    def problem(self) -> Optional[str]:
        """Why these limits are invalid, or None. Used by the node's parameter validation."""
        return limits_problem(self.stroke_min, self.stroke_max, self.slew_rate)


def limits_problem(stroke_min: float, stroke_max: float, slew_rate: float) -> Optional[str]:
    """Reason why (stroke_min, stroke_max, slew_rate) are not valid actuator limits, or None."""
    for name, value in (("stroke_min", stroke_min), ("stroke_max", stroke_max),
                        ("slew_rate", slew_rate)):
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            return f"{name}: expected a number, got {value!r}"
        if not math.isfinite(value):
            return f"{name}: must be finite, got {value!r}"
    if stroke_min > stroke_max:
        return f"stroke_min ({stroke_min!r} m) must not exceed stroke_max ({stroke_max!r} m)"
    if not slew_rate > 0:
        return f"slew_rate: must be > 0 m/s, got {slew_rate!r}"
    return None


@dataclass
class CommandCounters:
    """
    Counts since the filter was created (they survive `CommandFilter.reset`).

    received: every command submitted; accepted: finite ones (clamped included);
    clamped: finite but outside the stroke; rejected: NaN or +-Inf, and malformed ones;
    malformed: payloads that are not a Float64 in an encoding the node reads (`cdr`);
    rate_limited: accepted commands the actuator could not reach within one publish period
    at its slew rate (so the engine sees a ramp); lost: commands a publisher sent that the
    node never took (not in received; `command_loss`); unheard: commands a publisher numbered
    before the first one the node took from it (sent before the reader matched it;
    `command_loss`).
    """

    received: int = 0
    accepted: int = 0
    clamped: int = 0
    rejected: int = 0
    malformed: int = 0
    rate_limited: int = 0
    lost: int = 0
    unheard: int = 0

    def as_dict(self) -> dict[str, int]:
        return {f.name: getattr(self, f.name) for f in fields(self)}


class CommandFilter:
    """
    Turns a stream of raw commands into the actuator target the engine follows.

    Use: `submit` each received command in order (at the start of the tick in which it
    takes effect), then `begin_tick` once, then `advance` once per engine step and pass the
    result to ``Simulation.set_command``. Not thread-safe: one thread drives it.
    """

    def __init__(self, limits: DriveLimits, initial: float = 0.0) -> None:
        self._limits = limits
        self.counters = CommandCounters()
        self._initial = self._clamp(float(initial))
        self.target = self._initial       # last accepted (clamped) command, m
        self.applied = self._initial      # rate-limited target handed to the engine, m
        self._checked = True               # rate limit of `target` already assessed

    # -------------------------------------------------------------- limits
    @property
    def limits(self) -> DriveLimits:
        return self._limits

    def set_limits(self, limits: DriveLimits) -> None:
        """Apply a new stroke / slew rate; the current target is clamped into the new stroke."""
        self._limits = limits
        self.target = self._clamp(self.target)
        self._checked = False

    def _clamp(self, value: float) -> float:
        return min(max(value, self._limits.stroke_min), self._limits.stroke_max)

    # ------------------------------------------------------------ commands
    def submit(self, value: float) -> CommandStatus:
        """Validate one command; on success it becomes the new target."""
        c = self.counters
        c.received += 1
        if (not isinstance(value, (int, float)) or isinstance(value, bool)
                or not math.isfinite(value)):
            c.rejected += 1
            return CommandStatus.REJECTED
        value = float(value)
        clamped = self._clamp(value)
        c.accepted += 1
        self.target = clamped
        self._checked = False
        if clamped != value:
            c.clamped += 1
            return CommandStatus.CLAMPED
        return CommandStatus.ACCEPTED

    def reject_malformed(self) -> None:
        """Count a received payload that could not be read as a command (the target stays)."""
        c = self.counters
        c.received += 1
        c.rejected += 1
        c.malformed += 1

    def submit_many(self, values: Sequence[float]) -> tuple[int, int, float, float]:
        """
        `submit` for each of ``values`` (floats) in order, in one call.

        The same target and counters, without a Python call per command. Returns (rejected,
        clamped, last rejected value, last clamped value as received); the values are NaN when
        none.
        """
        lo, hi = self._limits.stroke_min, self._limits.stroke_max
        isfinite = math.isfinite
        target = self.target
        rejected = clamped = 0
        last_rejected = last_clamped = math.nan
        for value in values:
            if not isfinite(value):
                rejected += 1
                last_rejected = value
            elif value < lo:
                target, last_clamped = lo, value
                clamped += 1
            elif value > hi:
                target, last_clamped = hi, value
                clamped += 1
            else:
                target = value
        c = self.counters
        n = len(values)
        c.received += n
        c.accepted += n - rejected
        c.rejected += rejected
        c.clamped += clamped
        if n > rejected:
            self.target = float(target)
            self._checked = False
        return rejected, clamped, last_rejected, last_clamped

    def begin_tick(self, period: float) -> bool:
        """
        Start of a publish tick of ``period`` seconds.

        Count the new target as rate-limited if the actuator cannot reach it within the tick.
        Returns True when it was counted.
        """
        if self._checked:
            return False
        self._checked = True
        if abs(self.target - self.applied) > self._limits.slew_rate * period * (1 + 1e-12):
            self.counters.rate_limited += 1
            return True
        return False

    @property
    def settled(self) -> bool:
        """
        Return True when the engine's target equals the accepted command.

        That is, no ramp is in progress.
        """
        return self.applied == self.target

    def advance(self, dt: float) -> float:
        """Move the applied target towards the accepted command by at most slew_rate * dt."""
        delta = self.target - self.applied
        if delta != 0.0:
            limit = self._limits.slew_rate * dt
            if -limit <= delta <= limit:
                self.applied = self.target
            else:
                self.applied += limit if delta > 0 else -limit
        return self.applied

    def hold(self, value: float) -> None:
        """
        Set the target and applied target both to ``value``.

        The engine could not follow the command: the actuator stays where it was.
        """
        self.target = self.applied = float(value)
        self._checked = True

    def reset(self) -> None:
        """Back to the initial target (simulation reset); counters are kept."""
        self.target = self.applied = self._initial
        self._checked = True

    def differs(self, command: Any) -> bool:
        """Whether the applied target is not ``command`` (a number, or a one-entry array)."""
        if not isinstance(command, (int, float)):
            command = command[0]
        return bool(command != self.applied)

    @staticmethod
    def describe(value: float) -> str:
        """Return a target as text (``1e-06 m``)."""
        return f"{value:g} m"

    def values(self) -> list[tuple[str, float]]:
        """Diagnostics entries: the target and the applied target."""
        return [("drive_target", self.target), ("drive_applied", self.applied)]


class WarningThrottle:
    """
    At most one warning per kind every ``interval_s`` (wall clock).

    Each warning comes with the number of events it stands for. ``clock`` is injectable for tests.
    """

    def __init__(
        self, interval_s: float = 1.0, clock: Callable[[], float] = time.monotonic
    ) -> None:
        self.interval_s = float(interval_s)
        self._clock = clock
        self._last: dict[str, float] = {}
        self._pending: dict[str, int] = {}

    def event(self, kind: str, count: int = 1) -> Optional[int]:
        """
        Record ``count`` events of ``kind``.

        Return how many events the warning to be emitted now stands for (including these), or None
        if it is suppressed.
        """
        pending = self._pending.get(kind, 0) + count
        now = self._clock()
        last = self._last.get(kind)
        if last is not None and now - last < self.interval_s:
            self._pending[kind] = pending
            return None
        self._last[kind] = now
        self._pending[kind] = 0
        return pending
