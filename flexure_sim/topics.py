"""
Names of the stage node's interface: topics, frames and recording metadata records.

One home for every name the node publishes under and the tools look for (README
"## stage_node"), with no ROS import, so the engine-free tools share them with the node.
Topic names are relative to the node's namespace, except `CLOCK`.
"""
from __future__ import annotations

#: Root frame of every pose (REP-103: x right in the drawing, y up, z out of the plane).
ROOT_FRAME = "stage"

#: Drive command (subscribed), m along the drive axis.
COMMAND = "drive/displacement"
#: Actuator output actually applied, m along the drive axis.
DRIVE_INPUT = "drive/input"
#: Force the actuator applies to the driven body, N along the drive axis.
DRIVE_FORCE = "drive/force"
#: Displacement of the output body from rest along the output axis, m.
OUTPUT = "output/displacement"
#: The output as the mechanism's sensor reads it (noise, resolution, bandwidth, latency), m.
MEASURED = "output/measured"
#: Output setpoint the example controller (pi_controller) tracks, m.
SETPOINT = "setpoint"
#: Pose of every body frame, in body order.
POSE_ARRAY = "bodies/poses"
DIAGNOSTICS = "diagnostics"
#: Simulated time (fast and lockstep modes), absolute.
CLOCK = "/clock"

#: Name of the metadata record holding the mechanism and the node's parameters.
METADATA_NAME = "flexure_sim"
#: Name of the metadata records written when parameters change during a recording.
PARAMETER_CHANGE_NAME = "flexure_sim.parameters"


def body_pose(body: str) -> str:
    """Pose of one body's frame."""
    return f"bodies/{body}/pose"


def hinge_wrench(hinge: str) -> str:
    """Wrench a hinge exerts on its body B, in its frame b."""
    return f"hinges/{hinge}/wrench"


def hinge_deflection(hinge: str) -> str:
    """Pose of a hinge's frame b in its frame a."""
    return f"hinges/{hinge}/deflection"


def hinge_compression(hinge: str) -> str:
    """Compression of the compression hinge along the drive axis."""
    return f"hinges/{hinge}/compression"


def hinge_frame(hinge: str) -> str:
    """Frame b of a hinge (on its body B); the hinge's wrench is expressed in it."""
    return f"hinge_{hinge}"


def hinge_frame_a(hinge: str) -> str:
    """Frame a of a hinge (on its body A)."""
    return f"hinge_{hinge}_a"
