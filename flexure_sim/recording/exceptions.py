"""Exceptions raised by the recording layer: one hierarchy rooted at `RecordingError`."""
from __future__ import annotations

from pathlib import Path

from flexure_sim.errors import FlexureSimError


#: Exit codes of every program that reads logs (the flexure-sim tools, replay).
EXIT_OK = 0
EXIT_BAD_FILE = 1
EXIT_USAGE = 2


class RecordingError(FlexureSimError):
    """Base class of every error raised on purpose by `flexure_sim.recording`."""


class RunError(RecordingError):
    """
    A log that reads but cannot be used as asked (missing topics...), or bad usage.

    ``exit_code`` is `EXIT_BAD_FILE` or `EXIT_USAGE`.
    """

    def __init__(self, message: str, exit_code: int = EXIT_BAD_FILE) -> None:
        super().__init__(message)
        self.exit_code = exit_code


class SchemaNotFoundError(RecordingError):
    """A message type's definition (.msg) could not be found under the ament prefixes."""


class RecorderClosedError(RecordingError):
    """The recorder was used after `close()`."""


class RecorderFailedError(RecordingError):
    """The background writer stopped on an I/O error; the cause is chained."""


class CorruptLogError(RecordingError):
    """
    A log file is empty, truncated, damaged or not a rosbag2 (profile ``ros2``) MCAP file.

    Attributes say what is wrong and how much of the file was readable:
    ``reason``, ``readable_messages`` (messages in intact chunks), ``readable_bytes`` (length
    of the intact prefix), ``total_bytes`` and ``damaged_chunks`` (chunks skipped because they
    fail their CRC or do not parse; reading went on after them).
    """

    def __init__(
        self,
        path: str | Path,
        reason: str,
        *,
        readable_messages: int = 0,
        readable_bytes: int = 0,
        total_bytes: int = 0,
        damaged_chunks: int = 0,
        hint: str = "",
    ) -> None:
        self.path = Path(path)
        self.reason = reason
        self.readable_messages = readable_messages
        self.readable_bytes = readable_bytes
        self.total_bytes = total_bytes
        self.damaged_chunks = damaged_chunks
        if damaged_chunks and readable_bytes >= total_bytes:
            extent = f"outside the {damaged_chunks} damaged chunk(s)"
        else:
            extent = f"in the first {readable_bytes} of {total_bytes} bytes"
            if damaged_chunks:
                extent += f" outside the {damaged_chunks} damaged chunk(s)"
        message = f"{self.path}: {reason} [{readable_messages} message(s) readable {extent}]"
        if hint:
            message += f"; {hint}"
        super().__init__(message)


class UndecodableMessageError(CorruptLogError):
    """A message does not decode as its channel's type and the reader was asked to be strict."""
