"""
Hinge shapes for the finite-element model: their parameters, profile and gmsh outline.

Every shape is a plate of thickness ``t`` (out of the plane) whose elastic part lies between two
clamp lines x = -l and x = +l, symmetric about both axes of its frame: the material is
|y| <= y_top(x) for |x| <= l, with the narrowest section (the neck) at x = 0. Body A is
clamped at x = -l, body B at x = +l; the hinge frame is at the centre, x along the hinge
(the axial direction of ``stiffness.notch_stiffness``), y across it.

* ``circular``: D (hole diameter), h (neck), t; R = D/2, l = R,
  y_top = h/2 + R - sqrt(R^2 - x^2).
* ``elliptical``: a (semi-axis along x), b (semi-axis across: the notch depth), h, t; l = a,
  y_top = h/2 + b (1 - sqrt(1 - x^2/a^2)).
* ``corner_filleted``: length (clamp to clamp), r (fillet radius), h, t; l = length/2,
  y_top = h/2 for |x| <= l - r, then a quarter circle of radius r up to h/2 + r at the clamp.
* ``leaf``: length (clamp to clamp), thickness, width (the plate thickness), fillet (radius,
  may be 0): the corner-filleted profile with h = thickness, r = fillet.

A circular notch is a corner-filleted one with length = D and r = D/2 (a test checks this).
The ``leaf`` is reported in the convention of ``stiffness.cantilever_stiffness``: the leaf runs
along the hinge frame's y axis (model.py turns the result by 90 degrees).

The circular, elliptical and filleted profiles meet their clamp lines tangentially (the hole
reaches the clamp at its widest point), so the outline has a zero-angle corner at each of the
four clamp ends. The material there is as wide as the hinge is and barely strains; the mesh
simply puts a few thin triangles into each corner.

Each shape also gives the geometry in dimensionless form for the cache and the derivatives
(model.py): a reference length ``ell`` (the neck or leaf thickness) and the ratios of the other
lengths to it.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Mapping

import numpy as np

from flexure_sim.errors import FlexureSimError


class ShapeError(FlexureSimError, ValueError):
    """A hinge shape's parameters are missing, unknown or inconsistent (names them)."""


@dataclass(frozen=True)
class Shape:
    """
    One hinge shape: its name, length parameters and thickness key.

    ``lengths``: the in-plane lengths in the order of ``ratios`` (the first is the reference
    length ell); ``plate``: the key of the out-of-plane thickness; ``optional``: lengths that
    default to 0.
    """

    name: str
    lengths: tuple[str, ...]
    plate: str
    optional: tuple[str, ...] = ()

    @property
    def keys(self) -> tuple[str, ...]:
        """Return every geometry key of the shape (in-plane lengths, then the plate thickness)."""
        return self.lengths + (self.plate,)


SHAPES = {
    "circular": Shape("circular", ("h", "D"), "t"),
    "elliptical": Shape("elliptical", ("h", "a", "b"), "t"),
    "corner_filleted": Shape("corner_filleted", ("h", "length", "r"), "t"),
    "leaf": Shape("leaf", ("thickness", "length", "fillet"), "width", ("fillet",)),
}


def shape(name: str) -> Shape:
    """Return the named shape; ShapeError listing the known ones otherwise."""
    try:
        return SHAPES[name]
    except (KeyError, TypeError):
        raise ShapeError(f"unknown hinge shape {name!r} ({', '.join(SHAPES)})") from None


@dataclass(frozen=True)
class Profile:
    """
    A hinge outline in units of the reference length (ell = 1).

    ``half``: l, the clamp lines are x = -l and x = +l; ``neck``: the half-width at x = 0;
    ``flat``: the x at which the straight part of the upper outline (y = neck, from x = 0)
    ends; ``arc``: the concave elliptical (or circular) arc from there to the clamp, as
    (centre x, centre y, semi-axis x, semi-axis y); semi-axis 0 for none (a sharp leaf).
    """

    half: float
    neck: float
    flat: float
    arc: tuple[float, float, float, float]  # centre x, centre y, semi-axis x, semi-axis y

    def y_top(self, x) -> np.ndarray:
        """Half-width of the material at x (vectorised; |x| <= half)."""
        x = np.abs(np.asarray(x, dtype=float))
        cx, cy, ax, ay = self.arc
        s = np.clip((x - cx) / ax, -1.0, 1.0) if ax > 0 else np.zeros_like(x)
        curved = cy - ay * np.sqrt(np.maximum(1.0 - s * s, 0.0))
        return np.where(x <= self.flat, self.neck, curved)

    @property
    def corner(self) -> float:
        """Half-width at the clamp lines."""
        return float(self.y_top(self.half))


def profile(name: str, ratios: tuple[float, ...]) -> Profile:
    """
    Return the outline of a shape from its ratios.

    The ratios are the lengths of ``Shape.lengths`` after the first, divided by the first.
    ShapeError names a geometry that is not a hinge (a fillet longer than half the hinge).
    """
    if name == "circular":
        (d,) = ratios
        r = 0.5 * d
        return Profile(r, 0.5, 0.0, (0.0, 0.5 + r, r, r))
    if name == "elliptical":
        a, b = ratios
        return Profile(a, 0.5, 0.0, (0.0, 0.5 + b, a, b))
    if name in ("corner_filleted", "leaf"):
        length, r = ratios
        half = 0.5 * length
        if r > half:
            key = "r" if name == "corner_filleted" else "fillet"
            raise ShapeError(f"{key}: the fillet radius ({r:g} x the neck) exceeds half the "
                             f"length ({half:g} x the neck)")
        return Profile(half, 0.5, half - r, (half - r, 0.5 + r, r, r))
    raise ShapeError(f"unknown hinge shape {name!r} ({', '.join(SHAPES)})")


def ratios_of(name: str, values: Mapping[str, Any]) -> tuple[float, ...]:
    """Return the ratios (plain floats) of a shape's lengths to its reference length."""
    lengths = shape(name).lengths
    ell = float(values[lengths[0]])
    return tuple(float(values[k]) / ell for k in lengths[1:])


def build_outline(gmsh, prof: Profile) -> dict:
    """
    Add the outline of ``prof`` to the current gmsh model (built-in kernel, ell = 1).

    Returns the physical group tags {"left": clamp A, "right": clamp B, "free": the notch
    surfaces, "domain": the surface}.
    """
    geo = gmsh.model.geo
    half, neck, flat = prof.half, prof.neck, prof.flat
    cx, cy, ax, ay = prof.arc
    top = prof.corner
    circle = ax > 0 and abs(ax - ay) <= 1e-12 * ax
    necks = {s: geo.addPoint(0.0, s * neck, 0.0) for s in (1, -1)}
    corners = {}

    def side(s, d):
        """Curves from the neck point of side s (+1 top, -1 bottom) to its corner at x = d l."""
        curves, start = [], necks[s]
        if flat > 0:
            p = geo.addPoint(d * flat, s * neck, 0.0)
            curves.append(geo.addLine(start, p))
            start = p
        if ax > 0:
            centre = geo.addPoint(d * cx, s * cy, 0.0)
            end = geo.addPoint(d * half, s * top, 0.0)
            if circle:
                curves.append(geo.addCircleArc(start, centre, end))
            else:
                major = (geo.addPoint(d * (cx + ax), s * cy, 0.0) if ax >= ay
                         else geo.addPoint(d * cx, s * (cy - ay), 0.0))
                curves.append(geo.addEllipseArc(start, centre, major, end))
            start = end
        corners[s, d] = start
        return curves

    outward = {(s, d): side(s, d) for s in (1, -1) for d in (1, -1)}
    right = geo.addLine(corners[-1, 1], corners[1, 1])
    left = geo.addLine(corners[1, -1], corners[-1, -1])
    loop = ([-c for c in reversed(outward[-1, -1])] + outward[-1, 1] + [right]
            + [-c for c in reversed(outward[1, 1])] + outward[1, -1] + [left])
    surface = geo.addPlaneSurface([geo.addCurveLoop(loop)])
    geo.synchronize()
    free = [c for curves in outward.values() for c in curves]
    return {
        "left": gmsh.model.addPhysicalGroup(1, [left]),
        "right": gmsh.model.addPhysicalGroup(1, [right]),
        "free": gmsh.model.addPhysicalGroup(1, free),
        "domain": gmsh.model.addPhysicalGroup(2, [surface]),
    }
