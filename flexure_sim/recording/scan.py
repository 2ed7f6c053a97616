"""Validated reading of MCAP files at the record level (no ROS semantics).

`scan_file` reads a file linearly, checking chunk CRCs, the data section CRC and the summary
CRC, and stops at the first problem, keeping what was read intact before it: messages of
complete chunks only. `read_summary` reads just the header, footer and summary section.
Neither raises on damage; they report it in ``problem`` for the caller to word.
"""
from __future__ import annotations

import io
import struct
import zlib
from dataclasses import dataclass, field
from pathlib import Path

from mcap.exceptions import EndOfFile, InvalidMagic, RecordLengthLimitExceeded
from mcap.records import (
    Channel,
    Chunk,
    ChunkIndex,
    DataEnd,
    Footer,
    Header,
    Message,
    Metadata,
    MetadataIndex,
    Schema,
    Statistics,
)
from mcap.stream_reader import CRCValidationError, StreamReader, breakup_chunk

MAGIC = b"\x89MCAP0\r\n"
_FOOTER_LENGTH = 1 + 8 + 20  # opcode, record length, summary_start, offset_start, crc
_FOOTER_OPCODE = 0x02


@dataclass
class FileScan:
    """Everything a linear pass read before its first problem (``problem`` is None if none)."""

    total_bytes: int
    header: Header | None = None
    schemas: dict[int, Schema] = field(default_factory=dict)
    channels: dict[int, Channel] = field(default_factory=dict)
    messages: list[Message] = field(default_factory=list)
    metadata: list[Metadata] = field(default_factory=list)
    chunk_offsets: list[int] = field(default_factory=list)
    statistics: Statistics | None = None
    chunk_indexes: list[ChunkIndex] = field(default_factory=list)
    metadata_indexes: list[MetadataIndex] = field(default_factory=list)
    data_end: bool = False
    footer: Footer | None = None
    intact_bytes: int = 0
    problem: str | None = None
    truncated: bool = False
    cause: BaseException | None = None


@dataclass
class SummarySection:
    """Header and summary of a file that was closed properly (``problem`` is None)."""

    total_bytes: int
    header: Header | None = None
    schemas: dict[int, Schema] = field(default_factory=dict)
    channels: dict[int, Channel] = field(default_factory=dict)
    statistics: Statistics | None = None
    chunk_indexes: list[ChunkIndex] = field(default_factory=list)
    metadata: list[Metadata] = field(default_factory=list)
    problem: str | None = None
    cause: BaseException | None = None


def scan_file(path: Path) -> FileScan:
    """Read ``path`` record by record, validating CRCs; stop at the first problem."""
    total = path.stat().st_size
    scan = FileScan(total_bytes=total)
    if total == 0:
        scan.problem = "the file is empty (0 bytes)"
        scan.truncated = True
        return scan
    with path.open("rb") as stream:
        magic = stream.read(len(MAGIC))
        if magic != MAGIC:
            scan.truncated = MAGIC.startswith(magic)
            scan.problem = (
                f"truncated: the file ends inside the MCAP magic ({total} bytes)"
                if scan.truncated
                else "not an MCAP file (bad magic at the start)"
            )
            return scan
        stream.seek(0)
        reader = StreamReader(
            stream, emit_chunks=True, validate_crcs=True, record_size_limit=total
        )
        start = len(MAGIC)
        try:
            for record in reader.records:
                end = stream.tell()
                _take(scan, record, start)
                start = scan.intact_bytes = end
        except EndOfFile as exc:
            scan.truncated = True
            scan.cause = exc
            scan.problem = (
                f"truncated: the file ({total} bytes) ends inside the record that starts at "
                f"byte {start}; the recording was not closed properly"
            )
        except InvalidMagic as exc:
            scan.cause = exc
            scan.problem = (
                "not an MCAP file (bad magic at the start)"
                if scan.header is None
                else "damaged: bad magic after the footer"
            )
        except CRCValidationError as exc:
            scan.cause = exc
            scan.problem = f"damaged: {exc} (record at byte {start})"
        except RecordLengthLimitExceeded as exc:  # a cut file, or a damaged length field
            scan.truncated = True
            scan.cause = exc
            scan.problem = (
                f"truncated: the file ({total} bytes) ends inside the record that starts at "
                f"byte {start} (or its length field is damaged: {exc})"
            )
        except Exception as exc:  # any parse failure of damaged bytes
            scan.cause = exc
            scan.problem = (
                "damaged: the closing magic after the footer is missing or wrong"
                if scan.footer is not None
                else f"damaged: cannot parse the record at byte {start} "
                f"({type(exc).__name__}: {exc})"
            )
    if scan.problem is None:
        scan.problem = _check_complete(path, scan)
        if scan.problem is None:
            scan.intact_bytes = total
    return scan


def _take(scan: FileScan, record: object, start: int) -> None:
    if scan.header is None and not isinstance(record, Header):
        raise ValueError(f"the first record is a {type(record).__name__}, not a Header")
    if isinstance(record, Header):
        if scan.header is not None:
            raise ValueError("a second Header record")
        scan.header = record
    elif isinstance(record, Chunk):
        messages: list[Message] = []
        for inner in breakup_chunk(record, validate_crc=True):
            if isinstance(inner, Schema):
                scan.schemas[inner.id] = inner
            elif isinstance(inner, Channel):
                scan.channels[inner.id] = inner
            elif isinstance(inner, Message):
                if inner.channel_id not in scan.channels:
                    raise ValueError(f"a message on unknown channel id {inner.channel_id}")
                messages.append(inner)
        scan.messages.extend(messages)
        scan.chunk_offsets.append(start)
    elif isinstance(record, Schema):
        scan.schemas[record.id] = record
    elif isinstance(record, Channel):
        scan.channels[record.id] = record
    elif isinstance(record, Message):
        if record.channel_id not in scan.channels:
            raise ValueError(f"a message on unknown channel id {record.channel_id}")
        scan.messages.append(record)
    elif isinstance(record, Metadata):
        if not scan.data_end:
            scan.metadata.append(record)
    elif isinstance(record, Statistics):
        scan.statistics = record
    elif isinstance(record, ChunkIndex):
        scan.chunk_indexes.append(record)
    elif isinstance(record, MetadataIndex):
        scan.metadata_indexes.append(record)
    elif isinstance(record, DataEnd):
        scan.data_end = True
    elif isinstance(record, Footer):
        scan.footer = record


def _check_complete(path: Path, scan: FileScan) -> str | None:
    """Consistency of a file that parsed to its end: footer, summary CRC, statistics, index."""
    if scan.footer is None or not scan.data_end:
        return "incomplete: no DataEnd/Footer record"
    crc_problem = _summary_crc_problem(path, scan.footer, scan.total_bytes)
    if crc_problem:
        return crc_problem
    stats = scan.statistics
    if stats is None:
        return "incomplete: the summary has no Statistics record"
    counted: dict[int, int] = {}
    for message in scan.messages:
        counted[message.channel_id] = counted.get(message.channel_id, 0) + 1
    if stats.message_count != len(scan.messages) or {
        k: v for k, v in stats.channel_message_counts.items() if v
    } != counted:
        return (
            f"inconsistent: the Statistics record counts {stats.message_count} messages, "
            f"the chunks hold {len(scan.messages)}"
        )
    indexed = sorted(ci.chunk_start_offset for ci in scan.chunk_indexes)
    if indexed != scan.chunk_offsets:
        return "inconsistent: the chunk index does not match the chunks in the file"
    return None


def _summary_crc_problem(path: Path, footer: Footer, total: int) -> str | None:
    if footer.summary_crc == 0:
        return None
    summary_end = total - len(MAGIC) - 4  # the CRC covers up to the footer's crc field
    if not 0 < footer.summary_start <= summary_end:
        return "damaged: the footer points outside the file"
    with path.open("rb") as stream:
        stream.seek(footer.summary_start)
        crc = zlib.crc32(stream.read(summary_end - footer.summary_start))
    if crc != footer.summary_crc:
        return f"damaged: summary CRC mismatch (expected {footer.summary_crc}, computed {crc})"
    return None


def read_summary(path: Path) -> SummarySection:
    """Header, summary records and indexed Metadata records, without reading the chunks."""
    total = path.stat().st_size
    section = SummarySection(total_bytes=total)
    try:
        with path.open("rb") as stream:
            header_records = StreamReader(stream, record_size_limit=total).records
            header = next(header_records)
            if not isinstance(header, Header):
                raise ValueError(f"the first record is a {type(header).__name__}")
            section.header = header
            if total < 2 * len(MAGIC) + _FOOTER_LENGTH:
                section.problem = "incomplete: too short for a footer"
                return section
            stream.seek(total - len(MAGIC) - _FOOTER_LENGTH)
            tail = stream.read()
            if tail[-len(MAGIC):] != MAGIC or tail[:9] != bytes([_FOOTER_OPCODE, 20]) + bytes(7):
                section.problem = "incomplete: no footer (the recording was not closed)"
                return section
            summary_start, _, summary_crc = struct.unpack_from("<QQI", tail, 9)
            footer = Footer(summary_start, 0, summary_crc)
            if summary_start == 0:
                section.problem = "incomplete: the file has no summary section"
                return section
            crc_problem = _summary_crc_problem(path, footer, total)
            if crc_problem:
                section.problem = crc_problem
                return section
            stream.seek(summary_start)
            summary = io.BytesIO(stream.read())  # summary, footer and the closing magic
            metadata_indexes: list[MetadataIndex] = []
            for record in StreamReader(summary, skip_magic=True, record_size_limit=total).records:
                if isinstance(record, Schema):
                    section.schemas[record.id] = record
                elif isinstance(record, Channel):
                    section.channels[record.id] = record
                elif isinstance(record, Statistics):
                    section.statistics = record
                elif isinstance(record, ChunkIndex):
                    section.chunk_indexes.append(record)
                elif isinstance(record, MetadataIndex):
                    metadata_indexes.append(record)
            for index in sorted(metadata_indexes, key=lambda i: i.offset):  # file order
                stream.seek(index.offset)
                records = StreamReader(stream, skip_magic=True, record_size_limit=total).records
                record = next(records)
                if not isinstance(record, Metadata) or record.name != index.name:
                    raise ValueError(f"no Metadata record {index.name!r} at byte {index.offset}")
                section.metadata.append(record)
    except Exception as exc:  # any parse failure of damaged bytes
        section.cause = exc
        section.problem = f"damaged: cannot parse the summary ({type(exc).__name__}: {exc})"
    if section.problem is None and section.statistics is None:
        section.problem = "incomplete: the summary has no Statistics record"
    return section
