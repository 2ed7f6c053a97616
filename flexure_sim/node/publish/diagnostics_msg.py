"""
The diagnostics message of the stage node, and the stamp and value formats it shares.

`encode_diagnostics` packs a diagnostic_msgs/DiagnosticArray straight to CDR
(`cdr.pack_diagnostics`), `diagnostics_message` builds the same message as rclpy objects (the
reference); `value_text` is the one text form of parameter and diagnostics values.
"""
from __future__ import annotations

from typing import Any, Sequence

from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy.serialization import serialize_message

from flexure_sim.node.publish.cdr import pack_diagnostics, packing_applies, split_stamp


def stamp_msg(stamp_ns: int) -> Time:
    sec, nsec = split_stamp(stamp_ns)
    return Time(sec=sec, nanosec=nsec)


def encode_diagnostics(
    stamp_ns: int,
    name: str,
    hardware_id: str,
    level: int,
    message: str,
    values: Sequence[tuple[str, Any]],
) -> bytes:
    """
    CDR of `diagnostics_message` with the same arguments.

    Packed by `cdr.pack_diagnostics` (serialized by serialize_message where packing does not
    apply).
    """
    if not packing_applies("diagnostic_msgs/msg/DiagnosticArray"):
        return serialize_message(
            diagnostics_message(stamp_ns, name, hardware_id, level, message, values))
    sec, nsec = split_stamp(stamp_ns)
    return pack_diagnostics(sec, nsec, level, name, message, hardware_id,
                            [(k, value_text(v)) for k, v in values])


def diagnostics_message(
    stamp_ns: int,
    name: str,
    hardware_id: str,
    level: int,
    message: str,
    values: Sequence[tuple[str, Any]],
) -> DiagnosticArray:
    """
    One DiagnosticStatus in a DiagnosticArray.

    Values are formatted with str() (floats with repr precision). The reference for
    `encode_diagnostics`.
    """
    status = DiagnosticStatus()
    status.level = bytes([level])
    status.name = name
    status.message = message
    status.hardware_id = hardware_id
    status.values = [KeyValue(key=k, value=value_text(v)) for k, v in values]
    array = DiagnosticArray()
    array.header.stamp = stamp_msg(stamp_ns)
    array.status = [status]
    return array


def value_text(value: Any) -> str:
    """
    Return a parameter or diagnostics value as text, as ROS writes it on the command line.

    true/false, floats with repr precision, everything else with str().
    """
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return repr(value)
    return str(value)


OK = 0
WARN = 1
ERROR = 2
