"""
The summary section of an MCAP file, read without the chunks.

`read_summary`, and the summary CRC check `iter_file` also uses. Reports damage in ``problem``,
never raises.
"""
from __future__ import annotations

import io
import struct
import zlib
from dataclasses import dataclass, field
from pathlib import Path

from mcap.records import (
    Channel,
    ChunkIndex,
    Footer,
    Header,
    Metadata,
    MetadataIndex,
    Schema,
    Statistics,
)
from mcap.stream_reader import StreamReader

MAGIC = b"\x89MCAP0\r\n"
_FOOTER_LENGTH = 1 + 8 + 20  # opcode, record length, summary_start, offset_start, crc
_FOOTER_OPCODE = 0x02


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


def summary_crc_problem(path: Path, footer: Footer, total: int) -> str | None:
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
            crc_problem = summary_crc_problem(path, footer, total)
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
        section.problem = f"damaged: cannot parse the summary ({type(exc).__name__}: {exc})"
    if section.problem is None and section.statistics is None:
        section.problem = "incomplete: the summary has no Statistics record"
    return section
