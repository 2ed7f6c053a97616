"""
Reading a rosbag2 MCAP log in one streaming pass: `LogReader`, and `read_log` on top of it.

`LogReader(path)` checks what can be checked before reading the messages (the header, the
``ros2`` profile, the summary of a properly closed file, the channels); `LogReader.messages`
then yields the messages in file order, decoded with mcap-ros2-support from the schemas in the
file (no ROS installation needed), holding one chunk in memory at a time. Only the topics a
caller selects are decoded.

Strict by default about the file: an empty, truncated, damaged or non-``ros2``-profile file
raises `CorruptLogError` saying what is wrong and how much was readable (a damaged chunk is
found when the pass reaches it; the error comes at the end of the pass). With ``recover=True``
the readable part is read instead: the complete chunks before a cut, and every chunk that
passes its CRC around a damaged one; ``note`` says what was lost.

Lenient by default about messages: whatever other nodes publish must not make a recording
unusable, so a message that does not decode as its channel's type is skipped and counted per
topic (``undecodable``; its bytes stay in the file). ``strict=True`` raises
`UndecodableMessageError` instead.
"""
from __future__ import annotations

import os
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from mcap.records import Channel, Header, Schema
from mcap_ros2.decoder import DecoderFactory

from flexure_sim.recording.bag_metadata import (
    METADATA_RECORD_KEY, METADATA_RECORD_NAME, parse_serialized_metadata,
)
from flexure_sim.recording.channels import TopicInfo, TopicTable, check_profile, topic_infos
from flexure_sim.recording.exceptions import CorruptLogError, UndecodableMessageError
from flexure_sim.recording.scan import FileScan, iter_file, scan_file, start_scan
from flexure_sim.recording.summary import read_summary


@dataclass(frozen=True)
class LogMessage:
    """One message; times in ns; ``message`` is the decoded object (None if not decoded)."""

    topic: str
    type: str
    log_time_ns: int
    publish_time_ns: int
    sequence: int
    data: bytes = field(repr=False)
    message: Any = None


def undecodable_note(undecodable: Mapping[str, int]) -> str:
    """
    One line for the messages skipped because they do not decode.

    e.g. ``1 undecodable message on /drive/displacement`` ('' if none).
    """
    return ", ".join(
        f"{n} undecodable message{'' if n == 1 else 's'} on {topic}"
        for topic, n in sorted(undecodable.items())
        if n
    )


class LogReader:
    """
    A rosbag2 MCAP log opened for one streaming pass (see the module docstring).

    Before the pass, ``topics`` and ``metadata_records`` come from the summary (empty for a
    file without a valid one, read with ``recover``); after it, from what was read,
    with the counts of the messages actually read, and ``complete``, ``note``,
    ``undecodable``, ``start_ns``/``end_ns`` and ``bag_metadata`` are final.
    """

    def __init__(
        self, path: str | os.PathLike[str], recover: bool = False, strict: bool = False
    ) -> None:
        self.path = Path(path)
        self.recover = recover
        self.strict = strict
        section = read_summary(self.path)
        if section.header is None or (section.problem is not None and not recover):
            scan = scan_file(self.path)
            if scan.header is not None:
                check_profile(self.path, scan.header, scan)
            hint = "open it with recover=True to read the readable part"
            raise corrupt(self.path, scan, scan.problem or section.problem, hint=hint)
        self.header: Header = section.header
        check_profile(self.path, self.header)
        self.summary_ok = section.problem is None
        self._section = section
        counts = section.statistics.channel_message_counts if section.statistics else {}
        self.topics: dict[str, TopicInfo] = {}
        if self.summary_ok:
            by_channel = topic_infos(self.path, section.schemas, section.channels, counts)
            self.topics = {t.name: t for t in by_channel.values()}
        self.metadata_records: tuple[tuple[str, dict[str, str]], ...] = tuple(
            (r.name, dict(r.metadata)) for r in section.metadata
        )
        self.scan: FileScan | None = None
        self.undecodable: dict[str, int] = {}
        self.bag_metadata: dict[str, Any] | None = None

    # ------------------------------------------------------------------ the pass
    def messages(
        self, select: Callable[[TopicInfo], bool] | None = None, decode: bool = True
    ) -> Iterator[LogMessage]:
        """
        Yield the messages of the selected topics (all by default), in file order.

        ``select`` is asked once per topic. Messages that do not decode are skipped and
        counted (``strict``: raise). Raises `CorruptLogError` at the end of the pass if the
        file is damaged and ``recover`` is False.
        """
        if self.scan is not None:
            raise RuntimeError("LogReader.messages: a log is read in one pass only")
        scan = self.scan = start_scan(self._section)
        plans: dict[int, tuple[TopicInfo, Callable[[bytes], Any] | None, bool]] = {}
        decoders = DecoderFactory()
        index = self._section.chunk_indexes if self.summary_ok else ()
        for record in iter_file(self.path, scan, index):
            plan = plans.get(record.channel_id)
            if plan is None:
                plan = plans[record.channel_id] = self._plan(
                    scan, record.channel_id, select, decoders if decode else None
                )
            topic, decoder, wanted = plan
            if not wanted:
                continue
            decoded = None
            if decoder is not None:
                try:
                    decoded = decoder(record.data)
                except Exception as exc:  # noqa: BLE001 - any failure of the CDR decoder
                    count = self.undecodable.get(topic.name, 0) + 1
                    self.undecodable[topic.name] = count
                    if self.strict:
                        raise UndecodableMessageError(
                            self.path,
                            f"message {scan.counts[record.channel_id]} on {topic.name} does "
                            f"not decode as {topic.type} ({type(exc).__name__}: {exc})",
                            readable_messages=scan.message_count,
                            readable_bytes=scan.intact_bytes,
                            total_bytes=scan.total_bytes,
                        ) from exc
                    continue
            yield LogMessage(
                topic=topic.name,
                type=topic.type,
                log_time_ns=record.log_time,
                publish_time_ns=record.publish_time,
                sequence=record.sequence,
                data=record.data,
                message=decoded,
            )
        self._finish(scan)

    def read_through(self, decode: bool = True) -> None:
        """Run the pass without keeping anything (to check the file and count)."""
        for _ in self.messages(decode=decode):
            pass

    def _plan(
        self,
        scan: FileScan,
        channel_id: int,
        select: Callable[[TopicInfo], bool] | None,
        decoders: DecoderFactory | None,
    ) -> tuple[TopicInfo, Callable[[bytes], Any] | None, bool]:
        channel = scan.channels[channel_id]
        topic = topic_infos(self.path, scan.schemas, {channel_id: channel}, {})[channel_id]
        wanted = select is None or bool(select(topic))
        decoder = None
        if wanted and decoders is not None:
            decoder = _decoder(self.path, decoders, scan.schemas[channel.schema_id], channel)
        return topic, decoder, wanted

    def _finish(self, scan: FileScan) -> None:
        by_channel = topic_infos(self.path, scan.schemas, scan.channels, scan.counts)
        self.topics = {t.name: t for t in by_channel.values()}
        if not self.summary_ok:
            self.metadata_records = tuple((r.name, dict(r.metadata)) for r in scan.metadata)
        if scan.problem is not None and not self.recover:
            hint = "open it with recover=True to read the readable part"
            raise corrupt(self.path, scan, hint=hint)
        self.bag_metadata = _bag_metadata(self.path, scan, self.metadata, strict=not self.recover)

    # ------------------------------------------------------------------ results
    @property
    def metadata(self) -> dict[str, dict[str, str]]:
        """Metadata record name -> its key/value map (the last record of a name wins)."""
        return {name: dict(values) for name, values in self.metadata_records}

    @property
    def complete(self) -> bool:
        return self.scan is not None and self.scan.problem is None

    @property
    def message_count(self) -> int:
        """Messages read in the pass (those of damaged chunks excluded)."""
        return self.scan.message_count if self.scan is not None else 0

    @property
    def chunk_count(self) -> int:
        return len(self.scan.chunk_offsets) if self.scan is not None else 0

    @property
    def unchecked_chunks(self) -> int:
        """Chunks the file gives no CRC for (their damage cannot be detected)."""
        return self.scan.unchecked_chunks if self.scan is not None else 0

    @property
    def start_ns(self) -> int:
        """First log time of the messages read (0 if none)."""
        return self.scan.start_ns or 0 if self.scan is not None else 0

    @property
    def end_ns(self) -> int:
        return self.scan.end_ns or 0 if self.scan is not None else 0

    @property
    def note(self) -> str:
        """Return what a damaged file read with ``recover`` lost ('' for an intact file)."""
        return recovery_note(self.scan) if self.scan is not None else ""


@dataclass(frozen=True)
class McapLog(TopicTable):
    """
    Contents of a log; ``complete`` is False for a recovered part, explained in ``note``.

    ``metadata`` maps each Metadata record name to its last record; ``metadata_records`` holds
    every record, in file order (e.g. successive parameter changes under one name).
    ``undecodable``: messages skipped per topic because they do not decode.
    """

    path: Path
    profile: str
    library: str
    topics: dict[str, TopicInfo]
    messages: list[LogMessage]
    metadata: dict[str, dict[str, str]]
    bag_metadata: dict[str, Any] | None
    complete: bool
    note: str = ""
    chunk_count: int = 0
    metadata_records: tuple[tuple[str, dict[str, str]], ...] = ()
    undecodable: dict[str, int] = field(default_factory=dict)

    @property
    def message_count(self) -> int:
        return len(self.messages)

    def messages_on(self, topic: str) -> list[LogMessage]:
        return [m for m in self.messages if m.topic == topic]


def open_reader(path: str | os.PathLike[str], recover: bool = False,
                strict: bool = False) -> Any:
    """
    Return a `LogReader` of an MCAP file, or a `bag_read.BagReader` of a bag directory.

    The BagReader has the same interface and reads the bag's files in order as one run.
    """
    if Path(path).is_dir():
        from flexure_sim.recording.bag_read import BagReader
        return BagReader(path, recover=recover, strict=strict)
    return LogReader(path, recover=recover, strict=strict)


def read_log(
    path: str | os.PathLike[str], recover: bool = False, decode: bool = True,
    strict: bool = False,
) -> McapLog:
    """
    Return every message of ``path`` (a file or a bag directory) in one list.

    For small logs and tests; tools stream with `open_reader`. Decoded unless ``decode`` is
    False.
    """
    reader = open_reader(path, recover=recover, strict=strict)
    messages = list(reader.messages(decode=decode))
    return McapLog(
        path=reader.path,
        profile=reader.header.profile,
        library=reader.header.library,
        topics=reader.topics,
        messages=messages,
        metadata=reader.metadata,
        bag_metadata=reader.bag_metadata,
        complete=reader.complete,
        note=reader.note,
        chunk_count=reader.chunk_count,
        metadata_records=reader.metadata_records,
        undecodable=dict(reader.undecodable),
    )


def recovery_note(scan: FileScan) -> str:
    """Return what a pass over a damaged file read and lost ('' for an intact file)."""
    if scan.problem is None:
        return ""
    if scan.stopped:
        good = len(scan.chunk_offsets) - len(scan.damaged)
        text = (
            f"recovered {scan.message_count} message(s) from {good} intact chunk(s) in the "
            f"first {scan.intact_bytes} of {scan.total_bytes} bytes; stopped because "
            f"{scan.stopped}"
        )
    else:
        text = f"recovered {scan.message_count} message(s)"
    if scan.damaged:
        text += "; skipped damaged " + "; ".join(d.describe() for d in scan.damaged)
    if scan.inconsistent:
        text += f"; {scan.inconsistent}"
    return text


def corrupt(
    path: Path, scan: FileScan, reason: str | None = None, hint: str = ""
) -> CorruptLogError:
    """Return a `CorruptLogError` for ``scan`` (its problem unless ``reason`` is given)."""
    return CorruptLogError(
        path,
        reason or scan.problem or "unreadable",
        readable_messages=scan.message_count,
        readable_bytes=scan.intact_bytes,
        total_bytes=scan.total_bytes,
        damaged_chunks=len(scan.damaged),
        hint=hint if scan.message_count else "",
    )


def _decoder(
    path: Path, factory: DecoderFactory, schema: Schema, channel: Channel
) -> Callable[[bytes], Any]:
    try:
        decoder = factory.decoder_for(channel.message_encoding, schema)
    except Exception as exc:  # noqa: BLE001 - schema text the parser rejects
        raise CorruptLogError(
            path, f"schema {schema.name} does not parse ({type(exc).__name__}: {exc})"
        ) from exc
    if decoder is None:
        raise CorruptLogError(path, f"no ROS 2 decoder for schema {schema.name}")
    return decoder


def _bag_metadata(
    path: Path, scan: FileScan, metadata: Mapping[str, Mapping[str, str]], strict: bool
) -> dict[str, Any] | None:
    record = metadata.get(METADATA_RECORD_NAME)
    if record is None or METADATA_RECORD_KEY not in record:
        return None
    try:
        parsed = parse_serialized_metadata(record[METADATA_RECORD_KEY])
    except ValueError as exc:
        if strict:
            raise corrupt(path, scan, f"the rosbag2 metadata record is invalid: {exc}") from exc
        return None
    if not isinstance(parsed.get("custom_data"), dict):
        parsed["custom_data"] = {}  # rosbag2 and rosbags write `custom_data: null` or omit it
    if strict and parsed["message_count"] != scan.message_count:
        raise corrupt(
            path,
            scan,
            f"the rosbag2 metadata counts {parsed['message_count']} messages, "
            f"the file holds {scan.message_count}",
        )
    return parsed
