"""
A body's mass and inertia in a mechanism file: given, or from its outline, thickness and material.

Part of the loader (mechanism/loader.py); messages name the file, key and problem. A body gives
``mass`` (kg) and ``inertia`` (kg m^2, about its mass centre, the body frame's origin), or a
plate of uniform ``thickness`` (m) cut to its ``shape`` outline (the display outline, body frame)
from a named ``material`` (engine/hinges/materials.py: its density) or an explicit ``density``
(kg/m^3): then

    m = rho t A,      I = rho t J_o,

with the polygon's area A = 1/2 sum (x_i y_{i+1} - x_{i+1} y_i) and polar second moment about
the origin J_o = 1/12 sum (x_i y_{i+1} - x_{i+1} y_i)(x_i^2 + x_i x_{i+1} + x_{i+1}^2 + y_i^2
+ y_i y_{i+1} + y_{i+1}^2) (the shoelace formula and its second moment, e.g. Bourke, "Calculating
the area and centroid of a polygon", 1988; a test checks a rectangle's b h (b^2 + h^2) / 12).
The body frame is at the mass centre, so the outline's centroid must be at its origin (refused
otherwise, with the centroid). A ``mass`` or ``inertia`` given next to a material wins.
"""
from __future__ import annotations

from typing import Any, Sequence

import numpy as np

from flexure_sim.engine.hinges import materials
from flexure_sim.engine.mechanism.values import Ctx
from flexure_sim.engine.mechanism.values import number

#: Largest distance (m) between an outline's centroid and the body frame's origin.
CENTROID_TOLERANCE = 1e-9


def polygon_properties(points: Sequence[Sequence[float]]) -> tuple[float, np.ndarray, float]:
    """Return (area, centroid (2,), polar second moment about the origin) of a simple polygon."""
    p = np.asarray(points, dtype=float)
    x, y = p[:, 0], p[:, 1]
    xn, yn = np.roll(x, -1), np.roll(y, -1)
    cross = x * yn - xn * y
    area = 0.5 * cross.sum()
    centroid = np.array([((x + xn) * cross).sum(), ((y + yn) * cross).sum()]) / (6.0 * area)
    polar = (cross * (x * x + x * xn + xn * xn + y * y + y * yn + yn * yn)).sum() / 12.0
    if area < 0:  # clockwise outline
        area, polar = -area, -polar
    return float(area), centroid, float(polar)


def mass_and_inertia(ctx: Ctx, key: str, spec: dict, shape: Any) -> tuple[float, float]:
    """Return a body's (mass, inertia): given, or of its plate (module docstring)."""
    plate = "material" in spec or "density" in spec or "thickness" in spec
    if not plate:
        if "mass" not in spec or "inertia" not in spec:
            missing = "mass" if "mass" not in spec else "inertia"
            raise ctx.fail(f"{key}.{missing}", "missing required key (or give thickness, shape "
                           "and a material or density)")
        return (number(ctx, f"{key}.mass", spec["mass"], positive=True),
                number(ctx, f"{key}.inertia", spec["inertia"], positive=True))
    for need in ("thickness", "shape"):
        if need not in spec:
            raise ctx.fail(f"{key}.{need}", "missing required key: a body of a material is a "
                           "plate of a thickness cut to its shape")
    if "material" not in spec and "density" not in spec:
        raise ctx.fail(f"{key}.thickness", "give a material or a density for the plate")
    t = number(ctx, f"{key}.thickness", spec["thickness"], positive=True)
    if "density" in spec:
        rho = number(ctx, f"{key}.density", spec["density"], positive=True)
    else:
        try:
            rho = materials.lookup(spec["material"])["density"]
        except materials.MaterialError as exc:
            raise ctx.fail(f"{key}.material", str(exc)) from None
    area, centroid, polar = polygon_properties(shape)
    if not area > 0:
        raise ctx.fail(f"{key}.shape", "the outline has no area")
    if np.hypot(*centroid) > CENTROID_TOLERANCE:
        raise ctx.fail(f"{key}.shape", f"the outline's centroid ({centroid[0]:.6g}, "
                       f"{centroid[1]:.6g}) m is not at the body frame's origin, the mass "
                       "centre: move the outline, or give mass and inertia")
    mass = (number(ctx, f"{key}.mass", spec["mass"], positive=True) if "mass" in spec
            else rho * t * area)
    inertia = (number(ctx, f"{key}.inertia", spec["inertia"], positive=True)
               if "inertia" in spec else rho * t * polar)
    return mass, inertia
