"""
The stage's ``visualization_msgs/MarkerArray`` packed straight to CDR.

From the plain `markers.MarkerSpec` data of one display tick (see `cdr` for the encoding).

Building the rclpy messages costs ~1 ms and serialize_message another ~0.5 ms for the
microstage's 14 markers: one and a half publish periods at 1 kHz, on the stepping thread.
A scene's layout is fixed (same markers, same number of points per outline, same strings),
so the whole array is one ``struct.Struct`` computed once; per display tick only the stamp,
poses, scales, colours and points are filled in (~0.1 ms in all, measured in
test/test_node_markers.py). ``test/test_node_markers.py`` proves the bytes identical to
serialize_message of `markers.MarkerScene.message` outside the alignment padding.

Marker.msg (Jazzy), in order: header, ns, id, type, action, pose, scale, color, lifetime,
frame_locked, points[], colors[], texture_resource, texture (sensor_msgs/CompressedImage:
header, format, data[]), uv_coordinates[], text, mesh_resource, mesh_file (filename,
data[]), mesh_use_embedded_materials.
"""
from __future__ import annotations

import struct
from typing import Sequence

from flexure_sim.node.publish.cdr import CDR_LE, split_stamp
from flexure_sim.node.publish.markers import MarkerSpec

#: Marker.ADD
_ADD = 0


class _Builder:
    """
    A CDR layout as struct codes, with a slot (constant value or None = variable) per value.

    Offsets are relative to the end of the encapsulation header.
    """

    def __init__(self) -> None:
        self.fmt = ["<4s"]
        self.slots: list[object] = [CDR_LE]
        self.offset = 0
        self.padding: list[int] = []

    def _align(self, size: int) -> None:
        pad = (-self.offset) % size
        if pad:
            self.fmt.append(f"{pad}x")
            self.padding.extend(4 + self.offset + i for i in range(pad))
            self.offset += pad

    def put(self, code: str, size: int, values: Sequence[object]) -> None:
        """``len(values)`` fields of one struct ``code`` (None: filled in per pack)."""
        if not values:
            return
        self._align(size)
        self.fmt.append(f"{len(values)}{code}")
        self.slots.extend(values)
        self.offset += size * len(values)

    def string(self, text: str) -> None:
        data = text.encode("utf-8") + b"\x00"
        self._align(4)
        self.fmt.append(f"I{len(data)}s")
        self.slots.extend((len(data), data))
        self.offset += 4 + len(data)

    def empty_sequence(self) -> None:
        self.put("I", 4, [0])


def _shape(specs: Sequence[MarkerSpec]) -> tuple:
    """Return what fixes the layout: every constant field of every marker."""
    return tuple((s.ns, s.id, s.type, s.text, len(s.points)) for s in specs)


class MarkerArrayPacker:
    """Packs the MarkerArray of a scene whose markers have frame ``frame_id``."""

    def __init__(self, frame_id: str) -> None:
        self.frame_id = frame_id
        self._shape: tuple = ()
        self._struct = struct.Struct("<4s")
        self._template: list[object] = []
        self._variable: list[int] = []
        #: Absolute offsets of the alignment padding bytes (for the comparison test).
        self.padding: tuple[int, ...] = ()

    def _build(self, specs: Sequence[MarkerSpec]) -> None:
        b = _Builder()
        b.put("I", 4, [len(specs)])
        for s in specs:
            b.put("i", 4, [None])  # stamp sec
            b.put("I", 4, [None])  # stamp nanosec
            b.string(self.frame_id)
            b.string(s.ns)
            b.put("i", 4, [s.id, s.type, _ADD])
            b.put("d", 8, [None] * 10)  # pose (7), scale (3)
            b.put("f", 4, [None] * 4)  # color
            b.put("i", 4, [0])  # lifetime sec
            b.put("I", 4, [0])  # lifetime nanosec
            b.put("?", 1, [False])  # frame_locked
            b.put("I", 4, [len(s.points)])
            b.put("d", 8, [None] * (3 * len(s.points)))
            b.empty_sequence()  # colors
            b.string("")  # texture_resource
            b.put("i", 4, [0])  # texture.header.stamp
            b.put("I", 4, [0])
            b.string("")  # texture.header.frame_id
            b.string("")  # texture.format
            b.empty_sequence()  # texture.data
            b.empty_sequence()  # uv_coordinates
            b.string(s.text)
            b.string("")  # mesh_resource
            b.string("")  # mesh_file.filename
            b.empty_sequence()  # mesh_file.data
            b.put("?", 1, [False])  # mesh_use_embedded_materials
        self._struct = struct.Struct("".join(b.fmt))
        self._template = b.slots
        self._variable = [i for i, v in enumerate(b.slots) if v is None]
        self.padding = tuple(b.padding)
        self._shape = _shape(specs)

    def pack(self, specs: Sequence[MarkerSpec], stamp_ns: int) -> bytes:
        """CDR bytes of the MarkerArray of ``specs`` stamped ``stamp_ns``."""
        if _shape(specs) != self._shape:
            self._build(specs)
        sec, nsec = split_stamp(stamp_ns)
        values: list[float] = []
        for s in specs:
            values.append(sec)
            values.append(nsec)
            values.extend(s.pose)
            values.extend(s.scale)
            values.extend(s.rgba)
            for point in s.points:
                values.extend(point)
        args = list(self._template)
        for index, value in zip(self._variable, values):
            args[index] = value
        return self._struct.pack(*args)
