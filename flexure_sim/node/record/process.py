"""
MCAP recording in a helper process, so writing the file costs the stepping loop no GIL time.

At 1 kHz the node records ~26 000 messages/s. `McapRecorder` already writes on a background
thread, but in the node's process that thread competes with the stepping loop for the GIL
(~8 us per message, ~200 us per 1 ms tick). So the node runs the recorder in a child process
(``python -m flexure_sim.node.record.child``, using the recording layer's public API) and
hands it each tick's payloads as one frame on a pipe, which the child polls (`child.PolledInput`:
a write that wakes no reader costs ~1 us).

Protocol on the child's stdin, frames of ``<opcode:1><length:u32 LE><body>``:

- ``O`` open: JSON {path, topics: [[name, type, qos], ...], metadata: {name: {k: v}},
  claimed, bag: null (one MCAP file) or {max_bytes, max_duration_ns} (a bag directory)}
- ``B`` batch: ``<stamp:u64>`` then per message ``<channel:u16><size:u32><cdr bytes>``
  (channel = index into the topics of the open file)
- ``M`` metadata: JSON {name, data}
- ``D`` dropped: JSON {channel index: count} of messages the parent could not send
- ``C`` close the file; ``Q`` quit.

``O`` and ``C`` are answered with one JSON line on the child's stdout ({"ok": true, ...} or
{"ok": false, "error": ...}). The child runs in its own session and ignores SIGINT/SIGTERM:
the node decides when a file ends. If the node dies (even ``kill -9``), the child reads EOF and
finishes the open file, so it is complete; if both die, the chunks already written are
readable (``read_log(path, recover=True)``). If the file cannot be written (a full disk), the
child leaves one line {"ok": false, "error": "<file>: <reason>"} on its stdout and exits 1,
with no traceback; the parent's next frame fails with that reason (`RecordingError`), and the
chunks already written stay readable.

Test hooks (environment): ``FLEXURE_SIM_RECORDER_WRITE_DELAY_S`` makes every write the child
makes to the file's descriptor first sleep that long (a slow or contended disk);
``FLEXURE_SIM_RECORDER_MAX_BACKLOG`` (bytes) replaces `MAX_BACKLOG` in the node's process.

Loss policy. The child never drops: when its writer falls behind it stops reading the pipe.
A `ProcessRecording` made ``lossless`` (fast and lockstep modes, which have no deadline) then
waits for the pipe: back-pressure slows the simulation, nothing is lost. One that is not
(real-time mode) must not stall the paced loop: frames go out through a non-blocking pipe
(1 MiB where the system allows it), what does not fit waits in a backlog of at most
`MAX_BACKLOG` bytes, and beyond that whole ticks are dropped. Every dropped message is counted
(`ProcessRecording.dropped_count`, which the node reports as ``recording_dropped``) and sent
to the child (``D``), which adds it to the file's dropped count (bag metadata
``custom_data['flexure_sim.dropped_messages']``, printed by ``flexure-sim info``).
"""
from __future__ import annotations

import errno
import fcntl
import json
import os
import select
import struct
import subprocess
import sys
import threading
import time
from collections import deque
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from flexure_sim.recording import RecordingError
from flexure_sim.recording.mcap_batch import FRAME_ITEM
from flexure_sim.recording.qos import as_qos_description

FRAME_HEADER = struct.Struct("<cI")
FRAME_STAMP = struct.Struct("<Q")
#: Bytes of frames kept in the parent when the pipe is full, before ticks are dropped (only
#: for recordings that are not lossless).
MAX_BACKLOG = 64 << 20
#: How long open/close wait for the child's answer.
ANSWER_TIMEOUT_S = 60.0
_F_SETPIPE_SZ = 1031
#: Environment variables of the test hooks: seconds every write of the file takes; backlog.
WRITE_DELAY_ENV = "FLEXURE_SIM_RECORDER_WRITE_DELAY_S"
MAX_BACKLOG_ENV = "FLEXURE_SIM_RECORDER_MAX_BACKLOG"
#: Ticks the child's writer thread may have queued: the pipe is the real buffer.
CHILD_QUEUE = 64
#: Niceness the recorder process adds to its own (lower priority than the node's).
RECORDER_NICE = 10


class RecorderProcess:
    """The child process; one at a time, files opened and closed by `ProcessRecording`."""

    def __init__(self) -> None:
        env = dict(os.environ)
        package_root = str(Path(__file__).resolve().parents[3])
        env["PYTHONPATH"] = os.pathsep.join(p for p in (package_root, env.get("PYTHONPATH")) if p)
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "flexure_sim.node.record.child"],
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, env=env, start_new_session=True,
            bufsize=0,
        )
        assert self.proc.stdin is not None and self.proc.stdout is not None
        self._fd = self.proc.stdin.fileno()
        try:
            fcntl.fcntl(self._fd, _F_SETPIPE_SZ, 1 << 20)
        except OSError:
            pass
        self._lock = threading.Lock()  # one writer at a time (stepping thread or control)
        self._backlog: deque[bytes] = deque()
        self._backlog_bytes = 0
        self._blocking = True
        self.max_backlog = int(os.environ.get(MAX_BACKLOG_ENV) or MAX_BACKLOG)

    # ------------------------------------------------------------------ pipe
    def send(self, opcode: bytes, body: bytes, *, droppable: bool = False,
             wait: bool = True) -> bool:
        """
        Queue one frame and write what the pipe takes.

        A ``droppable`` frame is refused (False) when the backlog is full. ``wait``: write the
        whole backlog, waiting for the pipe; otherwise never wait (what does not fit stays in the
        backlog).
        """
        frame = FRAME_HEADER.pack(opcode, len(body)) + body
        with self._lock:
            if droppable and self._backlog_bytes + len(frame) > self.max_backlog:
                return False
            self._backlog.append(frame)
            self._backlog_bytes += len(frame)
            self._flush(block=wait)
        return True

    def _flush(self, block: bool) -> None:
        if block != self._blocking:
            os.set_blocking(self._fd, block)
            self._blocking = block
        backlog = self._backlog
        while backlog:
            frame = backlog[0]
            try:
                n = os.write(self._fd, frame)
            except BlockingIOError:
                return
            except BrokenPipeError as exc:
                raise RecordingError(self.exit_reason()) from exc
            except OSError as exc:
                if exc.errno == errno.EAGAIN:
                    return
                raise RecordingError(f"cannot write to the recorder process: {exc}") from exc
            self._backlog_bytes -= n
            if n == len(frame):
                backlog.popleft()
            else:
                backlog[0] = frame[n:]

    def answer(self, timeout: float = ANSWER_TIMEOUT_S) -> dict[str, Any]:
        """Return the child's JSON answer to an open or close (one line on its stdout)."""
        assert self.proc.stdout is not None
        fd = self.proc.stdout.fileno()
        deadline = time.monotonic() + timeout
        line = b""
        while not line.endswith(b"\n"):
            remaining = deadline - time.monotonic()
            if remaining <= 0 or not select.select([fd], [], [], remaining)[0]:
                raise RecordingError(f"the recorder process did not answer within {timeout:g} s")
            chunk = os.read(fd, 65536)
            if not chunk:
                raise RecordingError(self.exit_reason(line))
            line += chunk
        return json.loads(line)

    def exit_reason(self, pending: bytes = b"") -> str:
        """Why the child stopped: the error it left on its stdout, else its exit code."""
        assert self.proc.stdout is not None
        fd = self.proc.stdout.fileno()
        text = pending
        try:
            while select.select([fd], [], [], 1.0)[0]:
                chunk = os.read(fd, 65536)
                if not chunk:
                    break
                text += chunk
        except OSError:
            pass
        for line in reversed(text.splitlines()):
            try:
                error = json.loads(line).get("error")
            except (ValueError, AttributeError):
                continue
            if error:
                return f"the recorder process stopped: {error}"
        try:
            code = self.proc.wait(5)
        except subprocess.TimeoutExpired:
            code = None
        return f"the recorder process exited (exit code {code})"

    def quit(self, timeout: float = 30.0) -> None:
        try:
            self.send(b"Q", b"")
            assert self.proc.stdin is not None
            self.proc.stdin.close()
        except (RecordingError, OSError):
            pass
        try:
            self.proc.wait(timeout)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait(5)

    def alive(self) -> bool:
        return self.proc.poll() is None


class ProcessRecording:
    """
    One MCAP file written by a `RecorderProcess`.

    ``topics``: (absolute name, ``pkg/msg/Type``, QoS) in channel order; `write_batch` takes
    the payloads of one tick as (channel index, bytes) pairs. ``lossless`` (default): wait for
    the recorder rather than drop (fast and lockstep modes); False: never wait, drop whole
    batches the pipe and backlog cannot take and count them (real-time mode). ``claimed``:
    ``path`` is an empty file (or, for a bag, an empty directory) the caller created to
    claim the name (`session.claim_recording_path`). ``bag``: None for one MCAP file at
    ``path``; else ``path`` is a rosbag2 bag directory (`recording.bag.BagRecorder`) split at
    ``bag["max_bytes"]`` bytes or ``bag["max_duration_ns"]`` (0: no limit).
    """

    def __init__(
        self,
        process: RecorderProcess,
        path: Path,
        topics: Sequence[tuple[str, str, Any]],
        metadata: Mapping[str, str],
        metadata_name: str,
        *,
        lossless: bool = True,
        claimed: bool = False,
        bag: Mapping[str, int] | None = None,
    ) -> None:
        self.process = process
        self.path = Path(path)
        self.lossless = lossless
        spec = {
            "path": str(self.path.resolve()),
            "topics": [[name, type_name, as_qos_description(qos).to_dict()]
                       for name, type_name, qos in topics],
            "metadata": {metadata_name: dict(metadata)},
            "claimed": claimed,
            "bag": dict(bag) if bag is not None else None,
        }
        process.send(b"O", json.dumps(spec).encode())
        reply = process.answer()
        if not reply.get("ok"):
            raise RecordingError(reply.get("error", "the recorder process refused the file"))
        self.sent = 0
        self.dropped = 0
        self._unreported: dict[int, int] = {}  # channel -> dropped, not yet sent to the child
        self._closed = False

    def write_batch(self, items: Sequence[tuple[int, bytes]], stamp: int) -> bool:
        """
        Send one tick's messages (channel index, CDR bytes), log time ``stamp`` (ns).

        False if the batch was dropped (only when not ``lossless``; counted).
        """
        parts = [FRAME_STAMP.pack(stamp)]
        for channel, data in items:
            parts.append(FRAME_ITEM.pack(channel, len(data)))
            parts.append(data)
        return self.write_frame(b"".join(parts), [channel for channel, _ in items])

    def write_frame(self, body: bytes, channels: Sequence[int]) -> bool:
        """
        Send one tick's batch frame body as it is, ``channels`` one per message.

        `write_batch` builds such a body; the stepping loop packs its tick straight into one
        (``publish.tick_frame``). False if the frame was dropped (only when not ``lossless``;
        counted).
        """
        lossless = self.lossless
        if self.process.send(b"B", body, droppable=not lossless, wait=lossless):
            self.sent += len(channels)
            if self._unreported:
                self._report_dropped(wait=lossless)
            return True
        self.dropped += len(channels)
        unreported = self._unreported
        for channel in channels:
            unreported[channel] = unreported.get(channel, 0) + 1
        return False

    def _report_dropped(self, wait: bool) -> None:
        """Tell the child how many messages per channel never reached it (for the file)."""
        body = json.dumps({str(c): n for c, n in self._unreported.items()}).encode()
        self.process.send(b"D", body, wait=wait)  # small, never dropped
        self._unreported = {}

    def add_metadata(self, name: str, data: Mapping[str, str]) -> None:
        """
        Send a Metadata record.

        It is never dropped, and in real time it never waits for the pipe.
        """
        self.process.send(b"M", json.dumps({"name": name, "data": dict(data)}).encode(),
                          wait=self.lossless)

    @property
    def accepted_count(self) -> int:
        return self.sent

    @property
    def dropped_count(self) -> int:
        return self.dropped

    def close(self) -> dict[str, Any]:
        """
        Finish the file.

        Returns the child's counts (``dropped``: every message dropped on the way, the parent's
        included). Raises RecordingError on failure.
        """
        if self._closed:
            return {}
        self._closed = True
        if self._unreported:
            self._report_dropped(wait=True)
        self.process.send(b"C", b"")
        reply = self.process.answer()
        if not reply.get("ok"):
            raise RecordingError(
                reply.get("error", "the recorder process could not finish the file"))
        return reply
