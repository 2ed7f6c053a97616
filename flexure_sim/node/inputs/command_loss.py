"""
Drive commands a publisher sent that the node never took, counted from sequence gaps.

The command reader keeps the last ``command_depth`` commands (keep-last history). When
commands arrive faster than the stepping thread takes them, the middleware replaces the
oldest unseen one, and nothing tells the node: rmw_fastrtps_cpp (Jazzy) raises no
message-lost event for a sample a keep-last reader replaced (measured: 100 reliable commands
into a depth-5 reader, all acknowledged, 5 taken, sequence numbers 96-100, no event), and the
event would put the polled reader in the executor's wait set (`stage.qos_watch`). What the node
does see is each command's publication sequence number, which the stepping thread takes with
the command (``take_message``'s message info): a publisher numbers its messages 1, 2, 3...,
so the numbers skipped between two commands taken from one publisher are commands lost on the
way (replaced in the reader, or dropped from the publisher's own history before delivery).

rclpy's message info does not name the publisher (no gid in Jazzy: source and reception
timestamps and the two sequence numbers only), so `SequenceGaps` keeps one *stream* per
publisher it can tell apart by continuity: a number follows the stream whose last number is
the largest one below it; a number below every stream's last starts a new stream (a publisher
restarted or joined, which counts nothing); a gap while fewer streams are known than
publishers are matched starts a new stream too (the first command heard from a publisher
that joined before the node's reader). Streams beyond the matched publisher count (publishers
gone) are forgotten, least recently used first. With one publisher, the usual case, the count
is exact; with several publishers on one drive topic it is the total of the gaps the numbers
show, and a gap of one publisher can be taken for another's. Numbers never produce a negative
count.

A new stream's first number n also says that its publisher sent n - 1 commands before the
first one the node took (`SequenceGaps.unheard`): sent before the node's reader matched it (a
volatile writer delivers nothing to a reader that was not there yet, the usual case when a
controller starts publishing at once), or, when the reader overflowed before its first take,
replaced there. They are no loss of the node's, but they are counted, so that commands
recorded + lost + unheard = commands sent.

Cost in the stepping thread: one dict look-up per command (the info comes with every take),
one comparison per command when the next number follows on.
"""
from __future__ import annotations

from typing import Callable, Optional, Sequence


class SequenceGaps:
    """
    Publication sequence numbers of the commands taken, and the commands they show were lost.

    ``publishers`` returns how many publishers the subscription matches now (called only when
    a number does not follow on from the most recent stream).
    """

    def __init__(self, publishers: Callable[[], int]) -> None:
        self._publishers = publishers
        #: Last number of each stream, most recently continued first.
        self._lasts: list[int] = []
        #: Commands lost so far.
        self.lost = 0
        #: Commands numbered before the first one taken from each publisher (module docstring).
        self.unheard = 0

    def observe(self, numbers: Sequence[Optional[int]]) -> int:
        """Account for the numbers of the commands just taken, in order; return the new losses."""
        lasts = self._lasts
        lost = 0
        for n in numbers:
            if lasts and n == lasts[0] + 1:
                lasts[0] = n
            elif n is not None:  # None: a middleware without publication sequence numbers
                lost += self._place(n)
        self.lost += lost
        return lost

    def _place(self, n: int) -> int:
        lasts = self._lasts
        before = [k for k, last in enumerate(lasts) if last < n]
        publishers = None
        gap = 0
        if before:
            k = max(before, key=lasts.__getitem__)
            gap = n - lasts[k] - 1
            if gap > 0:
                publishers = self._publishers()
                if len(lasts) < publishers:
                    k, gap = -1, 0  # the first command heard from a publisher not seen yet
        else:
            k = -1  # below every stream: a publisher (re)started
        if k >= 0:
            del lasts[k]
        else:  # a new stream: its publisher sent n - 1 commands before this one
            self.unheard += max(n - 1, 0)
        lasts.insert(0, n)
        if len(lasts) > 1:
            if publishers is None:
                publishers = self._publishers()
            del lasts[max(publishers, 1):]  # publishers gone
        return gap
