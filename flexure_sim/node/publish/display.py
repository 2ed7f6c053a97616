"""
What the stage node publishes for viewers (RViz, Foxglove) at its display rate.

The markers (`markers`, packed by `marker_cdr`) and, where ``tf2_msgs`` is importable, TF.

Display ticks are counted in simulated time: every round(publish_rate / display_rate)
publish ticks (at least every tick), so a recording holds the same markers in every time
mode and a ``use_sim_time`` viewer sees display_rate in its own time. In real-time mode that
is display_rate of wall time too; in fast mode it is display_rate times the real-time factor.

Hinge colours: the stress ratio sigma / sigma_y (the engine's tick report, as the
diagnostics'; green 0, red 1 = yield) when the mechanism file gives a yield strength
``sigma_y`` to some hinge (hinges without one are drawn at 0); otherwise |wrench| relative
to its peak so far (`markers.MarkerScene`).

TF tree (REP-105 style, all frames with the node's frame prefix): ``stage`` -> each body
frame (on ``/tf`` at the display rate for moving bodies; on ``/tf_static`` for bodies held
by a ``fixed`` constraint), and each body frame -> the hinge frames on it (``hinge_<h>_a``
on body A, ``hinge_<h>`` on body B, at their position and angle in the body frame): fixed
to their body, so static. Hinge deflections stay on their topics; TF follows the bodies.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Any, Iterator, Optional

import numpy as np
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from flexure_sim import topics
from flexure_sim.engine.mechanism.parts import Fixed, Mechanism
from flexure_sim.engine.hinges.stress import ratio_map
from flexure_sim.topics import Frames
from flexure_sim.node.publish.marker_cdr import MarkerArrayPacker
from flexure_sim.node.publish.markers import MarkerScene


def tf_qos() -> QoSProfile:
    """Return the QoS of /tf as tf2's TransformBroadcaster offers it: reliable, depth 100."""
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=100,
                      reliability=ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.VOLATILE)


def tf_static_qos() -> QoSProfile:
    """
    Return the QoS of /tf_static as tf2's StaticTransformBroadcaster offers it.

    Reliable, keep last 1, transient local (late subscribers get the static transforms).
    """
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1,
                      reliability=ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.TRANSIENT_LOCAL)


class _Named:
    """Name and ``pkg/msg/Type`` of a topic whose type may not be importable (TF)."""

    def __init__(self, name: str, type_name: str) -> None:
        self.name, self.type_name = name, type_name


#: Display topics (publish/display.py): markers at the display rate; TF where tf2_msgs exists.
MARKERS = _Named(topics.MARKERS, "visualization_msgs/msg/MarkerArray")
TF = _Named(topics.TF, "tf2_msgs/msg/TFMessage")
TF_STATIC = _Named(topics.TF_STATIC, "tf2_msgs/msg/TFMessage")


def display_every(publish_rate: float, display_rate: float) -> int:
    """Publish ticks per display tick; 0 when the display is off (display_rate 0)."""
    if display_rate <= 0:
        return 0
    return max(1, round(publish_rate / display_rate))


@dataclass(frozen=True)
class Transform:
    """
    One TF transform as data.

    ``child`` in ``parent``, translation (x, y, z) in m and rotation (x, y, z, w) (a yaw-only
    quaternion: the stage is planar).
    """

    parent: str
    child: str
    translation: tuple[float, float, float]
    rotation: tuple[float, float, float, float]


def _planar(parent: str, child: str, x: float, y: float, yaw: float) -> Transform:
    h = 0.5 * yaw
    return Transform(parent, child, (x, y, 0.0), (0.0, 0.0, math.sin(h), math.cos(h)))


def fixed_bodies(mechanism: Mechanism) -> set[str]:
    """Bodies held at their initial pose by a ``fixed`` constraint."""
    return {c.body for c in mechanism.constraints if isinstance(c, Fixed)}


def static_transforms(mechanism: Mechanism, frames: Frames) -> list[Transform]:
    """
    Return the transforms that never change.

    Root -> fixed bodies (at their initial pose), and body -> each hinge frame on it (its position
    and angle in the body frame).
    """
    out = [_planar(frames.root, frames.body(b.name), *b.pose)
           for b in mechanism.bodies if b.name in fixed_bodies(mechanism)]
    for h in mechanism.hinges:
        out.append(_planar(frames.body(h.a.body), frames.hinge_a(h.name), *h.a.position,
                           h.a.angle))
        out.append(_planar(frames.body(h.b.body), frames.hinge_b(h.name), *h.b.position,
                           h.b.angle))
    return out


def moving_transforms(mechanism: Mechanism, frames: Frames, poses: np.ndarray) -> list[Transform]:
    """Return root -> each body that is not fixed, at its pose (x, y, theta) in ``poses``."""
    held = fixed_bodies(mechanism)
    return [_planar(frames.root, frames.body(b.name), float(x), float(y), float(th))
            for b, (x, y, th) in zip(mechanism.bodies, np.asarray(poses, dtype=float))
            if b.name not in held]


def tf_message_class() -> tuple[Optional[type], str]:
    """``tf2_msgs.msg.TFMessage`` and "", or None and why TF is off."""
    try:
        from tf2_msgs.msg import TFMessage
    except ImportError as exc:
        return None, (f"tf2_msgs is not importable ({exc}); it comes with ROS 2 "
                      "(ros-jazzy-tf2-msgs), not from PyPI")
    return TFMessage, ""


def tf_message(transforms: list[Transform], stamp_ns: int, message_class: type) -> Any:
    """Return a TFMessage of ``transforms`` stamped ``stamp_ns``."""
    from geometry_msgs.msg import TransformStamped

    sec, nsec = divmod(stamp_ns, 1_000_000_000)
    out = []
    for t in transforms:
        m = TransformStamped()
        m.header.stamp.sec, m.header.stamp.nanosec = sec, nsec
        m.header.frame_id, m.child_frame_id = t.parent, t.child
        v, q = m.transform.translation, m.transform.rotation
        v.x, v.y, v.z = t.translation
        q.x, q.y, q.z, q.w = t.rotation
        out.append(m)
    return message_class(transforms=out)


class Display:
    """Markers (and TF transforms) of one tick, as the stepping thread needs them."""

    def __init__(self, mechanism: Mechanism, frames: Frames, display_scale: float) -> None:
        self.mechanism = mechanism
        self.frames = frames
        self.scene = MarkerScene(mechanism, frames.prefix, display_scale)
        self.packer = MarkerArrayPacker(frames.root)
        stress = ratio_map(mechanism)
        #: The hinges' stress ratio map, None when no hinge has a yield strength.
        self.stress = stress if stress[0] else None
        #: "stress ratio" or "|wrench| / peak": what the hinge colours show.
        self.colouring = "stress ratio" if self.stress is not None else "|wrench| / peak"

    def geometry(self, report: Any) -> dict:
        """
        Return the drawn geometry of a tick (``MarkerScene.geometry``: arrays of its own).

        ``report``: the engine's tick report (``tick_report.ReportView``: poses, wrenches, the
        drive's force and the stress ratios, NaN where a hinge has no yield strength).
        """
        ratios = (np.nan_to_num(report.stress_ratios, nan=0.0)
                  if self.stress is not None else None)
        return self.scene.geometry(report.poses, report.wrenches, float(report.drive_force),
                                   ratios)

    def specs(self, report: Any, geometry: Optional[dict] = None) -> list:
        """Return the markers of a tick as plain data (``MarkerSpec``; `packer` packs them)."""
        return self.scene.specs_of(geometry if geometry is not None else self.geometry(report))

    def markers(self, report: Any, stamp_ns: int) -> bytes:
        """CDR bytes of the MarkerArray of the tick report ``report`` (`specs`)."""
        return self.packer.pack(self.specs(report), stamp_ns)

    def moving(self, report: Any) -> list[Transform]:
        """Return the transforms of the moving bodies at the tick report ``report``."""
        return moving_transforms(self.mechanism, self.frames, report.poses)

    def static(self) -> list[Transform]:
        """Return the transforms that never change (`static_transforms`)."""
        return static_transforms(self.mechanism, self.frames)


class DisplayOutput:
    """
    Publishes and records one display tick (stepping thread).

    The markers, and the moving TF transforms when ``tf_publisher`` is given. ``channels`` =
    recording channel of the markers and, with TF, of /tf and /tf_static (the static transforms are
    written once into each recording, as rosbag2 records a latched /tf_static).
    """

    def __init__(self, display: Display, publisher: Any, session: Any, channels: list[int],
                 tf_publisher: Any = None, tf_class: Optional[type] = None) -> None:
        self.display = display
        self._pub = publisher
        self._session = session
        self._channels = channels
        self._tf_pub = tf_publisher
        self._tf_class = tf_class
        self._recorded_static: Any = None
        self.ticks = 0
        self.time_sum = 0.0
        self.time_max = 0.0

    def publish(self, report: Any, stamp: int) -> None:
        """Publish (and record) the display of the tick report ``report`` (a ``ReportView``)."""
        for _ in self.stages(report, stamp):
            pass

    def stages(self, report: Any, stamp: int) -> Iterator[None]:
        """
        `publish` in stages, yielding between them (the paced loop's slack, `tick_extras`).

        The markers' geometry (and the TF transforms), their data, their packing, the recording,
        the publishing. ``report`` must not change until the first stage has run.
        """
        perf = time.perf_counter
        t0 = perf()
        d = self.display
        geometry = d.geometry(report)
        moving = d.moving(report) if self._tf_pub is not None else None
        spent = perf() - t0
        yield
        t0 = perf()
        specs = d.specs(report, geometry)
        spent += perf() - t0
        yield
        t0 = perf()
        payload = d.packer.pack(specs, stamp)
        tf = tf_message(moving, stamp, self._tf_class) if moving is not None else None
        spent += perf() - t0
        yield
        t0 = perf()
        items = [(self._channels[0], payload)]
        session = self._session
        if session.current is not None:
            if tf is not None:
                from rclpy.serialization import serialize_message
                items.append((self._channels[1], serialize_message(tf)))
                if self._recorded_static is not session.current:
                    static = tf_message(d.static(), stamp, self._tf_class)
                    items.append((self._channels[2], serialize_message(static)))
                    self._recorded_static = session.current
            session.write(items, stamp)
        spent += perf() - t0
        yield
        t0 = perf()
        self._pub.publish(payload)
        if tf is not None:
            self._tf_pub.publish(tf)
        spent += perf() - t0
        self.ticks += 1
        self.time_sum += spent
        self.time_max = max(self.time_max, spent)

    def values(self) -> list[tuple[str, Any]]:
        """Diagnostics of the display ticks."""
        return [("display_ticks", self.ticks),
                ("display_time_mean_us", 1e6 * self.time_sum / max(self.ticks, 1)),
                ("display_time_max_us", 1e6 * self.time_max),
                ("hinge_colour", self.display.colouring),
                ("tf", "on" if self._tf_pub is not None else "off")]


def build_display(node: Any, values: Any, qos: QoSProfile, watch: Any,
                  first_channel: int, spatial: bool = False) -> tuple[DisplayOutput, list, Any]:
    """
    Create the stage node's markers publisher, and TF publishers where tf2_msgs is importable.

    ``spatial``: ``node.mechanism`` is a mechanism in space, drawn by
    ``spatial_display.SpatialDisplay`` (else a planar `Display`).

    Returns the display output for the stepping loop (recording channels from
    ``first_channel`` on), the recorded display topics, (resolved name, type name, QoS) in
    channel order, and the /tf_static publisher (None without TF).
    """
    from visualization_msgs.msg import MarkerArray

    frames = node.interface.frames
    if spatial:
        from flexure_sim.node.publish.spatial_display import SpatialDisplay
        display: Any = SpatialDisplay(node.mechanism, frames, float(values["display_scale"]))
    else:
        display = Display(node.mechanism, frames, float(values["display_scale"]))
    pub = node.create_publisher(MarkerArray, MARKERS.name, qos,
                                event_callbacks=watch.publisher_callbacks(MARKERS.name))
    recorded = [(pub.topic_name, MARKERS.type_name, qos)]
    tf_class, why = tf_message_class()
    tf_pub = static_pub = None
    if tf_class is None:
        node.get_logger().info(
            f"TF off: {why}; poses are on bodies/poses and bodies/<body>/pose")
    else:
        tf_pub = node.create_publisher(tf_class, TF.name, tf_qos())
        static_pub = node.create_publisher(tf_class, TF_STATIC.name, tf_static_qos())
        static_pub.publish(tf_message(display.static(), node.get_clock().now().nanoseconds,
                                      tf_class))
        recorded += [(tf_pub.topic_name, TF.type_name, tf_qos()),
                     (static_pub.topic_name, TF_STATIC.type_name, tf_static_qos())]
    channels = list(range(first_channel, first_channel + len(recorded)))
    output = DisplayOutput(display, pub, node.session, channels, tf_pub, tf_class)
    return output, recorded, static_pub
