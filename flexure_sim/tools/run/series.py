"""
Time series of a recorded run, built message by message in compact arrays.

A run's numeric topics are kept as `array.array` buffers while the log streams past (8 bytes
per time stamp and per value, no decoded message objects), and become NumPy arrays at the
end. What is taken from each message type (SI units, angles in rad):

- ``std_msgs/msg/Float64``: ``data``;
- ``geometry_msgs/msg/WrenchStamped``: (moment z, f_x, f_y), and of a run of the spatial
  engine (`SeriesBuilder` ``spatial``) then (moment x, moment y, f_z): six columns whose first
  three are the planar ones;
- ``geometry_msgs/msg/PoseStamped``: (x, y, yaw);
- ``geometry_msgs/msg/PoseArray``: (x, y, yaw) of every pose, rows of varying length;
- ``rosgraph_msgs/msg/Clock``: the clock value in ns (exact, int64).
"""
from __future__ import annotations

import math
from array import array
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Optional

import numpy as np

FLOAT64 = "std_msgs/msg/Float64"
WRENCH = "geometry_msgs/msg/WrenchStamped"
POSE = "geometry_msgs/msg/PoseStamped"
POSE_ARRAY_TYPE = "geometry_msgs/msg/PoseArray"
CLOCK_TYPE = "rosgraph_msgs/msg/Clock"


@dataclass(frozen=True)
class Series:
    """Samples of one topic: ``t`` (s, simulation time) and ``values`` (n, ...)."""

    t: np.ndarray
    values: np.ndarray

    def __len__(self) -> int:
        return int(self.t.shape[0])

    @property
    def empty(self) -> bool:
        return self.t.shape[0] == 0


def yaw(q: Any) -> float:
    """Yaw of a quaternion (exact for the node's yaw-only quaternions)."""
    if q.x == 0.0 and q.y == 0.0:
        return 2.0 * math.atan2(q.z, q.w)
    return math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))


def pose2d(p: Any) -> tuple[float, float, float]:
    """(x, y, yaw) of a geometry_msgs/Pose."""
    return p.position.x, p.position.y, yaw(p.orientation)


def _wrench(m: Any) -> tuple[float, float, float]:
    return m.wrench.torque.z, m.wrench.force.x, m.wrench.force.y


def _wrench6(m: Any) -> tuple[float, ...]:
    w = m.wrench
    return w.torque.z, w.force.x, w.force.y, w.torque.x, w.torque.y, w.force.z


#: Message type -> (values per message, extractor); None: rows of varying length.
EXTRACTORS: dict[str, tuple[Optional[int], Callable[[Any], Any]]] = {
    FLOAT64: (1, lambda m: (m.data,)),
    WRENCH: (3, _wrench),
    POSE: (3, lambda m: pose2d(m.pose)),
    POSE_ARRAY_TYPE: (None, lambda m: [v for p in m.poses for v in pose2d(p)]),
}


class SeriesBuilder:
    """Appends (log time, values) of one topic's messages; `arrays` gives NumPy arrays."""

    def __init__(self, type_name: str, spatial: bool = False) -> None:
        self.type = type_name
        self.times = array("q")
        if type_name == CLOCK_TYPE:
            self.width: Optional[int] = 1
            self.values = array("q")
            self._get: Callable[[Any], Any] = (
                lambda m: (m.clock.sec * 1_000_000_000 + m.clock.nanosec,)
            )
        else:
            self.width, self._get = (6, _wrench6) if spatial and type_name == WRENCH else (
                EXTRACTORS[type_name])
            self.values = array("d")
        self.lengths = array("q")  # values per row, for rows of varying length

    @staticmethod
    def supports(type_name: str) -> bool:
        return type_name in EXTRACTORS or type_name == CLOCK_TYPE

    def add(self, log_time_ns: int, message: Any) -> None:
        row = self._get(message)
        self.values.extend(row)
        if self.width is None:
            self.lengths.append(len(row))
        self.times.append(log_time_ns)

    def arrays(self) -> tuple[np.ndarray, np.ndarray, Optional[np.ndarray]]:
        """Log times (ns), values ((n,) for one value per message, else flat), row lengths."""
        times = np.frombuffer(self.times, dtype=np.int64) if self.times else np.zeros(0, np.int64)
        dtype = np.int64 if self.type == CLOCK_TYPE else np.float64
        values = np.frombuffer(self.values, dtype=dtype) if self.values else np.zeros(0, dtype)
        lengths = None
        if self.width is None:
            lengths = np.frombuffer(self.lengths, dtype=np.int64) if self.lengths else (
                np.zeros(0, np.int64))
        elif self.width > 1:
            values = values.reshape(-1, self.width)
        return times, values, lengths
