"""`read_log`: the topics, types, counts and decoded messages of a rosbag2 MCAP log.

Strict by default: an empty, truncated, damaged or non-``ros2``-profile file raises
`CorruptLogError` saying what is wrong and how much was readable. With ``recover=True`` a file
cut short (e.g. by ``kill -9``) or damaged part-way yields the messages of the complete chunks
before the damage, and `McapLog.note` says how much was recovered. Messages are decoded with
mcap-ros2-support from the schemas in the file (no ROS installation needed).
"""
from __future__ import annotations

import os
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from mcap.records import Channel, Header, Metadata, Schema
from mcap_ros2.decoder import DecoderFactory

from .bag_metadata import METADATA_RECORD_KEY, METADATA_RECORD_NAME, parse_serialized_metadata
from .errors import CorruptLogError
from .qos import QosDescription, parse_qos_profiles_yaml
from .scan import FileScan, scan_file

PROFILE = "ros2"


@dataclass(frozen=True)
class TopicInfo:
    """One channel of the log: topic, type (``pkg/msg/Type``), count and rosbag2 metadata."""

    name: str
    type: str
    message_count: int
    qos: tuple[QosDescription, ...]
    type_hash: str
    message_encoding: str = "cdr"


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


class TopicTable:
    """Per-topic views of a ``topics`` mapping of TopicInfo (shared by McapLog and LogInfo)."""

    topics: dict[str, TopicInfo]

    @property
    def types(self) -> dict[str, str]:
        return {name: t.type for name, t in self.topics.items()}

    @property
    def counts(self) -> dict[str, int]:
        return {name: t.message_count for name, t in self.topics.items()}


@dataclass(frozen=True)
class McapLog(TopicTable):
    """Contents of a log; ``complete`` is False for a recovered prefix, explained in ``note``.

    ``metadata`` maps each Metadata record name to its last record; ``metadata_records`` holds
    every record, in file order (e.g. successive parameter changes under one name).
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

    @property
    def message_count(self) -> int:
        return len(self.messages)

    def messages_on(self, topic: str) -> list[LogMessage]:
        return [m for m in self.messages if m.topic == topic]


def read_log(path: str | os.PathLike[str], recover: bool = False, decode: bool = True) -> McapLog:
    """Read every message of ``path`` (in file order), decoding them unless ``decode`` is False."""
    path = Path(path)
    scan = scan_file(path)
    if scan.header is None:
        raise corrupt(path, scan)
    check_profile(path, scan.header, scan)
    if scan.problem is not None and not recover:
        raise corrupt(path, scan, hint="read_log(path, recover=True) returns the readable part")
    topics_by_channel = topic_infos(path, scan.schemas, scan.channels, _count(scan))
    decoders = _decoders(path, scan.schemas, scan.channels) if decode else {}
    messages: list[LogMessage] = []
    undecodable = 0
    for record in scan.messages:
        topic = topics_by_channel[record.channel_id]
        decoded = None
        if decode:
            try:
                decoded = decoders[record.channel_id](record.data)
            except Exception as exc:  # any failure of the CDR decoder
                if not recover:
                    raise corrupt(
                        path, scan, f"message {len(messages)} on {topic.name} does not decode "
                        f"as {topic.type} ({type(exc).__name__}: {exc})"
                    ) from exc
                undecodable += 1
                continue
        messages.append(
            LogMessage(
                topic=topic.name,
                type=topic.type,
                log_time_ns=record.log_time,
                publish_time_ns=record.publish_time,
                sequence=record.sequence,
                data=record.data,
                message=decoded,
            )
        )
    metadata = metadata_records(scan.metadata)
    bag_metadata = _bag_metadata(path, scan, metadata, strict=not recover)
    note = ""
    if scan.problem is not None:
        note = (
            f"recovered {len(messages)} message(s) from {len(scan.chunk_offsets)} complete "
            f"chunk(s) in the first {scan.intact_bytes} of {scan.total_bytes} bytes; "
            f"stopped because {scan.problem}"
        )
        if undecodable:
            note += f"; skipped {undecodable} message(s) that do not decode"
    return McapLog(
        path=path,
        profile=scan.header.profile,
        library=scan.header.library,
        topics={t.name: t for t in topics_by_channel.values()},
        messages=messages,
        metadata=metadata,
        bag_metadata=bag_metadata,
        complete=scan.problem is None,
        note=note,
        chunk_count=len(scan.chunk_offsets),
        metadata_records=tuple((r.name, dict(r.metadata)) for r in scan.metadata),
    )


def corrupt(
    path: Path, scan: FileScan, reason: str | None = None, hint: str = ""
) -> CorruptLogError:
    """A `CorruptLogError` for ``scan`` (its problem unless ``reason`` is given)."""
    return CorruptLogError(
        path,
        reason or scan.problem or "unreadable",
        readable_messages=len(scan.messages),
        readable_bytes=scan.intact_bytes,
        total_bytes=scan.total_bytes,
        hint=hint if scan.messages else "",
    )


def check_profile(path: Path, header: Header, scan: FileScan | None = None) -> None:
    """Raise `CorruptLogError` unless the MCAP profile is ``ros2``."""
    if header.profile != PROFILE:
        raise CorruptLogError(
            path,
            f"MCAP profile is {header.profile!r}, not {PROFILE!r}: not a rosbag2 log",
            readable_bytes=scan.intact_bytes if scan else 0,
            total_bytes=scan.total_bytes if scan else path.stat().st_size,
        )


def topic_infos(
    path: Path,
    schemas: Mapping[int, Schema],
    channels: Mapping[int, Channel],
    counts: Mapping[int, int],
) -> dict[int, TopicInfo]:
    """Channel id -> `TopicInfo`; raise `CorruptLogError` for a channel rosbag2 cannot use."""
    infos: dict[int, TopicInfo] = {}
    for channel_id, channel in sorted(channels.items()):
        schema = schemas.get(channel.schema_id)
        problem = None
        if schema is None:
            problem = f"channel {channel.topic} refers to missing schema {channel.schema_id}"
        elif channel.message_encoding != "cdr":
            problem = f"channel {channel.topic} has message encoding {channel.message_encoding!r}"
        elif schema.encoding != "ros2msg":
            problem = f"schema {schema.name} has encoding {schema.encoding!r}, not 'ros2msg'"
        elif "offered_qos_profiles" not in channel.metadata:
            problem = f"channel {channel.topic} lacks the offered_qos_profiles metadata"
        if problem is None:
            try:
                qos = tuple(parse_qos_profiles_yaml(channel.metadata["offered_qos_profiles"]))
            except ValueError as exc:
                problem = f"channel {channel.topic}: {exc}"
        if problem is not None:
            raise CorruptLogError(path, f"not a valid rosbag2 log: {problem}")
        assert schema is not None
        infos[channel_id] = TopicInfo(
            name=channel.topic,
            type=schema.name,
            message_count=counts.get(channel_id, 0),
            qos=qos,
            type_hash=channel.metadata.get("topic_type_hash", ""),
            message_encoding=channel.message_encoding,
        )
    return infos


def metadata_records(records: Iterable[Metadata]) -> dict[str, dict[str, str]]:
    """Metadata record name -> its key/value map (the last record of a name wins)."""
    return {record.name: dict(record.metadata) for record in records}


def _count(scan: FileScan) -> dict[int, int]:
    counts: dict[int, int] = {}
    for message in scan.messages:
        counts[message.channel_id] = counts.get(message.channel_id, 0) + 1
    return counts


def _decoders(
    path: Path, schemas: Mapping[int, Schema], channels: Mapping[int, Channel]
) -> dict[int, Callable[[bytes], Any]]:
    factory = DecoderFactory()
    decoders: dict[int, Callable[[bytes], Any]] = {}
    for channel_id, channel in channels.items():
        schema = schemas[channel.schema_id]
        try:
            decoder = factory.decoder_for(channel.message_encoding, schema)
        except Exception as exc:  # schema text the parser rejects
            raise CorruptLogError(
                path, f"schema {schema.name} does not parse ({type(exc).__name__}: {exc})"
            ) from exc
        if decoder is None:
            raise CorruptLogError(path, f"no ROS 2 decoder for schema {schema.name}")
        decoders[channel_id] = decoder
    return decoders


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
    if strict and parsed["message_count"] != len(scan.messages):
        raise corrupt(
            path,
            scan,
            f"the rosbag2 metadata counts {parsed['message_count']} messages, "
            f"the file holds {len(scan.messages)}",
        )
    return parsed
