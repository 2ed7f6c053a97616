"""
Validated reading of MCAP files at the record level (no ROS semantics).

`iter_file` reads a file linearly, in bounded memory (one chunk at a time), yielding the
Message records of every intact chunk while it fills a `FileScan` with what it saw. It checks
every CRC the file carries: each chunk's (a chunk that fails it, or does not parse, is skipped
and listed in ``FileScan.damaged``, and reading goes on with the next record), the data
section's and the summary's. It stops at the first damage it cannot step over (a record whose
framing is broken, a file cut short), keeping what was read intact before it.
`scan_file` runs that pass to the end (the summary is read by `summary.read_summary`).
Neither raises on damage: they report it for the caller to word.
"""
from __future__ import annotations

from collections.abc import Iterator, Sequence
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
    MessageIndex,
    Metadata,
    Schema,
    Statistics,
)
from mcap.stream_reader import CRCValidationError, StreamReader, breakup_chunk

from flexure_sim.recording.summary import MAGIC, SummarySection, read_summary, summary_crc_problem


@dataclass
class DamagedChunk:
    """
    A chunk whose contents fail their CRC or do not parse: its messages are lost.

    ``offset``/``end``: bytes of the chunk record; ``start_ns``/``end_ns``: the log times its
    record header (or the chunk index) declares; ``messages``: how many its message index
    lists (-1 if unknown). ``index`` -1: damaged bytes between chunks (message indexes).
    """

    index: int
    offset: int
    end: int
    reason: str
    start_ns: int
    end_ns: int
    messages: int = -1

    def describe(self) -> str:
        if self.index < 0:
            return f"bytes {self.offset}-{self.end} between chunks: {self.reason}; no message lost"
        lost = f"its {self.messages} message(s)" if self.messages >= 0 else "its messages"
        return (
            f"chunk {self.index + 1} (bytes {self.offset}-{self.end}, log time "
            f"{self.start_ns / 1e9:.9g}-{self.end_ns / 1e9:.9g} s): {self.reason}; {lost} lost"
        )


@dataclass
class FileScan:
    """
    What a linear pass read; ``problem`` is None for an intact, complete file.

    ``counts``: messages read per channel id (damaged chunks excluded); ``unchecked_chunks``:
    chunks written without a CRC (some writers, e.g. rosbags, write none); ``stopped``: why the
    pass ended before the end of the file; ``damaged``: chunks skipped; ``inconsistent``: a
    summary, index or data-section CRC problem found after reading every record.
    """

    total_bytes: int
    header: Header | None = None
    schemas: dict[int, Schema] = field(default_factory=dict)
    channels: dict[int, Channel] = field(default_factory=dict)
    counts: dict[int, int] = field(default_factory=dict)
    metadata: list[Metadata] = field(default_factory=list)
    chunk_offsets: list[int] = field(default_factory=list)
    unchecked_chunks: int = 0
    damaged: list[DamagedChunk] = field(default_factory=list)
    statistics: Statistics | None = None
    chunk_indexes: list[ChunkIndex] = field(default_factory=list)
    data_end: bool = False
    footer: Footer | None = None
    intact_bytes: int = 0
    stopped: str | None = None
    inconsistent: str | None = None
    start_ns: int | None = None
    end_ns: int | None = None

    @property
    def message_count(self) -> int:
        """Messages read (those of damaged chunks excluded)."""
        return sum(self.counts.values())

    @property
    def problem(self) -> str | None:
        """Everything wrong with the file, in one line (None if nothing)."""
        parts = []
        if self.stopped:
            parts.append(self.stopped)
        if self.damaged:
            shown = [d.describe() for d in self.damaged[:3]]
            if len(self.damaged) > 3:
                shown.append(f"and {len(self.damaged) - 3} more damaged chunk(s)")
            parts.append("damaged " + "; ".join(shown))
        if self.inconsistent:
            parts.append(self.inconsistent)
        return "; ".join(parts) or None


def scan_file(path: Path) -> FileScan:
    """Read ``path`` record by record, validating CRCs, keeping no messages (`iter_file`)."""
    section = read_summary(path)
    scan = start_scan(section)
    for _ in iter_file(path, scan, section.chunk_indexes if section.problem is None else ()):
        pass
    return scan


def start_scan(section: SummarySection) -> FileScan:
    """
    Return an empty `FileScan`, knowing the schemas and channels of ``section`` if it is intact.

    A damaged chunk may hold the only Schema or Channel record of a topic.
    """
    scan = FileScan(total_bytes=section.total_bytes)
    if section.problem is None:
        scan.schemas.update(section.schemas)
        scan.channels.update(section.channels)
    return scan


def iter_file(
    path: Path, scan: FileScan, chunk_index: Sequence[ChunkIndex] = ()
) -> Iterator[Message]:
    """
    Yield the Message records of ``path`` in file order, filling ``scan`` as it goes.

    Messages of damaged chunks are not yielded. ``chunk_index`` (the summary's, when it is
    intact) lets the pass step over a record whose framing is broken, to the next chunk it
    lists; without it, the pass stops there. ``scan.problem`` is final once the generator is
    exhausted.
    """
    total = scan.total_bytes = path.stat().st_size
    if total == 0:
        scan.stopped = "the file is empty (0 bytes)"
        return
    with path.open("rb") as stream:
        magic = stream.read(len(MAGIC))
        if magic != MAGIC:
            scan.stopped = (
                f"truncated: the file ends inside the MCAP magic ({total} bytes)"
                if MAGIC.startswith(magic)
                else "not an MCAP file (bad magic at the start)"
            )
            return
        stream.seek(0)
        records = StreamReader(
            stream, emit_chunks=True, validate_crcs=True, record_size_limit=total
        ).records
        start = len(MAGIC)
        while True:
            try:
                record = next(records)
            except StopIteration:
                break
            except CRCValidationError as exc:  # the data section CRC, checked at DataEnd
                scan.data_end = True
                start = scan.intact_bytes = stream.tell()
                if not scan.damaged:
                    scan.inconsistent = (
                        f"damaged: the data section fails its CRC ({exc}) though every chunk "
                        "passes its own: a record outside the chunks (metadata, message "
                        "index) is damaged"
                    )
                records = StreamReader(stream, skip_magic=True, record_size_limit=total).records
                continue
            except Exception as exc:  # noqa: BLE001 - any failure to parse damaged bytes
                resume = _step_over(scan, exc, start, chunk_index)
                if resume is None:
                    _stop(scan, exc, start, total)
                    return
                stream.seek(resume)
                records = StreamReader(
                    stream, skip_magic=True, emit_chunks=True, record_size_limit=total
                ).records
                start = resume
                continue
            end = stream.tell()
            try:
                yield from _take(scan, record, start, end)
            except ValueError as exc:
                _stop(scan, exc, start, total)
                return
            start = scan.intact_bytes = end
    scan.intact_bytes = total  # every record parsed, up to the closing magic
    scan.inconsistent = scan.inconsistent or _check_complete(path, scan)


def _step_over(
    scan: FileScan, exc: BaseException, start: int, chunk_index: Sequence[ChunkIndex]
) -> int | None:
    """
    Where to resume after a record at ``start`` that does not parse.

    The next chunk the index lists (the damage is recorded), or None (stop).
    """
    later = sorted(
        (ci for ci in chunk_index if ci.chunk_start_offset > start),
        key=lambda ci: ci.chunk_start_offset,
    )
    if not later or scan.data_end:
        return None
    resume = later[0].chunk_start_offset
    reason = f"does not parse ({type(exc).__name__}: {exc}); reading resumed at byte {resume}"
    here = [ci for ci in chunk_index if ci.chunk_start_offset == start]
    if here:
        scan.chunk_offsets.append(start)
        scan.damaged.append(DamagedChunk(
            len(scan.chunk_offsets) - 1, start, resume, reason,
            here[0].message_start_time, here[0].message_end_time))
    else:
        scan.damaged.append(DamagedChunk(-1, start, resume, reason, 0, 0, 0))
    return resume


def _stop(scan: FileScan, exc: BaseException, start: int, total: int) -> None:
    if isinstance(exc, EndOfFile):
        scan.stopped = (
            f"truncated: the file ({total} bytes) ends inside the record that starts at "
            f"byte {start}; the recording was not closed properly"
        )
    elif isinstance(exc, InvalidMagic):
        scan.stopped = (
            "not an MCAP file (bad magic at the start)"
            if scan.header is None
            else "damaged: bad magic after the footer"
        )
    elif isinstance(exc, RecordLengthLimitExceeded):  # a cut file, or a damaged length field
        scan.stopped = (
            f"truncated: the file ({total} bytes) ends inside the record that starts at "
            f"byte {start} (or its length field is damaged: {exc})"
        )
    elif scan.footer is not None:
        scan.stopped = "damaged: the closing magic after the footer is missing or wrong"
    else:
        scan.stopped = (
            f"damaged: cannot parse the record at byte {start} ({type(exc).__name__}: {exc})"
        )


def _take(scan: FileScan, record: object, start: int, end: int) -> Iterator[Message]:
    """Account for one top-level record; yield the messages it holds."""
    if scan.header is None and not isinstance(record, Header):
        raise ValueError(f"the first record is a {type(record).__name__}, not a Header")
    if isinstance(record, Header):
        if scan.header is not None:
            raise ValueError("a second Header record")
        scan.header = record
    elif isinstance(record, Chunk):
        scan.chunk_offsets.append(start)
        if record.uncompressed_crc == 0:
            scan.unchecked_chunks += 1
        inner = _chunk_records(scan, record, start, end)
        for item in inner:
            if isinstance(item, Schema):
                scan.schemas[item.id] = item
            elif isinstance(item, Channel):
                scan.channels[item.id] = item
        for item in inner:
            if isinstance(item, Message):
                _count(scan, item)
                yield item
    elif isinstance(record, MessageIndex):
        if scan.damaged and scan.damaged[-1].offset == scan.chunk_offsets[-1]:
            damaged = scan.damaged[-1]
            damaged.messages = max(damaged.messages, 0) + len(record.records)
    elif isinstance(record, Schema):
        scan.schemas[record.id] = record
    elif isinstance(record, Channel):
        scan.channels[record.id] = record
    elif isinstance(record, Message):
        if record.channel_id not in scan.channels:
            raise ValueError(f"a message on unknown channel id {record.channel_id}")
        _count(scan, record)
        yield record
    elif isinstance(record, Metadata):
        if not scan.data_end:
            scan.metadata.append(record)
    elif isinstance(record, Statistics):
        scan.statistics = record
    elif isinstance(record, ChunkIndex):
        scan.chunk_indexes.append(record)
    elif isinstance(record, DataEnd):
        scan.data_end = True
    elif isinstance(record, Footer):
        scan.footer = record


def _chunk_records(scan: FileScan, chunk: Chunk, start: int, end: int) -> list[object]:
    """Return the records of an intact chunk; [] (and an entry in ``scan.damaged``) otherwise."""
    try:
        inner = breakup_chunk(chunk, validate_crc=True)
        channels = set(scan.channels) | {r.id for r in inner if isinstance(r, Channel)}
        for item in inner:
            if isinstance(item, Message) and item.channel_id not in channels:
                raise ValueError(f"a message on unknown channel id {item.channel_id}")
        return inner
    except CRCValidationError as exc:
        reason = f"CRC mismatch: expected {exc.expected}, computed {exc.actual}"
    except Exception as exc:  # noqa: BLE001 - decompression or parse failure of damaged bytes
        reason = f"its records do not parse: {type(exc).__name__}: {exc}"
    scan.damaged.append(
        DamagedChunk(len(scan.chunk_offsets) - 1, start, end, reason,
                     chunk.message_start_time, chunk.message_end_time)
    )
    return []


def _count(scan: FileScan, message: Message) -> None:
    scan.counts[message.channel_id] = scan.counts.get(message.channel_id, 0) + 1
    t = message.log_time
    if scan.start_ns is None or t < scan.start_ns:
        scan.start_ns = t
    if scan.end_ns is None or t > scan.end_ns:
        scan.end_ns = t


def _check_complete(path: Path, scan: FileScan) -> str | None:
    """Consistency of a file that parsed to its end: footer, summary CRC, statistics, index."""
    if scan.footer is None or not scan.data_end:
        return "incomplete: no DataEnd/Footer record"
    crc_problem = summary_crc_problem(path, scan.footer, scan.total_bytes)
    if crc_problem:
        return crc_problem
    stats = scan.statistics
    if stats is None:
        return "incomplete: the summary has no Statistics record"
    if not scan.damaged and (
        stats.message_count != scan.message_count
        or {k: v for k, v in stats.channel_message_counts.items() if v} != scan.counts
    ):
        return (
            f"inconsistent: the Statistics record counts {stats.message_count} messages, "
            f"the chunks hold {scan.message_count}"
        )
    indexed = sorted(ci.chunk_start_offset for ci in scan.chunk_indexes)
    if indexed != scan.chunk_offsets:
        return "inconsistent: the chunk index does not match the chunks in the file"
    return None
