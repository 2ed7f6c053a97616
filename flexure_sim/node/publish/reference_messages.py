"""
The stage node's tick messages as rclpy message objects.

They are the reference `StageInterface.encode` is tested against (publish/interface.py packs the
same messages straight to CDR).
"""
from __future__ import annotations

import math
from typing import Any

from geometry_msgs.msg import Pose, PoseArray, PoseStamped, TransformStamped, WrenchStamped
from rosgraph_msgs.msg import Clock
from std_msgs.msg import Float64

from flexure_sim.node.publish.diagnostics_msg import stamp_msg


def yaw_quaternion(yaw: float) -> tuple[float, float, float, float]:
    """(x, y, z, w) of a rotation by ``yaw`` about z."""
    half = 0.5 * yaw
    return 0.0, 0.0, math.sin(half), math.cos(half)


def reference_messages(itf: Any, snap: Any, stamp_ns: int, measured: float = 0.0) -> list[Any]:
    """Every tick topic's message of ``snap`` for the `interface.StageInterface` ``itf``."""
    stamp = stamp_msg(stamp_ns)
    fr = itf.frames
    out: list[Any] = []
    if itf.publishes_clock:
        out.append(Clock(clock=stamp))
    array = PoseArray()
    array.header.stamp = stamp
    array.header.frame_id = fr.root
    poses = []
    for (x, y, th) in snap.poses.tolist():
        pose = Pose()
        pose.position.x, pose.position.y, pose.position.z = x, y, 0.0
        q = pose.orientation
        q.x, q.y, q.z, q.w = yaw_quaternion(th)
        poses.append(pose)
    array.poses = poses
    out.append(array)
    for pose in poses:
        msg = PoseStamped()
        msg.header.stamp = stamp
        msg.header.frame_id = fr.root
        msg.pose = pose
        out.append(msg)
    for name, (m, fx, fy), (a, px, py) in zip(
        itf.hinge_names, snap.wrenches.tolist(), snap.deflections.tolist()
    ):
        w = WrenchStamped()
        w.header.stamp = stamp
        w.header.frame_id = fr.hinge_b(name)
        w.wrench.force.x, w.wrench.force.y, w.wrench.force.z = fx, fy, 0.0
        w.wrench.torque.x, w.wrench.torque.y, w.wrench.torque.z = 0.0, 0.0, m
        out.append(w)
        d = TransformStamped()
        d.header.stamp = stamp
        d.header.frame_id = fr.hinge_a(name)
        d.child_frame_id = fr.hinge_b(name)
        t = d.transform.translation
        t.x, t.y, t.z = px, py, 0.0
        r = d.transform.rotation
        r.x, r.y, r.z, r.w = yaw_quaternion(a)
        out.append(d)
    for d, (m, fx, fy) in zip(itf.wrench_drives, snap.drive_wrenches.tolist()):
        w = WrenchStamped()
        w.header.stamp = stamp
        w.header.frame_id = fr.body(d.body)
        w.wrench.force.x, w.wrench.force.y, w.wrench.force.z = fx, fy, 0.0
        w.wrench.torque.x, w.wrench.torque.y, w.wrench.torque.z = 0.0, 0.0, m
        out.append(w)
    out.extend(Float64(data=v) for v in itf.scalars(snap, measured))
    return out
