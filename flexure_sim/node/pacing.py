"""Real-time pacing of the stage node's publish ticks against a steady clock (no ROS).

Tick k is due at the absolute deadline ``D_k = t0 + k * period`` of a monotonic clock
(``time.perf_counter``): the loop sleeps until shortly before ``D_k``, busy-waits the rest
(``spin_s``), then steps the engine over one publish period and publishes. Deadlines are
absolute, so sleep jitter does not accumulate.

A tick is **missed** when its work finishes after ``D_{k+1}`` (the next tick is then late).
A late loop catches up by running ticks back to back; if it falls more than ``max_lag_s``
behind, it **slips**: the schedule is re-anchored at the current time and the ticks skipped
are counted (simulated time then runs behind wall time by that much).
"""
from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Callable


@dataclass
class PacingStats:
    """Counters since `Pacer.start`: ticks run, ticks missed (finished after the next
    deadline), slips (re-anchorings) and ticks skipped by them, worst start lateness (s)."""

    ticks: int = 0
    missed: int = 0
    slips: int = 0
    skipped: int = 0
    max_late_s: float = 0.0


class Pacer:
    """Absolute-deadline scheduler. ``spin_s``: the last part of each wait is busy-waited
    instead of slept (sleep overshoots by ~0.1 ms and lets the core idle). ``clock`` and
    ``sleep`` are injectable for tests."""

    def __init__(
        self,
        period: float,
        *,
        max_lag_s: float = 0.1,
        spin_s: float = 0.0,
        clock: Callable[[], float] = time.perf_counter,
        sleep: Callable[[float], None] = time.sleep,
    ) -> None:
        if not period > 0:
            raise ValueError(f"period: must be > 0 s, got {period!r}")
        self.period = float(period)
        self.max_lag_s = max(float(max_lag_s), 2.0 * self.period)
        self._clock = clock
        self._sleep = sleep
        self.stats = PacingStats()
        self.spin_s = float(spin_s)
        self._t0 = clock()
        self._k = 0

    def start(self) -> None:
        """Anchor the schedule now: the first tick is due one period from now."""
        self._t0 = self._clock()
        self._k = 0

    def set_period(self, period: float) -> None:
        """Change the period from the next tick on (re-anchors at the current deadline)."""
        if not period > 0:
            raise ValueError(f"period: must be > 0 s, got {period!r}")
        self._t0 = self._t0 + self._k * self.period
        self._k = 0
        self.period = float(period)
        self.max_lag_s = max(self.max_lag_s, 2.0 * self.period)

    def reanchor(self) -> None:
        """Forget lateness (after a pause such as a reset): the next tick is due one period
        from now, without counting a slip."""
        self._t0 = self._clock() - self._k * self.period

    def wait(self) -> float:
        """Sleep until the next tick's deadline (or slip if far behind); return the deadline."""
        self._k += 1
        deadline = self._t0 + self._k * self.period
        now = self._clock()
        if now < deadline:
            spin = self.spin_s
            if deadline - now > spin:
                self._sleep(deadline - now - spin)
            if spin:
                clock = self._clock
                while clock() < deadline:
                    pass
            late = self._clock() - deadline  # the sleep's overshoot
            if late > self.stats.max_late_s:
                self.stats.max_late_s = late
            return deadline
        late = now - deadline
        if late > self.max_lag_s:
            skipped = int(late // self.period)
            self.stats.slips += 1
            self.stats.skipped += skipped
            self._t0 = now - self._k * self.period
            return now
        if late > self.stats.max_late_s:
            self.stats.max_late_s = late
        return deadline

    def done(self) -> bool:
        """Mark the current tick's work finished; return True if it missed its slot."""
        self.stats.ticks += 1
        if self._clock() > self._t0 + (self._k + 1) * self.period:
            self.stats.missed += 1
            return True
        return False
