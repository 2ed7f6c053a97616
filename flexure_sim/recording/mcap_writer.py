"""Synchronous, chunked and indexed MCAP writer that hands every finished chunk to the OS.

File layout (valid MCAP, the layout the C++ writer used by rosbag2 produces):
magic, Header; Schema and Channel records in the data section as they are added; Chunks
(uncompressed, with CRC), each followed by its MessageIndex records; Metadata records;
DataEnd (with data section CRC); summary (Schemas, Channels, Statistics, ChunkIndexes,
MetadataIndexes, SummaryOffsets); Footer (with summary CRC); magic.

Every finished chunk and every record outside chunks is flushed to the OS at once, so a killed
process leaves a file whose complete chunks a linear reader recovers. Not thread-safe: one
thread (the recorder's background writer) owns an instance.
"""
from __future__ import annotations

import contextlib
import os
import struct
import zlib
from collections import defaultdict
from typing import BinaryIO

from mcap.data_stream import RecordBuilder
from mcap.opcode import Opcode
from mcap.records import (
    Channel,
    Chunk,
    ChunkIndex,
    DataEnd,
    Footer,
    Header,
    McapRecord,
    Message,
    MessageIndex,
    Metadata,
    MetadataIndex,
    Schema,
    Statistics,
    SummaryOffset,
)

MAGIC = b"\x89MCAP0\r\n"


class ChunkedMcapWriter:
    """Writes one MCAP file to ``stream`` (which it closes in `finish`).

    ``chunk_size`` bounds the uncompressed size of a chunk; `finish_chunk` closes the open chunk
    early (the recorder calls it on a timer). ``fsync`` adds an ``os.fsync`` after each chunk
    (survives power loss, not only a killed process), when the stream has a file descriptor.
    """

    def __init__(
        self,
        stream: BinaryIO,
        *,
        profile: str,
        library: str,
        chunk_size: int = 1 << 20,
        fsync: bool = False,
    ) -> None:
        if chunk_size <= 0:
            raise ValueError(f"chunk_size: must be > 0, got {chunk_size}")
        self._stream = stream
        self._chunk_size = chunk_size
        self._fsync = fsync
        self._position = 0
        self._data_crc = 0
        self._schemas: dict[int, Schema] = {}
        self._channels: dict[int, Channel] = {}
        self._chunk_indexes: list[ChunkIndex] = []
        self._metadata_indexes: list[MetadataIndex] = []
        self._channel_counts: dict[int, int] = defaultdict(int)
        self._message_count = 0
        self._start_time = 0
        self._end_time = 0
        self._chunk = RecordBuilder()
        self._chunk_messages = 0
        self._chunk_start = 0
        self._chunk_end = 0
        self._chunk_index: dict[int, list[tuple[int, int]]] = {}
        self._finished = False
        self._write_raw(MAGIC)
        self._write_records([Header(profile=profile, library=library)])

    # -- state ------------------------------------------------------------------------------
    @property
    def open_chunk_messages(self) -> int:
        """Messages buffered in the chunk not yet written."""
        return self._chunk_messages

    @property
    def message_count(self) -> int:
        return self._message_count

    @property
    def channel_message_counts(self) -> dict[int, int]:
        return dict(self._channel_counts)

    @property
    def message_time_range(self) -> tuple[int, int]:
        """(first, last) log time in ns; (0, 0) before the first message."""
        return self._start_time, self._end_time

    @property
    def chunk_count(self) -> int:
        return len(self._chunk_indexes)

    # -- records ----------------------------------------------------------------------------
    def add_schema(self, schema_id: int, name: str, encoding: str, data: bytes) -> None:
        if schema_id in self._schemas:
            raise ValueError(f"schema_id: {schema_id} already added")
        schema = Schema(id=schema_id, name=name, encoding=encoding, data=data)
        self._schemas[schema_id] = schema
        self._write_records([schema])

    def add_channel(
        self,
        channel_id: int,
        topic: str,
        message_encoding: str,
        schema_id: int,
        metadata: dict[str, str],
    ) -> None:
        if channel_id in self._channels:
            raise ValueError(f"channel_id: {channel_id} already added")
        if schema_id not in self._schemas:
            raise ValueError(f"schema_id: {schema_id} was not added")
        channel = Channel(
            id=channel_id,
            topic=topic,
            message_encoding=message_encoding,
            metadata=dict(metadata),
            schema_id=schema_id,
        )
        self._channels[channel_id] = channel
        self._write_records([channel])

    def add_message(
        self, channel_id: int, log_time: int, publish_time: int, sequence: int, data: bytes
    ) -> bool:
        """Buffer a message in the open chunk; return True if this closed (wrote) the chunk."""
        if channel_id not in self._channels:
            raise ValueError(f"channel_id: {channel_id} was not added")
        if self._chunk_messages == 0:
            self._chunk_start = self._chunk_end = log_time
        else:
            self._chunk_start = min(self._chunk_start, log_time)
            self._chunk_end = max(self._chunk_end, log_time)
        if self._message_count == 0:
            self._start_time = self._end_time = log_time
        else:
            self._start_time = min(self._start_time, log_time)
            self._end_time = max(self._end_time, log_time)
        self._chunk_index.setdefault(channel_id, []).append((log_time, self._chunk.count))
        Message(
            channel_id=channel_id,
            log_time=log_time,
            publish_time=publish_time,
            sequence=sequence & 0xFFFFFFFF,
            data=data,
        ).write(self._chunk)
        self._chunk_messages += 1
        self._message_count += 1
        self._channel_counts[channel_id] += 1
        if self._chunk.count >= self._chunk_size:
            return self.finish_chunk()
        return False

    def add_metadata(self, name: str, data: dict[str, str]) -> None:
        offset = self._position
        self._write_records([Metadata(name=name, metadata=dict(data))])
        self._metadata_indexes.append(
            MetadataIndex(offset=offset, length=self._position - offset, name=name)
        )

    def finish_chunk(self) -> bool:
        """Write the open chunk and its message indexes, then flush; False if it was empty."""
        if self._chunk_messages == 0:
            return False
        records = self._chunk.end()
        chunk = Chunk(
            compression="",
            data=records,
            message_start_time=self._chunk_start,
            message_end_time=self._chunk_end,
            uncompressed_crc=zlib.crc32(records),
            uncompressed_size=len(records),
        )
        chunk_start = self._position
        builder = RecordBuilder()
        chunk.write(builder)
        chunk_length = builder.count
        index_offsets: dict[int, int] = {}
        for channel_id in sorted(self._chunk_index):
            index_offsets[channel_id] = chunk_start + builder.count
            entries = sorted(self._chunk_index[channel_id])
            MessageIndex(channel_id=channel_id, records=entries).write(builder)
        self._write_raw(builder.end())
        self._chunk_indexes.append(
            ChunkIndex(
                message_start_time=chunk.message_start_time,
                message_end_time=chunk.message_end_time,
                chunk_start_offset=chunk_start,
                chunk_length=chunk_length,
                message_index_offsets=index_offsets,
                message_index_length=self._position - chunk_start - chunk_length,
                compression="",
                compressed_size=len(records),
                uncompressed_size=len(records),
            )
        )
        self._chunk_messages = 0
        self._chunk_index = {}
        self._sync()
        return True

    def finish(self) -> None:
        """Write the last chunk, DataEnd, the summary and the footer; sync and close the stream."""
        if self._finished:
            return
        self.finish_chunk()
        self._write_records([DataEnd(data_section_crc=self._data_crc)])
        summary_start = self._position
        builder = RecordBuilder()
        offsets: list[SummaryOffset] = []

        def group(opcode: Opcode, records: list[McapRecord]) -> None:
            if not records:
                return
            start = builder.count
            for record in records:
                record.write(builder)
            offsets.append(
                SummaryOffset(
                    group_opcode=opcode,
                    group_start=summary_start + start,
                    group_length=builder.count - start,
                )
            )

        statistics = Statistics(
            message_count=self._message_count,
            schema_count=len(self._schemas),
            channel_count=len(self._channels),
            attachment_count=0,
            metadata_count=len(self._metadata_indexes),
            chunk_count=len(self._chunk_indexes),
            message_start_time=self._start_time,
            message_end_time=self._end_time,
            channel_message_counts=dict(sorted(self._channel_counts.items())),
        )
        group(Opcode.SCHEMA, list(self._schemas.values()))
        group(Opcode.CHANNEL, list(self._channels.values()))
        group(Opcode.STATISTICS, [statistics])
        group(Opcode.CHUNK_INDEX, list(self._chunk_indexes))
        group(Opcode.METADATA_INDEX, list(self._metadata_indexes))
        summary_offset_start = summary_start + builder.count
        for offset in offsets:
            offset.write(builder)
        summary = builder.end()
        footer_prefix = struct.pack("<BQQQ", Opcode.FOOTER, 20, summary_start, summary_offset_start)
        summary_crc = zlib.crc32(footer_prefix, zlib.crc32(summary))
        self._write_raw(summary)
        self._write_records(
            [
                Footer(
                    summary_start=summary_start,
                    summary_offset_start=summary_offset_start,
                    summary_crc=summary_crc,
                )
            ]
        )
        self._write_raw(MAGIC)
        self._stream.flush()
        self._fsync_stream()
        self._finished = True
        self._stream.close()

    def abandon(self) -> None:
        """Close the stream without finishing (after an error); flushed chunks stay readable."""
        self._finished = True
        with contextlib.suppress(OSError):
            self._stream.close()

    # -- output -----------------------------------------------------------------------------
    def _write_records(self, records: list[McapRecord]) -> None:
        builder = RecordBuilder()
        for record in records:
            record.write(builder)
        self._write_raw(builder.end())
        self._stream.flush()

    def _write_raw(self, data: bytes) -> None:
        self._stream.write(data)
        self._data_crc = zlib.crc32(data, self._data_crc)
        self._position += len(data)

    def _sync(self) -> None:
        self._stream.flush()
        if self._fsync:
            self._fsync_stream()

    def _fsync_stream(self) -> None:
        try:
            fileno = self._stream.fileno()
        except (AttributeError, OSError, ValueError):
            return
        with contextlib.suppress(OSError):  # pipes and some special files cannot be synced
            os.fsync(fileno)
