"""
Names of the stage node's interface: topics, frames and recording metadata records.

One home for every name the node publishes under and the tools look for (docs/node.md),
with no ROS import, so the engine-free tools share them with the node.
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


#: Command of the one drive when its actuator takes volts (``actuator: {command: voltage}``), V.
COMMAND_VOLTAGE = "drive/voltage"


def drive_command(drive: str, kind: str = "displacement") -> str:
    """
    Command of one named drive (several drives; subscribed).

    ``drive/<name>/displacement`` (m, or rad on theta), for a force drive
    ``drive/<name>/force`` (N, or N m), for a drive whose actuator takes volts
    ``drive/<name>/voltage`` (V); ``kind`` is one of those three words.
    """
    return f"drive/{drive}/{kind if kind in ('force', 'voltage') else 'displacement'}"


def drive_input(drive: str) -> str:
    """Actuator output actually applied by one named drive (a force drive's force)."""
    return f"drive/{drive}/input"


def drive_force(drive: str) -> str:
    """Force one named displacement drive's actuator applies to its body."""
    return f"drive/{drive}/force"


def drive_position(drive: str) -> str:
    """Displacement of a named force drive's body from rest along the drive's direction."""
    return f"drive/{drive}/position"


def output_displacement(output: str) -> str:
    """Displacement of one named output from rest (several outputs)."""
    return f"output/{output}/displacement"


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


#: Topic of the stage drawn for RViz/Foxglove (visualization_msgs/MarkerArray).
MARKERS = "markers"
#: TF topics (absolute, as tf2 listeners expect).
TF = "/tf"
TF_STATIC = "/tf_static"


def frame_prefix_problem(prefix: object) -> str | None:
    """
    Why ``prefix`` cannot prefix frame ids (None if it can).

    tf2 frame ids have no leading slash and no whitespace.
    """
    if not isinstance(prefix, str):
        return f"frame_prefix: expected a string, got {prefix!r}"
    if prefix.startswith("/"):
        return f"frame_prefix: frame ids have no leading slash (tf2), got {prefix!r}"
    if any(c.isspace() for c in prefix):
        return f"frame_prefix: no whitespace allowed in frame ids, got {prefix!r}"
    return None


class Frames:
    """
    Every frame id the node publishes.

    With its ``frame_prefix`` (e.g. ``stage1/``) prepended, so two stages can share one TF tree and
    one RViz view. The one place frame ids are made: headers, child_frame_ids, markers and TF all
    take them from here.
    """

    def __init__(self, prefix: str = "") -> None:
        problem = frame_prefix_problem(prefix)
        if problem:
            raise ValueError(problem)
        self.prefix = prefix
        self.root = prefix + ROOT_FRAME

    def body(self, body: str) -> str:
        """Return the frame of one body, at its mass centre."""
        return self.prefix + body

    def hinge_b(self, hinge: str) -> str:
        """Frame b of a hinge (`hinge_frame`)."""
        return self.prefix + hinge_frame(hinge)

    def hinge_a(self, hinge: str) -> str:
        """Frame a of a hinge (`hinge_frame_a`)."""
        return self.prefix + hinge_frame_a(hinge)
