"""
The stage drawn for RViz and Foxglove: a ``visualization_msgs/MarkerArray`` per display tick.

Every marker is in the root frame (``stage``, with the node's frame prefix):

- ``bodies``: one closed LINE_STRIP per body, its outline (the ``shape`` of the mechanism file,
  else the convex hull of its hinge points and its frame origin) at the body's pose;
- ``hinges``: one flat CYLINDER (a disc) per hinge at its frame b, coloured by its load, from
  green (no load) to red (the load reference, 1.0);
- ``drive``: an ARROW at the driven body's drive point, along the drive axis, its length
  proportional to the drive force (``ARROW_M_PER_N``), pointing where the force pushes.

Displacements are magnified by ``display_scale`` about the unstressed pose (micrometre motions
are invisible at true scale): a body at rest pose z0 and pose z is drawn at z0 + s (z - z0).
The published poses, wrenches and deflections stay true; only the markers are magnified.
"""

from __future__ import annotations

from dataclasses import dataclass
import math
from typing import Optional, Sequence

import numpy as np

from flexure_sim.engine.mechanism.parts import Mechanism
from flexure_sim.topics import ROOT_FRAME

#: Disc of a hinge marker: diameter and thickness, m.
HINGE_DISC_M = (1.5e-3, 0.3e-3)
#: Width of the body outlines, m.
LINE_WIDTH_M = 0.3e-3
#: Arrow length per newton of drive force, m/N (the stage's 30 N at full stroke: 6 mm).
ARROW_M_PER_N = 2e-4
#: Colour of the body outlines (r, g, b, a).
BODY_RGBA = (0.55, 0.6, 0.7, 1.0)
DRIVE_RGBA = (0.2, 0.4, 1.0, 1.0)
#: Drive arrow: shaft diameter, head diameter, head length, m.
ARROW_SCALE_M = (0.4e-3, 0.8e-3, 1.0e-3)
#: visualization_msgs/Marker types used (Marker.msg constants).
ARROW, CYLINDER, LINE_STRIP = 0, 3, 4
_IDENTITY = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0)


def _hull(points: np.ndarray) -> np.ndarray:
    """
    Return the convex hull of 2-D points, counter-clockwise (monotone chain).

    Fewer than three distinct points, or collinear ones, give the points in order along
    their line (an outline that is a bar).
    """
    pts = sorted({(round(float(x), 12), round(float(y), 12)) for x, y in points})
    if len(pts) < 3:
        return np.array(pts, dtype=float)

    def cross(o, a, b):
        return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])

    lower: list = []
    for p in pts:
        while len(lower) >= 2 and cross(lower[-2], lower[-1], p) <= 0:
            lower.pop()
        lower.append(p)
    upper: list = []
    for p in reversed(pts):
        while len(upper) >= 2 and cross(upper[-2], upper[-1], p) <= 0:
            upper.pop()
        upper.append(p)
    hull = lower[:-1] + upper[:-1]
    if len(hull) < 3:  # collinear
        return np.array([pts[0], pts[-1]], dtype=float)
    return np.array(hull, dtype=float)


def body_outlines(mechanism: Mechanism) -> list[np.ndarray]:
    """Return each body's outline vertices (k, 2) in its body frame, m."""
    outlines = []
    for body in mechanism.bodies:
        if body.shape is not None:
            outlines.append(np.array(body.shape, dtype=float))
            continue
        points = [(0.0, 0.0)]
        for h in mechanism.hinges:
            for frame in (h.a, h.b):
                if frame.body == body.name:
                    points.append(frame.position)
        outlines.append(_hull(np.array(points, dtype=float)))
    return outlines


def displayed_poses(rest: np.ndarray, poses: np.ndarray, scale: float) -> np.ndarray:
    """Return the poses (n, 3) drawn: rest + scale (pose - rest)."""
    return rest + scale * (poses - rest)


def to_root(pose: Sequence[float], points: np.ndarray) -> np.ndarray:
    """Return body-frame points (k, 2) in the root frame for a body at pose (x, y, theta)."""
    x, y, th = pose
    c, s = math.cos(th), math.sin(th)
    # rows (px, py) @ [[c, s], [-s, c]] = (c px - s py, s px + c py)
    return points @ np.array([[c, s], [-s, c]]) + np.array([x, y])


def load_colour(ratio: float) -> tuple[float, float, float, float]:
    """Return green at 0 through yellow to red at 1 (and above), opaque."""
    r = min(max(ratio, 0.0), 1.0)
    return (min(1.0, 2.0 * r), min(1.0, 2.0 * (1.0 - r)), 0.0, 1.0)


@dataclass
class MarkerScene:
    """
    The marker geometry of one mechanism; `message` makes a MarkerArray of one tick.

    ``load_reference`` maps a hinge's load to its colour: ``hinge_loads(snapshot)`` / reference
    is 1.0 at red. By default the load is |wrench| (moment in N m and force in N, combined as
    |m| / arm + |f| with the arm ``LOAD_ARM_M``) and the reference is the largest load seen so
    far, so the most loaded hinge of the run is red.
    """

    mechanism: Mechanism
    frame_prefix: str = ""
    display_scale: float = 1.0

    #: Lever arm combining a hinge's moment with its force into one load figure, m.
    LOAD_ARM_M = 1e-3

    def __post_init__(self) -> None:
        mech = self.mechanism
        self.outlines = body_outlines(mech)
        self.rest = np.array([b.pose for b in mech.bodies], dtype=float)
        self._body_index = {b.name: i for i, b in enumerate(mech.bodies)}
        self._peak_load = 0.0
        # Every drawn point in its body's frame, with its body's index, so that one
        # vectorised to_root places all of them: the outlines (closed: first vertex again
        # when they are polygons), then each hinge's frame b.
        local, owner, self._splits = [], [], []
        for i, outline in enumerate(self.outlines):
            closed = np.vstack([outline, outline[:1]]) if len(outline) >= 3 else outline
            local.append(closed)
            owner += [i] * len(closed)
            self._splits.append(len(owner))
        local.append(np.array([h.b.position for h in mech.hinges], dtype=float).reshape(-1, 2))
        owner += [self._body_index[h.b.body] for h in mech.hinges]
        self._local = np.vstack(local)
        self._owner = np.array(owner, dtype=int)

    def hinge_loads(self, wrenches: np.ndarray) -> np.ndarray:
        """Return one load figure per hinge from its wrench (m, fx, fy): |m| / arm + |f|."""
        w = np.asarray(wrenches, dtype=float)
        return np.abs(w[:, 0]) / self.LOAD_ARM_M + np.hypot(w[:, 1], w[:, 2])

    def geometry(self, poses: np.ndarray, wrenches: np.ndarray, drive_force: float,
                 ratios: Optional[np.ndarray] = None) -> dict:
        """
        Return the drawn geometry of one tick (root frame, m), as plain arrays.

        ``outlines``: closed polylines, one per body; ``hinges``: (n, 2) disc centres;
        ``ratios``: load ratio per hinge (given, e.g. stress ratios, or |wrench| / its peak so
        far); ``arrow``: (start, end) of the drive arrow or None.
        """
        mech = self.mechanism
        shown = displayed_poses(self.rest, np.asarray(poses, dtype=float), self.display_scale)
        # to_root of every point at once, each with the pose of its body
        held = shown[self._owner]
        c, s = np.cos(held[:, 2]), np.sin(held[:, 2])
        lx, ly = self._local[:, 0], self._local[:, 1]
        placed = np.column_stack([held[:, 0] + c * lx - s * ly, held[:, 1] + s * lx + c * ly])
        parts = np.split(placed, self._splits)
        outlines, centres = parts[:-1], parts[-1]
        if ratios is None:
            loads = self.hinge_loads(wrenches)
            self._peak_load = max(self._peak_load, float(loads.max(initial=0.0)))
            ratios = loads / self._peak_load if self._peak_load > 0 else np.zeros_like(loads)
        arrow = None
        drive = mech.drive
        if drive is not None:
            i = self._body_index[drive.body]
            start = shown[i, :2]
            axis = np.asarray(drive.axis, dtype=float)
            arrow = (start, start + ARROW_M_PER_N * drive_force * axis)
        return {"outlines": outlines, "hinges": centres, "ratios": np.asarray(ratios),
                "arrow": arrow}

    def specs(self, poses: np.ndarray, wrenches: np.ndarray, drive_force: float,
              ratios: Optional[np.ndarray] = None) -> list["MarkerSpec"]:
        """
        Return the markers of one tick as plain data.

        `message` and `marker_cdr.MarkerArrayPacker` both turn it into a MarkerArray: one
        definition.
        """
        return self.specs_of(self.geometry(poses, wrenches, drive_force, ratios))

    def specs_of(self, g: dict) -> list["MarkerSpec"]:
        """Return the markers of the drawn geometry ``g`` (`geometry`) as plain data."""
        out = []
        for k, (body, pts) in enumerate(zip(self.mechanism.bodies, g["outlines"])):
            out.append(MarkerSpec("bodies", k, LINE_STRIP, body.name, _IDENTITY,
                                  (LINE_WIDTH_M, 0.0, 0.0), BODY_RGBA,
                                  [(x, y, 0.0) for x, y in pts.tolist()]))
        for k, (hinge, (x, y), ratio) in enumerate(zip(
                self.mechanism.hinges, g["hinges"].tolist(), g["ratios"].tolist())):
            out.append(MarkerSpec("hinges", k, CYLINDER, hinge.name,
                                  (x, y, 0.0, 0.0, 0.0, 0.0, 1.0),
                                  (HINGE_DISC_M[0], HINGE_DISC_M[0], HINGE_DISC_M[1]),
                                  load_colour(ratio), []))
        if g["arrow"] is not None:
            out.append(MarkerSpec("drive", 0, ARROW, "", _IDENTITY, ARROW_SCALE_M, DRIVE_RGBA,
                                  [(float(p[0]), float(p[1]), 0.0) for p in g["arrow"]]))
        return out

    def message(self, poses: np.ndarray, wrenches: np.ndarray, drive_force: float,
                stamp_ns: int, ratios: Optional[np.ndarray] = None):
        """
        Return the ``visualization_msgs/MarkerArray`` of one tick as rclpy objects.

        It is the reference the node's packed bytes are tested against.
        """
        from builtin_interfaces.msg import Time
        from geometry_msgs.msg import Point
        from visualization_msgs.msg import Marker, MarkerArray

        stamp = Time(sec=stamp_ns // 1_000_000_000, nanosec=stamp_ns % 1_000_000_000)
        frame = self.frame_prefix + ROOT_FRAME
        markers = []
        for spec in self.specs(poses, wrenches, drive_force, ratios):
            m = Marker()
            m.header.stamp = stamp
            m.header.frame_id = frame
            m.ns, m.id, m.type, m.action = spec.ns, spec.id, spec.type, Marker.ADD
            m.text = spec.text
            p, q = m.pose.position, m.pose.orientation
            p.x, p.y, p.z, q.x, q.y, q.z, q.w = spec.pose
            m.scale.x, m.scale.y, m.scale.z = spec.scale
            m.color.r, m.color.g, m.color.b, m.color.a = spec.rgba
            m.points = [Point(x=x, y=y, z=z) for x, y, z in spec.points]
            markers.append(m)
        return MarkerArray(markers=markers)


@dataclass(frozen=True)
class MarkerSpec:
    """
    One marker as data.

    namespace, id, type (visualization_msgs/Marker constants), text, pose (x, y, z, qx, qy, qz,
    qw), scale, colour (r, g, b, a) and points (x, y, z).
    """

    ns: str
    id: int
    type: int
    text: str
    pose: tuple
    scale: tuple
    rgba: tuple
    points: list
