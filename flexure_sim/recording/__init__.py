"""
MCAP recording in the rosbag2 (ROS 2 Jazzy) format.

Write with `McapRecorder`, read back streaming with `LogReader` (or whole with `read_log`),
summarise with `log_info`. Needs mcap and mcap-ros2-support; never imports rclpy.
"""
from .bag_metadata import (
    TopicRecord,
    build_bag_metadata,
    metadata_yaml,
    parse_serialized_metadata,
)
from .errors import (
    CorruptLogError,
    RecorderClosedError,
    RecorderFailedError,
    RecordingError,
    RunError,
    SchemaNotFoundError,
    UndecodableMessageError,
)
from .info import LogInfo, log_info
from .qos import QosDescription, parse_qos_profiles_yaml, qos_profiles_yaml
from .reader import LogMessage, LogReader, McapLog, TopicInfo, read_log, undecodable_note
from .schema import MessageSchema, SchemaResolver, ament_prefixes, load_schema
from .writer import McapRecorder, RecordingStats

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
