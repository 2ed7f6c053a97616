"""
The recorder process's side of `record_process`.

Reads the frames the node sends on stdin and writes them with `McapRecorder` (one file) or
`BagRecorder` (a bag directory: its metadata.yaml is written each time a file is finished,
so also when the node died). Protocol, loss policy and test hooks: `record_process`.

Run as ``python -m flexure_sim.node.record.child`` by `record_process.RecorderProcess`.
"""
from __future__ import annotations

import contextlib
import io
import json
import os
import signal
import sys
import time
from pathlib import Path
from typing import Any, BinaryIO, Optional

from flexure_sim.recording import McapRecorder, QosDescription, RecordingError
from flexure_sim.recording.bag import BagRecorder
from flexure_sim.recording.mcap_writer import describe
from flexure_sim.node.record.process import (
    CHILD_QUEUE, FRAME_HEADER, FRAME_STAMP, RECORDER_NICE, WRITE_DELAY_ENV,
)


def _lower_priority() -> None:
    """
    Let the node's paced thread take a shared core from the recorder as soon as it wakes.

    The recorder works in bursts (a compressed chunk every few hundred ms) that, at equal priority,
    the scheduler may let finish first: a late tick. The pipe and the backlog absorb the recorder's
    delay instead.
    """
    try:
        os.nice(RECORDER_NICE)
    except OSError:
        pass


class _SlowFile(io.FileIO):
    """A file whose every write first sleeps ``delay`` seconds (the test hook's slow disk)."""

    delay = 0.0

    def write(self, data: Any) -> Optional[int]:
        time.sleep(self.delay)
        return super().write(data)


def _output(path: Path, claimed: bool = False) -> Path | BinaryIO:
    """Return what the recorder writes to: the path, or a slowed file when the test hook asks."""
    delay = float(os.environ.get(WRITE_DELAY_ENV) or 0.0)
    if delay <= 0.0:
        return path
    raw = _SlowFile(path, "wb" if claimed else "xb")
    raw.delay = delay
    return io.BufferedWriter(raw)


def _fill(new: Any, spec: dict[str, Any]) -> Any:
    """Add the topics and metadata of an ``O`` frame to a new recorder (closed on failure)."""
    try:
        for name, type_name, qos in spec["topics"]:
            new.add_topic(name, type_name, QosDescription.from_dict(qos))
        for name, data in spec["metadata"].items():
            new.add_metadata(name, data)
    except BaseException:
        with contextlib.suppress(RecordingError):
            new.close()
        raise
    return new


def _open(spec: dict[str, Any]) -> McapRecorder | BagRecorder:
    """Return a recorder for an ``O`` frame; the child never drops (it waits for its writer)."""
    path = Path(spec["path"])
    limits = spec.get("bag")
    if limits is not None:  # a bag directory (claimed: the node made it, empty, with mkdir)
        return _fill(BagRecorder(
            path, max_bytes=int(limits.get("max_bytes", 0)),
            max_duration_ns=int(limits.get("max_duration_ns", 0)),
            claimed=bool(spec.get("claimed")), open_file=_output, queue_size=CHILD_QUEUE,
            max_block_s=None), spec)
    # claimed: the node created the empty file with O_EXCL (session), so it is ours to fill.
    claimed = bool(spec.get("claimed")) and path.is_file() and path.stat().st_size == 0
    if path.exists() and not claimed:
        raise RecordingError(f"{path}: exists; recordings are never overwritten")
    path.parent.mkdir(parents=True, exist_ok=True)
    try:
        new = McapRecorder(_output(path, claimed), queue_size=CHILD_QUEUE, max_block_s=None,
                           overwrite=claimed)
    except BaseException:
        with contextlib.suppress(OSError):  # not even the header fits: leave no empty file
            if path.stat().st_size == 0:
                path.unlink()
        raise
    return _fill(new, spec)


#: How long the recorder sleeps when the pipe is empty, s (`PolledInput`).
READ_POLL_S = 0.002


class PolledInput:
    """
    The node's pipe, read without ever blocking in ``read``: the recorder polls it.

    A reader blocked in ``read`` is woken by every frame the node writes, and that wake-up is
    the writer's cost. Measured on a 2-core VM (load 3.5; a 7 kB write every 0.8 ms into a
    pipe a child process reads): a reader blocked in ``read``, 19.3-20.5 us a write (median;
    mean 16-27 us, p99 32-231 us; another run, 8.7 us median, p99 2.4-3.0 ms: the woken reader
    preempts the writer), against 1.2 us (mean 1.4-1.5 us, p99 4-5 us) when the reader polls
    every 2 ms. Polling every `READ_POLL_S` keeps ~2 ticks in the pipe at 1 kHz (the pipe holds
    1 MiB where the system allows it: ~140 ticks of the stage); a full pipe makes the node
    wait (fast, lockstep) or keep the frames in its backlog (real time). What the node wrote
    before it died is still read, then EOF ends the file.
    """

    def __init__(self, stream: BinaryIO, poll_s: float = READ_POLL_S) -> None:
        self._fd = stream.fileno()
        os.set_blocking(self._fd, False)
        self._poll_s = poll_s
        self._buffer = bytearray()
        self._at = 0

    def read_exact(self, n: int) -> Optional[bytes]:
        """Return the next ``n`` bytes, or None at the end of the input before ``n`` bytes."""
        buffer = self._buffer
        while len(buffer) - self._at < n:
            try:
                chunk = os.read(self._fd, 1 << 20)
            except BlockingIOError:
                time.sleep(self._poll_s)
                continue
            if not chunk:
                return None
            if self._at:
                del buffer[:self._at]
                self._at = 0
            buffer += chunk
        start = self._at
        self._at = start + n
        return bytes(buffer[start:start + n])


def _child(stdin: BinaryIO, stdout: BinaryIO) -> int:
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, signal.SIG_IGN)
    _lower_priority()
    recorder: Optional[McapRecorder | BagRecorder] = None
    path = ""
    names: tuple[str, ...] = ()

    def reply(obj: dict[str, Any]) -> None:
        stdout.write(json.dumps(obj).encode() + b"\n")
        stdout.flush()

    read_exact = PolledInput(stdin).read_exact

    try:
        while True:
            header = read_exact(FRAME_HEADER.size)
            if header is None:
                break  # the node is gone: finish the file below
            opcode, length = FRAME_HEADER.unpack(header)
            body = read_exact(length) if length else b""
            if body is None:
                break
            if opcode == b"B":
                if recorder is None:
                    continue
                (stamp,) = FRAME_STAMP.unpack_from(body, 0)
                recorder.write_frame(body, FRAME_STAMP.size, names, stamp)
            elif opcode == b"O":
                spec = json.loads(body)
                try:
                    new = _open(spec)
                except (RecordingError, OSError, ValueError) as exc:
                    reply({"ok": False, "error": describe(exc)})
                    continue
                recorder, names, path = new, tuple(t[0] for t in spec["topics"]), spec["path"]
                reply({"ok": True})
            elif opcode == b"M":
                if recorder is not None:
                    item = json.loads(body)
                    recorder.add_metadata(item["name"], item["data"])
            elif opcode == b"D":
                if recorder is not None:
                    for channel, count in json.loads(body).items():
                        recorder.add_dropped(names[int(channel)], int(count))
            elif opcode == b"C":
                if recorder is None:
                    reply({"ok": True, "accepted": 0, "dropped": 0})
                    continue
                current, recorder = recorder, None
                try:
                    stats = current.close()
                except RecordingError as exc:
                    reply({"ok": False, "error": f"{path}: {describe(exc)}"})
                    continue
                reply({"ok": True, "accepted": stats.accepted_count,
                       "dropped": stats.dropped_count})
            elif opcode == b"Q":
                break
        if recorder is not None:
            recorder.close()
    except RecordingError as exc:
        # The file cannot be written (a full disk...): one line for the node, then exit; the
        # chunks already written stay readable.
        reason = f"{path}: {describe(exc)}"
        try:
            reply({"ok": False, "error": reason})
        except OSError:  # the node is gone too: say it where a user may look
            print(f"flexure_sim recorder: ERROR: {reason}", file=sys.stderr, flush=True)
        if recorder is not None:
            with contextlib.suppress(RecordingError):
                recorder.close()
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(_child(sys.stdin.buffer, sys.stdout.buffer))
