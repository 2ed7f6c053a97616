"""MCAP recording in a helper process, so writing the file costs the stepping loop no GIL time.

At 1 kHz the node records ~26 000 messages/s. `McapRecorder` already writes on a background
thread, but in the node's process that thread competes with the stepping loop for the GIL
(~8 us per message, ~200 us per 1 ms tick). So the node runs the recorder in a child process
(``python -m flexure_sim.node.record_process``, using the recording layer's public API) and
hands it each tick's payloads as one frame on a pipe: a few microseconds per tick.

Protocol on the child's stdin, frames of ``<opcode:1><length:u32 LE><body>``:

- ``O`` open: JSON {path, topics: [[name, type, qos], ...], metadata: {name: {k: v}}}
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

import contextlib
import errno
import fcntl
import io
import json
import os
import select
import signal
import struct
import subprocess
import sys
import threading
import time
from collections import deque
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, BinaryIO, Optional

from ..recording import McapRecorder, QosDescription, RecordingError
from ..recording.mcap_writer import describe
from ..recording.qos import as_qos_description

_HEADER = struct.Struct("<cI")
_STAMP = struct.Struct("<Q")
_ITEM = struct.Struct("<HI")
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
        package_root = str(Path(__file__).resolve().parents[2])
        env["PYTHONPATH"] = os.pathsep.join(p for p in (package_root, env.get("PYTHONPATH")) if p)
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "flexure_sim.node.record_process"],
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
        """Queue one frame and write what the pipe takes. A ``droppable`` frame is refused
        (False) when the backlog is full. ``wait``: write the whole backlog, waiting for the
        pipe; otherwise never wait (what does not fit stays in the backlog)."""
        frame = _HEADER.pack(opcode, len(body)) + body
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
        """The child's JSON answer to an open or close (one line on its stdout)."""
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
    """One MCAP file written by a `RecorderProcess`.

    ``topics``: (absolute name, ``pkg/msg/Type``, QoS) in channel order; `write_batch` takes
    the payloads of one tick as (channel index, bytes) pairs. ``lossless`` (default): wait for
    the recorder rather than drop (fast and lockstep modes); False: never wait, drop whole
    batches the pipe and backlog cannot take and count them (real-time mode).
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
    ) -> None:
        self.process = process
        self.path = Path(path)
        self.lossless = lossless
        spec = {
            "path": str(self.path.resolve()),
            "topics": [[name, type_name, as_qos_description(qos).to_dict()]
                       for name, type_name, qos in topics],
            "metadata": {metadata_name: dict(metadata)},
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
        """Send one tick's messages (channel index, CDR bytes), log time ``stamp`` (ns).

        False if the batch was dropped (only when not ``lossless``; counted)."""
        parts = [_STAMP.pack(stamp)]
        for channel, data in items:
            parts.append(_ITEM.pack(channel, len(data)))
            parts.append(data)
        lossless = self.lossless
        if self.process.send(b"B", b"".join(parts), droppable=not lossless, wait=lossless):
            self.sent += len(items)
            if self._unreported:
                self._report_dropped(wait=lossless)
            return True
        self.dropped += len(items)
        unreported = self._unreported
        for channel, _ in items:
            unreported[channel] = unreported.get(channel, 0) + 1
        return False

    def _report_dropped(self, wait: bool) -> None:
        """Tell the child how many messages per channel never reached it (for the file)."""
        body = json.dumps({str(c): n for c, n in self._unreported.items()}).encode()
        self.process.send(b"D", body, wait=wait)  # small, never dropped
        self._unreported = {}

    def add_metadata(self, name: str, data: Mapping[str, str]) -> None:
        """A Metadata record; never dropped, and in real time it never waits for the pipe."""
        self.process.send(b"M", json.dumps({"name": name, "data": dict(data)}).encode(),
                          wait=self.lossless)

    @property
    def accepted_count(self) -> int:
        return self.sent

    @property
    def dropped_count(self) -> int:
        return self.dropped

    def close(self) -> dict[str, Any]:
        """Finish the file; returns the child's counts (``dropped``: every message dropped on
        the way, the parent's included). Raises RecordingError on failure."""
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


# ============================================================================ child
def _lower_priority() -> None:
    """Let the node's paced thread take a shared core from the recorder as soon as it wakes.
    The recorder works in bursts (a compressed chunk every few hundred ms) that, at equal
    priority, the scheduler may let finish first: a late tick. The pipe and the backlog
    absorb the recorder's delay instead."""
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


def _output(path: Path) -> Path | BinaryIO:
    """What the recorder writes to: the path, or a slowed file when the test hook asks."""
    delay = float(os.environ.get(WRITE_DELAY_ENV) or 0.0)
    if delay <= 0.0:
        return path
    raw = _SlowFile(path, "xb")
    raw.delay = delay
    return io.BufferedWriter(raw)


def _open(spec: dict[str, Any]) -> McapRecorder:
    """A recorder for an ``O`` frame; the child never drops (it waits for its writer)."""
    path = Path(spec["path"])
    if path.exists():
        raise RecordingError(f"{path}: exists; recordings are never overwritten")
    path.parent.mkdir(parents=True, exist_ok=True)
    try:
        new = McapRecorder(_output(path), queue_size=CHILD_QUEUE, max_block_s=None)
    except BaseException:
        with contextlib.suppress(OSError):  # not even the header fits: leave no empty file
            if path.stat().st_size == 0:
                path.unlink()
        raise
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


def _child(stdin: BinaryIO, stdout: BinaryIO) -> int:
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, signal.SIG_IGN)
    _lower_priority()
    recorder: Optional[McapRecorder] = None
    path = ""
    names: list[str] = []

    def reply(obj: dict[str, Any]) -> None:
        stdout.write(json.dumps(obj).encode() + b"\n")
        stdout.flush()

    def read_exact(n: int) -> Optional[bytes]:
        chunks, got = [], 0
        while got < n:
            chunk = stdin.read(n - got)
            if not chunk:
                return None
            chunks.append(chunk)
            got += len(chunk)
        return b"".join(chunks)

    try:
        while True:
            header = read_exact(_HEADER.size)
            if header is None:
                break  # the node is gone: finish the file below
            opcode, length = _HEADER.unpack(header)
            body = read_exact(length) if length else b""
            if body is None:
                break
            if opcode == b"B":
                if recorder is None:
                    continue
                (stamp,) = _STAMP.unpack_from(body, 0)
                offset = _STAMP.size
                messages = []
                while offset < len(body):
                    channel, size = _ITEM.unpack_from(body, offset)
                    offset += _ITEM.size
                    messages.append((names[channel], body[offset:offset + size]))
                    offset += size
                recorder.write_batch(messages, stamp)
            elif opcode == b"O":
                spec = json.loads(body)
                try:
                    new = _open(spec)
                except (RecordingError, OSError, ValueError) as exc:
                    reply({"ok": False, "error": describe(exc)})
                    continue
                recorder, names, path = new, [t[0] for t in spec["topics"]], spec["path"]
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
