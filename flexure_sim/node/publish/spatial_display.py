"""
Markers and TF of a mechanism in space (``SpatialSnapshot``), as `display.Display` a planar one.

TF (frame ids from `topics.Frames`, REP-103): ``stage`` -> each body frame at its position and
orientation (moving bodies on ``/tf`` at the display rate, bodies held by a ``fixed``
constraint on ``/tf_static``), and each body frame -> its hinge frames (``hinge_<h>_a`` on
body A, ``hinge_<h>`` on body B) at their position and orientation in the body, static.

Markers (``visualization_msgs/MarkerArray``, all in the root frame):

- ``bodies``: one LINE_STRIP per body, from its frame origin out to each of its hinge frames
  and back (a star: a body in space has no outline in the mechanism file);
- ``hinges``: one SPHERE per hinge at its frame b, coloured green -> red by its load |m| / arm
  + |f| (`markers.MarkerScene.LOAD_ARM_M`) relative to the peak so far (there is no yield
  strength in 3-D);
- ``drive``: one ARROW per drive from its body's origin along its direction, ``ARROW_M_PER_N``
  long per newton of drive force.

Motion is magnified by ``display_scale`` about the rest pose: a body at position p and
rotation vector phi from rest (R = R0 Exp(phi)) is drawn at p0 + s (p - p0) with R0 Exp(s phi).
Rotations are SciPy's (``scipy.spatial.transform.Rotation``).
"""
from __future__ import annotations

from typing import Any, Optional

import numpy as np
from scipy.spatial.transform import Rotation

from flexure_sim.engine.mechanism.parts import Fixed
from flexure_sim.node.publish.display import Transform
from flexure_sim.node.publish.marker_cdr import MarkerArrayPacker
from flexure_sim.node.publish.markers import (
    ARROW, ARROW_M_PER_N, ARROW_SCALE_M, BODY_RGBA, DRIVE_RGBA, HINGE_DISC_M, LINE_WIDTH_M,
    MarkerScene, MarkerSpec, load_colour,
)

#: visualization_msgs/Marker SPHERE.
SPHERE = 2
_IDENTITY = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0)
_AXES = {"x": (1.0, 0.0, 0.0), "y": (0.0, 1.0, 0.0), "z": (0.0, 0.0, 1.0)}


def _xyzw(wxyz: Any) -> tuple[float, float, float, float]:
    w, x, y, z = (float(v) for v in wxyz)
    return x, y, z, w


class SpatialDisplay:
    """Markers and TF of one spatial mechanism (module docstring); the `display.Display` API."""

    #: What the hinge colours show (diagnostics ``hinge_colour``).
    colouring = "|wrench| / peak"

    def __init__(self, mechanism: Any, frames: Any, display_scale: float) -> None:
        self.mechanism = mechanism
        self.frames = frames
        self.scale = float(display_scale)
        self.packer = MarkerArrayPacker(frames.root)
        bodies = mechanism.bodies
        self._index = {b.name: i for i, b in enumerate(bodies)}
        self._rest = np.array([b.position for b in bodies], dtype=float).reshape(-1, 3)
        self._r0 = Rotation.from_quat([_xyzw(b.quaternion) for b in bodies])
        self.fixed = {c.body for c in mechanism.constraints if isinstance(c, Fixed)}
        # Every drawn point in its body's coordinates with its body's index, so that one
        # vectorised rotation places all of them: each body's star (origin, out to a hinge
        # frame, back, ...), then each hinge's frame b.
        local: list = []
        owner: list = []
        self._splits = []
        for i, b in enumerate(bodies):
            local.append((0.0, 0.0, 0.0))
            for h in mechanism.hinges:
                for frame in (h.a, h.b):
                    if frame.body == b.name:
                        local += [tuple(frame.position), (0.0, 0.0, 0.0)]
            owner += [i] * (len(local) - len(owner))
            self._splits.append(len(local))
        for h in mechanism.hinges:
            local.append(tuple(h.b.position))
            owner.append(self._index[h.b.body])
        self._local = np.array(local, dtype=float).reshape(-1, 3)
        self._owner = np.array(owner, dtype=int)
        self._drives = []
        for d in mechanism.drives:
            axis = _AXES.get(d.coordinate[-1], d.axis) if d.coordinate else d.axis
            self._drives.append((self._index[d.body], np.array(axis, dtype=float)))
        self._peak = 0.0

    def placed(self, snap: Any) -> tuple[np.ndarray, np.ndarray]:
        """
        Return the drawn body positions (n, 3) and every drawn point (root frame, magnified).

        The points: each body's star, then each hinge's frame b (the order of `specs`).
        """
        s = self.scale
        positions = self._rest + s * (np.asarray(snap.positions, dtype=float) - self._rest)
        phi = np.asarray(snap.rotations, dtype=float).reshape(-1, 3)
        rotations = self._r0 * Rotation.from_rotvec(s * phi)
        owner = self._owner
        return positions, positions[owner] + rotations[owner].apply(self._local)

    def geometry(self, snap: Any) -> tuple[np.ndarray, np.ndarray]:
        """Return the drawn geometry of the snapshot ``snap`` (`placed`)."""
        return self.placed(snap)

    def specs(self, snap: Any, geometry: Optional[tuple] = None) -> list[MarkerSpec]:
        """
        Return the markers of the snapshot ``snap`` as plain data (`marker_cdr` packs them).

        ``geometry``: its `geometry`, if already taken.
        """
        positions, points = geometry if geometry is not None else self.placed(snap)
        parts = np.split(points, self._splits)
        out = []
        for k, (body, pts) in enumerate(zip(self.mechanism.bodies, parts[:-1])):
            out.append(MarkerSpec("bodies", k, 4, body.name, _IDENTITY, (LINE_WIDTH_M, 0.0, 0.0),
                                  BODY_RGBA, [tuple(p) for p in pts.tolist()]))
        w = np.asarray(snap.wrenches, dtype=float).reshape(-1, 6)
        loads = (np.linalg.norm(w[:, :3], axis=1) / MarkerScene.LOAD_ARM_M
                 + np.linalg.norm(w[:, 3:], axis=1))
        self._peak = max(self._peak, float(loads.max(initial=0.0)))
        ratios = loads / self._peak if self._peak > 0 else np.zeros_like(loads)
        size = HINGE_DISC_M[0]
        for k, (hinge, (x, y, z), ratio) in enumerate(zip(
                self.mechanism.hinges, parts[-1].tolist(), ratios.tolist())):
            out.append(MarkerSpec("hinges", k, SPHERE, hinge.name, (x, y, z, 0.0, 0.0, 0.0, 1.0),
                                  (size, size, size), load_colour(ratio), []))
        forces = np.asarray(snap.drive_forces, dtype=float)
        for k, ((i, axis), force) in enumerate(zip(self._drives, forces.tolist())):
            start = positions[i]
            end = start + ARROW_M_PER_N * force * axis
            out.append(MarkerSpec("drive", k, ARROW, "", _IDENTITY, ARROW_SCALE_M, DRIVE_RGBA,
                                  [tuple(start.tolist()), tuple(end.tolist())]))
        return out

    def markers(self, snap: Any, stamp_ns: int) -> bytes:
        """CDR bytes of the MarkerArray of the snapshot ``snap``."""
        return self.packer.pack(self.specs(snap), stamp_ns)

    def moving(self, snap: Any) -> list[Transform]:
        """Return root -> each body that is not fixed, at its pose in ``snap`` (true scale)."""
        fr = self.frames
        return [Transform(fr.root, fr.body(b.name), tuple(p), _xyzw(q))
                for b, p, q in zip(self.mechanism.bodies,
                                   np.asarray(snap.positions, dtype=float).tolist(),
                                   np.asarray(snap.quaternions, dtype=float).tolist())
                if b.name not in self.fixed]

    def static(self) -> list[Transform]:
        """Return root -> the fixed bodies at rest and body -> each hinge frame on it."""
        fr = self.frames
        out = [Transform(fr.root, fr.body(b.name), tuple(float(v) for v in b.position),
                         _xyzw(b.quaternion))
               for b in self.mechanism.bodies if b.name in self.fixed]
        for h in self.mechanism.hinges:
            for frame, child in ((h.a, fr.hinge_a(h.name)), (h.b, fr.hinge_b(h.name))):
                out.append(Transform(fr.body(frame.body), child,
                                     tuple(float(v) for v in frame.position),
                                     _xyzw(frame.quaternion)))
        return out
