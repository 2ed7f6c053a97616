"""Drive command intake of the stage node: the stepping thread takes what the command
subscription's reader holds once per tick (`polled`), validates each command in order
(`drive_input.CommandFilter`), warns at most once per second per kind, and records every
received command — rejected ones included — at the tick's log time.
"""
from __future__ import annotations

import math
from typing import Any, Callable, Optional

from .drive_input import CommandFilter, CommandStatus, WarningThrottle, parse_float64_cdr
from .interface import COMMAND_DEPTH
from .polled import take_raw

#: Most commands taken from the reader per tick (more wait for the next tick).
COMMAND_TAKE_LIMIT = COMMAND_DEPTH


class CommandIntake:
    """Commands of one polled subscription into one `CommandFilter` (None: no drive) and onto
    recording channel ``channel`` through ``record(items, stamp)``."""

    def __init__(self, subscription: Any, drive_filter: Optional[CommandFilter], channel: int,
                 record: Callable[[list[tuple[int, bytes]], int], None], log: Any,
                 throttle: WarningThrottle) -> None:
        self.subscription = subscription
        self.filter = drive_filter
        self.channel = channel
        self._record = record
        self._log = log
        self._throttle = throttle

    def apply(self, stamp: int) -> None:
        """Take the commands received since the last tick; validate them in order; record each
        at log time ``stamp`` (ns)."""
        commands = take_raw(self.subscription, COMMAND_TAKE_LIMIT)
        if not commands:
            return
        filt = self.filter
        channel = self.channel
        received = [(channel, data) for data in commands]
        if filt is not None:
            for data in commands:
                try:
                    value = parse_float64_cdr(data)
                except ValueError:
                    value = math.nan
                status = filt.submit(value)
                if status is CommandStatus.REJECTED:
                    self.warn("rejected", f"drive command {value!r} rejected (not finite)")
                elif status is CommandStatus.CLAMPED:
                    lim = filt.limits
                    self.warn("clamped", f"drive command {value:g} m outside the stroke "
                              f"[{lim.stroke_min:g}, {lim.stroke_max:g}] m: clamped")
        self._record(received, stamp)

    def discard(self) -> None:
        """Drop what the reader holds (commands sent before a reset)."""
        take_raw(self.subscription, COMMAND_TAKE_LIMIT)

    def warn(self, kind: str, message: str) -> None:
        """A throttled warning about one command of ``kind`` (a counter of the filter)."""
        count = self._throttle.event(kind)
        if count is not None:
            total = getattr(self.filter.counters, kind) if self.filter else count
            suffix = (f" ({count} such commands since the last warning, {total} in all)"
                      if count > 1 else f" ({total} in all)")
            self._log.warning(message + suffix)
