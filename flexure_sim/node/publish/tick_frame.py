"""
A tick's messages packed in one compiled call, into the recorder's batch frame.

`StageInterface.encode` packs a tick message by message from a ``Snapshot`` (one
``struct.pack`` each, sines and cosines of the half angles in Python: ~15 us for the stage's 26
messages, on top of the snapshot's ~50 us). Here the layout is resolved once: the batch frame
the recorder process reads (``record.process``: ``<stamp:u64>``, then per message
``<channel:u16><size:u32><cdr bytes>``) is a template with every constant byte in place (CDR
headers, frame ids, lengths, padding), and `fill_frame` (compiled) writes the stamps and the
float64 fields straight from the engine's tick report (``engine.solver.tick_report``). The
frame is recorded as it is, and each published payload is a slice of it: the bytes recorded
are the bytes published.

Two templates: every tick topic, and the control topics only (``monitor_rate``). The sources
of the float64 fields (`sources`) follow `StageInterface.encode`, which stays the reference
(``test/test_node_tick_frame.py`` proves the payloads byte-identical to it, and therefore to
``serialize_message``, for every kind of mechanism). Under a middleware whose wire format the
packers do not reproduce (`cdr.packing_applies`), the node uses ``encode`` instead.
"""
from __future__ import annotations

import math
import sys
from typing import Any, Sequence

import numpy as np

from flexure_sim.engine import jit as kernel_cache
from flexure_sim.engine.jit import njit
from flexure_sim.node.publish.cdr import split_stamp
from flexure_sim.node.record.process import FRAME_ITEM, FRAME_STAMP

#: Kinds of a float64 field's source: a report value, the sine / cosine of half a report value
#: (a yaw's quaternion), the sensor's reading, zero.
VALUE, SIN_HALF, COS_HALF, MEASURED, ZERO = 0, 1, 2, 3, 4
#: The compiled fill writes the host's byte order: little-endian hosts only (else `encode`).
APPLIES = sys.byteorder == "little"
#: Byte offset of the stamp (sec, nanosec) in a stamped payload, and of a Float64's value.
_STAMP_AT = 4
_FLOAT_AT = 4


def sources(interface: Any, index: dict[str, slice]) -> list[list[tuple[int, int]]]:
    """
    Per tick topic (`StageInterface.tick_topics` order), its float64 fields' (kind, source).

    ``index``: the tick report's layout (``TickReport.index``); a source is an entry of the
    report. The order of the fields is that of `StageInterface.encode`.
    """
    pose, defl, wrench = (index["poses"].start, index["deflections"].start,
                          index["wrenches"].start)
    bodies = {name: k for k, name in enumerate(interface.body_names)}
    hinges = {name: k for k, name in enumerate(interface.hinge_names)}
    outputs = {o.name: k for k, o in enumerate(interface.mechanism.all_outputs)}
    drives = {d.name: k for k, d in enumerate(interface.mechanism.drives)}

    def entry(part: str, k: int) -> tuple[int, int]:
        return VALUE, index[part].start + k

    def yaw_pose(b: int) -> list[tuple[int, int]]:
        p = pose + 3 * b
        return [(VALUE, p), (VALUE, p + 1), (ZERO, 0), (ZERO, 0), (ZERO, 0),
                (SIN_HALF, p + 2), (COS_HALF, p + 2)]

    out: list[list[tuple[int, int]]] = []
    for spec in interface.tick_topics:
        key, _, name = spec.key.partition(":")
        if key == "clock":
            fields: list[tuple[int, int]] = []
        elif key == "poses":
            fields = [f for b in range(len(bodies)) for f in yaw_pose(b)]
        elif key == "pose":
            fields = yaw_pose(bodies[name])
        elif key == "wrench":  # force (f_x, f_y, 0), torque (0, 0, moment)
            w = wrench + 3 * hinges[name]
            fields = [(VALUE, w + 1), (VALUE, w + 2), (ZERO, 0), (ZERO, 0), (ZERO, 0),
                      (VALUE, w)]
        elif key == "deflection":  # translation (p_x, p_y, 0), rotation about z by alpha
            d = defl + 3 * hinges[name]
            fields = [(VALUE, d + 1), (VALUE, d + 2), (ZERO, 0), (ZERO, 0), (ZERO, 0),
                      (SIN_HALF, d), (COS_HALF, d)]
        elif key == "drive_wrench":  # force (f_x, f_y, 0), torque (0, 0, moment)
            w = index["drive_wrenches"].start + 3 * drives[name]
            fields = [(VALUE, w + 1), (VALUE, w + 2), (ZERO, 0), (ZERO, 0), (ZERO, 0),
                      (VALUE, w)]
        elif key == "compression":
            fields = [entry("compression", 0)]
        elif key == "output":
            fields = [entry("outputs", outputs[name] if name else 0)]
        elif key == "measured":
            fields = [(MEASURED, 0)]
        elif key == "drive_input":
            fields = [entry("drive_inputs", drives[name] if name else 0)]
        elif key == "drive_force":
            fields = [entry("drive_forces", drives[name] if name else 0)]
        elif key == "drive_position":
            fields = [entry("drive_positions", drives[name])]
        else:
            raise ValueError(f"tick topic {spec.key!r}: no source in the tick report")
        out.append(fields)
    return out


class FrameLayout:
    """
    The template of one batch frame and where `fill_frame` writes.

    ``spans``: each message's payload (start, end) in the frame, in publishing order;
    ``channels``: their recording channels.
    """

    def __init__(self, payloads: Sequence[bytes], fields: Sequence[Sequence[tuple[int, int]]],
                 stamped: Sequence[bool], channels: Sequence[int]) -> None:
        parts = [FRAME_STAMP.pack(0)]
        at = FRAME_STAMP.size
        offsets, kinds, src, stamps, spans = [], [], [], [], []
        for payload, field, has_stamp, channel in zip(payloads, fields, stamped, channels):
            parts.append(FRAME_ITEM.pack(channel, len(payload)))
            at += FRAME_ITEM.size
            first = at + len(payload) - 8 * len(field) if field else at
            for j, (kind, source) in enumerate(field):
                offsets.append(first + 8 * j)
                kinds.append(kind)
                src.append(source)
            if has_stamp:
                stamps.append(at + _STAMP_AT)
            spans.append((at, at + len(payload)))
            parts.append(payload)
            at += len(payload)
        self.template = np.frombuffer(b"".join(parts), dtype=np.uint8).copy()
        self.offsets = np.array(offsets, dtype=np.int64)
        self.kinds = np.array(kinds, dtype=np.int64)
        self.sources = np.array(src, dtype=np.int64)
        self.stamps = np.array(stamps, dtype=np.int64)
        self.spans = spans
        self.channels = list(channels)
        self.buffer = self.template.copy()


class TickFrame:
    """
    The stage's tick messages for one interface and tick report layout (module docstring).

    `pack` returns the frame (bytes) and the layout whose ``spans`` slice the payloads out.
    """

    def __init__(self, interface: Any, index: dict[str, slice]) -> None:
        self.interface = interface
        fields = sources(interface, index)
        packers = interface.packers()
        payloads, stamped = [], []
        for spec, packer, field in zip(interface.tick_topics, packers, fields):
            if spec.key == "clock":
                payloads.append(packer.pack(0, 0))
                stamped.append(True)
            elif spec.type_name == "std_msgs/msg/Float64":
                payloads.append(packer.pack(0.0))
                stamped.append(False)
            else:
                payloads.append(packer.pack(0, 0, *([0.0] * len(field))))
                stamped.append(True)
        control = interface.control_indices
        self.full = FrameLayout(payloads, fields, stamped, range(len(payloads)))
        self.control = FrameLayout([payloads[i] for i in control], [fields[i] for i in control],
                                   [stamped[i] for i in control], control)

    def pack(self, values: np.ndarray, measured: float, stamp_ns: int,
             monitor: bool = True) -> tuple[bytes, FrameLayout]:
        """
        Return the batch frame body of a tick and its layout.

        ``values``: the tick report; ``measured``: the sensor's reading; ``monitor`` False: the
        control topics only.
        """
        layout = self.full if monitor else self.control
        sec, nsec = split_stamp(stamp_ns)
        buffer = layout.buffer
        fill_frame(buffer, layout.offsets, layout.kinds, layout.sources, values, measured,
                   layout.stamps, stamp_ns, sec, nsec)
        return buffer.tobytes(), layout


@njit(cache=True)
def fill_frame(buffer, offsets, kinds, sources, values, measured, stamps, stamp_ns, sec, nsec):
    """
    Write a tick into a frame template (`FrameLayout`).

    The frame's stamp, each stamped message's (sec, nanosec) and every float64 field, in the
    host's (little-endian) byte order, each at its byte offset.
    """
    word = np.empty(1, dtype=np.uint64)
    word_bytes = word.view(np.uint8)
    word[0] = stamp_ns
    for b in range(8):
        buffer[b] = word_bytes[b]
    times = np.empty(2, dtype=np.uint32)
    times[0] = np.uint32(sec)
    times[1] = np.uint32(nsec)
    time_bytes = times.view(np.uint8)
    for i in range(stamps.shape[0]):
        at = stamps[i]
        for b in range(8):
            buffer[at + b] = time_bytes[b]
    field = np.empty(1, dtype=np.float64)
    field_bytes = field.view(np.uint8)
    for j in range(offsets.shape[0]):
        kind = kinds[j]
        if kind == VALUE:
            x = values[sources[j]]
        elif kind == SIN_HALF:
            x = math.sin(0.5 * values[sources[j]])
        elif kind == COS_HALF:
            x = math.cos(0.5 * values[sources[j]])
        elif kind == MEASURED:
            x = measured
        else:
            x = 0.0
        field[0] = x
        at = offsets[j]
        for b in range(8):
            buffer[at + b] = field_bytes[b]


kernel_cache.revalidate(kernel_cache.dispatchers_of(globals()), __file__)
