"""
MCAP recording in the rosbag2 (ROS 2 Jazzy) format.

Write with `McapRecorder`, read back streaming with `LogReader` (or whole with `read_log`),
summarise with `log_info`. Needs mcap and mcap-ros2-support; never imports rclpy.
"""
from flexure_sim.recording.bag_metadata import (
    TopicRecord, build_bag_metadata, metadata_yaml, parse_serialized_metadata,
)
from flexure_sim.recording.exceptions import (
    CorruptLogError, RecorderClosedError, RecorderFailedError, RecordingError, RunError,
    SchemaNotFoundError, UndecodableMessageError,
)
from flexure_sim.recording.log_info import LogInfo, log_info
from flexure_sim.recording.qos import QosDescription, parse_qos_profiles_yaml, qos_profiles_yaml
from flexure_sim.recording.reader import (
    LogMessage, LogReader, McapLog, TopicInfo, read_log, undecodable_note,
)
from flexure_sim.recording.schema import MessageSchema, SchemaResolver, ament_prefixes, load_schema
from flexure_sim.recording.writer import McapRecorder, RecordingStats

__all__ = [
    "CorruptLogError",
    "LogInfo",
    "LogMessage",
    "LogReader",
    "McapLog",
    "McapRecorder",
    "MessageSchema",
    "QosDescription",
    "RecorderClosedError",
    "RecorderFailedError",
    "RecordingError",
    "RecordingStats",
    "RunError",
    "SchemaNotFoundError",
    "SchemaResolver",
    "TopicInfo",
    "TopicRecord",
    "UndecodableMessageError",
    "ament_prefixes",
    "build_bag_metadata",
    "load_schema",
    "log_info",
    "metadata_yaml",
    "parse_qos_profiles_yaml",
    "parse_serialized_metadata",
    "qos_profiles_yaml",
    "read_log",
    "undecodable_note",
]
