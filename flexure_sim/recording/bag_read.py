"""
A bag directory (`bag`) read as one run.

`BagReader`, a `reader.LogReader` per file (in order, `bag.bag_files`) behind the LogReader
interface, so every tool streams a directory as it streams a file. Topics are merged by name
(counts summed), messages and metadata records come in file order (the metadata of each name is the
last one), and ``bag_metadata`` is the directory's metadata.yaml (else the files' own rosbag2
records combined).

Strict reading (``recover`` False) also checks metadata.yaml against the files at the end of
the pass: its total, per-file and per-topic counts must equal what the files hold (a stale or
foreign metadata.yaml is an error, named).
"""
from __future__ import annotations

import dataclasses
import os
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

from flexure_sim.recording.bag import METADATA_FILE, bag_files, read_bag_metadata
from flexure_sim.recording.bag_metadata import combine_bag_metadata
from flexure_sim.recording.exceptions import CorruptLogError


def _files(directory: Path) -> list[Path]:
    files = bag_files(directory)
    if not files:
        raise CorruptLogError(directory, "a directory without MCAP files or metadata.yaml")
    missing = [p.name for p in files if not p.is_file()]
    if missing:
        raise CorruptLogError(directory, f"{METADATA_FILE} lists missing file(s) "
                                         f"{', '.join(missing)}")
    return files


def check_counts(directory: Path, meta: dict[str, Any], parts: list[Any]) -> None:
    """
    Check that metadata.yaml counts what the bag's files hold, else raise CorruptLogError.

    ``meta`` must count what the files ``parts`` (read through, in order) hold: in all, per
    file and per topic.
    """
    total = sum(p.message_count for p in parts)
    if meta["message_count"] != total:
        raise CorruptLogError(directory, f"{METADATA_FILE} counts {meta['message_count']} "
                                         f"messages, the files hold {total}")
    for entry, part in zip(meta.get("files") or [], parts):
        if entry.get("message_count") != part.message_count:
            raise CorruptLogError(
                directory, f"{METADATA_FILE} counts {entry.get('message_count')} messages in "
                f"{entry.get('path')}, the file holds {part.message_count}")
    for t in meta["topics_with_message_count"]:
        name = t["topic_metadata"]["name"]
        held = sum(p.topics[name].message_count for p in parts if name in p.topics)
        if t["message_count"] != held:
            raise CorruptLogError(directory, f"{METADATA_FILE} counts {t['message_count']} "
                                             f"messages on {name}, the files hold {held}")


def _asked_once(select: Callable[[Any], bool]) -> Callable[[Any], bool]:
    """``select``, asked once per topic name, its answer remembered."""
    asked: dict[str, bool] = {}

    def once(topic: Any) -> bool:
        if topic.name not in asked:
            asked[topic.name] = bool(select(topic))
        return asked[topic.name]
    return once


class BagReader:
    """A bag directory opened for one streaming pass; the interface of `reader.LogReader`."""

    def __init__(self, directory: str | os.PathLike[str], recover: bool = False,
                 strict: bool = False) -> None:
        from flexure_sim.recording.reader import LogReader

        self.path = Path(directory)
        self.recover = recover
        self.strict = strict
        self.files = _files(self.path)
        self.parts = [LogReader(p, recover=recover, strict=strict) for p in self.files]
        self.header = self.parts[0].header
        try:
            self._meta = read_bag_metadata(self.path)
        except ValueError as exc:
            if not recover:
                raise CorruptLogError(self.path, str(exc)) from exc
            self._meta = None
        self.bag_metadata: dict[str, Any] | None = None
        self._done = False

    @property
    def summary_ok(self) -> bool:
        return all(p.summary_ok for p in self.parts)

    @property
    def topics(self) -> dict[str, Any]:
        merged: dict[str, Any] = {}
        for part in self.parts:
            for name, info in part.topics.items():
                if name in merged:
                    merged[name] = dataclasses.replace(
                        merged[name],
                        message_count=merged[name].message_count + info.message_count)
                else:
                    merged[name] = info
        return merged

    @property
    def metadata_records(self) -> tuple[tuple[str, dict[str, str]], ...]:
        return tuple(r for p in self.parts for r in p.metadata_records)

    @property
    def metadata(self) -> dict[str, dict[str, str]]:
        return {name: dict(values) for name, values in self.metadata_records}

    def messages(self, select: Callable[[Any], bool] | None = None,
                 decode: bool = True) -> Iterator[Any]:
        """
        Return the messages of every file in turn (`reader.LogReader.messages`).

        ``select`` is asked once per topic of the bag, as for one file (not once per file).
        """
        if self._done:
            raise RuntimeError("BagReader.messages: a log is read in one pass only")
        self._done = True
        once = _asked_once(select) if select is not None else None
        for part in self.parts:
            yield from part.messages(once, decode)
        if self._meta is not None:
            if not self.recover:
                check_counts(self.path, self._meta, self.parts)
            self.bag_metadata = self._meta
        else:
            own = [p.bag_metadata for p in self.parts]
            if all(m is not None for m in own):
                self.bag_metadata = combine_bag_metadata(own)

    def read_through(self, decode: bool = True) -> None:
        for _ in self.messages(decode=decode):
            pass

    @property
    def complete(self) -> bool:
        return all(p.complete for p in self.parts)

    @property
    def undecodable(self) -> dict[str, int]:
        out: dict[str, int] = {}
        for part in self.parts:
            for topic, n in part.undecodable.items():
                out[topic] = out.get(topic, 0) + n
        return out

    @property
    def message_count(self) -> int:
        return sum(p.message_count for p in self.parts)

    @property
    def chunk_count(self) -> int:
        return sum(p.chunk_count for p in self.parts)

    @property
    def unchecked_chunks(self) -> int:
        return sum(p.unchecked_chunks for p in self.parts)

    @property
    def start_ns(self) -> int:
        return min((p.start_ns for p in self.parts if p.message_count), default=0)

    @property
    def end_ns(self) -> int:
        return max((p.end_ns for p in self.parts if p.message_count), default=0)

    @property
    def note(self) -> str:
        return "; ".join(f"{p.path.name}: {p.note}" for p in self.parts if p.note)

    @property
    def size_bytes(self) -> int:
        return sum(p.stat().st_size for p in self.files)
