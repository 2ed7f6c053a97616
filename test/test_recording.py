"""
Tests of flexure_sim.recording with real rclpy messages and independent MCAP readers.

Files written by `McapRecorder` are read back with mcap + mcap-ros2-support, with rosbags
(bare .mcap and a rosbag2 bag directory) and with rclpy's own deserializer.
"""
from __future__ import annotations

import io
import json
import os
import select
import shutil
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
import yaml
from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import Pose, PoseArray, WrenchStamped
from mcap.reader import make_reader
from mcap.records import Chunk, Message
from mcap.stream_reader import StreamReader, breakup_chunk
from mcap.writer import CompressionType, Writer
from mcap_ros2.decoder import DecoderFactory
from rclpy.duration import Duration
from rclpy.qos import (
    DurabilityPolicy,
    HistoryPolicy,
    LivelinessPolicy,
    QoSProfile,
    ReliabilityPolicy,
    qos_profile_sensor_data,
)
from rclpy.serialization import deserialize_message, serialize_message
from rosbags.highlevel import AnyReader
from rosbags.rosbag2.metadata import parse_qos
from rosbags.typesys import Stores, get_typestore
from rosgraph_msgs.msg import Clock
from std_msgs.msg import Float64, String

from flexure_sim.recording import (
    CorruptLogError,
    McapRecorder,
    QosDescription,
    RecorderClosedError,
    RecorderFailedError,
    RecordingError,
    SchemaNotFoundError,
    ament_prefixes,
    load_schema,
    log_info,
    metadata_yaml,
    parse_qos_profiles_yaml,
    qos_profiles_yaml,
    read_log,
)
from flexure_sim.recording.scan import scan_file
from flexure_sim.recording.schema import SEPARATOR

REPO = Path(__file__).resolve().parents[1]
T0_NS = 5_000_000_000  # first sim-time stamp
DT_NS = 1_000_000  # 1 kHz
STEPS = 400
HINGES = ("hinge_a", "hinge_b")

TOPICS = {
    "/stage/hinge_a/wrench": "geometry_msgs/msg/WrenchStamped",
    "/stage/hinge_b/wrench": "geometry_msgs/msg/WrenchStamped",
    "/stage/body_poses": "geometry_msgs/msg/PoseArray",
    "/stage/output_displacement": "std_msgs/msg/Float64",
    "/diagnostics": "diagnostic_msgs/msg/DiagnosticArray",
    "/clock": "rosgraph_msgs/msg/Clock",
}
MECHANISM_RECORD = {"mechanism": "micropositioning_stage", "t_char": "0.001", "gain": "27.8"}


def share_dir(package: str) -> Path:
    for prefix in ament_prefixes():
        candidate = prefix / "share" / package
        if (candidate / "package.xml").is_file() or (candidate / "msg").is_dir():
            return candidate
    raise AssertionError(f"{package} is not installed under any ament prefix")


def stamp(ns: int) -> Time:
    sec, nanosec = divmod(ns, 1_000_000_000)
    return Time(sec=sec, nanosec=nanosec)


def make_messages(step: int) -> list[tuple[str, object]]:
    """Return the messages one simulation step publishes (diagnostics every 50 steps)."""
    t_ns = T0_NS + step * DT_NS
    out: list[tuple[str, object]] = []
    for k, hinge in enumerate(HINGES):
        wrench = WrenchStamped()
        wrench.header.stamp = stamp(t_ns)
        wrench.header.frame_id = hinge
        wrench.wrench.force.x = 1.5 * step + k
        wrench.wrench.force.y = -0.125 * step
        wrench.wrench.torque.z = 2.5e-3 * step * (k + 1)
        out.append((f"/stage/{hinge}/wrench", wrench))
    poses = PoseArray()
    poses.header.stamp = stamp(t_ns)
    poses.header.frame_id = "stage"
    for j in range(3):
        pose = Pose()
        pose.position.x = 1e-6 * step * (j + 1)
        pose.position.y = -2e-7 * step
        pose.orientation.z = 1e-4 * step
        pose.orientation.w = 1.0
        poses.poses.append(pose)
    out.append(("/stage/body_poses", poses))
    out.append(("/stage/output_displacement", Float64(data=27.8 * 1.35e-6 * step / STEPS)))
    if step % 50 == 0:
        status = DiagnosticStatus(
            level=DiagnosticStatus.OK,
            name="flexure_sim: stage",
            message=f"step {step}",
            hardware_id="sim",
            values=[KeyValue(key="step", value=str(step)), KeyValue(key="rtf", value="1.0")],
        )
        diag = DiagnosticArray()
        diag.header.stamp = stamp(t_ns)
        diag.status = [status]
        out.append(("/diagnostics", diag))
    out.append(("/clock", Clock(clock=stamp(t_ns))))
    return out


def expected_messages() -> list[tuple[str, int, object]]:
    return [
        (topic, T0_NS + step * DT_NS, msg)
        for step in range(STEPS)
        for topic, msg in make_messages(step)
    ]


def record_standard_log(path: Path, **options: object) -> list[tuple[str, int, object]]:
    expected = expected_messages()
    with McapRecorder(path, **options) as recorder:
        for name, type_name in TOPICS.items():
            qos = qos_profile_sensor_data if "wrench" in name else QoSProfile(depth=10)
            recorder.add_topic(name, type_name, qos)
        recorder.add_metadata("flexure_sim", MECHANISM_RECORD)
        for topic, t_ns, msg in expected:
            assert recorder.write(topic, serialize_message(msg), t_ns)
            if t_ns == T0_NS + 200 * DT_NS and topic == "/clock":
                recorder.add_metadata("flexure_sim.parameters", {"drive_gain": "2.0"})
    assert recorder.stats.dropped_count == 0
    return expected


@pytest.fixture(scope="module")
def standard_log(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, list]:
    path = tmp_path_factory.mktemp("log") / "stage.mcap"
    expected = record_standard_log(path, chunk_size=16 * 1024)
    return path, expected


@pytest.fixture(scope="module")
def mcap_contents(standard_log: tuple[Path, list]) -> dict:
    """Everything the mcap library reads from the standard log."""
    path, _ = standard_log
    with path.open("rb") as stream:
        reader = make_reader(stream, validate_crcs=True, decoder_factories=[DecoderFactory()])
        header = reader.get_header()
        summary = reader.get_summary()
        decoded = list(reader.iter_decoded_messages(log_time_order=False))
        metadata = {record.name: record.metadata for record in reader.iter_metadata()}
    return {"header": header, "summary": summary, "decoded": decoded, "metadata": metadata}


# -- schema ------------------------------------------------------------------------------------
def split_schema(text: str) -> tuple[str, list[tuple[str, str]]]:
    parts = text.split(f"\n{SEPARATOR}\n")
    dependencies = []
    for part in parts[1:]:
        first, _, body = part.partition("\n")
        assert first.startswith("MSG: "), first
        dependencies.append((first[len("MSG: "):], body))
    return parts[0], dependencies


def test_schema_of_wrench_stamped_is_concatenated_msg_files_as_rosbag2_writes_them() -> None:
    schema = load_schema("geometry_msgs/msg/WrenchStamped")
    assert schema.name == "geometry_msgs/msg/WrenchStamped"
    assert schema.encoding == "ros2msg"
    assert schema.text.count("=" * 80) == 4
    assert all(line == "=" * 80 for line in schema.text.splitlines() if line.startswith("==="))
    root, dependencies = split_schema(schema.text)
    geometry = share_dir("geometry_msgs") / "msg"
    assert root == (geometry / "WrenchStamped.msg").read_text()
    # Depth-first, the dependencies of each definition in sorted order, each once.
    assert [name for name, _ in dependencies] == [
        "geometry_msgs/Wrench",
        "geometry_msgs/Vector3",
        "std_msgs/Header",
        "builtin_interfaces/Time",
    ]
    bodies = dict(dependencies)
    assert bodies["geometry_msgs/Vector3"] == (geometry / "Vector3.msg").read_text()
    assert bodies["std_msgs/Header"] == (share_dir("std_msgs") / "msg" / "Header.msg").read_text()
    assert "MSG: std_msgs/Header\n" in schema.text
    assert "MSG: builtin_interfaces/Time\n" in schema.text


@pytest.mark.parametrize(
    ("type_name", "dependencies"),
    [
        ("geometry_msgs/msg/PoseArray", ["geometry_msgs/Pose", "geometry_msgs/Point",
                                         "geometry_msgs/Quaternion", "std_msgs/Header",
                                         "builtin_interfaces/Time"]),
        ("diagnostic_msgs/msg/DiagnosticArray", ["diagnostic_msgs/DiagnosticStatus",
                                                 "diagnostic_msgs/KeyValue", "std_msgs/Header",
                                                 "builtin_interfaces/Time"]),
        ("rosgraph_msgs/msg/Clock", ["builtin_interfaces/Time"]),
        ("std_msgs/Float64", []),
    ],
)
def test_schema_dependencies_of_recorded_types(type_name: str, dependencies: list[str]) -> None:
    _, found = split_schema(load_schema(type_name).text)
    assert [name for name, _ in found] == dependencies


def write_package(prefix: Path, package: str, messages: dict[str, str]) -> None:
    (prefix / "share" / "ament_index" / "resource_index" / "packages").mkdir(
        parents=True, exist_ok=True
    )
    (prefix / "share" / "ament_index" / "resource_index" / "packages" / package).write_text("")
    msg_dir = prefix / "share" / package / "msg"
    msg_dir.mkdir(parents=True)
    for name, text in messages.items():
        (msg_dir / f"{name}.msg").write_text(text)


def test_schema_lists_shared_dependencies_once_depth_first(tmp_path: Path) -> None:
    write_package(
        tmp_path,
        "demo_msgs",
        {
            "Outer": "# comment: Ignored words here\nZeta z\ndemo_msgs/Alpha[] alphas\n"
                     "Alpha[<=3] more\nstring<=8 label\nwstring w\nint32 COUNT=3\n",
            "Alpha": "Leaf leaf\nfloat64 x 0.5\n",
            "Zeta": "demo_msgs/Leaf first\nLeaf second\n",
            "Leaf": "uint8[4] bytes\n",
        },
    )
    schema = load_schema("demo_msgs/Outer", prefixes=[tmp_path])
    root, dependencies = split_schema(schema.text)
    assert root.startswith("# comment: Ignored words here\n")
    assert [name for name, _ in dependencies] == [
        "demo_msgs/Alpha", "demo_msgs/Leaf", "demo_msgs/Zeta"
    ]
    assert dict(dependencies)["demo_msgs/Leaf"] == "uint8[4] bytes\n"
    assert schema.type_hash == ""  # the fake package ships no .json type description


def test_schema_errors_name_the_problem(tmp_path: Path) -> None:
    with pytest.raises(SchemaNotFoundError, match="no_such_msgs/msg/Thing"):
        load_schema("no_such_msgs/msg/Thing")
    write_package(tmp_path, "broken_msgs", {"Top": "missing_msgs/Gone g\n"})
    with pytest.raises(SchemaNotFoundError, match="missing_msgs/msg/Gone"):
        load_schema("broken_msgs/msg/Top", prefixes=[tmp_path])
    with pytest.raises(ValueError, match="type_name"):
        load_schema("not a type")


@pytest.mark.parametrize("type_name", sorted(set(TOPICS.values())))
def test_type_hash_is_read_from_the_type_description(type_name: str) -> None:
    package, _, name = type_name.split("/")
    description = json.loads((share_dir(package) / "msg" / f"{name}.json").read_text())
    from_json = {h["type_name"]: h["hash_string"] for h in description["type_hashes"]}[type_name]
    schema = load_schema(type_name)
    assert schema.type_hash == from_json
    assert schema.type_hash.startswith("RIHS01_") and len(schema.type_hash) == 7 + 64
    # rosbags computes RIHS01 hashes independently from its own Jazzy type store.
    assert schema.type_hash == get_typestore(Stores.ROS2_JAZZY).hash_rihs01(type_name)


# -- QoS ---------------------------------------------------------------------------------------
QOS_KEYS = [
    "history", "depth", "reliability", "durability", "deadline", "lifespan", "liveliness",
    "liveliness_lease_duration", "avoid_ros_namespace_conventions",
]


def test_qos_yaml_from_rclpy_profiles_is_rosbag2_v9() -> None:
    custom = QoSProfile(
        history=HistoryPolicy.KEEP_ALL,
        depth=0,
        reliability=ReliabilityPolicy.RELIABLE,
        durability=DurabilityPolicy.TRANSIENT_LOCAL,
        deadline=Duration(seconds=1, nanoseconds=500),
        lifespan=Duration(nanoseconds=2**63 - 1),
        liveliness=LivelinessPolicy.MANUAL_BY_TOPIC,
        liveliness_lease_duration=Duration(seconds=3),
    )
    text = qos_profiles_yaml([qos_profile_sensor_data, QoSProfile(depth=10), custom])
    items = yaml.safe_load(text)
    assert [list(item) for item in items] == [QOS_KEYS] * 3
    sensor, default, kept = items
    assert sensor["history"] == "keep_last" and sensor["depth"] == 5
    assert sensor["reliability"] == "best_effort" and sensor["durability"] == "volatile"
    assert default["reliability"] == "reliable" and default["depth"] == 10
    assert default["deadline"] == {"sec": 0, "nsec": 0}
    assert default["liveliness"] == "system_default"
    assert kept["history"] == "keep_all" and kept["durability"] == "transient_local"
    assert kept["deadline"] == {"sec": 1, "nsec": 500}
    assert kept["lifespan"] == {"sec": 9223372036, "nsec": 854775807}  # RMW_DURATION_INFINITE
    assert kept["liveliness"] == "manual_by_topic"
    assert kept["liveliness_lease_duration"] == {"sec": 3, "nsec": 0}
    assert kept["avoid_ros_namespace_conventions"] is False
    # Round trip, and rosbags' parser reads the same policies.
    assert parse_qos_profiles_yaml(text) == [
        QosDescription.sensor_data(),
        QosDescription.reliable(10),
        QosDescription.from_profile(custom),
    ]
    parsed = parse_qos(text)
    assert [q.reliability.name for q in parsed] == ["BEST_EFFORT", "RELIABLE", "RELIABLE"]
    assert parsed[2].durability.name == "TRANSIENT_LOCAL"
    assert parsed[2].deadline.sec == 1 and parsed[2].deadline.nsec == 500


def test_qos_description_matches_rclpy_presets_and_rejects_bad_values() -> None:
    assert QosDescription.from_profile(qos_profile_sensor_data) == QosDescription.sensor_data()
    assert QosDescription.from_profile(QoSProfile(depth=7)) == QosDescription.reliable(7)
    with pytest.raises(ValueError, match="reliability"):
        QosDescription(reliability="sometimes")
    with pytest.raises(ValueError, match="depth"):
        QosDescription(depth=-1)
    with pytest.raises(ValueError, match=r"not YAML|list"):
        parse_qos_profiles_yaml("history: [unclosed")


# -- a complete recording read back by independent readers ------------------------------------
def test_mcap_reader_decodes_every_message_with_equal_values(
    standard_log: tuple[Path, list], mcap_contents: dict
) -> None:
    _, expected = standard_log
    decoded = mcap_contents["decoded"]
    assert len(decoded) == len(expected)
    for (topic, t_ns, original), (schema, channel, message, value) in zip(
        expected, decoded, strict=True
    ):
        assert channel.topic == topic
        assert schema.name == TOPICS[topic]
        assert message.log_time == message.publish_time == t_ns
        if isinstance(original, WrenchStamped):
            assert value.header.frame_id == original.header.frame_id
            assert (value.header.stamp.sec, value.header.stamp.nanosec) == (
                original.header.stamp.sec, original.header.stamp.nanosec)
            assert value.wrench.force.x == original.wrench.force.x
            assert value.wrench.force.y == original.wrench.force.y
            assert value.wrench.torque.z == original.wrench.torque.z
        elif isinstance(original, PoseArray):
            assert [p.position.x for p in value.poses] == [p.position.x for p in original.poses]
            assert [p.orientation.z for p in value.poses] == [
                p.orientation.z for p in original.poses]
        elif isinstance(original, Float64):
            assert value.data == original.data
        elif isinstance(original, DiagnosticArray):
            assert value.status[0].name == original.status[0].name
            assert bytes([value.status[0].level]) == original.status[0].level
            assert [(kv.key, kv.value) for kv in value.status[0].values] == [
                (kv.key, kv.value) for kv in original.status[0].values]
        elif isinstance(original, Clock):
            assert (value.clock.sec, value.clock.nanosec) == (
                original.clock.sec, original.clock.nanosec)
        else:  # pragma: no cover - every recorded type is checked above
            raise AssertionError(type(original))


def test_payloads_deserialize_with_rclpy_to_the_published_messages(
    standard_log: tuple[Path, list], mcap_contents: dict
) -> None:
    _, expected = standard_log
    decoded = mcap_contents["decoded"]
    for (_, _, original), (_, _, message, _) in zip(expected, decoded, strict=True):
        assert deserialize_message(message.data, type(original)) == original


def test_header_schemas_and_channels_follow_the_ros2_profile(mcap_contents: dict) -> None:
    header, summary = mcap_contents["header"], mcap_contents["summary"]
    assert header.profile == "ros2"
    assert header.library.startswith("flexure_sim 0.")
    schemas = summary.schemas
    assert sorted(s.name for s in schemas.values()) == sorted(set(TOPICS.values()))  # one per type
    assert all(s.encoding == "ros2msg" for s in schemas.values())
    channels = {c.topic: c for c in summary.channels.values()}
    assert sorted(channels) == sorted(TOPICS)
    for topic, channel in channels.items():
        assert channel.message_encoding == "cdr"
        assert schemas[channel.schema_id].name == TOPICS[topic]
        assert channel.metadata["topic_type_hash"] == load_schema(TOPICS[topic]).type_hash
        qos = yaml.safe_load(channel.metadata["offered_qos_profiles"])
        assert [list(q) for q in qos] == [QOS_KEYS]
        assert qos[0]["reliability"] == ("best_effort" if "wrench" in topic else "reliable")
    wrench_schema = schemas[channels["/stage/hinge_a/wrench"].schema_id].data.decode()
    assert wrench_schema == load_schema("geometry_msgs/msg/WrenchStamped").text


@pytest.mark.filterwarnings("ignore:(start|end)_time is deprecated:DeprecationWarning")
def test_statistics_and_indexes_are_present_and_usable(
    standard_log: tuple[Path, list], mcap_contents: dict
) -> None:
    path, expected = standard_log
    summary = mcap_contents["summary"]
    stats = summary.statistics
    assert stats is not None
    assert stats.message_count == len(expected)
    assert stats.message_start_time == T0_NS
    assert stats.message_end_time == T0_NS + (STEPS - 1) * DT_NS
    by_topic = {summary.channels[cid].topic: n for cid, n in stats.channel_message_counts.items()}
    assert by_topic == {t: sum(1 for e in expected if e[0] == t) for t in TOPICS}
    assert stats.chunk_count == len(summary.chunk_indexes) > 3  # 16 KiB chunks
    assert all(ci.compression == "" for ci in summary.chunk_indexes)
    assert all(ci.message_index_offsets for ci in summary.chunk_indexes)
    # Indexed, time-filtered, topic-filtered reading goes through chunk and message indexes.
    window = (T0_NS + 100 * DT_NS, T0_NS + 200 * DT_NS)
    with path.open("rb") as stream:
        reader = make_reader(stream, validate_crcs=True)
        got = [
            m.log_time
            for _, _, m in reader.iter_messages(
                topics=["/clock"], start_time=window[0], end_time=window[1], reverse=True
            )
        ]
    assert got == [T0_NS + s * DT_NS for s in range(199, 99, -1)]


def test_rosbag2_metadata_record_parses_with_correct_counts(
    standard_log: tuple[Path, list], mcap_contents: dict
) -> None:
    path, expected = standard_log
    record = mcap_contents["metadata"]["rosbag2"]
    assert list(record) == ["serialized_metadata"]
    meta = yaml.safe_load(record["serialized_metadata"])
    assert meta["version"] == 9
    assert meta["storage_identifier"] == "mcap"
    assert meta["message_count"] == len(expected)
    assert meta["starting_time"] == {"nanoseconds_since_epoch": T0_NS}
    assert meta["duration"] == {"nanoseconds": (STEPS - 1) * DT_NS}
    assert meta["compression_format"] == "" and meta["compression_mode"] == ""
    assert meta["relative_file_paths"] == [path.name]
    assert meta["files"] == [{
        "path": path.name,
        "starting_time": {"nanoseconds_since_epoch": T0_NS},
        "duration": {"nanoseconds": (STEPS - 1) * DT_NS},
        "message_count": len(expected),
    }]
    assert meta["ros_distro"] == "jazzy"
    assert meta["custom_data"] == {"flexure_sim.dropped_messages": "0"}
    topics = {t["topic_metadata"]["name"]: t for t in meta["topics_with_message_count"]}
    assert sorted(topics) == sorted(TOPICS)
    for name, entry in topics.items():
        info = entry["topic_metadata"]
        assert entry["message_count"] == sum(1 for e in expected if e[0] == name)
        assert info["type"] == TOPICS[name]
        assert info["serialization_format"] == "cdr"
        assert info["type_description_hash"] == load_schema(TOPICS[name]).type_hash
        assert isinstance(info["offered_qos_profiles"], str)
        assert [list(q) for q in yaml.safe_load(info["offered_qos_profiles"])] == [QOS_KEYS]
    assert mcap_contents["metadata"]["flexure_sim"] == MECHANISM_RECORD


def check_rosbags_reader(reader: AnyReader, expected: list) -> None:
    counts = {c.topic: c.msgcount for c in reader.connections}
    assert counts == {t: sum(1 for e in expected if e[0] == t) for t in TOPICS}
    assert {c.topic: c.msgtype for c in reader.connections} == TOPICS
    got = []
    for connection, timestamp, raw in reader.messages():
        got.append((connection.topic, timestamp, reader.deserialize(raw, connection.msgtype)))
    assert [(t, ts) for t, ts, _ in got] == [(t, ts) for t, ts, _ in expected]
    for (_, _, value), (_, _, original) in zip(got, expected, strict=True):
        if isinstance(original, WrenchStamped):
            assert value.wrench.force.x == original.wrench.force.x
            assert value.header.frame_id == original.header.frame_id
        elif isinstance(original, PoseArray):
            assert [p.position.x for p in value.poses] == [p.position.x for p in original.poses]
        elif isinstance(original, Float64):
            assert value.data == original.data
        elif isinstance(original, DiagnosticArray):
            assert value.status[0].values[0].value == original.status[0].values[0].value
        elif isinstance(original, Clock):
            assert value.clock.nanosec == original.clock.nanosec


def test_rosbags_reads_the_bare_mcap_file(standard_log: tuple[Path, list]) -> None:
    path, expected = standard_log
    with AnyReader([path]) as reader:
        assert reader.message_count == len(expected)
        assert reader.start_time == T0_NS
        check_rosbags_reader(reader, expected)


def test_rosbags_reads_a_bag_directory_made_from_the_rosbag2_record(
    standard_log: tuple[Path, list], tmp_path: Path
) -> None:
    path, expected = standard_log
    info = log_info(path)
    assert info.bag_metadata is not None
    bag = tmp_path / "stage_bag"
    bag.mkdir()
    shutil.copy(path, bag / info.bag_metadata["relative_file_paths"][0])
    (bag / "metadata.yaml").write_text(metadata_yaml(info.bag_metadata))
    with AnyReader([bag]) as reader:  # parses our metadata.yaml (topics, QoS, counts)
        assert reader.message_count == len(expected)
        assert reader.duration == (STEPS - 1) * DT_NS + 1
        assert all(c.ext.offered_qos_profiles for c in reader.connections)
        check_rosbags_reader(reader, expected)


def test_read_log_and_log_info_report_topics_counts_times_and_metadata(
    standard_log: tuple[Path, list]
) -> None:
    path, expected = standard_log
    log = read_log(path)
    assert log.complete and log.note == ""
    assert log.types == TOPICS
    assert log.counts == {t: sum(1 for e in expected if e[0] == t) for t in TOPICS}
    assert [(m.topic, m.log_time_ns) for m in log.messages] == [(t, ts) for t, ts, _ in expected]
    clock = log.messages_on("/clock")
    assert [m.message.clock.sec for m in clock[:2]] == [5, 5]
    assert [m.sequence for m in clock[:3]] == [1, 2, 3]
    assert log.metadata["flexure_sim"] == MECHANISM_RECORD
    assert [name for name, _ in log.metadata_records] == [
        "flexure_sim", "flexure_sim.parameters", "rosbag2"
    ]
    assert log.metadata_records[1][1] == {"drive_gain": "2.0"}
    assert log.bag_metadata is not None and log.bag_metadata["message_count"] == len(expected)
    assert log.topics["/stage/hinge_a/wrench"].qos == (QosDescription.sensor_data(),)

    info = log_info(path)
    assert info.complete
    assert info.types == TOPICS and info.counts == log.counts
    assert info.message_count == len(expected)
    assert (info.start_ns, info.end_ns) == (T0_NS, T0_NS + (STEPS - 1) * DT_NS)
    assert info.duration_ns == (STEPS - 1) * DT_NS
    assert info.flexure_sim == MECHANISM_RECORD
    assert info.metadata_records == log.metadata_records
    text = info.format()
    assert "/stage/body_poses" in text and "geometry_msgs/msg/PoseArray" in text
    assert "flexure_sim.mechanism: micropositioning_stage" in text


# -- writer behaviour --------------------------------------------------------------------------
def test_chunks_are_bounded_by_chunk_size(tmp_path: Path) -> None:
    path = tmp_path / "small_chunks.mcap"
    record_standard_log(path, chunk_size=4096)
    with path.open("rb") as stream:
        summary = make_reader(stream).get_summary()
    sizes = [
        ci.uncompressed_size
        for ci in sorted(summary.chunk_indexes, key=lambda ci: ci.chunk_start_offset)
    ]
    largest_message = 400  # a PoseArray record is well below this
    assert len(sizes) > 20
    assert max(sizes[1:]) < 4096 + largest_message
    # mcap's Writer puts Schema and Channel records in the chunk open when they are added
    # (so every recovered chunk prefix is self-describing): the first chunk carries them too.
    definitions = sum(len(s.data) + len(s.name) + 64 for s in summary.schemas.values()) + sum(
        1024 for _ in summary.channels)
    assert sizes[0] < 4096 + largest_message + definitions


def test_open_chunk_reaches_the_disk_within_the_chunk_interval(tmp_path: Path) -> None:
    path = tmp_path / "live.mcap"
    recorder = McapRecorder(path, chunk_interval_s=0.05)
    try:
        recorder.add_topic("/clock", "rosgraph_msgs/msg/Clock")
        for step in range(5):
            recorder.write("/clock", serialize_message(Clock(clock=stamp(step))), step)
        deadline = time.monotonic() + 5.0
        recovered = read_log(path, recover=True)
        while recovered.message_count < 5 and time.monotonic() < deadline:
            time.sleep(0.02)
            recovered = read_log(path, recover=True)
        assert recovered.message_count == 5
        assert not recovered.complete and "recovered 5 message(s)" in recovered.note
        with pytest.raises(CorruptLogError, match="truncated"):
            read_log(path)
    finally:
        recorder.close()
    assert read_log(path).complete


def test_full_queue_drops_are_counted_returned_and_recorded(tmp_path: Path) -> None:
    read_fd, write_fd = os.pipe()
    sink = os.fdopen(write_fd, "wb")
    recorder = McapRecorder(sink, chunk_size=1024, queue_size=4, max_block_s=0.0)
    recorder.add_topic("/big", "std_msgs/msg/String")
    payload = serialize_message(String(data="x" * 200_000))  # larger than a pipe buffer
    accepted = [recorder.write("/big", payload, i) for i in range(40)]
    stats = recorder.stats
    assert stats.dropped_count == accepted.count(False) >= 30
    assert stats.accepted_count == accepted.count(True)
    assert recorder.dropped_count == stats.dropped_count

    drained = bytearray()

    def drain() -> None:
        with os.fdopen(read_fd, "rb") as source:
            while chunk := source.read(1 << 16):
                drained.extend(chunk)

    reader_thread = threading.Thread(target=drain)
    reader_thread.start()
    recorder.close()
    reader_thread.join(10)
    path = tmp_path / "drained.mcap"
    path.write_bytes(bytes(drained))
    log = read_log(path)
    assert log.counts == {"/big": accepted.count(True)}
    assert [m.log_time_ns for m in log.messages] == [i for i, ok in enumerate(accepted) if ok]
    assert log.bag_metadata["custom_data"]["flexure_sim.dropped_messages"] == str(
        accepted.count(False)
    )


def test_batches_are_written_or_dropped_whole(tmp_path: Path) -> None:
    read_fd, write_fd = os.pipe()
    recorder = McapRecorder(os.fdopen(write_fd, "wb"), chunk_size=1024, queue_size=2,
                            max_block_s=0.0)
    for topic in ("/a", "/b"):
        recorder.add_topic(topic, "std_msgs/msg/String")
    big = serialize_message(String(data="x" * 200_000))  # larger than a pipe buffer
    kept = [recorder.write_batch([("/a", big), ("/b", big)], i) for i in range(20)]
    assert kept.count(False) >= 10
    stats = recorder.stats
    assert stats.dropped == {"/a": kept.count(False), "/b": kept.count(False)}
    assert stats.accepted == {"/a": kept.count(True), "/b": kept.count(True)}
    with pytest.raises(ValueError, match="/c"):
        recorder.write_batch([("/a", big), ("/c", big)], 0)
    drained = bytearray()

    def drain() -> None:
        with os.fdopen(read_fd, "rb") as source:
            while chunk := source.read(1 << 16):
                drained.extend(chunk)

    reader_thread = threading.Thread(target=drain)
    reader_thread.start()
    recorder.close()
    reader_thread.join(10)
    path = tmp_path / "batches.mcap"
    path.write_bytes(bytes(drained))
    log = read_log(path, decode=False)
    times = [i for i, ok in enumerate(kept) if ok]
    assert [(m.topic, m.log_time_ns) for m in log.messages] == [
        (t, i) for i in times for t in ("/a", "/b")]
    assert log.bag_metadata["custom_data"]["flexure_sim.dropped_messages"] == str(
        2 * kept.count(False))


def test_write_errors_surface_as_recording_errors() -> None:
    with pytest.raises(RecordingError, match="No space left"):
        McapRecorder(open("/dev/full", "wb"))  # noqa: SIM115 - closed by the recorder
    read_fd, write_fd = os.pipe()
    recorder = McapRecorder(os.fdopen(write_fd, "wb"), chunk_interval_s=0.01)
    os.close(read_fd)  # the reader goes away: the writer thread gets EPIPE
    recorder.add_topic("/out", "std_msgs/msg/Float64")
    payload = serialize_message(Float64(data=1.0))
    deadline = time.monotonic() + 10.0
    with pytest.raises(RecorderFailedError, match="Broken pipe"):
        while time.monotonic() < deadline:
            recorder.write("/out", payload, 0)
            time.sleep(0.001)
    with pytest.raises(RecorderFailedError):
        recorder.close()
    recorder.close()  # the failure is reported once; closing again is a no-op


def test_close_is_idempotent_and_use_after_close_raises(tmp_path: Path) -> None:
    path = tmp_path / "closed.mcap"
    recorder = McapRecorder(path)
    recorder.add_topic("/out", "std_msgs/msg/Float64")
    assert recorder.write("/out", serialize_message(Float64(data=1.0)), 7)
    first = recorder.close()
    assert recorder.close() == first and first.accepted == {"/out": 1}
    assert recorder.closed
    with pytest.raises(RecorderClosedError):
        recorder.write("/out", serialize_message(Float64(data=2.0)), 8)
    with pytest.raises(RecorderClosedError):
        recorder.add_topic("/other", "std_msgs/msg/Float64")
    assert read_log(path).counts == {"/out": 1}


def test_context_manager_finishes_the_file_when_the_loop_raises(tmp_path: Path) -> None:
    path = tmp_path / "interrupted.mcap"
    with pytest.raises(KeyboardInterrupt), McapRecorder(path) as recorder:
        recorder.add_topic("/out", "std_msgs/msg/Float64")
        for i in range(10):
            recorder.write("/out", serialize_message(Float64(data=float(i))), i)
        raise KeyboardInterrupt
    log = read_log(path)
    assert log.complete and [m.message.data for m in log.messages] == [float(i) for i in range(10)]


def test_arguments_are_validated(tmp_path: Path) -> None:
    path = tmp_path / "args.mcap"
    with McapRecorder(path) as recorder:
        with pytest.raises(ValueError, match="name"):
            recorder.add_topic("relative/name", "std_msgs/msg/Float64")
        with pytest.raises(SchemaNotFoundError):
            recorder.add_topic("/unknown", "no_such_msgs/msg/Nothing")
        recorder.add_topic("/out", "std_msgs/Float64")
        recorder.add_topic("/out", "std_msgs/msg/Float64")  # same topic again: no-op
        with pytest.raises(ValueError, match="std_msgs/msg/String"):
            recorder.add_topic("/out", "std_msgs/msg/String")
        with pytest.raises(ValueError, match="topic"):
            recorder.write("/missing", b"\x00\x01\x00\x00", 0)
        with pytest.raises(ValueError, match="stamp_ns"):
            recorder.write("/out", serialize_message(Float64()), -1)
        with pytest.raises(ValueError, match="stamp_ns"):
            recorder.write("/out", serialize_message(Float64()), 1.5)  # type: ignore[arg-type]
        with pytest.raises(ValueError, match="reserved"):
            recorder.add_metadata("rosbag2", {"a": "b"})
        with pytest.raises(ValueError, match="str"):
            recorder.add_metadata("flexure_sim", {"gain": 27.8})  # type: ignore[dict-item]
        assert recorder.topics == {"/out": "std_msgs/msg/Float64"}
    with pytest.raises(Exception, match="exists") as excinfo:
        McapRecorder(path)
    assert excinfo.type.__name__ == "RecordingError"
    with pytest.raises(ValueError, match="queue_size"):
        McapRecorder(tmp_path / "q.mcap", queue_size=0)
    assert read_log(path).topics["/out"].type == "std_msgs/msg/Float64"


def run_python(code: str, *args: str, **kwargs: object) -> subprocess.Popen:
    python_path = os.pathsep.join([str(REPO), os.environ.get("PYTHONPATH", "")])
    env = dict(os.environ, PYTHONPATH=python_path)
    return subprocess.Popen([sys.executable, "-c", code, *args], cwd=REPO, env=env, **kwargs)


def test_recording_layer_imports_without_rclpy() -> None:
    code = (
        "import sys, flexure_sim.recording as r, flexure_sim.recording.writer\n"
        "assert 'rclpy' not in sys.modules, 'rclpy was imported'\n"
    )
    assert run_python(code).wait(60) == 0


def test_recorder_never_closed_is_finished_at_interpreter_exit(tmp_path: Path) -> None:
    path = tmp_path / "forgotten.mcap"
    code = (
        "import sys\n"
        "from flexure_sim.recording import McapRecorder\n"
        "r = McapRecorder(sys.argv[1])\n"
        "r.add_topic('/out', 'std_msgs/msg/Float64')\n"
        "for i in range(100):\n"
        "    r.write('/out', b'\\x00\\x01\\x00\\x00' + bytes(8), i)\n"
    )
    assert run_python(code, str(path)).wait(60) == 0
    log = read_log(path, decode=False)
    assert log.complete and log.counts == {"/out": 100}


KILL_SCRIPT = r"""
import sys, time
from flexure_sim.recording import McapRecorder
from geometry_msgs.msg import WrenchStamped
from rclpy.serialization import serialize_message

recorder = McapRecorder(sys.argv[1], chunk_interval_s=0.05)
recorder.add_topic("/stage/hinge_a/wrench", "geometry_msgs/msg/WrenchStamped")
recorder.add_metadata("flexure_sim", {"mechanism": "kill_test"})
ready_at = time.monotonic() + 0.5
announced = False
step = 0
while True:
    msg = WrenchStamped()
    msg.header.frame_id = "hinge_a"
    msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(step * 1_000_000, 10**9)
    msg.wrench.force.x = float(step)
    recorder.write("/stage/hinge_a/wrench", serialize_message(msg), step * 1_000_000)
    step += 1
    if not announced and time.monotonic() > ready_at:
        print("recording", flush=True)
        announced = True
    time.sleep(0.0005)
"""


def test_kill_9_leaves_recoverable_complete_chunks(tmp_path: Path) -> None:
    path = tmp_path / "killed.mcap"
    child = run_python(KILL_SCRIPT, str(path), stdout=subprocess.PIPE, text=True)
    try:
        ready, _, _ = select.select([child.stdout], [], [], 60)
        assert ready and child.stdout.readline().strip() == "recording"
        time.sleep(0.3)
    finally:
        child.send_signal(signal.SIGKILL)
        child.wait(30)
        child.stdout.close()
    assert child.returncode == -signal.SIGKILL

    with pytest.raises(CorruptLogError, match="readable") as excinfo:
        read_log(path)
    assert excinfo.value.readable_messages > 0
    assert "recover=True" in str(excinfo.value)
    with pytest.raises(CorruptLogError):
        log_info(path)

    log = read_log(path, recover=True)
    assert not log.complete and log.note.startswith("recovered ")
    assert log.message_count == excinfo.value.readable_messages > 100
    forces = [m.message.wrench.force.x for m in log.messages]
    assert forces == [float(i) for i in range(len(forces))]  # complete chunks, in order, no gaps
    assert all(m.message.header.frame_id == "hinge_a" for m in log.messages)
    assert log.metadata["flexure_sim"] == {"mechanism": "kill_test"}
    info = log_info(path, recover=True)
    assert info.counts == {"/stage/hinge_a/wrench": log.message_count} and not info.complete


# -- corrupt and foreign files -----------------------------------------------------------------
@pytest.fixture(scope="module")
def reference_bytes(tmp_path_factory: pytest.TempPathFactory) -> bytes:
    path = tmp_path_factory.mktemp("ref") / "ref.mcap"
    record_standard_log(path, chunk_size=8 * 1024)
    return path.read_bytes()


def assert_corrupt(path: Path, *patterns: str) -> CorruptLogError:
    for call in (lambda: read_log(path), lambda: log_info(path)):
        with pytest.raises(CorruptLogError) as excinfo:
            call()
        assert type(excinfo.value) is CorruptLogError
        message = str(excinfo.value)
        assert str(path) in message and "readable" in message
        assert any(p in message for p in patterns), message
    return excinfo.value


def test_empty_file_is_reported(tmp_path: Path) -> None:
    path = tmp_path / "empty.mcap"
    path.write_bytes(b"")
    error = assert_corrupt(path, "empty")
    assert error.readable_messages == 0 and error.total_bytes == 0
    with pytest.raises(CorruptLogError, match="empty"):
        read_log(path, recover=True)


@pytest.mark.parametrize("fraction", [0.0001, 0.0004, 0.002, 0.25, 0.5, 0.75, 0.999, 0.9999, 1.0])
def test_truncated_file_is_reported_and_its_prefix_recovered(
    reference_bytes: bytes, tmp_path: Path, fraction: float
) -> None:
    size = max(1, min(len(reference_bytes) - 1, int(len(reference_bytes) * fraction)))
    path = tmp_path / "cut.mcap"
    path.write_bytes(reference_bytes[:size])
    error = assert_corrupt(path, "truncated", "incomplete", "damaged")
    assert error.total_bytes == size
    full = read_log_bytes(reference_bytes, tmp_path)
    try:
        partial = read_log(path, recover=True)
    except CorruptLogError as exc:
        assert size < 64 and "truncated" in str(exc)  # not even the header survived
        return
    assert not partial.complete and "recovered" in partial.note
    assert [m.data for m in partial.messages] == [
        m.data for m in full.messages[: partial.message_count]
    ]
    assert all(m.message is not None for m in partial.messages)
    if fraction >= 0.5:
        assert partial.message_count > 0


def read_log_bytes(data: bytes, tmp_path: Path) -> object:
    path = tmp_path / "full.mcap"
    path.write_bytes(data)
    return read_log(path)


def flip_positions(size: int) -> list[int]:
    evenly = list(range(0, size, max(1, size // 97)))
    edges = list(range(0, 40)) + list(range(size - 60, size))
    return sorted(set(evenly + edges))


def chunk_payloads(data: bytes) -> dict[int, list[bytes]]:
    """Chunk offset -> payloads of its messages, read with the mcap library's StreamReader."""
    out: dict[int, list[bytes]] = {}
    stream = io.BytesIO(data)
    reader = StreamReader(stream, emit_chunks=True)
    start = 8
    for record in reader.records:
        if isinstance(record, Chunk):
            out[start] = [r.data for r in breakup_chunk(record) if isinstance(r, Message)]
        start = stream.tell()
    return out


def test_every_flipped_byte_is_detected(reference_bytes: bytes, tmp_path: Path) -> None:
    """
    Strict reading refuses every flip.

    Recovery keeps every intact chunk, also those after a chunk that fails its CRC or whose framing
    is broken (the summary's chunk index says where the next chunk starts), and exactly their
    messages.
    """
    by_chunk = chunk_payloads(reference_bytes)
    path = tmp_path / "flipped.mcap"
    skipped_over = 0
    for position in flip_positions(len(reference_bytes)):
        damaged = bytearray(reference_bytes)
        damaged[position] ^= 0xFF
        path.write_bytes(bytes(damaged))
        with pytest.raises(CorruptLogError) as excinfo:
            read_log(path)
        assert type(excinfo.value) is CorruptLogError, position
        try:
            partial = read_log(path, recover=True, decode=False)
        except CorruptLogError:
            continue  # header or profile destroyed
        scan = scan_file(path)
        for chunk in scan.damaged:
            if "CRC mismatch" in chunk.reason:
                assert chunk.offset <= position < chunk.end, position
        lost = {chunk.offset for chunk in scan.damaged}
        expected = [d for offset in scan.chunk_offsets if offset not in lost
                    for d in by_chunk[offset]]
        assert [m.data for m in partial.messages] == expected, position
        if lost and scan.chunk_offsets[-1] not in lost and not scan.stopped:
            skipped_over += 1
    assert skipped_over > 10  # flips inside chunks: the chunks after them were still read


def test_chunks_after_a_damaged_chunk_holding_the_channels_are_recovered(tmp_path: Path) -> None:
    """
    The mcap library's Writer puts Schema and Channel records inside the first chunk using them.

    When that chunk is damaged, the summary's copies still give the later chunks' messages their
    topic.
    """
    path = tmp_path / "mcap_writer.mcap"
    with path.open("wb") as stream:
        writer = Writer(stream, compression=CompressionType.NONE, chunk_size=512)
        writer.start(profile="ros2", library="test")
        schema_id = writer.register_schema(
            "std_msgs/msg/Float64", "ros2msg", load_schema("std_msgs/msg/Float64").text.encode()
        )
        qos = qos_profiles_yaml([QosDescription.sensor_data()])
        channel_id = writer.register_channel(
            "/x", "cdr", schema_id, metadata={"offered_qos_profiles": qos}
        )
        for k in range(200):
            payload = serialize_message(Float64(data=float(k)))
            writer.add_message(channel_id, log_time=k, data=payload, publish_time=k)
        writer.finish()
    data = path.read_bytes()
    by_chunk = chunk_payloads(data)
    first = min(by_chunk)
    damaged = bytearray(data)
    damaged[first + 200] ^= 0x01
    path.write_bytes(bytes(damaged))
    with pytest.raises(CorruptLogError, match="chunk 1 "):
        read_log(path)
    log = read_log(path, recover=True)
    assert [m.message.data for m in log.messages] == [
        deserialize_message(d, Float64).data
        for offset in sorted(by_chunk) if offset != first for d in by_chunk[offset]
    ]
    assert len(by_chunk) > 5 and log.message_count == 200 - len(by_chunk[first])


def test_mcap_with_another_profile_is_rejected(tmp_path: Path) -> None:
    path = tmp_path / "ros1.mcap"
    with path.open("wb") as stream:
        writer = Writer(stream, compression=CompressionType.NONE)
        writer.start(profile="ros1", library="test")
        schema_id = writer.register_schema("std_msgs/Float64", "ros1msg", b"float64 data")
        channel_id = writer.register_channel("/x", "ros1", schema_id)
        writer.add_message(channel_id, log_time=1, data=bytes(8), publish_time=1)
        writer.finish()
    assert_corrupt(path, "profile is 'ros1'")
    with pytest.raises(CorruptLogError, match="not a rosbag2 log"):
        read_log(path, recover=True)


def test_ros2_profile_channel_without_qos_metadata_is_rejected(tmp_path: Path) -> None:
    path = tmp_path / "no_qos.mcap"
    with path.open("wb") as stream:
        writer = Writer(stream, compression=CompressionType.NONE)
        writer.start(profile="ros2", library="test")
        schema_id = writer.register_schema(
            "std_msgs/msg/Float64", "ros2msg", load_schema("std_msgs/msg/Float64").text.encode()
        )
        channel_id = writer.register_channel("/x", "cdr", schema_id)
        payload = serialize_message(Float64())
        writer.add_message(channel_id, log_time=1, data=payload, publish_time=1)
        writer.finish()
    with pytest.raises(CorruptLogError, match="offered_qos_profiles"):
        read_log(path)


def test_a_file_that_is_not_mcap_is_rejected(tmp_path: Path) -> None:
    path = tmp_path / "notes.mcap"
    path.write_text("stage gain 27.8 at 1.35 um input\n" * 10)
    assert_corrupt(path, "not an MCAP file")
