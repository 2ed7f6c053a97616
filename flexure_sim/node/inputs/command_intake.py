"""
Drive command intake of the stage node.

The stepping thread takes what the command subscription's reader holds once per tick (`polled`),
validates each command in order (`drive_input.CommandFilter`), warns at most once per second per
kind, and records every received command at the tick's log time: a Float64 (accepted, clamped
or rejected as not finite) on the command topic's channel, a payload that is not a Float64 on
the topic's ``/rejected`` channel as a std_msgs/UInt8MultiArray holding the received bytes
(`cdr.pack_uint8_array`), so that the command channel holds nothing but Float64s. Commands a
publisher sent that the reader replaced before a tick took them are counted from the gaps in
their sequence numbers (`command_loss`).
"""
from __future__ import annotations

import struct
import time
from typing import Any, Callable, Optional, Sequence

from flexure_sim.node.publish.cdr import (
    CDR_LE, FAST_DDS, middleware, pack_uint8_array, parse_float64,
)
from flexure_sim.node.inputs.drive_bank import units
from flexure_sim.node.inputs.command_checks import CommandFilter, WarningThrottle
from flexure_sim.node.inputs.command_loss import SequenceGaps
from flexure_sim.node.publish.interface import COMMAND_DEPTH
from flexure_sim.node.stage.polled import take_raw

#: Suffix of the recording channel of a command topic's malformed payloads.
REJECTED_SUFFIX = "/rejected"
#: A std_msgs/Float64 as rmw_fastrtps writes it: the CDR_LE header (read as a uint32), the
#: float64. `decode_float64_batch` unpacks a batch of these with one struct call.
_FLOAT64_SIZE = 12
_CDR_LE_WORD = struct.unpack("<I", CDR_LE)[0]
_batch_structs: dict[int, struct.Struct] = {}


def decode_float64_batch(payloads: Sequence[bytes],
                         malformed: Optional[list[int]] = None) -> tuple[list[float], list[str]]:
    """
    Return the values of the payloads that decode as std_msgs/Float64, and why the others do not.

    The values are in order, as `cdr.parse_float64` gives them one by one: a batch of plain
    little-endian payloads under Fast DDS (the usual case) in one ``struct.unpack``, anything
    else through parse_float64. test_node_commands pins the two together. ``malformed``: a list
    to which the index of each payload that does not decode is appended.
    """
    n = len(payloads)
    if set(map(len, payloads)) == {_FLOAT64_SIZE} and middleware() in FAST_DDS:
        layout = _batch_structs.get(n)
        if layout is None:
            layout = _batch_structs.setdefault(n, struct.Struct("<" + "Id" * n))
        fields = layout.unpack(b"".join(payloads))
        if fields[0::2].count(_CDR_LE_WORD) == n:
            return list(fields[1::2]), []
    values, problems = [], []
    for k, data in enumerate(payloads):
        try:
            values.append(parse_float64(data))
        except ValueError as exc:  # not a Float64 we can read: refused, never a NaN
            problems.append(str(exc))
            if malformed is not None:
                malformed.append(k)
    return values, problems


class CommandIntake:
    """
    Commands of one polled subscription into one `CommandFilter` and onto recording channels.

    The filter is None: no drive; the channel is ``channel``, malformed payloads go to
    ``rejected_channel``, through ``record(items, stamp)``. ``label`` and ``unit`` name the
    drive and its unit in warnings (``drive 'x'``, ``rad``). ``depth``: the reader's history
    depth, the most commands taken per tick (more wait for the next tick).
    """

    def __init__(self, subscription: Any, drive_filter: Optional[CommandFilter], channel: int,
                 record: Callable[[list[tuple[int, bytes]], int], None], log: Any,
                 throttle: WarningThrottle, label: str = "drive", unit: str = "m",
                 rejected_channel: int = -1, depth: int = COMMAND_DEPTH) -> None:
        self.label = label
        self.unit = unit
        self.subscription = subscription
        self.filter = drive_filter
        self.channel = channel
        self.rejected_channel = rejected_channel
        self.depth = depth
        self._record = record
        self._log = log
        self._throttle = throttle
        #: Commands taken so far, and the wall-clock time their intake took (s).
        self.count = 0
        self.time_s = 0.0
        self.gaps = SequenceGaps(subscription.get_publisher_count)

    def apply(self, stamp: int) -> None:
        """
        Take the commands received since the last tick.

        Validate them in order; record each at log time ``stamp`` (ns). Per batch, not per command:
        one decode, one filter call, one recording frame; the time it takes is summed in `time_s`
        (`count` commands).
        """
        t0 = time.perf_counter()
        numbers: list[Optional[int]] = []
        commands = take_raw(self.subscription, self.depth, numbers)
        if not commands:
            return
        self._count_lost(numbers)
        filt = self.filter
        malformed: list[int] = []
        if filt is not None:
            values, problems = decode_float64_batch(commands, malformed)
            for _ in problems:
                filt.reject_malformed()
            if problems:
                self.warn("malformed", f"{self.label} command rejected: {problems[0]}",
                          len(problems))
            rejected, clamped, bad, outside = filt.submit_many(values)
            if rejected:
                self.warn("rejected", f"{self.label} command {bad!r} rejected (not finite)",
                          rejected)
            if clamped:
                lim, unit = filt.limits, self.unit
                self.warn("clamped", f"{self.label} command {outside:g} {unit} outside the "
                          f"stroke [{lim.stroke_min:g}, {lim.stroke_max:g}] {unit}: clamped",
                          clamped)
        channel = self.channel
        if malformed:
            unreadable = set(malformed)
            elsewhere = self.rejected_channel
            self._record([(elsewhere, pack_uint8_array(data)) if k in unreadable
                          else (channel, data) for k, data in enumerate(commands)], stamp)
        else:
            self._record([(channel, data) for data in commands], stamp)
        self.count += len(commands)
        self.time_s += time.perf_counter() - t0

    def _count_lost(self, numbers: list[Optional[int]]) -> None:
        unheard = self.gaps.unheard
        lost = self.gaps.observe(numbers)
        if self.filter is not None:
            self.filter.counters.unheard += self.gaps.unheard - unheard
        if lost and self.filter is not None:
            self.filter.counters.lost += lost
            self.warn("lost", f"{self.label} commands lost: a publisher sent {lost} commands "
                      f"the node never took (its command reader holds {self.depth}, taken "
                      f"once per tick; the oldest are replaced)", lost)

    def discard(self) -> None:
        """Drop what the reader holds (commands sent before a reset; gaps still count)."""
        numbers: list[Optional[int]] = []
        take_raw(self.subscription, self.depth, numbers)
        self._count_lost(numbers)

    def warn_rate_limited(self) -> None:
        """Warn that the last accepted command is beyond the slew limit within a tick."""
        self.warn("rate_limited", f"{self.label} command faster than the slew limit "
                  f"({self.filter.limits.slew_rate:g} {self.unit}/s): ramping")

    def warn(self, kind: str, message: str, events: int = 1) -> None:
        """
        Log a throttled warning about ``events`` commands of ``kind``.

        ``kind`` is a counter of the filter; ``message`` describes the last of them.
        """
        count = self._throttle.event(kind, events)
        if count is not None:
            total = getattr(self.filter.counters, kind) if self.filter else count
            suffix = (f" ({count} such commands since the last warning, {total} in all)"
                      if count > 1 else f" ({total} in all)")
            self._log.warning(message + suffix)


class IntakeGroup:
    """The intakes of several drives (one subscription each), used like one `CommandIntake`."""

    def __init__(self, intakes: Sequence[CommandIntake], bank: Any) -> None:
        self.intakes = list(intakes)
        self._bank = bank  # drive_bank.FilterBank: which drives were rate-limited

    @property
    def count(self) -> int:
        return sum(i.count for i in self.intakes)

    @property
    def time_s(self) -> float:
        return sum(i.time_s for i in self.intakes)

    def apply(self, stamp: int) -> None:
        for intake in self.intakes:
            intake.apply(stamp)

    def discard(self) -> None:
        for intake in self.intakes:
            intake.discard()

    def warn_rate_limited(self) -> None:
        """Warn for each drive whose filter counted its command as rate-limited this tick."""
        for intake, limited in zip(self.intakes, self._bank.limited):
            if limited:
                intake.warn_rate_limited()


def intake_for(subscriptions: Sequence[Any], drive_filter: Any, named: Sequence[Any],
               first_channel: int, record: Callable[[list[tuple[int, bytes]], int], None],
               log: Any, throttle: WarningThrottle, unit: str = "m",
               first_rejected: int = -1, depth: int = COMMAND_DEPTH) -> Any:
    """
    Return the stepping loop's intake of the command ``subscriptions`` (one per drive).

    The single drive's `CommandIntake` (``named`` empty), an `IntakeGroup` of the ``named``
    drives of the `drive_bank.FilterBank` ``drive_filter``, or None without a drive; drive k
    records on channel ``first_channel + k``, its malformed payloads on ``first_rejected + k``.
    ``unit``: the single drive's command unit; ``depth``: the readers' history depth.
    """
    if not subscriptions:
        return None
    if not named:
        return CommandIntake(subscriptions[0], drive_filter, first_channel, record, log,
                             throttle, unit=unit, rejected_channel=first_rejected, depth=depth)
    return IntakeGroup([
        CommandIntake(sub, drive_filter.filters[k], first_channel + k, record, log, throttle,
                      f"drive {d.name}", units(d)[0], first_rejected + k, depth)
        for k, (sub, d) in enumerate(zip(subscriptions, named))], drive_filter)
