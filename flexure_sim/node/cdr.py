"""Precompiled CDR packers for the few fixed-layout messages the stage node publishes.

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
"""
from __future__ import annotations

import struct
from collections.abc import Sequence

#: Encapsulation header of little-endian plain CDR (what rmw_fastrtps_cpp writes).
CDR_LE = b"\x00\x01\x00\x00"


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
    """A message made of a std_msgs/Header with a fixed frame_id, optional fixed strings and
    a fixed uint32 sequence count, then ``n_doubles`` float64 values.

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
    """Pad ``out`` (whose first 4 bytes are the encapsulation header, so alignment modulo 4
    is unchanged by it) to a multiple of 4 bytes with zeros."""
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
    """diagnostic_msgs/DiagnosticArray holding one DiagnosticStatus with ``values`` as its
    KeyValue pairs (strings). serialize_message needs ~300 us for the node's ~50 values, a
    third of a 1 kHz tick; this takes ~30 us. ``padding``, if given, receives the offsets
    of the padding bytes written (for comparison with serialize_message)."""
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
    for key, value in values:
        _put_string(out, key, padding)
        _put_string(out, value, padding)
    return bytes(out)


def split_stamp(stamp_ns: int) -> tuple[int, int]:
    """Nanoseconds -> (sec, nanosec) as in builtin_interfaces/Time (stamp_ns >= 0)."""
    return divmod(stamp_ns, 1_000_000_000)
