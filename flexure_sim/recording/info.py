"""`log_info`: what ``ros2 bag info`` shows of a log, plus the ``flexure_sim`` metadata record.

A properly closed file is summarised from its summary section (CRC-checked) without reading
the chunks, so damage inside chunks is found by `read_log`, not here. A file without a valid
summary raises `CorruptLogError`, unless ``recover=True``: then it is scanned and summarised
from its readable part.
"""
from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from .bag_metadata import METADATA_RECORD_KEY, METADATA_RECORD_NAME, parse_serialized_metadata
from .errors import CorruptLogError
from .reader import TopicInfo, TopicTable, check_profile, corrupt, metadata_records, read_log, topic_infos
from .scan import read_summary, scan_file

RECORD_NAME = "flexure_sim"


@dataclass(frozen=True)
class LogInfo(TopicTable):
    """Summary of a log; times in ns (``start_ns``/``end_ns`` are first/last log times).

    ``metadata``: last Metadata record of each name; ``metadata_records``: all, in file order.
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

    @property
    def duration_ns(self) -> int:
        return self.end_ns - self.start_ns if self.message_count else 0

    @property
    def flexure_sim(self) -> dict[str, str]:
        """The ``flexure_sim`` metadata record (mechanism and parameters), empty if absent."""
        return dict(self.metadata.get(RECORD_NAME, {}))

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
        if not self.complete:
            lines.append(f"Recovered:      {self.note}")
        return "\n".join(lines)


def log_info(path: str | os.PathLike[str], recover: bool = False) -> LogInfo:
    """Summarise ``path``; see the module docstring for incomplete files."""
    path = Path(path)
    section = read_summary(path)
    if section.header is not None:
        check_profile(path, section.header)
    if section.problem is not None:
        if recover:
            return _from_log(path)
        scan = scan_file(path)
        if scan.header is not None:
            check_profile(path, scan.header, scan)
        raise corrupt(
            path, scan, scan.problem or section.problem,
            hint="log_info(path, recover=True) summarises the readable part",
        )
    assert section.header is not None and section.statistics is not None
    stats = section.statistics
    topics = topic_infos(path, section.schemas, section.channels, stats.channel_message_counts)
    metadata = metadata_records(section.metadata)
    bag_metadata = None
    if METADATA_RECORD_KEY in metadata.get(METADATA_RECORD_NAME, {}):
        try:
            text = metadata[METADATA_RECORD_NAME][METADATA_RECORD_KEY]
            bag_metadata = parse_serialized_metadata(text)
        except ValueError as exc:
            raise CorruptLogError(path, f"the rosbag2 metadata record is invalid: {exc}") from exc
    return LogInfo(
        path=path,
        size_bytes=section.total_bytes,
        profile=section.header.profile,
        library=section.header.library,
        topics={t.name: t for t in topics.values()},
        message_count=stats.message_count,
        start_ns=stats.message_start_time,
        end_ns=stats.message_end_time,
        chunk_count=stats.chunk_count,
        metadata=metadata,
        bag_metadata=bag_metadata,
        complete=True,
        metadata_records=tuple((r.name, dict(r.metadata)) for r in section.metadata),
    )


def _from_log(path: Path) -> LogInfo:
    log = read_log(path, recover=True, decode=False)
    times = [m.log_time_ns for m in log.messages]
    return LogInfo(
        path=path,
        size_bytes=path.stat().st_size,
        profile=log.profile,
        library=log.library,
        topics=log.topics,
        message_count=log.message_count,
        start_ns=min(times, default=0),
        end_ns=max(times, default=0),
        chunk_count=log.chunk_count,
        metadata=log.metadata,
        bag_metadata=log.bag_metadata,
        complete=log.complete,
        note=log.note,
        metadata_records=log.metadata_records,
    )
