"""
`log_info`.

What ``ros2 bag info`` shows of a log, plus the ``flexure_sim`` metadata record, checked against
the file's contents.

The summary section alone cannot tell a damaged chunk from an intact one, so `log_info` reads
the whole file once (streaming, one chunk in memory): every chunk CRC is checked and, with
``decode`` (the default), every message is decoded, so that messages that do not decode are
counted per topic (``undecodable``). A damaged or incomplete file raises `CorruptLogError`
saying what is damaged and how much is readable, unless ``recover=True``: then the readable
part is summarised and ``note`` says what was lost.
"""
from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping, Optional

from flexure_sim.recording.reader import TopicInfo, TopicTable, open_reader, undecodable_note

RECORD_NAME = "flexure_sim"
#: Key of the rosbag2 ``custom_data`` entry in which the recorder counts dropped messages.
DROPPED_KEY = "flexure_sim.dropped_messages"


@dataclass(frozen=True)
class LogInfo(TopicTable):
    """
    Summary of a log; times in ns (``start_ns``/``end_ns`` are first/last log times).

    ``metadata``: last Metadata record of each name; ``metadata_records``: all, in file order;
    ``undecodable``: messages per topic that do not decode as the topic's type;
    ``unchecked_chunks``: chunks without a CRC (damage inside them cannot be detected);
    ``decoded``: whether messages were decoded (else ``undecodable`` is not known).
    """

    path: Path
    size_bytes: int
    profile: str
    library: str
    topics: dict[str, TopicInfo]
    message_count: int
    start_ns: int
    end_ns: int
    chunk_count: int
    metadata: dict[str, dict[str, str]]
    bag_metadata: dict[str, Any] | None
    complete: bool
    note: str = ""
    metadata_records: tuple[tuple[str, dict[str, str]], ...] = ()
    undecodable: dict[str, int] = field(default_factory=dict)
    unchecked_chunks: int = 0
    decoded: bool = True

    @property
    def duration_ns(self) -> int:
        return self.end_ns - self.start_ns if self.message_count else 0

    @property
    def flexure_sim(self) -> dict[str, str]:
        """
        Return the ``flexure_sim`` metadata record (mechanism and parameters).

        Empty if absent.
        """
        return dict(self.metadata.get(RECORD_NAME, {}))

    @property
    def dropped_messages(self) -> Optional[str]:
        """Messages the recorder counted as dropped (None if the file does not say)."""
        return dropped_messages(self.bag_metadata)

    def format(self) -> str:
        """Human-readable summary in the spirit of ``ros2 bag info``."""
        lines = [
            f"Files:          {self.path}",
            f"Size:           {self.size_bytes} B",
            f"Storage:        mcap (profile {self.profile}, written by {self.library})",
            f"Duration:       {self.duration_ns / 1e9:.9f} s",
            f"Start:          {self.start_ns} ns",
            f"End:            {self.end_ns} ns",
            f"Messages:       {self.message_count} in {self.chunk_count} chunk(s)",
            "Topics:",
        ]
        width = max((len(n) for n in self.topics), default=0)
        for name, topic in sorted(self.topics.items()):
            lines.append(f"  {name:<{width}}  {topic.type}  count {topic.message_count}")
        for key, value in sorted(self.flexure_sim.items()):
            lines.append(f"{RECORD_NAME}.{key}: {value}")
        if self.undecodable:
            lines.append(f"Undecodable:    {undecodable_note(self.undecodable)}")
        if not self.complete:
            lines.append(f"Recovered:      {self.note}")
        return "\n".join(lines)


def dropped_messages(bag_metadata: Optional[Mapping[str, Any]]) -> Optional[str]:
    """
    Return the recorder's count of dropped messages in rosbag2 metadata.

    Tolerating files of other writers (no metadata, ``custom_data: null``).
    """
    custom = (bag_metadata or {}).get("custom_data")
    if not isinstance(custom, Mapping):
        return None
    value = custom.get(DROPPED_KEY)
    return None if value is None else str(value)


def log_info(
    path: str | os.PathLike[str], recover: bool = False, decode: bool = True,
    strict: bool = False,
) -> LogInfo:
    """
    Summarise ``path`` after reading it through.

    See the module docstring (``strict``: raise `UndecodableMessageError` for a message that does
    not decode).
    """
    path = Path(path)
    reader = open_reader(path, recover=recover, strict=strict)  # a file or a bag directory
    reader.read_through(decode=decode)
    return LogInfo(
        path=path,
        size_bytes=getattr(reader, "size_bytes", None) or path.stat().st_size,
        profile=reader.header.profile,
        library=reader.header.library,
        topics=reader.topics,
        message_count=reader.message_count,
        start_ns=reader.start_ns,
        end_ns=reader.end_ns,
        chunk_count=reader.chunk_count,
        metadata=reader.metadata,
        bag_metadata=reader.bag_metadata,
        complete=reader.complete,
        note=reader.note,
        metadata_records=reader.metadata_records,
        undecodable=dict(reader.undecodable),
        unchecked_chunks=reader.unchecked_chunks,
        decoded=decode,
    )
