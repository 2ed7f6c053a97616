"""
The MCAP file the recorder writes, with a message path that takes a tick at a time.

``BatchWriter`` writes the file ``mcap.writer.Writer`` writes with ``chunk_size``, no
compression, ``enable_crcs`` and ``enable_data_crcs`` (every index, statistics, summary
offsets), byte for byte for the same calls (``test/test_mcap_batch.py`` holds the two side by
side); every record other than a message is the library's (``mcap.records``). What it adds is
``add_batch`` and ``add_frame``: a tick's messages, one log time, packed with one ``struct``
call each and joined into the open chunk once per chunk; a frame's payloads are views into it
until then, and the message indexes are arrays of integers (no Python object a message that
lives until the chunk ends, which the cyclic garbage collector would walk). ``flexure-sim
bench`` (``recorder``): 0.62 us of CPU a message against the library's 2.66 us.

Measured reason for writing it rather than calling ``Writer.add_message``: the library builds
a ``Message`` object and writes five fields through a ``BytesIO`` for each message, 2.9 us a
message; with the recorder's own bookkeeping 6.6 us, or 170 us of CPU for each of the stage's
26-message ticks: a third of a core at 2 kHz, next to the node and a controller on a 2-core
machine. In the 2 kHz closed loop of ``tools/bench/closed_loop.py`` (interleaved runs), a
recorder that wrote only the two control topics let 98.1-98.4 % of the commands reach the next
tick, against 92.6-93.0 % with every topic written: the difference was the recorder's work.
With this writer and frames passed through (``McapRecorder.write_frame``), 97.5 % (two runs).
``flexure-sim bench`` prints the CPU time a message of both writers (``recorder``,
``tools/bench/recorder_bench.py``).
"""
from __future__ import annotations

import struct
import sys
import zlib
from array import array
from typing import BinaryIO, Iterator, Sequence, TypeVar

from mcap.data_stream import RecordBuilder
from mcap.opcode import Opcode
from mcap.records import (
    Channel, Chunk, ChunkIndex, DataEnd, Footer, Header, Metadata, MetadataIndex, Schema,
    Statistics, SummaryOffset,
)

from flexure_sim.recording.exceptions import RecordingError

#: A message in a recorder frame (``add_frame``): its channel's index, its size; the payload
#: follows.
FRAME_ITEM = struct.Struct("<HI")
T = TypeVar("T")
#: A MessageIndex record's head: opcode, record length, channel id, byte length of its
#: (log time, offset) pairs, which follow as little-endian uint64s (MCAP spec, "Message Index").
INDEX_HEAD = struct.Struct("<BQHI")
_MESSAGE_INDEX = int(Opcode.MESSAGE_INDEX)
_SWAP = sys.byteorder != "little"
#: The file's first and last 8 bytes (MCAP spec, "Magic").
MAGIC = bytes((137, 77, 67, 65, 80, 48, 13, 10))
#: A Message record's head: opcode, record length, channel id, sequence, log time, publish
#: time (MCAP spec, "Message"); the payload follows.
MESSAGE_HEAD = struct.Struct("<BQHIQQ")
_HEAD = MESSAGE_HEAD.size
_HEAD_FIELDS = _HEAD - 9      # the record length counts what follows its own field
_MESSAGE = int(Opcode.MESSAGE)
_SEQUENCE_MASK = 0xFFFFFFFF


def frame_messages(frame: bytes, start: int, names: Sequence[T]) -> Iterator[tuple[T, memoryview]]:
    """
    (``names[index]``, payload) of each message of a frame from ``start`` (``add_frame``).

    The payloads are views into ``frame``; `RecordingError` if the last one ends past it.
    """
    view = memoryview(frame)
    end = len(frame)
    unpack = FRAME_ITEM.unpack_from
    step = FRAME_ITEM.size
    at = start
    while at < end:
        index, size = unpack(frame, at)
        at += step
        yield names[index], view[at:at + size]
        at += size
    if at != end:
        raise RecordingError(f"a recorder frame's last message ends {at - end} bytes after "
                             "the frame")


class BatchWriter:
    """
    An MCAP writer on ``stream`` (``write`` and ``tell``; `mcap_writer.PositionStream`).

    The methods of ``mcap.writer.Writer`` the recorder uses (``start``, ``register_schema``,
    ``register_channel``, ``add_metadata``, ``flush``, ``finish``) with the same results, and
    ``add_batch`` and ``add_frame`` for its messages, the same records as the library's
    ``add_message`` of each. A chunk is finished once it passes ``chunk_size`` bytes, after
    the message that passed it, as the library does.
    """

    def __init__(self, stream: BinaryIO, chunk_size: int) -> None:
        self._stream = stream
        self._chunk_size = chunk_size
        self._data_crc = 0
        self._schemas: list[Schema] = []
        self._channels: list[Channel] = []
        # The open chunk: its records as parts, their length, the message index per channel
        # ({channel: array of log time, offset in the chunk, log time, ...}: no Python object
        # a message that lives until the chunk ends), its messages and time span.
        self._parts: list[bytes | memoryview] = []
        self._size = 0
        self._index: dict[int, array] = {}
        self._in_chunk = 0
        self._chunk_start = self._chunk_end = 0
        # The file's statistics and indexes.
        self._counts: dict[int, int] = {}
        self._messages = 0
        self._start = self._end = 0
        self._chunk_indexes: list[ChunkIndex] = []
        self._metadata_indexes: list[MetadataIndex] = []

    @property
    def message_times(self) -> tuple[int, int]:
        """Return the earliest and latest log time of the messages written ((0, 0): none)."""
        return self._start, self._end

    @property
    def channel_counts(self) -> dict[int, int]:
        """Messages written so far per channel id (the Statistics record's counts)."""
        return self._counts

    def _emit(self, data: bytes) -> None:
        """Write ``data`` to the data section (its CRC follows)."""
        self._data_crc = zlib.crc32(data, self._data_crc)
        self._stream.write(data)

    @staticmethod
    def _record(record) -> bytes:
        builder = RecordBuilder()
        record.write(builder)
        return builder.end()

    def start(self, profile: str, library: str) -> None:
        """Magic and the Header record."""
        self._emit(MAGIC)
        self._emit(self._record(Header(profile, library)))

    def register_schema(self, name: str, encoding: str, data: bytes) -> int:
        """Add a Schema record to the open chunk; return its id (1, 2, ...)."""
        schema = Schema(id=len(self._schemas) + 1, data=data, encoding=encoding, name=name)
        self._schemas.append(schema)
        self._to_chunk(self._record(schema))
        return schema.id

    def register_channel(self, topic: str, message_encoding: str, schema_id: int,
                         metadata: dict[str, str]) -> int:
        """Add a Channel record to the open chunk; return its id (1, 2, ...)."""
        channel = Channel(id=len(self._channels) + 1, topic=topic,
                          message_encoding=message_encoding, schema_id=schema_id,
                          metadata=metadata)
        self._channels.append(channel)
        self._to_chunk(self._record(channel))
        return channel.id

    def _to_chunk(self, record: bytes) -> None:
        self._parts.append(record)
        self._size += len(record)
        if self._size > self._chunk_size:
            self._finish_chunk()

    def add_batch(self, stamp: int, messages: Sequence[tuple[int, bytes]]) -> None:
        """
        Add the Message records of ``messages`` (channel id, payload) at log time ``stamp``.

        Each message's sequence is its number on its channel in this file (1, 2, ...; modulo
        2^32): the same records as ``add_message(channel, stamp, payload, stamp, number)``.
        """
        if messages:
            self._put(stamp, iter(messages))

    def add_frame(self, stamp: int, frame: bytes, start: int,
                  channel_ids: Sequence[int]) -> None:
        """
        Add a frame's messages, as ``add_batch`` does.

        From ``start``, per message ``FRAME_ITEM`` (its index into ``channel_ids``, its size)
        then its payload (the recorder process's ``B`` frames, ``node/record/process.py``).
        The payloads are not copied until the chunk is.
        """
        if start < len(frame):
            self._put(stamp, frame_messages(frame, start, channel_ids))

    def _put(self, stamp: int, messages: Iterator[tuple[int, bytes | memoryview]]) -> None:
        """Add the Message records of at least one message (``add_batch``), in one loop."""
        pack = MESSAGE_HEAD.pack
        append = self._parts.append
        index = self._index
        counts = self._counts
        limit = self._chunk_size
        size = self._size
        self._times(stamp)
        added = total = 0
        for channel_id, data in messages:
            number = counts.get(channel_id, 0) + 1
            counts[channel_id] = number
            entries = index.get(channel_id)
            if entries is None:
                entries = index[channel_id] = array("Q")
            entries.append(stamp)
            entries.append(size)
            length = len(data)
            append(pack(_MESSAGE, _HEAD_FIELDS + length, channel_id, number & _SEQUENCE_MASK,
                        stamp, stamp))
            append(data)
            size += _HEAD + length
            added += 1
            if size > limit:
                self._size, self._in_chunk = size, self._in_chunk + added
                self._finish_chunk()
                total += added
                size = added = 0
                self._chunk_start = self._chunk_end = stamp
                append, index = self._parts.append, self._index
        self._size = size
        self._in_chunk += added
        self._messages += total + added

    def _times(self, log_time: int) -> None:
        """Widen the open chunk's and the file's message time spans to ``log_time``."""
        if not self._in_chunk:
            self._chunk_start = self._chunk_end = log_time
        elif log_time < self._chunk_start:
            self._chunk_start = log_time
        elif log_time > self._chunk_end:
            self._chunk_end = log_time
        if not self._messages or log_time < self._start:
            self._start = log_time
        if log_time > self._end:
            self._end = log_time

    def add_metadata(self, name: str, data: dict[str, str]) -> None:
        """Write a Metadata record into the data section, indexed (``Writer.add_metadata``)."""
        offset = self._stream.tell()
        record = self._record(Metadata(name=name, metadata=data))
        self._metadata_indexes.append(MetadataIndex(offset=offset, length=len(record),
                                                    name=name))
        self._emit(record)

    def _finish_chunk(self) -> None:
        """Write the open chunk as a Chunk record, then its message indexes (as ``Writer``)."""
        if not self._in_chunk:
            return
        data = b"".join(self._parts)
        chunk = Chunk(compression="", data=data, message_start_time=self._chunk_start,
                      message_end_time=self._chunk_end, uncompressed_crc=zlib.crc32(data),
                      uncompressed_size=len(data))
        record = self._record(chunk)
        start = self._stream.tell()
        self._emit(record)
        entry = ChunkIndex(message_start_time=self._chunk_start,
                           message_end_time=self._chunk_end, chunk_start_offset=start,
                           chunk_length=len(record), message_index_offsets={},
                           message_index_length=0, compression="",
                           compressed_size=len(data), uncompressed_size=len(data))
        at = first = start + len(record)
        indexes = []
        for channel_id, entries in self._index.items():
            entry.message_index_offsets[channel_id] = at
            if _SWAP:
                entries.byteswap()
            size = 8 * len(entries)
            indexes.append(INDEX_HEAD.pack(_MESSAGE_INDEX, 6 + size, channel_id, size))
            indexes.append(entries.tobytes())
            at += INDEX_HEAD.size + size
        entry.message_index_length = at - first
        self._emit(b"".join(indexes))
        self._chunk_indexes.append(entry)
        self._parts, self._size, self._index, self._in_chunk = [], 0, {}, 0

    def flush(self) -> None:
        """Finish the open chunk (if it holds a message) and flush the stream."""
        self._finish_chunk()
        self._stream.flush()

    def finish(self) -> None:
        """DataEnd, the summary (``Writer.finish``'s groups and offsets), Footer, magic."""
        self._finish_chunk()
        self._emit(self._record(DataEnd(self._data_crc)))
        summary_start = self._stream.tell()
        summary = RecordBuilder()
        offsets = []
        statistics = Statistics(
            attachment_count=0, channel_count=len(self._channels),
            channel_message_counts=self._counts, chunk_count=len(self._chunk_indexes),
            message_count=self._messages, metadata_count=len(self._metadata_indexes),
            message_start_time=self._start, message_end_time=self._end,
            schema_count=len(self._schemas))
        groups = ((Opcode.SCHEMA, self._schemas), (Opcode.CHANNEL, self._channels),
                  (Opcode.STATISTICS, [statistics]), (Opcode.CHUNK_INDEX, self._chunk_indexes),
                  (Opcode.ATTACHMENT_INDEX, []), (Opcode.METADATA_INDEX, self._metadata_indexes))
        for opcode, records in groups:
            group_start = summary.count
            for record in records:
                record.write(summary)
            offsets.append(SummaryOffset(group_opcode=opcode,
                                         group_start=summary_start + group_start,
                                         group_length=summary.count - group_start))
        offset_start = summary_start + summary.count
        for offset in offsets:
            offset.write(summary)
        data = summary.end()
        crc = zlib.crc32(data)
        crc = zlib.crc32(struct.pack("<BQQQ", Opcode.FOOTER, 20, summary_start, offset_start),
                         crc)
        self._stream.write(data)
        self._stream.write(self._record(Footer(summary_start=summary_start,
                                               summary_offset_start=offset_start,
                                               summary_crc=crc)))
        self._stream.write(MAGIC)
