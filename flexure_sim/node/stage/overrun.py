"""
A visible warning when real-time ticks do not fit their period (no ROS).

The diagnostics report missed ticks at ~10 Hz; someone developing a controller against the
stage reads the log first. `OverrunWatch` counts, per second of wall time, the paced ticks,
those missed and the wall time of their work; when more than `MISSED_FRACTION` of the
second's ticks were missed it returns one line naming the measured work per tick against the
period and what to change, at most once per `REPEAT_S` (the line says how many seconds were
over the limit since the last one).
"""
from __future__ import annotations

from typing import Optional

#: Missed ticks in a second beyond which the watch warns.
MISSED_FRACTION = 0.01
#: Length of a counting window, s of wall time.
WINDOW_S = 1.0
#: Least time between two warnings, s.
REPEAT_S = 10.0


class OverrunWatch:
    """
    Per-second counts of the paced ticks, their misses and their work (module docstring).

    Call `tick` after every paced tick with the wall time ``now`` (s, any monotonic clock), the
    tick's work (s) and whether it missed; it returns the warning line when one is due, else
    None. `describe` supplies the remedies' current settings.
    """

    def __init__(self, period: float, now: float) -> None:
        self.period = period
        self._window_end = now + WINDOW_S
        self._ticks = self._missed = 0
        self._work = self._work_max = 0.0
        self._next_warning = now
        self._over = 0
        #: Warnings returned so far.
        self.warnings = 0

    def set_period(self, period: float, now: float) -> None:
        """Take a new publish period; a new window starts."""
        self.period = period
        self._restart(now)

    def _restart(self, now: float) -> None:
        self._window_end = now + WINDOW_S
        self._ticks = self._missed = 0
        self._work = self._work_max = 0.0

    def tick(self, now: float, work: float, missed: bool, settings: str) -> Optional[str]:
        """
        Count one tick; the warning line if one is due (else None).

        ``settings``: the node's current publish_rate, monitor_rate and stepping_priority, as
        the warning quotes them.
        """
        self._ticks += 1
        self._missed += missed
        self._work += work
        if work > self._work_max:
            self._work_max = work
        if now < self._window_end:
            return None
        ticks, missed_n = self._ticks, self._missed
        mean, worst = self._work / ticks, self._work_max
        self._restart(now)
        if missed_n <= MISSED_FRACTION * ticks:
            return None
        self._over += 1
        if now < self._next_warning:
            return None
        self._next_warning = now + REPEAT_S
        over, self._over = self._over, 0
        since = (f" (over {100 * MISSED_FRACTION:g} % in {over} second{'s' if over > 1 else ''}"
                 " since the last such warning)" if self.warnings else "")
        self.warnings += 1
        return (
            f"real time: {missed_n} of {ticks} ticks ({100.0 * missed_n / ticks:.1f} %) missed "
            f"in the last second{since}: a tick's work takes "
            f"{1e6 * mean:.0f} us on average, {1e6 * worst:.0f} us at most, of the "
            f"{1e6 * self.period:.0f} us period. Remedies: a lower publish_rate (fewer, longer "
            "ticks), monitor_rate (poses, wrenches and deflections at a lower rate), "
            "stepping_priority (SCHED_FIFO, with wake_spin at most half the period); now "
            f"{settings}")
