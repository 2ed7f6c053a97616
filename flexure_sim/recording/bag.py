"""
Bag directories as ``ros2 bag record`` (rosbag2 Jazzy, storage mcap) writes them.

``<dir>/metadata.yaml`` and ``<dir>/<dir>_0.mcap``, ``<dir>_1.mcap``... when split.

`BagRecorder` writes one: each file is a complete `McapRecorder` MCAP (its own summary and
``rosbag2`` metadata record), and ``metadata.yaml`` (`bag_metadata.combine_bag_metadata` of
the files' own metadata: one definition) is rewritten each time a file is finished, so it
always lists the finished files. A new file starts before a batch (one tick: never split)
once the current file holds ``max_bytes`` of message payload (rosbag2's
``max_bagfile_size``, counted before MCAP framing and chunk compression) or spans
``max_duration_ns`` of log time (rosbag2's ``max_bagfile_duration``); 0 = no limit.

`bag_files` lists a directory's files in order (``relative_file_paths`` of its metadata.yaml,
else the ``*_N.mcap`` files by N), so readers take a directory as one run.
"""
from __future__ import annotations

import os
import re
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

from flexure_sim.recording.bag_metadata import (
    combine_bag_metadata, metadata_yaml, parse_metadata_yaml,
)
from flexure_sim.recording.exceptions import RecordingError
from flexure_sim.recording.mcap_batch import frame_messages
from flexure_sim.recording.writer import McapRecorder, Output, RecordingStats

METADATA_FILE = "metadata.yaml"
_INDEX = re.compile(r"_(\d+)\.mcap$")


def bag_file_name(directory: Path, index: int) -> str:
    """Name of the ``index``-th file of the bag in ``directory`` (rosbag2: <dir>_<index>.mcap)."""
    return f"{directory.name}_{index}.mcap"


class BagRecorder:
    """
    A rosbag2 bag directory written with `McapRecorder` files; the same recording API.

    ``directory`` must not exist, or (``claimed``) exist empty (a name the caller claimed).
    ``open_file(path)`` returns what each McapRecorder writes to (default: the path);
    ``recorder_options`` go to every McapRecorder.
    """

    def __init__(self, directory: str | os.PathLike[str], *, max_bytes: int = 0,
                 max_duration_ns: int = 0, claimed: bool = False,
                 open_file: Callable[[Path], Output] | None = None,
                 **recorder_options: Any) -> None:
        if max_bytes < 0 or max_duration_ns < 0:
            raise ValueError("max_bytes, max_duration_ns: must be >= 0 (0: no limit)")
        self.directory = Path(directory)
        ours = claimed and self.directory.is_dir() and not any(self.directory.iterdir())
        try:
            if not ours:
                self.directory.mkdir(parents=True)
        except FileExistsError:
            raise RecordingError(
                f"{self.directory}: exists; recordings are never overwritten") from None
        except OSError as exc:
            raise RecordingError(f"cannot create {self.directory}: {exc}") from exc
        self._max_bytes = max_bytes
        self._max_duration = max_duration_ns
        self._open_file = open_file or (lambda path: path)
        self._options = recorder_options
        self._topics: list[tuple[str, str, Any]] = []
        self._metadata: list[tuple[str, Mapping[str, str]]] = []
        self._finished: list[dict[str, Any]] = []
        self._accepted: dict[str, int] = {}
        self._dropped: dict[str, int] = {}
        self._closed = False
        self._file_bytes = 0
        self._file_start: int | None = None
        self._current = self._new_file()

    @property
    def path(self) -> Path:
        return self.directory

    @property
    def files(self) -> list[Path]:
        """Return the bag's files so far, in order (the last one still open unless closed)."""
        return [self.directory / bag_file_name(self.directory, i)
                for i in range(len(self._finished) + (0 if self._closed else 1))]

    def _new_file(self) -> McapRecorder:
        path = self.directory / bag_file_name(self.directory, len(self._finished))
        recorder = McapRecorder(self._open_file(path), **self._options)
        for name, type_name, qos in self._topics:
            recorder.add_topic(name, type_name, qos)
        for name, data in self._metadata:
            recorder.add_metadata(name, data)
        self._file_bytes = 0
        self._file_start = None
        return recorder

    def _finish_file(self) -> None:
        """Close the current file and rewrite metadata.yaml with it."""
        stats = self._current.close()
        for counts, target in ((stats.accepted, self._accepted), (stats.dropped, self._dropped)):
            for topic, n in counts.items():
                target[topic] = target.get(topic, 0) + n
        meta = self._current.bag_metadata
        if meta is not None:
            self._finished.append(meta)
            self._write_metadata()

    def _write_metadata(self) -> None:
        text = metadata_yaml(combine_bag_metadata(self._finished))
        tmp = self.directory / (METADATA_FILE + ".tmp")
        try:
            tmp.write_text(text)
            os.replace(tmp, self.directory / METADATA_FILE)  # never half a metadata.yaml
        except OSError as exc:
            raise RecordingError(f"{self.directory / METADATA_FILE}: {exc}") from exc

    # -- the McapRecorder API ----------------------------------------------------------------
    def add_topic(self, name: str, type_name: str, qos: Any = None) -> None:
        self._current.add_topic(name, type_name, qos)
        self._topics.append((name, type_name, qos))

    def add_metadata(self, name: str, data: Mapping[str, str]) -> None:
        """
        Write a metadata record into the current file.

        Repeated in every later file, so that each file describes its run on its own.
        """
        self._current.add_metadata(name, data)
        self._metadata.append((name, dict(data)))

    def add_dropped(self, topic: str, count: int) -> None:
        self._current.add_dropped(topic, count)

    def write_batch(self, messages: Sequence[tuple[str, bytes]], stamp_ns: int) -> bool:
        self._maybe_split(stamp_ns)
        kept = self._current.write_batch(messages, stamp_ns)
        if kept:
            if self._file_start is None:
                self._file_start = stamp_ns
            self._file_bytes += sum(len(p) for _, p in messages)
        return kept

    def write_frame(self, frame: bytes, start: int, topics: Sequence[str],
                    stamp_ns: int) -> bool:
        """`McapRecorder.write_frame` into the current file, as `write_batch` splits."""
        self._maybe_split(stamp_ns)
        kept = self._current.write_frame(frame, start, topics, stamp_ns)
        if kept:
            if self._file_start is None:
                self._file_start = stamp_ns
            if self._max_bytes:
                self._file_bytes += sum(len(p) for _, p in frame_messages(frame, start, topics))
        return kept

    def _maybe_split(self, stamp_ns: int) -> None:
        """Start the next file if the current one holds ``max_bytes`` or ``max_duration``."""
        if self._file_start is not None and (
                (self._max_bytes and self._file_bytes >= self._max_bytes)
                or (self._max_duration and stamp_ns - self._file_start >= self._max_duration)):
            self._finish_file()
            self._current = self._new_file()

    def write(self, topic: str, payload: bytes, stamp_ns: int) -> bool:
        return self.write_batch(((topic, payload),), stamp_ns)

    @property
    def stats(self) -> RecordingStats:
        current = self._current.stats if not self._closed else RecordingStats({}, {})
        accepted = dict(self._accepted)
        dropped = dict(self._dropped)
        for topic, n in current.accepted.items():
            accepted[topic] = accepted.get(topic, 0) + n
        for topic, n in current.dropped.items():
            dropped[topic] = dropped.get(topic, 0) + n
        return RecordingStats(accepted, dropped, current.pending)

    def close(self) -> RecordingStats:
        """Finish the last file and metadata.yaml (idempotent)."""
        if not self._closed:
            self._closed = True
            self._finish_file()
        return RecordingStats(dict(self._accepted), dict(self._dropped))


def is_bag_directory(path: Path) -> bool:
    """Return True if ``path`` is a directory holding a metadata.yaml or MCAP files."""
    return path.is_dir() and ((path / METADATA_FILE).is_file() or any(path.glob("*.mcap")))


def read_bag_metadata(directory: Path) -> dict[str, Any] | None:
    """Return the parsed metadata.yaml of a bag directory (None if absent; ValueError if bad)."""
    try:
        text = (directory / METADATA_FILE).read_text()
    except FileNotFoundError:
        return None
    except (OSError, UnicodeDecodeError) as exc:
        raise ValueError(f"{directory / METADATA_FILE}: unreadable ({exc})") from exc
    return parse_metadata_yaml(text)


def bag_files(directory: Path) -> list[Path]:
    """
    Return the files of a bag directory, in order.

    Those metadata.yaml lists, then any later ``*_N.mcap`` it does not (a file being written when
    both processes died); without a metadata.yaml, every ``*.mcap`` by its index N (then by name).
    """
    listed: list[Path] = []
    try:
        meta = read_bag_metadata(directory)
    except ValueError:
        meta = None
    if meta is not None:
        listed = [directory / p for p in meta["relative_file_paths"]]

    def key(p: Path) -> tuple[int, str]:
        m = _INDEX.search(p.name)
        return (int(m.group(1)) if m else -1, p.name)

    rest = sorted((p for p in directory.glob("*.mcap") if p not in listed), key=key)
    return listed + rest
