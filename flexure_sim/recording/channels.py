"""What a rosbag2 log's channels must carry, and the per-topic view of them (`TopicInfo`)."""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

from mcap.records import Channel, Header, Schema

from flexure_sim.recording.exceptions import CorruptLogError
from flexure_sim.recording.qos import QosDescription, parse_qos_profiles_yaml
from flexure_sim.recording.scan import FileScan

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


class TopicTable:
    """Per-topic views of a ``topics`` mapping of TopicInfo (shared by McapLog and LogInfo)."""

    topics: dict[str, TopicInfo]

    @property
    def types(self) -> dict[str, str]:
        return {name: t.type for name, t in self.topics.items()}

    @property
    def counts(self) -> dict[str, int]:
        return {name: t.message_count for name, t in self.topics.items()}


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
