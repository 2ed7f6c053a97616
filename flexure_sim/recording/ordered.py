"""
The messages of a log in log-time order, as a replay needs them.

A properly closed, intact file is first read through once (every CRC checked, nothing
decoded or kept), then played from its chunk index with the mcap library's indexed reader,
which holds only the chunks that overlap in time: memory does not grow with the file (a bag
directory: its files one after the other). A
damaged or incomplete file read with ``recover`` has no usable index: its readable payloads
are held in memory and sorted by log time (stable: file order on ties).
"""
from __future__ import annotations

import os
from collections.abc import Collection, Iterator
from pathlib import Path

from mcap.reader import make_reader

from flexure_sim.recording.reader import open_reader


class OrderedLog:
    """
    A log opened for playing.

    ``topics``, ``start_ns`` (first log time), ``complete`` and ``note`` as `LogReader` gives them,
    and `messages` (any number of passes).
    """

    def __init__(self, path: str | os.PathLike[str], recover: bool = False) -> None:
        reader = open_reader(path, recover=recover)
        #: The files played in turn: a bag's, in order (split by time: their log times follow
        #: one another), or the one file.
        self._files: list[Path] = list(getattr(reader, "files", [reader.path]))
        self._held: list[tuple[int, str, bytes]] | None = None
        if reader.summary_ok and not recover:
            reader.read_through(decode=False)  # refuses a damaged file before anything plays
        else:
            held = [(m.log_time_ns, m.topic, m.data) for m in reader.messages(decode=False)]
            held.sort(key=lambda item: item[0])
            self._held = held
        self.path: Path = reader.path
        self.topics = reader.topics
        self.start_ns = reader.start_ns
        self.message_count = reader.message_count
        self.complete = reader.complete
        self.note = reader.note
        self.undecodable: dict[str, int] = {}

    def messages(self, topics: Collection[str], start_ns: int) -> Iterator[tuple[int, str, bytes]]:
        """
        (log time ns, topic, payload) of ``topics`` logged at or after ``start_ns``.

        They come in log-time order.
        """
        wanted = set(topics)
        if self._held is not None:
            for item in self._held:
                if item[1] in wanted and item[0] >= start_ns:
                    yield item
            return
        if not wanted:
            return
        for path in self._files:
            with path.open("rb") as stream:
                reader = make_reader(stream, validate_crcs=True)
                for _, channel, message in reader.iter_messages(
                    topics=sorted(wanted), log_time_order=True
                ):  # (no time bound: its keyword changed between mcap versions)
                    if message.log_time >= start_ns:
                        yield message.log_time, channel.topic, message.data
