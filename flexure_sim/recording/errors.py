"""Exceptions raised by the recording layer: one hierarchy rooted at `RecordingError`."""
from __future__ import annotations

from pathlib import Path

from ..errors import FlexureSimError


class RecordingError(FlexureSimError):
    """Base class of every error raised on purpose by `flexure_sim.recording`."""


class SchemaNotFoundError(RecordingError):
    """A message type's definition (.msg) could not be found under the ament prefixes."""


class RecorderClosedError(RecordingError):
    """The recorder was used after `close()`."""


class RecorderFailedError(RecordingError):
    """The background writer stopped on an I/O error; the cause is chained."""


class CorruptLogError(RecordingError):
    """A log file is empty, truncated, damaged or not a rosbag2 (profile ``ros2``) MCAP file.

    Attributes say what is wrong and how much of the file was readable:
    ``reason``, ``readable_messages`` (messages in intact chunks before the damage),
    ``readable_bytes`` (length of the intact prefix) and ``total_bytes``.
    """

    def __init__(
        self,
        path: str | Path,
        reason: str,
        *,
        readable_messages: int = 0,
        readable_bytes: int = 0,
        total_bytes: int = 0,
        hint: str = "",
    ) -> None:
        self.path = Path(path)
        self.reason = reason
        self.readable_messages = readable_messages
        self.readable_bytes = readable_bytes
        self.total_bytes = total_bytes
        message = (
            f"{self.path}: {reason} "
            f"[{readable_messages} message(s) readable in the first {readable_bytes} "
            f"of {total_bytes} bytes]"
        )
        if hint:
            message += f"; {hint}"
        super().__init__(message)
