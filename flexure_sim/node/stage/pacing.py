"""
Real-time pacing of the stage node's publish ticks against a steady clock (no ROS).

Tick k is due at the absolute deadline ``D_k = t0 + k * period`` of a monotonic clock
(``time.perf_counter``): the loop sleeps until shortly before ``D_k``, busy-waits the rest
(``spin_s``), then steps the engine over one publish period and publishes. Deadlines are
absolute, so sleep jitter does not accumulate.

A tick is **missed** when its work finishes after ``D_{k+1}`` (the next tick is then late).
A loop less than ``merge_after`` periods late catches up by running ticks back to back. One
further behind **merges** the ticks it is late for into the next one: that tick covers all of
their periods (`Pacer.span`: the engine steps through every one, only the last is published)
and starts on the grid slot that is due now, so simulated time stays with wall time; each
merged tick counts as missed. Running late ticks back to back instead would cost every one of
them a full tick's work (publishing and recording), and a loop whose tick takes most of a
period would then stay behind for good. If it falls more than ``max_lag_s`` behind (a stopped
process), it **slips**: the schedule is re-anchored at the current time and the ticks skipped
are counted (simulated time then runs behind wall time by that much).
"""
from __future__ import annotations

import math
import os
import sys
import threading
import time
from dataclasses import dataclass, field
from typing import Callable, Iterable, Optional

import numpy as np

#: The shortest sleep a wait makes (s): Linux's default timer slack (prctl(2),
#: PR_SET_TIMERSLACK: 50 us), by which the kernel may end any sleep late. A shorter one can
#: only end after the busy-wait meant to absorb its lateness had begun, and on a VM each sleep
#: risks a late wake of the halted core; the wait spins instead. At 4 kHz, where the stage's
#: tick (47 us) and the 0.2 ms spin leave ~3 us to sleep, interleaved 10 s runs on a 2-core VM
#: missed 0.03-0.18 % of the ticks spinning against 0.24-0.70 % sleeping those microseconds.
MIN_SLEEP_S = 50e-6
#: A wait calls its ``warm`` only with more than this left before the deadline (s): a warm-up
#: (the engine's next step, discarded: ~10 us) must end before the tick is due.
WARM_MARGIN_S = 50e-6
#: Lateness histogram: 1 us bins up to 20 ms, the last bin collects anything later.
_BIN_S = 1e-6
_BINS = 20_000


@dataclass
class PacingStats:
    """
    Counters since `Pacer.start`.

    Ticks run, ticks missed (finished after the next deadline), slips (re-anchorings) and ticks
    skipped by them, worst start lateness (s). ``merged``: ticks merged into a later one
    (simulated, not published); they count among ``ticks`` and ``missed`` too.
    """

    ticks: int = 0
    missed: int = 0
    slips: int = 0
    skipped: int = 0
    merged: int = 0
    max_late_s: float = 0.0
    late_histogram: np.ndarray = field(default_factory=lambda: np.zeros(_BINS + 1, dtype=np.int64))
    observed: int = 0

    def observe(self, late: float) -> None:
        """Count one tick's start lateness (s) in the histogram."""
        self.late_histogram[min(int(max(late, 0.0) / _BIN_S), _BINS)] += 1
        self.observed += 1
        if late > self.max_late_s:
            self.max_late_s = late

    def late_percentiles(self, *qs: float) -> tuple[float, ...]:
        """
        Start lateness (s) below which a fraction q of the ticks started (bin upper edge).

        One value for each q. Called from the paced loop (diagnostics), so it sums the
        histogram only as far as the largest q needs: 256 bins, four times more at a time while
        short (the whole 160 kB histogram summed for each status cost ~20 us back to back and
        more, paced, between ticks, where it is not in the core's caches).
        """
        if self.observed == 0:
            return tuple(0.0 for _ in qs)
        # Integer targets: a float key would make searchsorted convert the whole array.
        targets = np.array([max(1, math.ceil(q * self.observed)) for q in qs], dtype=np.int64)
        histogram, n = self.late_histogram, 256
        cumulative = np.cumsum(histogram[:n])
        while cumulative[-1] < targets.max() and n <= _BINS:
            n *= 4
            cumulative = np.cumsum(histogram[:n])
        indices = np.minimum(np.searchsorted(cumulative, targets, side="left"), _BINS)
        return tuple((int(i) + 1) * _BIN_S for i in indices)

    def late_percentile(self, q: float) -> float:
        """`late_percentiles` for one q."""
        return self.late_percentiles(q)[0]


class Pacer:
    """
    Absolute-deadline scheduler.

    ``spin_s``: the last part of each wait is busy-waited instead of slept (sleep overshoots by
    ~0.1 ms and lets the core idle); with a spin, a wait whose sleep would be shorter than
    `MIN_SLEEP_S` spins throughout. ``warm``: called once where the busy-wait begins, if more
    than `WARM_MARGIN_S` is left (the engine's discarded next step, ``Simulation.warm``: the
    tick then finds its code and data in the core's caches); not without a spin.
    ``merge_after``: periods of lateness from which the late
    ticks are merged into one (0: never, catch up tick by tick). ``clock`` and ``sleep`` are
    injectable for tests.
    """

    def __init__(
        self,
        period: float,
        *,
        max_lag_s: float = 0.1,
        spin_s: float = 0.0,
        merge_after: int = 0,
        warm: Optional[Callable[[], None]] = None,
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
        self.merge_after = int(merge_after)
        self.warm = warm
        #: Periods the current tick covers (1, or more when late ticks were merged into it).
        self.span = 1
        self._t0 = clock()
        self._k = 0

    def start(self) -> None:
        """Anchor the schedule now: the first tick is due one period from now."""
        self._t0 = self._clock()
        self._k = 0

    def reset_stats(self) -> None:
        """Restart the counters (a new run: `~/reset`); the schedule is kept."""
        self.stats = PacingStats()

    def set_period(self, period: float) -> None:
        """Change the period from the next tick on (re-anchors at the current deadline)."""
        if not period > 0:
            raise ValueError(f"period: must be > 0 s, got {period!r}")
        self._t0 = self._t0 + self._k * self.period
        self._k = 0
        self.period = float(period)
        self.max_lag_s = max(self.max_lag_s, 2.0 * self.period)

    def reanchor(self) -> None:
        """
        Forget lateness (after a pause such as a reset).

        The next tick is due one period from now, without counting a slip.
        """
        self._t0 = self._clock() - self._k * self.period

    def wait(self) -> float:
        """
        Sleep until the next tick's deadline; return the deadline.

        Late by ``merge_after`` periods or more: merge the ticks it is late for into this one
        (`span`), whose deadline is then the last grid slot due; far behind: slip.
        """
        self._k += 1
        self.span = 1
        deadline = self._t0 + self._k * self.period
        now = self._clock()
        if now < deadline:
            spin = self.spin_s
            if not spin:
                self._sleep(deadline - now)
            else:
                if deadline - now - spin >= MIN_SLEEP_S:
                    self._sleep(deadline - now - spin)
                clock = self._clock
                if self.warm is not None and deadline - clock() > WARM_MARGIN_S:
                    self.warm()
                while clock() < deadline:
                    pass
            self.stats.observe(self._clock() - deadline)  # the sleep's overshoot
            return deadline
        late = now - deadline
        if late > self.max_lag_s:
            skipped = int(late // self.period)
            self.stats.slips += 1
            self.stats.skipped += skipped
            self._t0 = now - self._k * self.period
            self.stats.observe(late)
            return now
        behind = int(late // self.period)
        if self.merge_after and behind >= self.merge_after:
            stats = self.stats
            self._k += behind
            self.span += behind
            stats.merged += behind
            stats.ticks += behind
            stats.missed += behind
            stats.observe(late)  # how late the loop was, not the merged tick's own slot
            return deadline + behind * self.period
        self.stats.observe(late)
        return deadline

    @property
    def next_deadline(self) -> float:
        """Return when the tick after the current one is due (the clock's seconds)."""
        return self._t0 + (self._k + 1) * self.period

    @property
    def clock(self) -> Callable[[], float]:
        """Return the clock the deadlines are on."""
        return self._clock

    def done(self) -> bool:
        """Mark the current tick's work finished; return True if it missed its slot."""
        self.stats.ticks += 1
        if self._clock() > self._t0 + (self._k + 1) * self.period:
            self.stats.missed += 1
            return True
        return False


def set_thread_nice(nice: int) -> tuple[int, str]:
    """
    Ask the kernel to run the calling thread at niceness ``nice`` (Linux: each thread has its own).

    Returns the niceness in effect and, if the request was refused or is not supported here, why
    (empty when granted).

    A thread below the niceness of the other processes takes a shared core from them as
    soon as it wakes; on a busy 2-core machine that is what keeps paced ticks on time.
    Lowering niceness needs CAP_SYS_NICE or an RLIMIT_NICE that allows it.
    """
    if not sys.platform.startswith("linux"):
        return 0, f"per-thread niceness is Linux only (platform {sys.platform})"
    tid = threading.get_native_id()
    try:
        os.setpriority(os.PRIO_PROCESS, tid, nice)
    except OSError as exc:
        current = os.getpriority(os.PRIO_PROCESS, tid)
        return current, (
            f"niceness {nice} refused ({exc.strerror}); the stepping thread keeps {current}. "
            "Allow it with CAP_SYS_NICE or an RLIMIT_NICE of at least "
            f"{20 - nice} (limits.conf: '<user> - nice {nice}')")
    return os.getpriority(os.PRIO_PROCESS, tid), ""


def process_threads() -> set[int]:
    """Return the native ids of this process's threads (Linux: /proc/self/task; else empty)."""
    try:
        return {int(tid) for tid in os.listdir("/proc/self/task")}
    except OSError:
        return set()


def set_threads_nice(tids: Iterable[int], nice: int) -> tuple[int, str]:
    """
    Ask the kernel to run the threads ``tids`` of this process at niceness ``nice``.

    Returns how many of them have it now and, if some were refused, why (empty otherwise).
    Threads that ended meanwhile are skipped. Same permissions as `set_thread_nice`.
    """
    done, refused = 0, ""
    for tid in tids:
        try:
            os.setpriority(os.PRIO_PROCESS, tid, nice)
        except ProcessLookupError:
            continue
        except OSError as exc:
            refused = refused or f"niceness {nice} refused ({exc.strerror})"
            continue
        done += 1
    return done, refused


def set_thread_fifo(priority: int) -> tuple[int, str]:
    """
    Run the calling thread under SCHED_FIFO at ``priority`` (Linux real-time policy).

    Returns the real-time priority in effect (0: normal scheduling) and, if refused or not
    supported here, why (empty when granted). A SCHED_FIFO thread preempts every normally
    scheduled one as soon as it wakes, whatever their niceness: next to a CPU-bound process at
    niceness 19 the node's closed loop missed 4-8 % of its ticks at stepping_nice -10 and
    0.12 % under SCHED_FIFO (BENCHMARKS.md). Processes it starts get normal scheduling
    (SCHED_RESET_ON_FORK). Needs CAP_SYS_NICE or an RLIMIT_RTPRIO of at least ``priority``.
    """
    if not sys.platform.startswith("linux"):
        return 0, f"real-time scheduling is not set up on this platform ({sys.platform})"
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO | os.SCHED_RESET_ON_FORK,
                              os.sched_param(priority))
    except OSError as exc:
        return 0, (
            f"stepping_priority {priority} (SCHED_FIFO) refused ({exc.strerror}); the stepping "
            "thread keeps normal scheduling. Allow it with CAP_SYS_NICE or an RLIMIT_RTPRIO of "
            f"at least {priority} (limits.conf: '<user> - rtprio {priority}')")
    return os.sched_getparam(0).sched_priority, ""
