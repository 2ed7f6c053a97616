"""
Precompiled CDR packers for the few fixed-layout messages the stage node publishes.

``rclpy.serialization.serialize_message`` costs ~6 us per message plus ~6 us to build the
Python message; the node publishes ~26 messages per tick at up to 10 kHz, so it packs the
bytes itself with one ``struct.Struct.pack`` per message (~0.3 us). The layouts are
plain (XCDR1) little-endian CDR as rmw_fastrtps writes them: a 4-byte encapsulation header
``00 01 00 00`` (CDR_LE), then the fields, each aligned to its size relative to the end of
the header; strings are a uint32 length (including the terminating NUL), the bytes and the
NUL; sequences a uint32 count and the elements.

The packers write zeros into alignment padding, where serialize_message leaves whatever was
in its buffer; ``test/test_node_interface.py`` proves the output byte-identical to
serialize_message everywhere else (and equal after deserialization) for every message type
the node publishes.

The packed layouts are used only where they are known to be what the middleware expects:
`packing_applies` is true for the types in `PACKED_TYPES` under Fast DDS (rmw_fastrtps_*);
otherwise the node serializes with ``rclpy.serialization.serialize_message``.

`parse_float64` reads the drive commands. The encapsulation identifier (first two bytes,
DDS-XTypes 1.3, 7.6.3.1.2) names the encoding: plain CDR (``00 00`` big-, ``00 01``
little-endian) is read here (Fast DDS only); plain XCDR2 (``00 06``/``00 07``) and anything
under another middleware go to ``rclpy.serialization.deserialize_message``; delimited XCDR2
(``00 08``/``00 09``, an appendable type) is its 4-byte DHEADER followed by the plain XCDR2
members, handed to rclpy as plain XCDR2. Parameter-list encodings (mutable types) and
everything else are refused with ValueError, never turned into a number.
"""
from __future__ import annotations

import functools
import os
import struct
from collections.abc import Sequence

#: Encapsulation header of little-endian plain CDR (what rmw_fastrtps_cpp writes).
CDR_LE = b"\x00\x01\x00\x00"
#: Middlewares whose wire format the packers reproduce.
FAST_DDS = ("rmw_fastrtps_cpp", "rmw_fastrtps_dynamic_cpp")
#: Message types with a packer here (their layout is known).
PACKED_TYPES = frozenset({
    "rosgraph_msgs/msg/Clock", "std_msgs/msg/Float64", "geometry_msgs/msg/PoseStamped",
    "geometry_msgs/msg/PoseArray", "geometry_msgs/msg/WrenchStamped",
    "geometry_msgs/msg/TransformStamped", "diagnostic_msgs/msg/DiagnosticArray",
})
#: Encapsulation identifiers (DDS-XTypes 1.3, Table 60): name, byte order of the body.
ENCAPSULATIONS = {
    0x0000: ("CDR_BE", ">"), 0x0001: ("CDR_LE", "<"),
    0x0002: ("PL_CDR_BE", ">"), 0x0003: ("PL_CDR_LE", "<"),
    0x0006: ("CDR2_BE", ">"), 0x0007: ("CDR2_LE", "<"),
    0x0008: ("D_CDR2_BE", ">"), 0x0009: ("D_CDR2_LE", "<"),
    0x000A: ("PL_CDR2_BE", ">"), 0x000B: ("PL_CDR2_LE", "<"),
}


@functools.lru_cache(maxsize=1)
def middleware() -> str:
    """Return the rmw implementation rclpy loaded (``RMW_IMPLEMENTATION`` if rclpy cannot say)."""
    try:
        import rclpy
        return rclpy.get_rmw_implementation_identifier()
    except Exception:  # noqa: BLE001 - no rclpy or no rmw: the environment is all we know
        return os.environ.get("RMW_IMPLEMENTATION") or "rmw_fastrtps_cpp"


def packing_applies(type_name: str, rmw: str | None = None) -> bool:
    """Return True if the node may publish ``type_name`` packed here rather than serialize it."""
    return (rmw or middleware()) in FAST_DDS and type_name in PACKED_TYPES


class _Layout:
    """Builds a struct format for a fixed CDR layout and remembers the padding offsets."""

    def __init__(self) -> None:
        self.fmt = ["<4s"]
        self.offset = 0  # relative to the end of the encapsulation header
        self.constants: list[object] = []
        self.padding: list[int] = []  # absolute offsets (header included) of padding bytes

    def align(self, size: int) -> None:
        pad = (-self.offset) % size
        if pad:
            self.fmt.append(f"{pad}x")
            self.padding.extend(4 + self.offset + i for i in range(pad))
            self.offset += pad

    def time(self) -> None:
        """builtin_interfaces/Time: int32 sec, uint32 nanosec (variable)."""
        self.align(4)
        self.fmt.append("iI")
        self.offset += 8

    def const_string(self, text: str) -> None:
        data = text.encode("utf-8") + b"\x00"
        self.align(4)
        self.fmt.append(f"I{len(data)}s")
        self.constants.extend((len(data), data))
        self.offset += 4 + len(data)

    def const_uint32(self, value: int) -> None:
        self.align(4)
        self.fmt.append("I")
        self.constants.append(value)
        self.offset += 4

    def float64(self, count: int) -> None:
        if count:
            self.align(8)
            self.fmt.append(f"{count}d")
            self.offset += 8 * count

    def struct(self) -> struct.Struct:
        return struct.Struct("".join(self.fmt))


class StampedPacker:
    """
    A message made of a std_msgs/Header with a fixed frame_id.

    Optional fixed strings and a fixed uint32 sequence count, then ``n_doubles`` float64 values.

    Covers PoseStamped, WrenchStamped, TransformStamped (child_frame_id as extra string) and
    PoseArray (pose count as ``count``). ``pack(sec, nanosec, *doubles)``.
    """

    def __init__(
        self,
        frame_id: str,
        n_doubles: int,
        *,
        strings: Sequence[str] = (),
        count: int | None = None,
    ) -> None:
        layout = _Layout()
        layout.time()
        layout.const_string(frame_id)
        for text in strings:
            layout.const_string(text)
        if count is not None:
            layout.const_uint32(count)
        layout.float64(n_doubles)
        self._struct = layout.struct()
        self._constants = tuple(layout.constants)
        self.n_doubles = n_doubles
        self.size = self._struct.size
        self.padding = tuple(layout.padding)

    def pack(self, sec: int, nanosec: int, *doubles: float) -> bytes:
        return self._struct.pack(CDR_LE, sec, nanosec, *self._constants, *doubles)


class Float64Packer:
    """std_msgs/Float64: ``pack(value)``."""

    def __init__(self) -> None:
        layout = _Layout()
        layout.float64(1)
        self._pack = layout.struct().pack
        self.size = 12
        self.padding: tuple[int, ...] = tuple(layout.padding)

    def pack(self, value: float) -> bytes:
        return self._pack(CDR_LE, value)


class ClockPacker:
    """rosgraph_msgs/Clock: ``pack(sec, nanosec)``."""

    def __init__(self) -> None:
        layout = _Layout()
        layout.time()
        self._pack = layout.struct().pack
        self.size = 12
        self.padding: tuple[int, ...] = tuple(layout.padding)

    def pack(self, sec: int, nanosec: int) -> bytes:
        return self._pack(CDR_LE, sec, nanosec)


_U32 = struct.Struct("<I")
_TIME = struct.Struct("<iI")


def _align4(out: bytearray, padding: list[int] | None) -> None:
    """
    Pad ``out`` to a multiple of 4 bytes with zeros.

    The first 4 bytes of ``out`` are the encapsulation header, so alignment modulo 4 is
    unchanged by it.
    """
    pad = (-len(out)) % 4
    if pad:
        if padding is not None:
            padding.extend(range(len(out), len(out) + pad))
        out += bytes(pad)


def _put_string(out: bytearray, text: str, padding: list[int] | None) -> None:
    """Append a CDR string: aligned uint32 length (NUL included), the bytes, the NUL."""
    _align4(out, padding)
    data = text.encode("utf-8")
    out += _U32.pack(len(data) + 1)
    out += data
    out += b"\x00"


def pack_diagnostics(
    sec: int,
    nanosec: int,
    level: int,
    name: str,
    message: str,
    hardware_id: str,
    values: Sequence[tuple[str, str]],
    *,
    frame_id: str = "",
    padding: list[int] | None = None,
) -> bytes:
    """
    Serialize a diagnostic_msgs/DiagnosticArray holding one DiagnosticStatus.

    ``values`` are its KeyValue pairs (strings). serialize_message needs ~300 us for the node's
    ~50 values, a third of a 1 kHz tick; this takes ~30 us. ``padding``, if given, receives the
    offsets of the padding bytes written (for comparison with serialize_message).
    """
    out = bytearray(CDR_LE)
    out += _TIME.pack(sec, nanosec)
    _put_string(out, frame_id, padding)
    _align4(out, padding)
    out += _U32.pack(1)  # status: one element
    out.append(level)  # byte
    _put_string(out, name, padding)
    _put_string(out, message, padding)
    _put_string(out, hardware_id, padding)
    _align4(out, padding)
    out += _U32.pack(len(values))
    if padding is None and values:
        out += _key_values(values)
        return bytes(out)
    for key, value in values:
        _put_string(out, key, padding)
        _put_string(out, value, padding)
    return bytes(out)


#: Zero padding after a CDR string of length n + 1 (NUL included), indexed by n % 4.
_PAD_AFTER = (b"\x00" * 4, b"\x00" * 3, b"\x00" * 2, b"\x00")


def _key_values(values: Sequence[tuple[str, str]]) -> bytes:
    """
    Pack the KeyValue strings of `pack_diagnostics` from a 4-aligned offset, in one join.

    Each string is its uint32 length, its bytes, a NUL, and the zeros that align the next
    (none after the last): the bytes `_put_string` writes one call at a time. Built as one list
    and joined, a status of 62 values packs in 19 us against 33 us (one process, 2-core VM):
    the diagnostics go out on the stepping thread, in the slack between two ticks.
    """
    parts = []
    append = parts.append
    u32 = _U32.pack
    pad = _PAD_AFTER
    for pair in values:
        for text in pair:
            data = text.encode("utf-8")
            n = len(data)
            append(u32(n + 1))
            append(data)
            append(pad[n % 4])
    parts[-1] = b"\x00"  # the last string: its NUL, nothing to align
    return b"".join(parts)


def split_stamp(stamp_ns: int) -> tuple[int, int]:
    """Nanoseconds -> (sec, nanosec) as in builtin_interfaces/Time (stamp_ns >= 0)."""
    return divmod(stamp_ns, 1_000_000_000)


_DOUBLE = {"<": struct.Struct("<d"), ">": struct.Struct(">d")}
_UINT32 = {"<": struct.Struct("<I"), ">": struct.Struct(">I")}


def parse_float64(data: bytes, rmw: str | None = None) -> float:
    """
    Return the value of a serialized ``std_msgs/msg/Float64``.

    Any encoding named in the module docstring is read. Raises ValueError naming the problem
    (unknown or unsupported encapsulation, too short, not a Float64).
    """
    if len(data) < 4:
        raise ValueError(f"{len(data)} bytes: too short for a serialized Float64")
    kind = int.from_bytes(data[:2], "big")
    name, order = ENCAPSULATIONS.get(kind, ("", "<"))
    if not name:
        raise ValueError(f"unknown CDR encapsulation {bytes(data[:2]).hex(' ')}")
    if (rmw or middleware()) not in FAST_DDS:
        return _deserialize(data, name)
    if name in ("CDR_BE", "CDR_LE"):
        if len(data) < 12:
            raise ValueError(f"{name}: a Float64 needs 12 bytes, got {len(data)}")
        return _DOUBLE[order].unpack_from(data, 4)[0]
    if name in ("CDR2_BE", "CDR2_LE"):
        return _deserialize(data, name)
    if name in ("D_CDR2_BE", "D_CDR2_LE"):
        if len(data) < 8:
            raise ValueError(f"{name}: {len(data)} bytes, too short for a DHEADER")
        (size,) = _UINT32[order].unpack_from(data, 4)
        if not 0 <= len(data) - 8 - size < 4:  # the members, then at most end padding
            raise ValueError(f"{name}: DHEADER says {size} bytes, {len(data) - 8} follow")
        plain = (0x0006 if order == ">" else 0x0007).to_bytes(2, "big") + bytes(data[2:4])
        return _deserialize(plain + bytes(data[8:8 + size]), name)
    raise ValueError(f"{name}: parameter-list encoding (mutable types) not supported")


def _deserialize(data: bytes, name: str) -> float:
    """Deserialise a Float64 by rclpy (the middleware's own type support)."""
    from rclpy.serialization import deserialize_message
    from std_msgs.msg import Float64
    try:
        return float(deserialize_message(bytes(data), Float64).data)
    except Exception as exc:  # noqa: BLE001 - rclpy raises RMWError or others on bad bytes
        raise ValueError(f"{name}: not a Float64 ({type(exc).__name__})") from None


#: Type of the recording channel of the command payloads the node rejected as malformed.
REJECTED_TYPE = "std_msgs/msg/UInt8MultiArray"
_UINT8_ARRAY_HEAD = struct.Struct("<4sIII")


def pack_uint8_array(data: bytes) -> bytes:
    """
    Return a std_msgs/UInt8MultiArray (empty layout) whose ``data`` is ``data``, as CDR_LE.

    The layout's ``dim`` sequence (count 0) and ``data_offset`` (0), then the byte sequence:
    how the node records a command payload it could not read, so that every ROS reader decodes
    the channel and finds the received bytes verbatim in ``data``.
    """
    return _UINT8_ARRAY_HEAD.pack(CDR_LE, 0, 0, len(data)) + data
