"""
What a publish tick sends besides its topics: the display (markers, TF) and the diagnostics.

Each goes out a few times a second (``display_rate``, 30 Hz; diagnostics 10 Hz) and costs
more than a whole tick: back to back in one process a display takes ~80 us and a status ~60 us
against the tick's ~50 us, but paced, between ticks, where the core's caches have gone cold,
350-510 us and 340-480 us (10th-90th percentiles, 4 kHz, 2-core VM). Published from inside
the tick, nearly every display and diagnostics tick at 4 kHz ended after the next tick was
due. The paced loop therefore sends them after it has checked the tick's deadline
(`Pacer.done`), in the slack of the period, and in parts (**stages**: the markers' geometry,
their packing, the recording, the publishing; a status' values, their packing, ...): a stage
runs only where its expected time (a running mean of its own past times, with a margin) ends
before the next tick is due; the rest waits for the next tick's slack. So a display is spread
over the slack of a few ticks instead of pushing one tick past its successor's deadline (a
4 kHz node on a 2-core VM: 84 % of its missed ticks followed a display or a status sent whole).

A stage that never fits still runs, one a tick: once it has waited `MAX_WAIT_TICKS` ticks,
or at every tick once the next display (or status) of its kind has fallen due; when a third
one falls due, the oldest goes out whole at once, as the whole send was before. Nothing is
dropped; the diagnostics count the ticks after which a stage waited (``extras_deferred``)
and the stages run past their budget (``extras_forced``).

A display or status takes its state when its first stage runs (the report of the last tick
then, stamped with that tick's simulated time): in real time a few ticks after the one that
made it due. Lockstep and fast mode send everything at the end of the tick that made it due,
so that there, what is published and recorded, and in which order, is the tick's topics and
then its display and diagnostics; in real time the display and diagnostics may follow a
later tick's topics.
"""
from __future__ import annotations

import time
from collections import deque
from typing import Any, Callable, Iterator, Optional

#: Ticks a stage may wait for slack before it runs anyway.
MAX_WAIT_TICKS = 16
#: A stage runs where ``SAFETY`` times its expected time ends before the next tick is due.
SAFETY = 1.5
#: Weight of a stage's newest time in its running mean.
WEIGHT = 0.25


def crossed(first: int, count: int, every: int) -> bool:
    """Whether one of the ticks ``first .. first + count - 1`` is a multiple of ``every``."""
    return (first + count - 1) // every != (first - 1) // every


class _Job:
    """
    One display or status on its way out: its stages (a generator), where it is, its wait.

    ``newer``: how many of its kind fell due after it (1: a stage a tick; 2: all at once).
    """

    __slots__ = ("kind", "stages", "stage", "waited", "newer")

    def __init__(self, kind: str, stages: Iterator[None]) -> None:
        self.kind, self.stages = kind, stages
        self.stage = self.waited = self.newer = 0


class TickExtras:
    """
    The display and diagnostics the ticks of ``loop`` made due, until `send` has sent them.

    ``loop`` (a ``SteppingLoop``) holds them: ``display`` (``stages(view, stamp)``, a
    generator) or None, ``diagnostics`` (``stages(stamp)``) or None, the tick ``report`` whose
    ``view()`` the display draws, and ``sim`` (its state's time stamps them).
    """

    __slots__ = ("loop", "jobs", "expected", "deferred", "forced")

    def __init__(self, loop: Any) -> None:
        self.loop = loop
        self.jobs: deque[_Job] = deque()
        #: Running mean of each stage's time (s), by (kind, stage index).
        self.expected: dict[tuple[str, int], float] = {}
        #: Sends after which a stage was left waiting; stages run past their budget.
        self.deferred = self.forced = 0

    def note(self, display: bool, diagnostics: bool) -> None:
        """Make a display (if ``display``) and a status (if ``diagnostics``) due, in order."""
        loop = self.loop
        if display and loop.display is not None:
            self._add("display", self._display())
        if diagnostics and loop.diagnostics is not None:
            self._add("diagnostics", self._diagnostics())

    def _add(self, kind: str, stages: Iterator[None]) -> None:
        for job in self.jobs:
            if job.kind == kind:
                job.newer += 1
        self.jobs.append(_Job(kind, stages))

    def _display(self) -> Iterator[None]:
        loop = self.loop
        yield from loop.display.stages(loop.report.view(), round(loop.sim.state.t * 1e9))

    def _diagnostics(self) -> Iterator[None]:
        loop = self.loop
        yield from loop.diagnostics.stages(round(loop.sim.state.t * 1e9))

    @property
    def due(self) -> bool:
        """Whether anything waits for `send`."""
        return bool(self.jobs)

    def send(self, until: Optional[float] = None,
             clock: Callable[[], float] = time.perf_counter) -> None:
        """
        Run the waiting stages in order, the display's before the diagnostics'.

        Without ``until``: all of them. With it (a time on ``clock``: when the next tick is
        due), only those expected to end before it, and those that have waited too long.
        """
        jobs, expected = self.jobs, self.expected
        forced = False
        while jobs:
            job = jobs[0]
            key = (job.kind, job.stage)
            if until is not None and clock() + SAFETY * expected.get(key, 0.0) > until:
                if job.newer < 2:  # else: two newer ones due, this one goes out whole now
                    if forced or not (job.newer or job.waited >= MAX_WAIT_TICKS):
                        self.deferred += 1
                        for waiting in jobs:
                            waiting.waited += 1
                        return
                    forced = True  # one stage past the budget a tick
                    job.waited = 0
                self.forced += 1
            t0 = clock()
            ended = next(job.stages, True)
            took = clock() - t0
            mean = expected.get(key)
            expected[key] = took if mean is None else mean + WEIGHT * (took - mean)
            job.stage += 1
            if ended:
                jobs.popleft()

    def values(self) -> list[tuple[str, Any]]:
        """Diagnostics of the sending."""
        return [("extras_deferred", self.deferred), ("extras_forced", self.forced)]
