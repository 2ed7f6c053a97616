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


def split_stamp(stamp_ns: int) -> tuple[int, int]:
    """Nanoseconds -> (sec, nanosec) as in builtin_interfaces/Time (stamp_ns >= 0)."""
    return divmod(stamp_ns, 1_000_000_000)
