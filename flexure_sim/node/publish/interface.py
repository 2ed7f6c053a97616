"""
The stage node's ROS interface as data.

Topic table (names, types, units, frames, QoS) and the conversion of an engine ``Snapshot`` into
messages.

Two equivalent conversions exist: `StageInterface.messages` builds rclpy message objects
(the reference, readable), `StageInterface.encode` packs the same messages straight to CDR
bytes (what the node publishes and records; see `cdr`). Tests prove them identical. Where
the packed layouts do not apply (middleware other than Fast DDS, a type without a packer:
`cdr.packing_applies`), `encode` serializes the reference messages with serialize_message.

Conventions (docs/node.md):
- frames: root ``stage``; one frame per body, named after it; per hinge ``hinge_<name>``
  (its frame b, on body B) and ``hinge_<name>_a`` (its frame a, on body A), each with the
  node's ``frame_prefix`` in front (`topics.Frames`, the one place they are made). No leading
  slashes. Planar poses become 3D poses with z = 0 and a yaw-only quaternion (a mechanism in
  space: `spatial_messages.SpatialInterface`, the same table with 3-D content).
- all topic names are relative (namespaces and remapping apply), except ``/clock``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Optional

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseArray, PoseStamped, TransformStamped, WrenchStamped
from rclpy.serialization import serialize_message
from rosgraph_msgs.msg import Clock
from std_msgs.msg import Float64

from flexure_sim.engine.mechanism.parts import Mechanism
from flexure_sim.engine.mechanism.spatial_parts import Mechanism as SpatialMechanism
from flexure_sim import topics
from flexure_sim.topics import ROOT_FRAME, Frames, hinge_frame, hinge_frame_a
from flexure_sim.node.publish.diagnostics_msg import (  # noqa: F401 (re-exported)
    ERROR, OK, WARN, diagnostics_message, encode_diagnostics, stamp_msg, value_text,
)
from flexure_sim.node.publish.cdr import (
    ClockPacker, Float64Packer, StampedPacker, packing_applies, split_stamp,
)
from flexure_sim.node.inputs.drive_kind import command_kind, coordinate_unit, units
from flexure_sim.node.publish.qos_profiles import (  # noqa: F401 (re-exported)
    COMMAND_DEPTH, QUEUE_DEPTH, command_qos, stream_qos,
)
from flexure_sim.node.publish.reference_messages import (  # noqa: F401 (re-exported)
    reference_messages, yaw_quaternion,
)

TIME_MODES = ("realtime", "fast", "lockstep")
#: Modes in which the node publishes /clock (simulated time is not wall time).
CLOCK_MODES = ("fast", "lockstep")


def check_names(mechanism: Mechanism) -> None:
    """Raise ValueError if the mechanism's body and hinge names give clashing frame ids."""
    seen: dict[str, str] = {ROOT_FRAME: "the root frame"}
    frames = [(b.name, f"body {b.name!r}") for b in mechanism.bodies]
    for h in mechanism.hinges:
        frames.append((hinge_frame(h.name), f"frame b of hinge {h.name!r}"))
        frames.append((hinge_frame_a(h.name), f"frame a of hinge {h.name!r}"))
    for frame, owner in frames:
        if frame in seen:
            raise ValueError(
                f"mechanism {mechanism.name!r}: frame id {frame!r} of {owner} clashes with "
                f"{seen[frame]}; rename the body or hinge"
            )
        seen[frame] = owner


@dataclass(frozen=True)
class TopicSpec:
    """
    One topic.

    ``key`` (internal), relative ``name``, message class and ``pkg/msg/Type``, unit, frame id of
    its header (``""`` when unstamped) and what it carries.
    """

    key: str
    name: str
    msg_type: type
    type_name: str
    unit: str
    frame_id: str
    description: str


def _spec(
    key: str, name: str, msg_type: type, unit: str, frame_id: str, description: str
) -> TopicSpec:
    module = msg_type.__module__.split(".")[0]
    return TopicSpec(
        key, name, msg_type, f"{module}/msg/{msg_type.__name__}", unit, frame_id, description
    )


#: What a drive's command sets, by `drive_kind.command_kind`.
_COMMANDED = {"displacement": "actuator displacement", "force": "force",
              "voltage": "piezo actuator voltage"}


def _along(text: str, item: Any) -> str:
    """``text`` with the axis or coordinate of a drive or output."""
    if item.coordinate is not None:
        return f"{text}, coordinate {item.coordinate}"
    return f"{text} along ({', '.join(f'{a:g}' for a in item.axis)})"


class StageInterface:
    """
    Topic table of one mechanism in one time mode, and snapshot -> messages.

    ``tick_topics`` lists, in publishing order, the topics published every tick (``/clock``
    first in fast and lockstep modes); ``diagnostics`` is the diagnostics topic, ``commands``
    the drive command subscriptions, one per drive (``command``: the single drive's, None
    otherwise). A mechanism with one displacement drive has the topics ``drive/displacement``,
    ``drive/input``, ``drive/force``; with several drives (or a force drive) each drive has
    its own (``topics.drive_command`` ...). Likewise one output publishes
    ``output/displacement``, several one ``output/<name>/displacement`` each.
    """

    def __init__(self, mechanism: Mechanism, time_mode: str = "realtime",
                 frame_prefix: str = "") -> None:
        if time_mode not in TIME_MODES:
            raise ValueError(f"time_mode: expected one of {TIME_MODES}, got {time_mode!r}")
        check_names(mechanism)
        #: Frame ids of this node (prefixed).
        self.frames = fr = Frames(frame_prefix)
        self.mechanism = mechanism
        self.time_mode = time_mode
        self.publishes_clock = time_mode in CLOCK_MODES
        mech = mechanism
        bodies = [b.name for b in mech.bodies]
        hinges = [h.name for h in mech.hinges]
        self.body_names = bodies
        self.hinge_names = hinges
        # A planar mechanism's ``drive`` is its first drive; a spatial one has no such key.
        drive = mech.drives[0] if mech.drives else None
        self.has_drive = drive is not None and len(mech.drives) == 1 \
            and drive.kind == "displacement"
        #: The named drives (several, or a force drive): topics per drive; else empty.
        self.drives = () if self.has_drive else mech.drives
        outputs = mech.all_outputs
        self.has_output = len(outputs) == 1
        #: The named outputs when there are several: a topic each; else empty.
        self.outputs = outputs if len(outputs) > 1 else ()
        self.has_sensor = self.has_output and getattr(mech, "sensor", None) is not None
        self.compression_hinge: Optional[str] = (getattr(mech, "compression_hinge", None)
                                                 if self.has_drive else None)

        specs: list[TopicSpec] = []
        if self.publishes_clock:
            specs.append(
                _spec(
                    "clock",
                    topics.CLOCK,
                    Clock,
                    "s",
                    "",
                    "simulated time (fast and lockstep modes only)",
                )
            )
        specs.append(
            _spec(
                "poses",
                topics.POSE_ARRAY,
                PoseArray,
                "m, rad",
                fr.root,
                "pose of every body frame (at the mass centre) in the root frame, "
                f"in body order ({', '.join(bodies)})",
            )
        )
        for b in bodies:
            specs.append(
                _spec(
                    f"pose:{b}",
                    topics.body_pose(b),
                    PoseStamped,
                    "m, rad",
                    fr.root,
                    f"pose of body {b}'s frame (at its mass centre) in the root frame",
                )
            )
        for h in mech.hinges:
            specs.append(_spec(
                f"wrench:{h.name}", topics.hinge_wrench(h.name), WrenchStamped, "N, N m",
                fr.hinge_b(h.name),
                f"wrench hinge {h.name} exerts on its body B ({h.b.body}), in its frame b "
                f"({fr.hinge_b(h.name)}), torque about b's origin; the opposite acts on "
                f"body A ({h.a.body})"))
            specs.append(
                _spec(
                    f"deflection:{h.name}",
                    topics.hinge_deflection(h.name),
                    TransformStamped,
                    "m, rad",
                    fr.hinge_a(h.name),
                    f"deflection of hinge {h.name}: pose of frame b ({fr.hinge_b(h.name)}) in "
                    "frame a "
                    f"({fr.hinge_a(h.name)}); translation (p_x, p_y, 0), yaw alpha",
                )
            )
        #: The drives whose full wrench is published (every drive, a WrenchStamped each; none
        #: in 3-D: the spatial snapshot reports no drive wrench).
        self.wrench_drives = () if isinstance(mech, SpatialMechanism) else tuple(mech.drives)
        for d in self.wrench_drives:
            specs.append(_spec(
                f"drive_wrench:{d.name}",
                topics.DRIVE_WRENCH if self.has_drive else topics.drive_wrench(d.name),
                WrenchStamped, "N, N m", fr.body(d.body),
                f"full wrench drive {d.name} applies to its body {d.body} (the reaction of every "
                f"coordinate it holds and its applied force), in the body's frame "
                f"({fr.body(d.body)}), torque about its origin"))
        if self.compression_hinge is not None:
            c = self.compression_hinge
            specs.append(_spec(
                "compression", topics.hinge_compression(c), Float64, "m", "",
                f"compression of hinge {c}: displacement of its frame on body B minus that on "
                "body A, along the drive axis"))
        if self.has_output:
            specs.append(_spec(
                "output", topics.OUTPUT, Float64, coordinate_unit(outputs[0].coordinate), "",
                _along(f"displacement of the output body {outputs[0].body} from rest",
                       outputs[0])))
        if self.has_sensor:
            specs.append(_spec(
                "measured", topics.MEASURED, Float64, "m", "",
                "the output as the mechanism's sensor reads it (bandwidth, noise, resolution, "
                "latency in ticks; engine/actuators/sensor.py)"))
        for o in self.outputs:
            specs.append(_spec(
                f"output:{o.name}", topics.output_displacement(o.name), Float64,
                coordinate_unit(o.coordinate), "",
                _along(f"output {o.name}: displacement of body {o.body} from rest", o)))
        for d in self.drives:
            force = d.kind == "force"
            what = ("force applied (after validation and slew limiting)" if force else
                    "actuator output actually applied (after validation, slew limiting and "
                    "the actuator lag)")
            specs.append(_spec(
                f"drive_input:{d.name}", topics.drive_input(d.name), Float64,
                coordinate_unit(d.coordinate, force), "", _along(f"drive {d.name}: {what}", d)))
            if force:
                specs.append(_spec(
                    f"drive_position:{d.name}", topics.drive_position(d.name), Float64,
                    coordinate_unit(d.coordinate), "",
                    _along(f"drive {d.name}: displacement of body {d.body} from rest", d)))
            else:
                specs.append(_spec(
                    f"drive_force:{d.name}", topics.drive_force(d.name), Float64,
                    coordinate_unit(d.coordinate, True), "",
                    _along(f"drive {d.name}: force its actuator applies to body {d.body}", d)))
        if self.has_drive:
            specs.append(_spec(
                "drive_input", topics.DRIVE_INPUT, Float64, "m", "",
                "actuator output actually applied (after validation, slew limiting and the "
                "actuator lag), along the drive axis"))
            specs.append(
                _spec(
                    "drive_force",
                    topics.DRIVE_FORCE,
                    Float64,
                    "N",
                    "",
                    f"force the actuator applies to the driven body {drive.body} along the "
                    "drive axis",
                )
            )
        self.tick_topics: tuple[TopicSpec, ...] = tuple(specs)
        #: Indices in `tick_topics` of the control topics (published every tick whatever
        #: ``monitor_rate``): everything but poses, wrenches (hinges' and drives') and
        #: deflections.
        monitoring = ("poses", "pose", "wrench", "deflection", "drive_wrench")
        self.control_indices: tuple[int, ...] = tuple(
            i for i, spec in enumerate(specs) if spec.key.split(":")[0] not in monitoring)
        self.diagnostics = _spec("diagnostics", topics.DIAGNOSTICS, DiagnosticArray, "", "",
                                 "real-time factor, step times, solver work, command counters")
        self.command: Optional[TopicSpec] = None
        if self.has_drive and command_kind(drive) == "voltage":
            self.command = _spec("command", topics.COMMAND_VOLTAGE, Float64, "V", "",
                                 "drive command (subscribed): the piezo actuator's voltage")
        elif self.has_drive:
            self.command = _spec("command", topics.COMMAND, Float64, "m", "",
                                 "drive command (subscribed): target actuator displacement "
                                 "along the drive axis")
        self.commands: tuple[TopicSpec, ...] = (self.command,) if self.command else tuple(
            _spec(f"command:{d.name}", topics.drive_command(d.name, command_kind(d)), Float64,
                  units(d)[0], "",
                  _along(f"drive {d.name} command (subscribed): target " + _COMMANDED[
                      command_kind(d)], d))
            for d in self.drives)
        self._build_packers()
        #: True: `encode` packs (Fast DDS, every layout known); False: serialize_message.
        self.packed = all(packing_applies(spec.type_name) for spec in self.tick_topics)

    # ---------------------------------------------------------------- packing
    def _build_packers(self) -> None:
        nb = len(self.body_names)
        self._clock = ClockPacker()
        self._float = Float64Packer()
        fr = self.frames
        self._pose_array = StampedPacker(fr.root, 7 * nb, count=nb)
        self._poses = [StampedPacker(fr.root, 7) for _ in self.body_names]
        self._wrenches = [StampedPacker(fr.hinge_b(h), 6) for h in self.hinge_names]
        self._deflections = [
            StampedPacker(fr.hinge_a(h), 7, strings=(fr.hinge_b(h),)) for h in self.hinge_names
        ]
        self._drive_wrenches = [StampedPacker(fr.body(d.body), 6) for d in self.wrench_drives]

    def packers(self) -> list[Any]:
        """Return the packer of each tick topic, in `tick_topics` order (for the padding test)."""
        out: list[Any] = []
        if self.publishes_clock:
            out.append(self._clock)
        out.append(self._pose_array)
        out.extend(self._poses)
        for w, d in zip(self._wrenches, self._deflections):
            out.extend((w, d))
        out.extend(self._drive_wrenches)
        n_float = len(self.tick_topics) - len(out)
        out.extend([self._float] * n_float)
        return out

    def encode(self, snap: Any, stamp_ns: int, measured: float = 0.0,
               monitor: bool = True) -> list[bytes]:
        """
        CDR payloads of every tick topic, in `tick_topics` order, stamped ``stamp_ns``.

        ``measured`` is the sensor's reading of the tick (used if the mechanism has one).
        ``monitor`` False: only the control topics (those of `control_indices`, in order).
        """
        if not self.packed:
            messages = self.messages(snap, stamp_ns, measured)
            if not monitor:
                messages = [messages[i] for i in self.control_indices]
            return [serialize_message(m) for m in messages]
        sec, nsec = split_stamp(stamp_ns)
        out: list[bytes] = []
        if self.publishes_clock:
            out.append(self._clock.pack(sec, nsec))
        if monitor:
            self._encode_monitoring(snap, sec, nsec, out)
        f = self._float.pack
        out.extend([f(v) for v in self.scalars(snap, measured)])
        return out

    def scalars(self, snap: Any, measured: float = 0.0) -> list[float]:
        """Return the values of the Float64 tick topics (the last ones), `tick_topics` order."""
        out: list[float] = []
        if self.compression_hinge is not None:
            out.append(float(snap.compression))
        if self.has_output:
            out.append(float(snap.output))
        if self.has_sensor:
            out.append(float(measured))
        if self.outputs:
            out.extend(snap.outputs[o.name] for o in self.outputs)
        for k, d in enumerate(self.drives):
            out.append(float(snap.drive_inputs[k]))
            out.append(float(snap.drive_positions[k] if d.kind == "force"
                             else snap.drive_forces[k]))
        if self.has_drive:
            out.append(float(snap.drive_input))
            out.append(float(snap.drive_force))
        return out

    def _encode_monitoring(self, snap: Any, sec: int, nsec: int, out: list[bytes]) -> None:
        """Append the poses, wrenches and deflections of ``snap`` (packed) to ``out``."""
        flat: list[float] = []
        singles: list[bytes] = []
        sin, cos = math.sin, math.cos
        for packer, (x, y, th) in zip(self._poses, snap.poses.tolist()):
            h = 0.5 * th
            values = (x, y, 0.0, 0.0, 0.0, sin(h), cos(h))
            flat.extend(values)
            singles.append(packer.pack(sec, nsec, *values))
        out.append(self._pose_array.pack(sec, nsec, *flat))
        out.extend(singles)
        for wp, dp, (m, fx, fy), (a, px, py) in zip(
            self._wrenches, self._deflections, snap.wrenches.tolist(), snap.deflections.tolist()
        ):
            out.append(wp.pack(sec, nsec, fx, fy, 0.0, 0.0, 0.0, m))
            h = 0.5 * a
            out.append(dp.pack(sec, nsec, px, py, 0.0, 0.0, 0.0, sin(h), cos(h)))
        for wp, (m, fx, fy) in zip(self._drive_wrenches, snap.drive_wrenches.tolist()):
            out.append(wp.pack(sec, nsec, fx, fy, 0.0, 0.0, 0.0, m))

    # ------------------------------------------------------ reference messages
    def messages(self, snap: Any, stamp_ns: int, measured: float = 0.0) -> list[Any]:
        """Return the same messages as `encode`, as rclpy message objects (the reference)."""
        return reference_messages(self, snap, stamp_ns, measured)
