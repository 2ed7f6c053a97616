"""
The stage node's ROS interface for a mechanism in space (``SpatialSimulation``).

The topic table is `interface.StageInterface`'s (same names, types, frames and QoS); what
differs is the content, mapped from a ``SpatialSnapshot`` field by field:

- a body's pose: position (x, y, z) and orientation, the snapshot's unit quaternion (w, x, y,
  z) written in ROS order (x, y, z, w) (REP-103);
- a hinge's wrench on its body B, in its frame b: force (f_x, f_y, f_z) and torque (m_x,
  m_y, m_z), all six components (the snapshot's (m, f) order swapped to the message's);
- a hinge's deflection: translation p and the rotation whose rotation vector the snapshot
  gives (SciPy's ``Rotation.from_rotvec``, scalar last as ROS);
- drives and outputs as the planar interface's (inputs, forces, positions, outputs).

No drive wrenches (the spatial snapshot reports none), no compression hinge and no output
sensor in 3-D. `SpatialInterface.fields` computes every float of a tick's monitoring messages
in a few array operations; `encode` packs them with the planar packers and `messages` builds
the rclpy messages from the same fields (the reference the packed bytes are tested against).
"""
from __future__ import annotations

from dataclasses import replace
from typing import Any

import numpy as np
from geometry_msgs.msg import Pose, PoseArray, PoseStamped, TransformStamped, WrenchStamped
from rosgraph_msgs.msg import Clock
from scipy.spatial.transform import Rotation
from std_msgs.msg import Float64

from flexure_sim.node.publish.diagnostics_msg import stamp_msg
from flexure_sim.node.publish.interface import StageInterface


def ros_quaternions(wxyz: np.ndarray) -> np.ndarray:
    """Return unit quaternions (n, 4) given as (w, x, y, z) in ROS order (x, y, z, w)."""
    q = np.asarray(wxyz, dtype=float).reshape(-1, 4)
    return q[:, [1, 2, 3, 0]]


def deflection_quaternions(rotation_vectors: np.ndarray) -> np.ndarray:
    """Return the quaternions (x, y, z, w) of rotation vectors (n, 3) (SciPy, scalar last)."""
    phi = np.asarray(rotation_vectors, dtype=float).reshape(-1, 3)
    if not len(phi):
        return np.zeros((0, 4))
    return Rotation.from_rotvec(phi).as_quat()


class SpatialInterface(StageInterface):
    """The topic table of a spatial mechanism and ``SpatialSnapshot`` -> messages."""

    def __init__(self, mechanism: Any, time_mode: str = "realtime",
                 frame_prefix: str = "") -> None:
        super().__init__(mechanism, time_mode, frame_prefix)
        self.tick_topics = tuple(
            replace(spec, description=spec.description.replace(
                "translation (p_x, p_y, 0), yaw alpha", "translation p and rotation, 3-D"))
            for spec in self.tick_topics)

    def fields(self, snap: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """
        Return the floats of the monitoring messages of ``snap``.

        poses (n_bodies, 7): position, quaternion (x, y, z, w); wrenches (n_hinges, 6): force,
        torque; deflections (n_hinges, 7): translation, quaternion (x, y, z, w).
        """
        poses = np.hstack([snap.positions, ros_quaternions(snap.quaternions)])
        w = np.asarray(snap.wrenches, dtype=float).reshape(-1, 6)
        wrenches = np.hstack([w[:, 3:], w[:, :3]])
        d = np.asarray(snap.deflections, dtype=float).reshape(-1, 6)
        deflections = np.hstack([d[:, 3:], deflection_quaternions(d[:, :3])])
        return poses, wrenches, deflections

    def scalars(self, snap: Any, measured: float = 0.0) -> list[float]:
        """Return the values of the Float64 tick topics (the last ones), `tick_topics` order."""
        out: list[float] = []
        if self.has_output:
            out.append(float(next(iter(snap.outputs.values()))))
        if self.outputs:
            out.extend(float(snap.outputs[o.name]) for o in self.outputs)
        for k, d in enumerate(self.drives):
            out.append(float(snap.drive_inputs[k]))
            out.append(float(snap.drive_positions[k] if d.kind == "force"
                             else snap.drive_forces[k]))
        if self.has_drive:
            out.append(float(snap.drive_inputs[0]))
            out.append(float(snap.drive_forces[0]))
        return out

    def _encode_monitoring(self, snap: Any, sec: int, nsec: int, out: list[bytes]) -> None:
        """Append the poses, wrenches and deflections of ``snap`` (packed) to ``out``."""
        poses, wrenches, deflections = self.fields(snap)
        out.append(self._pose_array.pack(sec, nsec, *poses.ravel().tolist()))
        out.extend(p.pack(sec, nsec, *v) for p, v in zip(self._poses, poses.tolist()))
        for wp, dp, w, d in zip(self._wrenches, self._deflections, wrenches.tolist(),
                                deflections.tolist()):
            out.append(wp.pack(sec, nsec, *w))
            out.append(dp.pack(sec, nsec, *d))

    def messages(self, snap: Any, stamp_ns: int, measured: float = 0.0) -> list[Any]:
        """Return the same messages as `encode`, as rclpy message objects (the reference)."""
        stamp = stamp_msg(stamp_ns)
        fr = self.frames
        out: list[Any] = [Clock(clock=stamp)] if self.publishes_clock else []
        poses_f, wrenches, deflections = self.fields(snap)
        poses = []
        for x, y, z, qx, qy, qz, qw in poses_f.tolist():
            pose = Pose()
            pose.position.x, pose.position.y, pose.position.z = x, y, z
            o = pose.orientation
            o.x, o.y, o.z, o.w = qx, qy, qz, qw
            poses.append(pose)
        array = PoseArray(poses=poses)
        array.header.stamp, array.header.frame_id = stamp, fr.root
        out.append(array)
        for pose in poses:
            msg = PoseStamped(pose=pose)
            msg.header.stamp, msg.header.frame_id = stamp, fr.root
            out.append(msg)
        for name, w, d in zip(self.hinge_names, wrenches.tolist(), deflections.tolist()):
            msg = WrenchStamped()
            msg.header.stamp, msg.header.frame_id = stamp, fr.hinge_b(name)
            f, t = msg.wrench.force, msg.wrench.torque
            f.x, f.y, f.z, t.x, t.y, t.z = w
            out.append(msg)
            tf = TransformStamped()
            tf.header.stamp, tf.header.frame_id = stamp, fr.hinge_a(name)
            tf.child_frame_id = fr.hinge_b(name)
            p, r = tf.transform.translation, tf.transform.rotation
            p.x, p.y, p.z, r.x, r.y, r.z, r.w = d
            out.append(tf)
        out.extend(Float64(data=v) for v in self.scalars(snap, measured))
        return out
