"""
QoS profiles as rosbag2 (Jazzy, metadata version 9) writes them in ``offered_qos_profiles``.

The value is the YAML of a list of profiles, each with the keys, in order: history, depth,
reliability, durability, deadline {sec, nsec}, lifespan {sec, nsec}, liveliness,
liveliness_lease_duration {sec, nsec}, avoid_ros_namespace_conventions. Policies are the rmw
strings (``keep_last``, ``reliable``, ``volatile``, ``automatic``, ``system_default``...).

`QosDescription` is a plain description, so nothing here needs rclpy; `QosDescription.from_profile`
reads an ``rclpy.qos.QoSProfile`` (or anything with the same attributes).
"""
from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any

import yaml

_NS_PER_S = 1_000_000_000
#: rmw's RMW_DURATION_INFINITE, in nanoseconds ({sec: 9223372036, nsec: 854775807}).
INFINITE_NS = 2**63 - 1

HISTORY = ("system_default", "keep_last", "keep_all", "unknown")
RELIABILITY = ("system_default", "reliable", "best_effort", "unknown", "best_available")
DURABILITY = ("system_default", "transient_local", "volatile", "unknown", "best_available")
LIVELINESS = ("system_default", "automatic", "_deprecated", "manual_by_topic", "unknown",
              "best_available")
# Indexed by the rmw enum value (metadata version <= 8 stored integers).
_POLICIES = {
    "history": HISTORY,
    "reliability": RELIABILITY,
    "durability": DURABILITY,
    "liveliness": LIVELINESS,
}


@dataclass(frozen=True)
class QosDescription:
    """One offered QoS profile; durations in nanoseconds (0 = unspecified, `INFINITE_NS`)."""

    history: str = "keep_last"
    depth: int = 10
    reliability: str = "reliable"
    durability: str = "volatile"
    deadline_ns: int = 0
    lifespan_ns: int = 0
    liveliness: str = "system_default"
    liveliness_lease_duration_ns: int = 0
    avoid_ros_namespace_conventions: bool = False

    def __post_init__(self) -> None:
        for field_name, allowed in _POLICIES.items():
            value = getattr(self, field_name)
            if value not in allowed or value == "_deprecated":
                raise ValueError(f"{field_name}: {value!r} is not one of {allowed}")
        if self.depth < 0:
            raise ValueError(f"depth: must be >= 0, got {self.depth}")
        for field_name in ("deadline_ns", "lifespan_ns", "liveliness_lease_duration_ns"):
            value = getattr(self, field_name)
            if not 0 <= value <= INFINITE_NS:
                raise ValueError(f"{field_name}: must be in [0, 2**63-1], got {value}")

    @classmethod
    def reliable(cls, depth: int = 10) -> QosDescription:
        """Return rclpy's ``QoSProfile(depth=depth)``: keep_last, reliable, volatile."""
        return cls(depth=depth)

    @classmethod
    def sensor_data(cls) -> QosDescription:
        """Return rclpy's ``qos_profile_sensor_data``: keep_last 5, best_effort, volatile."""
        return cls(depth=5, reliability="best_effort")

    @classmethod
    def from_profile(cls, profile: Any) -> QosDescription:
        """Read an ``rclpy.qos.QoSProfile`` (duck-typed: policy enums, Duration values)."""
        return cls(
            history=_policy_name("history", profile.history),
            depth=int(profile.depth),
            reliability=_policy_name("reliability", profile.reliability),
            durability=_policy_name("durability", profile.durability),
            deadline_ns=_duration_ns("deadline", profile.deadline),
            lifespan_ns=_duration_ns("lifespan", profile.lifespan),
            liveliness=_policy_name("liveliness", profile.liveliness),
            liveliness_lease_duration_ns=_duration_ns(
                "liveliness_lease_duration", profile.liveliness_lease_duration
            ),
            avoid_ros_namespace_conventions=bool(profile.avoid_ros_namespace_conventions),
        )

    @classmethod
    def from_dict(cls, item: Mapping[str, Any]) -> QosDescription:
        """Read one entry of ``offered_qos_profiles`` (strings of v9, or integers of v8)."""
        try:
            return cls(
                history=_policy_name("history", item["history"]),
                depth=int(item["depth"]),
                reliability=_policy_name("reliability", item["reliability"]),
                durability=_policy_name("durability", item["durability"]),
                deadline_ns=_duration_ns("deadline", item["deadline"]),
                lifespan_ns=_duration_ns("lifespan", item["lifespan"]),
                liveliness=_policy_name("liveliness", item["liveliness"]),
                liveliness_lease_duration_ns=_duration_ns(
                    "liveliness_lease_duration", item["liveliness_lease_duration"]
                ),
                avoid_ros_namespace_conventions=bool(item["avoid_ros_namespace_conventions"]),
            )
        except KeyError as exc:
            raise ValueError(f"QoS profile lacks the key {exc.args[0]!r}") from None

    def to_dict(self) -> dict[str, Any]:
        """Return the profile as rosbag2 v9 encodes it, keys in rosbag2's order."""
        return {
            "history": self.history,
            "depth": self.depth,
            "reliability": self.reliability,
            "durability": self.durability,
            "deadline": _rmw_time(self.deadline_ns),
            "lifespan": _rmw_time(self.lifespan_ns),
            "liveliness": self.liveliness,
            "liveliness_lease_duration": _rmw_time(self.liveliness_lease_duration_ns),
            "avoid_ros_namespace_conventions": self.avoid_ros_namespace_conventions,
        }


QosLike = QosDescription | Mapping[str, Any] | Any


def as_qos_description(qos: QosLike) -> QosDescription:
    """Accept a `QosDescription`, a rosbag2-style dict, or an rclpy ``QoSProfile``."""
    if isinstance(qos, QosDescription):
        return qos
    if isinstance(qos, Mapping):
        return QosDescription.from_dict(qos)
    if all(hasattr(qos, a) for a in ("history", "depth", "reliability", "durability")):
        return QosDescription.from_profile(qos)
    raise TypeError(f"qos: expected QosDescription, dict or rclpy QoSProfile, got {type(qos)!r}")


def qos_profiles_yaml(profiles: Iterable[QosLike]) -> str:
    """
    Return the ``offered_qos_profiles`` string.

    A YAML list, ``""`` for no profiles (as rosbag2).
    """
    items = [as_qos_description(p).to_dict() for p in profiles]
    if not items:
        return ""
    return yaml.safe_dump(items, sort_keys=False, default_flow_style=False)


def parse_qos_profiles_yaml(text: str) -> list[QosDescription]:
    """Parse an ``offered_qos_profiles`` string; raise ValueError when it is not one."""
    if not text.strip():
        return []
    try:
        items = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        raise ValueError(f"offered_qos_profiles is not YAML: {exc}") from exc
    if not isinstance(items, list) or not all(isinstance(i, Mapping) for i in items):
        raise ValueError("offered_qos_profiles is not a YAML list of mappings")
    return [QosDescription.from_dict(item) for item in items]


def _policy_name(field_name: str, value: Any) -> str:
    allowed = _POLICIES[field_name]
    if isinstance(value, str):
        name = value.lower()
    elif hasattr(value, "name") and isinstance(value.name, str):
        name = value.name.lower()  # rclpy policy enums: KEEP_LAST -> keep_last
    elif isinstance(value, int) and 0 <= value < len(allowed):
        name = allowed[value]
    else:
        raise ValueError(f"{field_name}: cannot interpret {value!r} as a QoS policy")
    if name not in allowed or name == "_deprecated":
        raise ValueError(f"{field_name}: {value!r} is not one of {allowed}")
    return name


def _duration_ns(field_name: str, value: Any) -> int:
    if isinstance(value, bool):
        raise ValueError(f"{field_name}: cannot interpret {value!r} as a duration")
    if isinstance(value, int):
        return value
    if hasattr(value, "nanoseconds"):  # rclpy.duration.Duration
        return int(value.nanoseconds)
    if isinstance(value, Mapping) and "sec" in value and "nsec" in value:
        return min(int(value["sec"]) * _NS_PER_S + int(value["nsec"]), INFINITE_NS)
    raise ValueError(f"{field_name}: cannot interpret {value!r} as a duration")


def _rmw_time(ns: int) -> dict[str, int]:
    sec, nsec = divmod(ns, _NS_PER_S)
    return {"sec": sec, "nsec": nsec}
