"""
What a publish tick sends besides its topics: the display (markers, TF) and the diagnostics.

Each goes out a few times a second (``display_rate``, 30 Hz; diagnostics 10 Hz) and costs
more than a whole tick: in a stage node at 4 kHz (stepping thread under SCHED_FIFO, 2-core
VM) a display took 257 us and a status 334 us (medians, wall time) against the tick's 78 us,
about three times their cost ticked back to back in one process, where caches stay warm.
Published from inside the tick, 64-100 % of the display ticks and every diagnostics tick at
4 kHz ended after the next tick was due (node traces, 2-core VM under load). The paced loop
therefore sends them after it has checked the tick's deadline (`Pacer.done`), in the slack
of the period: the next tick starts that much later and misses only if the extras overrun
that slack too (interleaved runs at 4 kHz under SCHED_FIFO: 0.87-0.96 % of the ticks missed
against 1.88-2.07 % with the extras inside).
Lockstep and fast mode send them at the end of the tick, as the paced loop does: the order
of what is published and recorded is the same in every mode (after the tick's topics,
before the next tick's).
"""
from __future__ import annotations

from typing import Any


def crossed(first: int, count: int, every: int) -> bool:
    """Whether one of the ticks ``first .. first + count - 1`` is a multiple of ``every``."""
    return (first + count - 1) // every != (first - 1) // every


class TickExtras:
    """
    The display and diagnostics a tick of ``loop`` has made due, until `send`.

    ``loop`` (a ``SteppingLoop``) holds them: ``display`` (``publish(view, stamp)``) or None,
    ``diagnostics`` (``publish(stamp)``) or None, and the tick ``report`` whose ``view()`` the
    display draws.
    """

    __slots__ = ("loop", "stamp", "display_due", "diagnostics_due")

    def __init__(self, loop: Any) -> None:
        self.loop = loop
        self.stamp = 0
        self.display_due = self.diagnostics_due = False

    def note(self, stamp: int, display: bool, diagnostics: bool) -> None:
        """Make a tick's display and diagnostics (stamped ``stamp``) due, as asked."""
        self.stamp = stamp
        self.display_due = display and self.loop.display is not None
        self.diagnostics_due = diagnostics and self.loop.diagnostics is not None

    @property
    def due(self) -> bool:
        """Whether anything waits for `send`."""
        return self.display_due or self.diagnostics_due

    def send(self) -> None:
        """Publish (and record) what is due: the display first, then the diagnostics."""
        loop = self.loop
        if self.display_due:
            self.display_due = False
            loop.display.publish(loop.report.view(), self.stamp)
        if self.diagnostics_due:
            self.diagnostics_due = False
            loop.diagnostics.publish(self.stamp)
