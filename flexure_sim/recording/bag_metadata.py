"""
rosbag2 bag metadata (version 9, as Jazzy writes it).

In an MCAP file, rosbag2 stores the metadata as a Metadata record named ``rosbag2`` whose key
``serialized_metadata`` holds the YAML of the metadata struct itself (keys ``version``,
``storage_identifier``, ...). A bag directory's ``metadata.yaml`` holds the same struct under
the key ``rosbag2_bagfile_information``.
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import yaml

METADATA_RECORD_NAME = "rosbag2"
METADATA_RECORD_KEY = "serialized_metadata"
METADATA_VERSION = 9
FILE_KEY = "rosbag2_bagfile_information"


@dataclass(frozen=True)
class TopicRecord:
    """What the bag metadata says of one topic."""

    name: str
    type: str
    offered_qos_profiles: str
    type_description_hash: str
    message_count: int
    serialization_format: str = "cdr"


def build_bag_metadata(
    *,
    file_name: str,
    topics: Sequence[TopicRecord],
    start_ns: int,
    end_ns: int,
    custom_data: Mapping[str, str] | None = None,
    ros_distro: str = "jazzy",
) -> dict[str, Any]:
    """Return the metadata struct of a one-file MCAP bag, keys in rosbag2's order."""
    message_count = sum(t.message_count for t in topics)
    duration = max(0, end_ns - start_ns) if message_count else 0
    starting_time = start_ns if message_count else 0
    return {
        "version": METADATA_VERSION,
        "storage_identifier": "mcap",
        "duration": {"nanoseconds": duration},
        "starting_time": {"nanoseconds_since_epoch": starting_time},
        "message_count": message_count,
        "topics_with_message_count": [
            {
                "topic_metadata": {
                    "name": t.name,
                    "type": t.type,
                    "serialization_format": t.serialization_format,
                    "offered_qos_profiles": t.offered_qos_profiles,
                    "type_description_hash": t.type_description_hash,
                },
                "message_count": t.message_count,
            }
            for t in topics
        ],
        "compression_format": "",
        "compression_mode": "",
        "relative_file_paths": [file_name],
        "files": [
            {
                "path": file_name,
                "starting_time": {"nanoseconds_since_epoch": starting_time},
                "duration": {"nanoseconds": duration},
                "message_count": message_count,
            }
        ],
        "custom_data": dict(custom_data or {}),
        "ros_distro": ros_distro,
    }


def combine_bag_metadata(files: Sequence[Mapping[str, Any]]) -> dict[str, Any]:
    """
    Return the metadata of a bag made of several files (in order).

    From the one-file metadata of each (`build_bag_metadata`, as stored in each file's ``rosbag2``
    record): topics in order of first appearance with their counts summed, the files' entries in
    order, starting time and duration spanning the files that hold messages, custom_data summed for
    the flexure_sim counters (``flexure_sim.*`` keys holding integers), else the last value. This
    is what a bag directory's ``metadata.yaml`` holds (`metadata_yaml`).
    """
    if not files:
        raise ValueError("files: a bag has at least one file")
    topics: dict[str, dict[str, Any]] = {}
    entries: list[dict[str, Any]] = []
    custom: dict[str, str] = {}
    spans = []
    for meta in files:
        for t in meta["topics_with_message_count"]:
            name = t["topic_metadata"]["name"]
            if name in topics:
                topics[name]["message_count"] += t["message_count"]
            else:
                topics[name] = {"topic_metadata": dict(t["topic_metadata"]),
                                "message_count": t["message_count"]}
        entries.extend(dict(f) for f in meta["files"])
        if meta["message_count"]:
            start = meta["starting_time"]["nanoseconds_since_epoch"]
            spans.append((start, start + meta["duration"]["nanoseconds"]))
        for key, value in meta.get("custom_data", {}).items():
            if key.startswith("flexure_sim.") and key in custom and value.isdigit() \
                    and custom[key].isdigit():
                custom[key] = str(int(custom[key]) + int(value))
            else:
                custom[key] = value
    start = min((a for a, _ in spans), default=0)
    end = max((b for _, b in spans), default=0)
    first = files[0]
    return {
        "version": METADATA_VERSION,
        "storage_identifier": first["storage_identifier"],
        "duration": {"nanoseconds": end - start},
        "starting_time": {"nanoseconds_since_epoch": start},
        "message_count": sum(m["message_count"] for m in files),
        "topics_with_message_count": list(topics.values()),
        "compression_format": first.get("compression_format", ""),
        "compression_mode": first.get("compression_mode", ""),
        "relative_file_paths": [f["path"] for f in entries],
        "files": entries,
        "custom_data": custom,
        "ros_distro": first.get("ros_distro", "jazzy"),
    }


def parse_metadata_yaml(text: str) -> dict[str, Any]:
    """
    Return the metadata struct of a bag directory's ``metadata.yaml``.

    Checked as `parse_serialized_metadata`; ValueError naming what is wrong.
    """
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        raise ValueError(f"metadata.yaml is not YAML: {exc}") from exc
    if not isinstance(data, dict) or not isinstance(data.get(FILE_KEY), dict):
        raise ValueError(f"metadata.yaml: no {FILE_KEY} mapping")
    return parse_serialized_metadata(yaml.safe_dump(data[FILE_KEY]))


def dump_serialized_metadata(metadata: Mapping[str, Any]) -> str:
    """YAML for the ``serialized_metadata`` key of the ``rosbag2`` record."""
    return _dump(dict(metadata))


def metadata_yaml(metadata: Mapping[str, Any]) -> str:
    """Content of a bag directory's ``metadata.yaml`` for the same metadata."""
    return _dump({FILE_KEY: dict(metadata)})


def _dump(data: dict[str, Any]) -> str:
    # No line folding: multi-line strings (offered_qos_profiles) stay one double-quoted
    # line with \n escapes, as yaml-cpp writes them.
    text: str = yaml.safe_dump(
        data, sort_keys=False, default_flow_style=False, width=float("inf")
    )
    return text


def parse_serialized_metadata(text: str) -> dict[str, Any]:
    """Parse and check ``serialized_metadata``; raise ValueError naming what is wrong."""
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        raise ValueError(f"serialized_metadata is not YAML: {exc}") from exc
    if not isinstance(data, dict):
        raise ValueError("serialized_metadata is not a YAML mapping")
    required = {
        "version": int,
        "storage_identifier": str,
        "duration": dict,
        "starting_time": dict,
        "message_count": int,
        "topics_with_message_count": list,
        "relative_file_paths": list,
    }
    for key, kind in required.items():
        if not isinstance(data.get(key), kind):
            raise ValueError(f"serialized_metadata: {key!r} missing or not a {kind.__name__}")
    for entry in data["topics_with_message_count"]:
        topic = entry.get("topic_metadata") if isinstance(entry, dict) else None
        if not isinstance(topic, dict) or not isinstance(entry.get("message_count"), int):
            raise ValueError("serialized_metadata: malformed topics_with_message_count entry")
        for key in ("name", "type", "serialization_format"):
            if not isinstance(topic.get(key), str):
                raise ValueError(f"serialized_metadata: topic_metadata lacks {key!r}")
    return data
