"""
`McapRecorder`: records serialized ROS 2 messages to an MCAP file as rosbag2 (Jazzy) does.

The caller (the simulation loop) only enqueues; a background thread (`mcap_writer.Worker`,
with `mcap_batch.BatchWriter`) owns the file.

Overflow policy: the queue holds ``queue_size`` batches (`McapRecorder.write_batch`, e.g. one
tick; `write` queues a batch of one message). When it is full, a write waits at most
``max_block_s`` for room (``None``: as long as it takes, back-pressure that never drops), then
drops the batch, counts its messages per topic and returns False. Messages a producer
dropped before they reached the recorder are added with `McapRecorder.add_dropped`. Drops are
never silent: `McapRecorder.stats` exposes them and the bag metadata of the file records the
total under ``custom_data['flexure_sim.dropped_messages']``.

Crash safety: a chunk is closed and handed to the OS when it reaches ``chunk_size`` bytes or
``chunk_interval_s`` seconds (wall clock) after its first message, whichever comes first, so a
``kill -9`` loses at most that much. `close` (idempotent) writes the ``rosbag2`` metadata
record and the summary; a recorder never closed is finished at interpreter exit.
"""
from __future__ import annotations

import os
import queue
import re
import threading
import weakref
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import BinaryIO

from flexure_sim import __version__
from flexure_sim.recording.bag_metadata import METADATA_RECORD_NAME
from flexure_sim.recording.counts import Counters, RecordingStats
from flexure_sim.recording.exceptions import (
    RecorderClosedError, RecorderFailedError, RecordingError,
)
from flexure_sim.recording.mcap_batch import frame_messages
from flexure_sim.recording.mcap_writer import (
    DROPPED_KEY, AddMetadata, AddTopic, FrameItem, Worker, describe, metadata_items,
    start_writer,
)
from flexure_sim.recording.qos import QosDescription, QosLike, qos_profiles_yaml
from flexure_sim.recording.schema import SchemaResolver, normalize_type_name

__all__ = ["DROPPED_KEY", "McapRecorder", "RecordingStats"]
_TOPIC_NAME = re.compile(r"^(/[A-Za-z_][A-Za-z0-9_]*)+$")
_MAX_STAMP = 2**64 - 1

Output = str | os.PathLike[str] | BinaryIO
_CONTROL_TIMEOUT_S = 30.0


class McapRecorder:
    """
    Context-managed rosbag2-compatible MCAP recorder fed with CDR payloads.

    ``output`` is a path (created; an existing file is an error unless ``overwrite``) or a
    binary stream (closed by `close`). Payloads are the bytes of
    ``rclpy.serialization.serialize_message``; this class does not import rclpy.
    ``ament_prefixes`` overrides where message definitions are looked up (see `schema`).
    """

    def __init__(
        self,
        output: Output,
        *,
        chunk_size: int = 1 << 20,
        chunk_interval_s: float = 1.0,
        queue_size: int = 10_000,
        max_block_s: float | None = 0.05,
        fsync_chunks: bool = False,
        overwrite: bool = False,
        ament_prefixes: Sequence[str | os.PathLike[str]] | None = None,
        ros_distro: str = "jazzy",
    ) -> None:
        if chunk_size <= 0:
            raise ValueError(f"chunk_size: must be > 0, got {chunk_size}")
        if not chunk_interval_s > 0:
            raise ValueError(f"chunk_interval_s: must be > 0, got {chunk_interval_s}")
        if queue_size <= 0:
            raise ValueError(f"queue_size: must be > 0, got {queue_size}")
        if max_block_s is not None and not max_block_s >= 0:
            raise ValueError(f"max_block_s: must be >= 0 or None, got {max_block_s}")
        stream, self._path, file_name = _open_output(output, overwrite)
        writer, out = start_writer(stream, file_name, f"flexure_sim {__version__}", chunk_size)
        self._max_block_s = max_block_s
        self._resolver = SchemaResolver(ament_prefixes)
        self._lock = threading.RLock()
        self._counters = Counters()
        self._closed = False
        self._close_result: RecordingStats | None = None
        self._channels: dict[str, int] = {}
        self._types: dict[str, str] = {}
        self._schema_ids: dict[str, int] = {}
        self._frame_ids: tuple[Sequence[str], list[int]] | None = None
        self._worker = Worker(
            writer, out, file_name, self._counters.dropped_total,
            queue_size, chunk_interval_s, ros_distro, fsync_chunks,
        )
        self._finalizer = weakref.finalize(self, self._worker.shutdown, 30.0)

    # -- context manager --------------------------------------------------------------------
    def __enter__(self) -> McapRecorder:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    # -- properties -------------------------------------------------------------------------
    @property
    def path(self) -> Path | None:
        """Return the file written, or None when recording to a stream."""
        return self._path

    @property
    def closed(self) -> bool:
        return self._closed

    @property
    def topics(self) -> dict[str, str]:
        """Topic name -> type name (``pkg/msg/Type``) of the topics added so far."""
        with self._lock:
            return dict(self._types)

    @property
    def stats(self) -> RecordingStats:
        """
        Accept and dropped counts per topic, and batches still queued.

        A frame's messages (`write_frame`) count as accepted once written.
        """
        return self._counters.snapshot(self._worker.queue.qsize(), self._frames_written())

    def _frames_written(self) -> dict[str, int]:
        """Messages per topic written from `write_frame`'s frames so far."""
        topic_of = {channel_id: topic for topic, channel_id in self._channels.items()}
        return {topic_of[c]: n for c, n in self._worker.frame_counts().items() if n}

    @property
    def dropped_count(self) -> int:
        return self.stats.dropped_count

    @property
    def bag_metadata(self) -> dict | None:
        """Return the rosbag2 metadata written into the file by `close` (None before)."""
        return self._worker.bag_metadata

    # -- recording --------------------------------------------------------------------------
    def add_topic(
        self,
        name: str,
        type_name: str,
        qos: QosLike | Sequence[QosLike] | None = None,
    ) -> None:
        """
        Add a channel for topic ``name`` (absolute, ``/...``) of type ``pkg/msg/Type``.

        ``qos`` is the publisher's offered QoS: an rclpy ``QoSProfile``, a `QosDescription`,
        a rosbag2-style dict, or a list of those (default: `QosDescription.reliable()`).
        Adding the same topic with the same type again does nothing.
        """
        if not isinstance(name, str) or not _TOPIC_NAME.match(name):
            raise ValueError(f"name: expected an absolute topic name like '/a/b', got {name!r}")
        full_type = normalize_type_name(type_name)
        if qos is None:
            profiles: list[QosLike] = [QosDescription.reliable()]
        elif isinstance(qos, (list, tuple)):
            profiles = list(qos)
        else:
            profiles = [qos]
        qos_yaml = qos_profiles_yaml(profiles)
        with self._lock:
            self._check_open()
            known = self._types.get(name)
            if known is not None:
                if known != full_type:
                    raise ValueError(
                        f"name: topic {name} was added with type {known}, not {full_type}"
                    )
                return
            schema = self._resolver.schema(full_type)
            schema_id = self._schema_ids.get(full_type)
            new_schema = schema_id is None
            if schema_id is None:
                schema_id = len(self._schema_ids) + 1
            channel_id = len(self._channels) + 1
            self._worker.put_control(
                AddTopic(
                    channel_id=channel_id,
                    topic=name,
                    type_name=full_type,
                    schema_id=schema_id,
                    schema_text=schema.text.encode("utf-8") if new_schema else None,
                    qos_yaml=qos_yaml,
                    type_hash=schema.type_hash,
                ),
                _CONTROL_TIMEOUT_S,
            )
            self._schema_ids[full_type] = schema_id
            self._channels[name] = channel_id
            self._types[name] = full_type
            with self._counters.lock:
                self._counters.accepted[name] = 0
                self._counters.dropped[name] = 0

    def write(self, topic: str, payload: bytes | bytearray | memoryview, stamp_ns: int) -> bool:
        """
        Queue one CDR-serialized message; log_time = publish_time = ``stamp_ns`` (sim time).

        Returns False if the message was dropped because the queue stayed full for
        ``max_block_s`` (counted in `stats`); with ``max_block_s=None`` it waits for room and
        never drops. Raises `RecorderClosedError` after `close`, `RecorderFailedError` if the
        writer thread failed.
        """
        return self.write_batch(((topic, payload),), stamp_ns)

    def write_batch(
        self,
        messages: Sequence[tuple[str, bytes | bytearray | memoryview]],
        stamp_ns: int,
    ) -> bool:
        """
        Queue several messages (topic, CDR payload) with one log time.

        e.g. one tick of the simulation: one queue entry, kept or dropped whole (as `write` says).
        """
        channels = self._channels
        items = []
        for topic, payload in messages:
            channel_id = channels.get(topic)
            if channel_id is None:
                raise ValueError(f"topic: {topic!r} was not added (call add_topic first)")
            items.append((channel_id, payload if isinstance(payload, bytes) else bytes(payload)))
        _check_stamp(stamp_ns)
        with self._lock:
            self._check_writing()
            kept = self._enqueue((stamp_ns, items))
            counts = self._counters.accepted if kept else self._counters.dropped
            with self._counters.lock:
                for topic, _ in messages:
                    counts[topic] += 1
        return kept

    def write_frame(self, frame: bytes, start: int, topics: Sequence[str],
                    stamp_ns: int) -> bool:
        """
        Queue one tick's messages packed in ``frame``.

        From ``start``, per message its index into ``topics`` and its size
        (`mcap_batch.FRAME_ITEM`), then its CDR payload. `write_batch` of the same messages,
        kept or dropped whole alike, without a Python object per message on the way (the
        recorder process's frames, `BatchWriter.add_frame`). Its messages count in `stats` as
        accepted once written. Pass the same ``topics`` sequence each time: its channels are
        looked up once for it.
        """
        ids = self._frame_ids
        if ids is None or ids[0] is not topics:
            try:
                ids = self._frame_ids = (topics, [self._channels[t] for t in topics])
            except KeyError as exc:
                raise ValueError(f"topic: {exc.args[0]!r} was not added (call add_topic first)") \
                    from None
        _check_stamp(stamp_ns)
        with self._lock:
            self._check_writing()
            kept = self._enqueue(FrameItem(stamp_ns, frame, start, ids[1]))
            if not kept:
                dropped = self._counters.dropped
                with self._counters.lock:
                    for topic, _ in frame_messages(frame, start, topics):
                        dropped[topic] += 1
        return kept

    def _check_writing(self) -> None:
        """Raise if the recorder is closed or its writer failed (with ``_lock`` held)."""
        self._check_open()
        error = self._worker.error
        if error is not None:
            raise RecorderFailedError(f"MCAP writer failed: {describe(error)}") from error

    def _enqueue(self, item: object) -> bool:
        """
        Put a batch on the queue.

        Waiting at most ``max_block_s`` for room (None: until there is room, unless the writer
        thread fails).
        """
        pending = self._worker.queue
        try:
            pending.put_nowait(item)
            return True
        except queue.Full:
            if self._max_block_s is None:
                self._worker.put_control(item, None)
                return True
            if self._max_block_s <= 0:
                return False
        try:
            pending.put(item, timeout=self._max_block_s)
            return True
        except queue.Full:
            return False

    def add_metadata(self, name: str, data: Mapping[str, str]) -> None:
        """Write a Metadata record (e.g. ``flexure_sim``: mechanism name and parameters)."""
        if not isinstance(name, str) or not name:
            raise ValueError(f"name: expected a non-empty string, got {name!r}")
        if name == METADATA_RECORD_NAME:
            raise ValueError(f"name: {name!r} is reserved for the bag metadata written by close()")
        items = metadata_items(data)
        with self._lock:
            self._check_open()
            self._worker.put_control(AddMetadata(name, items), _CONTROL_TIMEOUT_S)

    def add_dropped(self, topic: str, count: int) -> None:
        """
        Count ``count`` messages of ``topic`` that a producer dropped.

        They were dropped before they reached this recorder (e.g. ticks a full pipe refused); the
        count goes in `stats` and the file's metadata.
        """
        if topic not in self._channels:
            raise ValueError(f"topic: {topic!r} was not added (call add_topic first)")
        if isinstance(count, bool) or not isinstance(count, int) or count < 0:
            raise ValueError(f"count: expected an int >= 0, got {count!r}")
        with self._lock:
            self._check_open()
            with self._counters.lock:
                self._counters.dropped[topic] += count

    def close(self, timeout_s: float = 30.0) -> RecordingStats:
        """
        Drain the queue, write the bag metadata and summary, close the file.

        Idempotent: later calls return the same stats. Raises `RecorderFailedError` (first call
        only) if the file could not be finished.
        """
        with self._lock:
            if self._closed:
                assert self._close_result is not None
                return self._close_result
            self._closed = True
        worker = self._worker
        self._close_result = self._counters.snapshot()
        self._finalizer.detach()
        worker.shutdown(timeout_s)
        if worker.thread.is_alive():
            raise RecorderFailedError(f"MCAP writer did not finish within {timeout_s} s")
        # The frames' messages count once written; a failed writer's stats keep what it wrote.
        self._close_result = self._counters.snapshot(0, self._frames_written())
        if worker.error is not None:
            raise RecorderFailedError(f"MCAP writer failed: {describe(worker.error)}") \
                from worker.error
        return self._close_result

    def _check_open(self) -> None:
        if self._closed:
            raise RecorderClosedError("the recorder is closed")


def _open_output(output: Output, overwrite: bool) -> tuple[BinaryIO, Path | None, str]:
    if isinstance(output, (str, os.PathLike)):
        path = Path(output)
        try:
            stream: BinaryIO = open(path, "wb" if overwrite else "xb")  # noqa: SIM115
        except OSError as exc:
            raise RecordingError(f"cannot create {path}: {exc}") from exc
        return stream, path, path.name
    if not hasattr(output, "write"):
        raise TypeError(f"output: expected a path or a binary stream, got {type(output)!r}")
    name = getattr(output, "name", None)
    file_name = Path(name).name if isinstance(name, str) and name else "recording.mcap"
    return output, None, file_name


def _check_stamp(stamp_ns: object) -> None:
    """Raise ValueError unless ``stamp_ns`` is an int of nanoseconds in [0, 2**64)."""
    if isinstance(stamp_ns, bool) or not isinstance(stamp_ns, int):
        raise ValueError(f"stamp_ns: expected an int of nanoseconds, got {stamp_ns!r}")
    if not 0 <= stamp_ns <= _MAX_STAMP:
        raise ValueError(f"stamp_ns: must be in [0, 2**64), got {stamp_ns}")
