"""
From log time to simulation time.

stage_node stamps every recorded message with log time = simulation time, so usually the map
is the identity. ``ros2 bag record`` without ``--use-sim-time`` of a fast-mode run logs the
wall-clock time of reception instead; if the recorded /clock values lie further than
`CLOCK_MISMATCH_NS` (median) from their own log times, a message's simulation time is the last
/clock value logged at or before it (exact to one tick).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Optional

import numpy as np

#: Log times further than this from the /clock values they carry are not simulation time.
CLOCK_MISMATCH_NS = 500_000_000


@dataclass(frozen=True)
class TimeBase:
    """
    ``clock``.

    (log times, sim times) of the recorded /clock, sorted by log time, when log times are not
    simulation time; None when they are.
    """

    clock: Optional[tuple[np.ndarray, np.ndarray]] = None

    @property
    def mapped(self) -> bool:
        return self.clock is not None

    def sim_ns(self, log_times_ns: np.ndarray) -> np.ndarray:
        """Return the simulation time (ns) of messages logged at ``log_times_ns``."""
        log_times_ns = np.asarray(log_times_ns, dtype=np.int64)
        if self.clock is None:
            return log_times_ns
        log_t, sim_t = self.clock
        k = np.searchsorted(log_t, log_times_ns, side="right") - 1
        return sim_t[np.clip(k, 0, sim_t.shape[0] - 1)]

    def seconds(self, log_times_ns: np.ndarray) -> np.ndarray:
        return self.sim_ns(log_times_ns) / 1e9


def time_base(clock_log_ns: Optional[np.ndarray], clock_sim_ns: Optional[np.ndarray]) -> TimeBase:
    """
    Return the time base of a run from its recorded /clock, if any.

    The /clock is given as log times and values, ns.
    """
    if clock_log_ns is None or clock_sim_ns is None or clock_log_ns.shape[0] == 0:
        return TimeBase()
    if float(np.median(np.abs(clock_log_ns - clock_sim_ns))) <= CLOCK_MISMATCH_NS:
        return TimeBase()
    order = np.argsort(clock_log_ns, kind="stable")
    return TimeBase((clock_log_ns[order], clock_sim_ns[order]))
