"""
The recorder's MCAP writer (`recording.mcap_batch.BatchWriter`) and its frame path.

The independent reference is the `mcap` library's own ``Writer``: for the same calls (schemas,
channels, messages in batches, metadata, flushes, chunk sizes down to one message a chunk,
log times that go back) both must write the same bytes. The frame path
(`McapRecorder.write_frame`, what the recorder process calls) must record what `write_batch`
records for the same messages, count them, drop and count whole frames when the queue is
full, and name a frame that is cut short.
"""
from __future__ import annotations

import io
import random
import threading
from pathlib import Path

import pytest
from mcap.reader import make_reader
from mcap.writer import CompressionType, Writer

from flexure_sim.recording import RecordingError
from flexure_sim.recording.bag import BagRecorder, bag_files
from flexure_sim.recording.mcap_batch import FRAME_ITEM, BatchWriter
from flexure_sim.recording.mcap_writer import PositionStream
from flexure_sim.recording.writer import McapRecorder

MS = 1_000_000


def _calls(rng: random.Random) -> list[tuple]:
    """Return a random sequence of writer calls; batches of 0-30 messages of 0-60 bytes."""
    calls: list[tuple] = [("schema", "pkg/msg/A", "ros2msg", b"float64 x"),
                          ("channel", "/a", "cdr", 1, {"k": "v"})]
    channels, t = 1, 0
    for i in range(rng.randint(0, 300)):
        r = rng.random()
        if r < 0.02:
            calls.append(("schema", f"pkg/msg/S{i}", "ros2msg", b"int32 y" * rng.randint(0, 9)))
        if r < 0.05:
            calls.append(("channel", f"/c{i}", "cdr", 1, {}))
            channels += 1
        elif r < 0.07:
            calls.append(("metadata", f"m{i}", {"i": str(i)}))
        elif r < 0.09:
            calls.append(("flush",))
        else:
            t = max(0, t + (rng.choice([0, MS, 5 * MS]) if rng.random() < 0.9 else -3 * MS))
            messages = [(rng.randint(1, channels), rng.randbytes(rng.randint(0, 60)))
                        for _ in range(rng.randint(0, 30))]
            calls.append(("batch", t, messages))
    return calls


def _write(calls: list[tuple], chunk_size: int, library: bool) -> bytes:
    """Return the file of ``calls``: the library's Writer (add_message each) or BatchWriter."""
    buffer = io.BytesIO()
    out = PositionStream(buffer)
    if library:
        writer = Writer(out, chunk_size=chunk_size, compression=CompressionType.NONE,
                        enable_crcs=True, enable_data_crcs=True)
    else:
        writer = BatchWriter(out, chunk_size)
    writer.start(profile="ros2", library="flexure_sim test")
    numbers: dict[int, int] = {}
    for kind, *args in calls:
        if kind == "schema":
            writer.register_schema(*args)
        elif kind == "channel":
            writer.register_channel(*args)
        elif kind == "metadata":
            writer.add_metadata(*args)
        elif kind == "flush":
            writer.flush()
        elif library:
            stamp, messages = args
            for channel, data in messages:
                numbers[channel] = numbers.get(channel, 0) + 1
                writer.add_message(channel, stamp, data, stamp, numbers[channel])
        elif len(args[1]) % 2:   # half of the batches as frames, half as lists
            stamp, messages = args
            frame = b"".join(FRAME_ITEM.pack(channel, len(data)) + data
                             for channel, data in messages)
            writer.add_frame(stamp, b"head" + frame, 4, list(range(channels_max(calls) + 1)))
        else:
            writer.add_batch(*args)
    writer.finish()
    return buffer.getvalue()


def channels_max(calls: list[tuple]) -> int:
    return sum(1 for c in calls if c[0] == "channel")


@pytest.mark.parametrize("seed", range(12))
def test_the_file_is_the_mcap_librarys_byte_for_byte(seed):
    rng = random.Random(seed)
    calls = _calls(rng)
    chunk_size = [1, 300, 4000, 1 << 20][seed % 4]
    ours = _write(calls, chunk_size, library=False)
    assert ours == _write(calls, chunk_size, library=True)
    # ... and a file the library's reader takes whole, CRCs checked.
    with io.BytesIO(ours) as f:
        reader = make_reader(f, validate_crcs=True)
        sent = sum(len(c[2]) for c in calls if c[0] == "batch")
        assert sum(1 for _ in reader.iter_messages()) == sent
        assert reader.get_summary().statistics.message_count == sent


def _frame(messages: list[tuple[int, bytes]], stamp: int = 0) -> bytes:
    return stamp.to_bytes(8, "little") + b"".join(FRAME_ITEM.pack(i, len(d)) + d
                                                  for i, d in messages)


def _messages(path: Path) -> list[tuple[str, int, int, bytes]]:
    with open(path, "rb") as f:
        return [(ch.topic, m.sequence, m.log_time, m.data)
                for _, ch, m in make_reader(f, validate_crcs=True).iter_messages(
                    log_time_order=False)]


def test_a_frame_records_what_the_same_batch_records(tmp_path):
    topics = ("/a", "/b", "/c")
    rng = random.Random(7)
    ticks = [[(rng.randrange(3), rng.randbytes(rng.randint(0, 40))) for _ in range(5)]
             for _ in range(200)]
    stats = {}
    for kind in ("batch", "frame"):
        with McapRecorder(tmp_path / f"{kind}.mcap", chunk_size=512) as rec:
            for topic in topics:
                rec.add_topic(topic, "std_msgs/msg/Float64")
            for k, messages in enumerate(ticks):
                if kind == "frame":
                    assert rec.write_frame(_frame(messages, k), 8, topics, k * MS)
                else:
                    assert rec.write_batch([(topics[i], d) for i, d in messages], k * MS)
            stats[kind] = rec.close()
    assert _messages(tmp_path / "frame.mcap") == _messages(tmp_path / "batch.mcap")
    assert stats["frame"].accepted == stats["batch"].accepted
    assert sum(stats["frame"].accepted.values()) == 5 * len(ticks)


def test_a_bag_of_frames_splits_where_a_bag_of_batches_does(tmp_path):
    topics = ("/a", "/b")
    for kind in ("batch", "frame"):
        bag = BagRecorder(tmp_path / kind, chunk_size=4096, max_bytes=48)
        for topic in topics:
            bag.add_topic(topic, "std_msgs/msg/Float64")
        for k in range(10):
            data = bytes(12)
            if kind == "frame":
                assert bag.write_frame(_frame([(0, data), (1, data)]), 8, topics, k * MS)
            else:
                assert bag.write_batch([("/a", data), ("/b", data)], k * MS)
        assert sum(bag.close().accepted.values()) == 20
    assert len(bag_files(tmp_path / "frame")) == len(bag_files(tmp_path / "batch")) == 5


class _StalledStream(io.RawIOBase):
    """A stream whose writes wait until ``go`` is set once ``stall`` is (a stalled disk)."""

    def __init__(self) -> None:
        self.go = threading.Event()
        self.stall = False

    def writable(self) -> bool:
        return True

    def write(self, data) -> int:
        if self.stall:
            self.go.wait()
        return len(data)


def test_frames_the_queue_cannot_take_are_dropped_whole_and_counted_per_topic():
    stream = _StalledStream()
    rec = McapRecorder(io.BufferedWriter(stream, 1), queue_size=1, max_block_s=0.0,
                       chunk_interval_s=1e-3)
    topics = ("/a", "/b")
    for topic in topics:
        rec.add_topic(topic, "std_msgs/msg/Float64")
    stream.stall = True
    frame = _frame([(0, bytes(8)), (1, bytes(8)), (1, bytes(8))])
    kept = [rec.write_frame(frame, 8, topics, k * MS) for k in range(50)]
    assert not all(kept)
    lost = kept.count(False)
    assert rec.stats.dropped == {"/a": lost, "/b": 2 * lost}
    stream.go.set()
    stats = rec.close()
    assert stats.accepted == {"/a": 50 - lost, "/b": 2 * (50 - lost)}
    assert stats.dropped == {"/a": lost, "/b": 2 * lost}


def test_a_frame_cut_short_fails_the_recording_with_its_reason(tmp_path):
    rec = McapRecorder(tmp_path / "cut.mcap")
    rec.add_topic("/a", "std_msgs/msg/Float64")
    frame = _frame([(0, bytes(8))])
    rec.write_frame(frame[:-3], 8, ("/a",), 0)
    with pytest.raises(RecordingError, match="last message ends 3 bytes after the frame"):
        rec.close()
