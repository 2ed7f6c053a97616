"""
Bag directories (issue 14, item 5) written by `BagRecorder`.

metadata.yaml field by field against rosbag2 Jazzy's schema, splitting by size and by duration into
complete MCAP files, and the directory read back as one run by rosbags (`rosbags.rosbag2.Reader`),
mcap and flexure_sim's own readers and tools.

rosbag2's schema, from ros2/rosbag2 (jazzy) rosbag2_storage/include/rosbag2_storage/yaml.hpp
(``convert<BagMetadata>::encode`` and the converters it calls) and metadata_io.cpp (file
``metadata.yaml``, top-level key ``rosbag2_bagfile_information``): the keys below, in this
order, with these types.
"""
from __future__ import annotations

import re
from pathlib import Path

import pytest
import yaml
from mcap.reader import make_reader
from rclpy.serialization import serialize_message
from rosbags.rosbag2 import Reader
from std_msgs.msg import Float64

from flexure_sim.cli import main
from flexure_sim.recording import CorruptLogError, log_info, read_log
from flexure_sim.recording.bag import METADATA_FILE, BagRecorder, bag_files

BAG_KEYS = ["version", "storage_identifier", "duration", "starting_time", "message_count",
            "topics_with_message_count", "compression_format", "compression_mode",
            "relative_file_paths", "files", "custom_data", "ros_distro"]
TOPIC_KEYS = ["name", "type", "serialization_format", "offered_qos_profiles",
              "type_description_hash"]
FILE_KEYS = ["path", "starting_time", "duration", "message_count"]
MS = 1_000_000


def record(directory: Path, ticks: int, **limits) -> BagRecorder:
    """Return a bag of ``ticks`` batches 1 ms apart, a Float64 on /a and /b (8 + 4 bytes)."""
    bag = BagRecorder(directory, chunk_size=4096, **limits)
    bag.add_topic("/a", "std_msgs/msg/Float64")
    bag.add_topic("/b", "std_msgs/msg/Float64")
    bag.add_metadata("flexure_sim", {"mechanism_name": "test"})
    for k in range(ticks):
        data = serialize_message(Float64(data=float(k)))
        assert bag.write_batch([("/a", data), ("/b", data)], (k + 1) * MS)
    bag.close()
    return bag


def load_metadata(directory: Path) -> dict:
    doc = yaml.safe_load((directory / METADATA_FILE).read_text())
    assert list(doc) == ["rosbag2_bagfile_information"]
    return doc["rosbag2_bagfile_information"]


def file_messages(path: Path) -> list[tuple[str, int]]:
    with open(path, "rb") as f:
        return [(ch.topic, m.log_time) for _, ch, m in make_reader(f).iter_messages()]


def test_metadata_yaml_matches_rosbag2_jazzy_field_by_field(tmp_path):
    bag = tmp_path / "run"
    record(bag, 10)
    meta = load_metadata(bag)
    assert list(meta) == BAG_KEYS
    assert meta["version"] == 9 and meta["storage_identifier"] == "mcap"
    assert meta["ros_distro"] == "jazzy"
    assert meta["compression_format"] == "" and meta["compression_mode"] == ""
    assert meta["duration"] == {"nanoseconds": 9 * MS}  # first to last message
    assert meta["starting_time"] == {"nanoseconds_since_epoch": 1 * MS}
    assert meta["message_count"] == 20
    assert meta["relative_file_paths"] == ["run_0.mcap"]
    for entry in meta["topics_with_message_count"]:
        assert list(entry) == ["topic_metadata", "message_count"]
        assert list(entry["topic_metadata"]) == TOPIC_KEYS
        t = entry["topic_metadata"]
        assert t["type"] == "std_msgs/msg/Float64" and t["serialization_format"] == "cdr"
        assert isinstance(t["offered_qos_profiles"], str)
        assert t["type_description_hash"].startswith("RIHS01_")
        assert entry["message_count"] == 10
    assert [e["topic_metadata"]["name"] for e in meta["topics_with_message_count"]] == ["/a", "/b"]
    (entry,) = meta["files"]
    assert list(entry) == FILE_KEYS
    assert entry == {"path": "run_0.mcap", "starting_time": {"nanoseconds_since_epoch": MS},
                     "duration": {"nanoseconds": 9 * MS}, "message_count": 20}
    assert isinstance(meta["custom_data"], dict)
    assert meta["custom_data"]["flexure_sim.dropped_messages"] == "0"
    # The file's own rosbag2 record says the same of its one file (one definition).
    assert read_log(bag / "run_0.mcap").bag_metadata["files"] == meta["files"]


def test_split_by_duration_gives_complete_files_and_metadata_that_counts_them(tmp_path):
    bag = tmp_path / "dur"
    record(bag, 25, max_duration_ns=10 * MS)  # a new file once one spans 10 ms
    meta = load_metadata(bag)
    names = [f"dur_{i}.mcap" for i in range(3)]
    assert meta["relative_file_paths"] == names == [e["path"] for e in meta["files"]]
    assert bag_files(bag) == [bag / n for n in names]
    held = [file_messages(bag / n) for n in names]  # each a complete, indexed MCAP
    assert [len(h) for h in held] == [e["message_count"] for e in meta["files"]] == [20, 20, 10]
    for h, e in zip(held, meta["files"]):
        times = [t for _, t in h]
        assert e["starting_time"]["nanoseconds_since_epoch"] == min(times)
        assert e["duration"]["nanoseconds"] == max(times) - min(times)
    assert meta["message_count"] == 50
    assert meta["duration"]["nanoseconds"] == 24 * MS
    # Every file describes its run on its own.
    assert all(read_log(bag / n).metadata["flexure_sim"] == {"mechanism_name": "test"}
               for n in names)


def test_split_by_size_counts_message_bytes(tmp_path):
    bag = tmp_path / "size"
    record(bag, 10, max_bytes=48)  # 24 bytes of payload per tick: two ticks per file
    meta = load_metadata(bag)
    assert [e["message_count"] for e in meta["files"]] == [4] * 5


def test_rosbags_and_flexure_sim_read_the_directory_as_one_run(tmp_path, capsys):
    bag = tmp_path / "one"
    record(bag, 25, max_duration_ns=10 * MS)
    with Reader(bag) as reader:  # rosbags' rosbag2 reader: the bag directory
        assert reader.message_count == 50
        assert [(c.topic, c.msgcount) for c in reader.connections] == [("/a", 25), ("/b", 25)]
        stamps = [t for _, t, _ in reader.messages()]
    assert sorted(stamps) == sorted(t for n in bag_files(bag) for _, t in file_messages(n))
    log = read_log(bag)
    assert [m.message.data for m in log.messages_on("/a")] == [float(k) for k in range(25)]
    assert log.counts == {"/a": 25, "/b": 25} and log.complete
    info = log_info(bag)
    assert (info.message_count, info.start_ns, info.end_ns) == (50, MS, 25 * MS)
    assert main(["info", str(bag)]) == 0
    out = capsys.readouterr().out
    assert re.search(r"/a\s+std_msgs/msg/Float64\s+25\b", out), out
    assert "3 file(s): one_0.mcap, one_1.mcap, one_2.mcap" in out


def test_a_metadata_yaml_that_disagrees_with_the_files_is_named(tmp_path):
    bag = tmp_path / "bad"
    record(bag, 5)
    path = bag / METADATA_FILE
    path.write_text(path.read_text().replace("message_count: 10", "message_count: 11", 1))
    with pytest.raises(CorruptLogError, match="metadata.yaml counts"):
        read_log(bag)
    empty = tmp_path / "empty"
    empty.mkdir()
    assert main(["info", str(empty)]) == 2


def test_a_topic_is_selected_once_for_the_whole_bag(tmp_path):
    """
    Readers keep per-topic state from the select call (tools build one series per topic).

    A bag of three files must ask once per topic, as one file does.
    """
    from flexure_sim.recording.reader import open_reader

    bag = tmp_path / "sel"
    record(bag, 25, max_duration_ns=10 * MS)
    asked = []
    reader = open_reader(bag)
    got = [m.topic for m in reader.messages(lambda t: asked.append(t.name) or t.name == "/a")]
    assert sorted(asked) == ["/a", "/b"]
    assert got == ["/a"] * 25
