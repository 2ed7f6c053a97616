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
- ``C`` close the file; ``Q`` quit.

``O`` and ``C`` are answered with one JSON line on the child's stdout ({"ok": true, ...} or
{"ok": false, "error": ...}). The child runs in its own session and ignores SIGINT/SIGTERM:
the node decides when a file ends. If the node dies (even ``kill -9``), the child reads EOF and
finishes the open file, so it is complete; if both die, the chunks already written are
readable (``read_log(path, recover=True)``).

The parent never blocks on the pipe while recording: frames go out through a non-blocking
pipe (1 MiB where the system allows it); what does not fit waits in a bounded backlog, and
beyond that ticks are dropped and counted.
"""
from __future__ import annotations

import errno
import fcntl
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
from ..recording.qos import as_qos_description

_HEADER = struct.Struct("<cI")
_STAMP = struct.Struct("<Q")
_ITEM = struct.Struct("<HI")
#: Bytes of frames kept in the parent when the pipe is full, before ticks are dropped.
MAX_BACKLOG = 64 << 20
#: How long open/close wait for the child's answer.
ANSWER_TIMEOUT_S = 60.0
_F_SETPIPE_SZ = 1031
#: Niceness the recorder process adds to its own (lower priority than the node's).
RECORDER_NICE = 10


class RecorderProcess:
    """The child process; one at a time, files opened and closed by `ProcessRecording`."""

    def __init__(self) -> None:
        env = dict(os.environ)
        package_root = str(Path(__file__).resolve().parents[2])
        env["PYTHONPATH"] = package_root + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
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
        self.dropped_ticks = 0

    # ------------------------------------------------------------------ pipe
    def send(self, opcode: bytes, body: bytes, *, droppable: bool = False) -> bool:
        """Queue one frame. Droppable frames (message batches) are refused when the backlog is
        full; others always go (blocking if need be)."""
        frame = _HEADER.pack(opcode, len(body)) + body
        with self._lock:
            if droppable and self._backlog_bytes + len(frame) > MAX_BACKLOG:
                self.dropped_ticks += 1
                return False
            self._backlog.append(frame)
            self._backlog_bytes += len(frame)
            self._flush(block=not droppable)
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
                raise RecordingError(f"the recorder process exited ({self.proc.poll()})") from exc
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
                raise RecordingError(f"the recorder process exited (exit code {self.proc.poll()})")
            line += chunk
        return json.loads(line)

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
    the payloads of one tick as (channel index, bytes) pairs. ``claimed``: ``path`` is an
    empty file the caller created to claim the name (`session.claim_recording_path`).
    """

    def __init__(
        self,
        process: RecorderProcess,
        path: Path,
        topics: Sequence[tuple[str, str, Any]],
        metadata: Mapping[str, str],
        metadata_name: str,
        *,
        claimed: bool = False,
    ) -> None:
        self.process = process
        self.path = Path(path)
        self.index = {name: i for i, (name, _, _) in enumerate(topics)}
        spec = {
            "path": str(self.path.resolve()),
            "topics": [[name, type_name, as_qos_description(qos).to_dict()] for name, type_name, qos in topics],
            "metadata": {metadata_name: dict(metadata)},
            "claimed": claimed,
        }
        process.send(b"O", json.dumps(spec).encode())
        reply = process.answer()
        if not reply.get("ok"):
            raise RecordingError(reply.get("error", "the recorder process refused the file"))
        self.sent = 0
        self.dropped = 0
        self._closed = False

    def write_batch(self, items: Sequence[tuple[int, bytes]], stamp: int) -> bool:
        """Send one tick's messages (channel index, CDR bytes), log time ``stamp`` (ns)."""
        parts = [_STAMP.pack(stamp)]
        for channel, data in items:
            parts.append(_ITEM.pack(channel, len(data)))
            parts.append(data)
        if self.process.send(b"B", b"".join(parts), droppable=True):
            self.sent += len(items)
            return True
        self.dropped += len(items)
        return False

    def write(self, topic: str, payload: bytes, stamp: int) -> bool:
        return self.write_batch(((self.index[topic], payload),), stamp)

    def add_metadata(self, name: str, data: Mapping[str, str]) -> None:
        self.process.send(b"M", json.dumps({"name": name, "data": dict(data)}).encode())

    @property
    def accepted_count(self) -> int:
        return self.sent

    @property
    def dropped_count(self) -> int:
        return self.dropped

    def close(self) -> dict[str, Any]:
        """Finish the file; returns the child's counts. Raises RecordingError on failure."""
        if self._closed:
            return {}
        self._closed = True
        self.process.send(b"C", b"")
        reply = self.process.answer()
        if not reply.get("ok"):
            raise RecordingError(reply.get("error", "the recorder process could not finish the file"))
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


def _child(stdin: BinaryIO, stdout: BinaryIO) -> int:
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, signal.SIG_IGN)
    _lower_priority()
    recorder: Optional[McapRecorder] = None
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
                write = recorder.write
                while offset < len(body):
                    channel, size = _ITEM.unpack_from(body, offset)
                    offset += _ITEM.size
                    write(names[channel], body[offset:offset + size], stamp)
                    offset += size
            elif opcode == b"O":
                spec = json.loads(body)
                try:
                    path = Path(spec["path"])
                    # claimed: the node created the empty file with O_EXCL (session), it is ours.
                    claimed = bool(spec.get("claimed")) and path.is_file() \
                        and path.stat().st_size == 0
                    if path.exists() and not claimed:
                        raise RecordingError(f"{path}: exists; recordings are never overwritten")
                    path.parent.mkdir(parents=True, exist_ok=True)
                    new = McapRecorder(path, overwrite=claimed)
                    try:
                        for name, type_name, qos in spec["topics"]:
                            new.add_topic(name, type_name, QosDescription.from_dict(qos))
                        for name, data in spec["metadata"].items():
                            new.add_metadata(name, data)
                    except BaseException:
                        new.close()
                        raise
                except (RecordingError, OSError, ValueError) as exc:
                    reply({"ok": False, "error": str(exc)})
                    continue
                recorder, names = new, [t[0] for t in spec["topics"]]
                reply({"ok": True})
            elif opcode == b"M":
                if recorder is not None:
                    item = json.loads(body)
                    recorder.add_metadata(item["name"], item["data"])
            elif opcode == b"C":
                if recorder is None:
                    reply({"ok": True, "accepted": 0, "dropped": 0})
                    continue
                current, recorder = recorder, None
                try:
                    stats = current.close()
                except RecordingError as exc:
                    reply({"ok": False, "error": str(exc)})
                    continue
                reply({"ok": True, "accepted": stats.accepted_count, "dropped": stats.dropped_count})
            elif opcode == b"Q":
                break
    finally:
        if recorder is not None:
            recorder.close()
    return 0


if __name__ == "__main__":
    sys.exit(_child(sys.stdin.buffer, sys.stdout.buffer))
