"""
The recorder's background thread: it owns the output stream and the file's `BatchWriter`.

The file is the one ``mcap.writer.Writer`` writes (profile ``ros2``, uncompressed chunks with
CRCs, a data-section CRC, message and chunk indexes, statistics, summary offsets: the layout
rosbag2 opens), byte for byte; `mcap_batch.BatchWriter` writes it a tick at a time, about a
quarter of the CPU time a message of the library's ``add_message`` (its docstring has the
measured reason).
Schema and Channel records go into the chunk open when they are added (so a recovered prefix
of complete chunks holds its definitions); the first chunk carries them on top of
``chunk_size``.

Crash safety: the writer finishes a chunk when it passes ``chunk_size`` bytes, and this thread
calls its ``flush()`` (finish the open chunk, flush the stream)
``chunk_interval_s`` seconds (wall clock) after the first message not yet flushed, so every
message reaches the OS within that time and a ``kill -9`` loses at most the open chunk. Chunks
are uncompressed (rosbag2's default), so a recovered prefix needs no decompressor.
"""
from __future__ import annotations

import contextlib
import os
import queue
import threading
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import BinaryIO


from flexure_sim.recording.bag_metadata import (
    METADATA_RECORD_KEY, METADATA_RECORD_NAME, TopicRecord, build_bag_metadata,
    dump_serialized_metadata,
)
from flexure_sim.recording.exceptions import RecorderFailedError, RecordingError
from flexure_sim.recording.mcap_batch import BatchWriter

PROFILE = "ros2"
MESSAGE_ENCODING = "cdr"
SCHEMA_ENCODING = "ros2msg"
DROPPED_KEY = "flexure_sim.dropped_messages"


class PositionStream:
    """
    The output stream as the writer sees it.

    ``tell()`` counts the bytes written, so pipes and other unseekable streams work too.
    """

    def __init__(self, stream: BinaryIO) -> None:
        self.stream = stream
        self.position = 0

    def write(self, data: bytes) -> int:
        self.stream.write(data)
        self.position += len(data)
        return len(data)

    def tell(self) -> int:
        return self.position

    def flush(self) -> None:
        self.stream.flush()

    def fsync(self) -> None:
        """``os.fsync`` where the stream has a file descriptor that can be synced."""
        try:
            fileno = self.stream.fileno()
        except (AttributeError, OSError, ValueError):
            return
        with contextlib.suppress(OSError):  # pipes and some special files cannot be synced
            os.fsync(fileno)

    def close(self) -> None:
        self.stream.close()


def start_writer(
    stream: BinaryIO, file_name: str, library: str, chunk_size: int
) -> tuple[BatchWriter, PositionStream]:
    """
    Return a started `BatchWriter` on ``stream``.

    The header is flushed at once, so a stream that cannot be written fails here (`RecordingError`)
    rather than in the background thread.
    """
    out = PositionStream(stream)
    writer = BatchWriter(out, chunk_size)
    try:
        writer.start(profile=PROFILE, library=library)
        out.flush()
    except OSError as exc:
        with contextlib.suppress(OSError):  # flushing the buffered header fails again
            stream.close()
        raise RecordingError(f"cannot write {file_name}: {describe(exc)}") from exc
    return writer, out


@dataclass(frozen=True)
class AddTopic:
    channel_id: int
    topic: str
    type_name: str
    schema_id: int
    schema_text: bytes | None  # None when the schema was already written
    qos_yaml: str
    type_hash: str


@dataclass(frozen=True)
class AddMetadata:
    name: str
    data: dict[str, str]


class Close:
    pass


@dataclass(frozen=True)
class FrameItem:
    """A tick's messages as a frame (`BatchWriter.add_frame`): time, frame, start, ids."""

    stamp: int
    frame: bytes
    start: int
    channel_ids: list[int]


class Worker:
    """
    The background thread and everything it owns. Holds no reference to the recorder.

    Queue items: ``(stamp_ns, [(channel_id, payload), ...])`` tuples (messages), `FrameItem`,
    `AddTopic`, `AddMetadata`, `Close`. ``dropped`` returns the total count of dropped messages
    when the bag metadata is written.
    """

    def __init__(
        self,
        writer: BatchWriter,
        out: PositionStream,
        file_name: str,
        dropped: Callable[[], int],
        queue_size: int,
        chunk_interval_s: float,
        ros_distro: str,
        fsync: bool = False,
    ) -> None:
        self.queue: queue.Queue[object] = queue.Queue(maxsize=queue_size)
        self.error: BaseException | None = None
        self._writer = writer
        self._out = out
        self._file_name = file_name
        self._dropped = dropped
        self._interval = chunk_interval_s
        self._ros_distro = ros_distro
        self._fsync = fsync
        self._topics: dict[int, AddTopic] = {}
        #: Messages per channel written from `write_batch`'s tuples; the rest came in frames.
        self.batch_counts: dict[int, int] = {}
        self.bag_metadata: dict | None = None
        self._deadline: float | None = None
        self.thread = threading.Thread(target=self._run, name="mcap-recorder", daemon=True)
        self.thread.start()

    def put_control(self, item: object, timeout_s: float | None) -> None:
        """
        Enqueue an item that must not be dropped.

        Waiting for room at most ``timeout_s`` (None: as long as the thread runs); fail if the
        thread is gone, failed or stuck.
        """
        deadline = None if timeout_s is None else time.monotonic() + timeout_s
        while True:
            if self.error is not None:
                raise RecorderFailedError(f"MCAP writer failed: {describe(self.error)}") \
                    from self.error
            try:
                self.queue.put(item, timeout=0.1)
                return
            except queue.Full:
                if not self.thread.is_alive():
                    raise RecorderFailedError("MCAP writer thread is not running") from None
                if deadline is not None and time.monotonic() > deadline:
                    raise RecorderFailedError(
                        f"MCAP writer made no room in its queue for {timeout_s} s"
                    ) from None

    def shutdown(self, timeout_s: float) -> None:
        """Finish the file (drains the queue first); used by close() and at interpreter exit."""
        if self.thread.is_alive():
            deadline = time.monotonic() + timeout_s
            with contextlib.suppress(RecordingError):
                self.put_control(Close(), timeout_s)
            self.thread.join(max(0.0, deadline - time.monotonic()))

    def _run(self) -> None:
        writer = self._writer
        get = self.queue.get
        monotonic = time.monotonic
        try:
            while True:
                timeout = None
                if self._deadline is not None:
                    timeout = max(0.0, self._deadline - monotonic())
                try:
                    item = get(timeout=timeout)
                except queue.Empty:
                    self._flush()
                    continue
                kind = type(item)
                if kind is tuple or kind is FrameItem:
                    if kind is tuple:
                        stamp, messages = item
                        writer.add_batch(stamp, messages)
                        batch = self.batch_counts
                        for channel_id, _ in messages:
                            batch[channel_id] = batch.get(channel_id, 0) + 1
                    else:
                        writer.add_frame(item.stamp, item.frame, item.start, item.channel_ids)
                    if self._deadline is None:
                        self._deadline = monotonic() + self._interval
                    elif monotonic() >= self._deadline:
                        self._flush()
                elif isinstance(item, AddTopic):
                    if item.schema_text is not None:
                        writer.register_schema(item.type_name, SCHEMA_ENCODING, item.schema_text)
                    writer.register_channel(
                        item.topic,
                        MESSAGE_ENCODING,
                        item.schema_id,
                        {"offered_qos_profiles": item.qos_yaml,
                         "topic_type_hash": item.type_hash},
                    )
                    self._topics[item.channel_id] = item
                elif isinstance(item, AddMetadata):
                    writer.add_metadata(item.name, item.data)
                elif isinstance(item, Close):
                    self._finish()
                    return
        except BaseException as exc:  # reported to the producer side
            self.error = exc
            with contextlib.suppress(OSError, ValueError):  # the buffer fails to flush again
                self._out.close()

    def frame_counts(self) -> dict[int, int]:
        """Messages per channel written from `FrameItem` frames so far."""
        batch = self.batch_counts
        return {channel_id: n - batch.get(channel_id, 0)
                for channel_id, n in list(self._writer.channel_counts.items())}

    def _flush(self) -> None:
        """Finish the open chunk and hand it to the OS (and the disk with ``fsync``)."""
        self._writer.flush()
        if self._fsync:
            self._out.fsync()
        self._deadline = None

    def _finish(self) -> None:
        topics = [
            TopicRecord(
                name=t.topic,
                type=t.type_name,
                offered_qos_profiles=t.qos_yaml,
                type_description_hash=t.type_hash,
                message_count=self._writer.channel_counts.get(t.channel_id, 0),
            )
            for t in sorted(self._topics.values(), key=lambda t: t.channel_id)
        ]
        start, end = self._writer.message_times
        metadata = build_bag_metadata(
            file_name=self._file_name,
            topics=topics,
            start_ns=start,
            end_ns=end,
            custom_data={DROPPED_KEY: str(self._dropped())},
            ros_distro=self._ros_distro,
        )
        #: The file's rosbag2 metadata (for a bag directory's metadata.yaml).
        self.bag_metadata = metadata
        self._writer.flush()
        self._writer.add_metadata(
            METADATA_RECORD_NAME, {METADATA_RECORD_KEY: dump_serialized_metadata(metadata)}
        )
        self._writer.finish()
        self._out.flush()
        self._out.fsync()
        self._out.close()


def describe(exc: BaseException) -> str:
    """One line naming an I/O failure (``No space left on device``), without a traceback."""
    if isinstance(exc, OSError) and exc.strerror:
        where = f" ({exc.filename})" if exc.filename else ""
        return f"{exc.strerror}{where}"
    return str(exc) or type(exc).__name__


def metadata_items(data: Mapping[str, str]) -> dict[str, str]:
    """Return a Metadata record's key/value map, checked: keys and values must be str."""
    items = dict(data)
    for key, value in items.items():
        if not isinstance(key, str) or not isinstance(value, str):
            raise ValueError(f"data: keys and values must be str, got {key!r}: {value!r}")
    return items
