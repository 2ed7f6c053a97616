"""
The recorder's cost a message (``flexure-sim bench``, ``recorder``), with no ROS.

A tick of 26 messages of 12-404 bytes (sizes like the stage node's tick), written `TICKS`
times into an in-memory MCAP file with 1 MiB chunks, by the `mcap` library's
``Writer.add_message`` one message at a time and by `mcap_batch.BatchWriter.add_frame` one
frame at a time (what the recorder process does); CPU time of the better of `REPEATS` runs,
in a process of its own that loads only the recording layer, as the recorder process does
(``python -m flexure_sim.tools.bench.recorder_bench`` prints the JSON): in the bench's own
process, where the engine, SciPy and ROS are loaded, each collection of Python's cyclic
garbage collector walks far more objects.
"""
from __future__ import annotations

import io
import json
import subprocess
import sys
import time

from flexure_sim.recording.mcap_batch import FRAME_ITEM, BatchWriter
from flexure_sim.recording.mcap_writer import PositionStream

#: Payload sizes of one tick (bytes): Float64s, poses, wrenches, the tick's larger messages.
SIZES = [12] * 6 + [96] * 10 + [108] * 8 + [404] * 2
TICKS = 5000
REPEATS = 3


def _run(batched: bool) -> float:
    from mcap.writer import CompressionType, Writer

    out = PositionStream(io.BytesIO())
    if batched:
        writer = BatchWriter(out, 1 << 20)
    else:
        writer = Writer(out, chunk_size=1 << 20, compression=CompressionType.NONE,
                        enable_crcs=True, enable_data_crcs=True)
    writer.start(profile="ros2", library="bench")
    ids = [writer.register_channel(f"/t{i}", "cdr", 0, {}) for i in range(len(SIZES))]
    payloads = [bytes(size) for size in SIZES]
    frame = b"".join(FRAME_ITEM.pack(i, len(p)) + p for i, p in enumerate(payloads))
    start = time.process_time()
    if batched:
        for k in range(TICKS):
            writer.add_frame(k * 1000, frame, 0, ids)
    else:
        for k in range(TICKS):
            for channel_id, payload in zip(ids, payloads):
                writer.add_message(channel_id, k * 1000, payload, k * 1000, k + 1)
    writer.finish()
    return time.process_time() - start


def bench_recorder() -> dict:
    """`measure` in a process of its own (module docstring)."""
    out = subprocess.run([sys.executable, "-m", __name__], check=True, capture_output=True,
                         text=True).stdout
    return json.loads(out)


def measure() -> dict:
    """CPU µs a message and a tick of both writers, and their ratio."""
    library = min(_run(False) for _ in range(REPEATS))
    batched = min(_run(True) for _ in range(REPEATS))
    messages = TICKS * len(SIZES)
    return {"messages_per_tick": len(SIZES), "ticks": TICKS,
            "library_us_per_message": library / messages * 1e6,
            "batch_us_per_message": batched / messages * 1e6,
            "library_us_per_tick": library / TICKS * 1e6,
            "batch_us_per_tick": batched / TICKS * 1e6,
            "speedup": library / batched}


def print_recorder(r: dict) -> None:
    print(f"\nrecorder, a tick of {r['messages_per_tick']} messages written {r['ticks']} times "
          f"(CPU): mcap Writer.add_message {r['library_us_per_message']:.2f} us a message "
          f"({r['library_us_per_tick']:.0f} us a tick); BatchWriter.add_frame "
          f"{r['batch_us_per_message']:.2f} us ({r['batch_us_per_tick']:.0f} us a tick), "
          f"{r['speedup']:.1f}x")


if __name__ == "__main__":
    print(json.dumps(measure()))
