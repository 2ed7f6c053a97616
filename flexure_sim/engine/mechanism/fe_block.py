"""
A ``model: fe`` stiffness specification, checked: the hinge's shape, geometry and material.

Part of the loader (stiffness_block.py); messages name the file, key and problem. Keys:
``shape`` (circular, elliptical, corner_filleted, leaf), the shape's lengths (m; see
engine/hinges/fe/shapes.py: circular D, h, t; elliptical a, b, h, t; corner_filleted length,
r, h, t; leaf length, thickness, width and optional fillet), ``E`` (Pa), ``nu``, optional
``plane`` (auto, stress, strain; auto by the rule of engine/hinges/fe/fe_model.py), optional
``resolution`` (elements across a section, 4..64, default 16) and the strengths (``material``,
``sigma_y``, ``sigma_u``, ``sigma_e``: stiffness_block.py). The stiffness, the peak-stress
coefficients and the fibres' signed-stress coefficients (fatigue) come from one
finite-element solve, cached on disk (engine/hinges/fe/cache.py).
"""
from __future__ import annotations

from typing import Any

import numpy as np

from flexure_sim.engine.hinges.fe import fe_model
from flexure_sim.engine.kinematics import hyperdual as hd
from flexure_sim.engine.hinges.fe.mesh import MeshError
from flexure_sim.engine.hinges.fe.shapes import SHAPES, ShapeError
from flexure_sim.engine.hinges.fe.solves import DEFAULT_RESOLUTION
from flexure_sim.engine.hinges.stress import StressGeometry
from flexure_sim.engine.mechanism.values import Ctx
from flexure_sim.engine.mechanism.values import no_unknown, number, require, shown

PLANES = ("auto", "stress", "strain")
RESOLUTIONS = (4, 64)


def fe_numbers(ctx: Ctx, key: str, spec: dict) -> dict[str, Any]:
    """
    Return the checked numbers of a ``model: fe`` spec (``sigma_y`` already taken out).

    {"shape", "geometry": {length key: m}, "E", "nu", "plane", "resolution"}.
    """
    name = require(ctx, key, spec, "shape")
    if not isinstance(name, str) or name not in SHAPES:
        raise ctx.fail(f"{key}.shape", f"unknown hinge shape {shown(name)} "
                       f"({', '.join(SHAPES)})")
    s = SHAPES[name]
    no_unknown(ctx, key, spec, {"model", "shape", "E", "nu", "plane", "resolution", *s.keys})
    geometry = {}
    for k in s.keys:
        if k in s.optional and k not in spec:
            geometry[k] = 0.0
            continue
        geometry[k] = number(ctx, f"{key}.{k}", require(ctx, key, spec, k),
                             positive=k not in s.optional, nonnegative=True)
    E = number(ctx, f"{key}.E", require(ctx, key, spec, "E"), positive=True)
    nu = number(ctx, f"{key}.nu", require(ctx, key, spec, "nu"))
    if not 0 <= float(hd.real(nu)) < 0.5:  # a design's nu may carry derivative parts
        raise ctx.fail(f"{key}.nu", f"Poisson's ratio must be in [0, 0.5), got {nu}")
    plane = spec.get("plane", "auto")
    if plane not in PLANES:
        raise ctx.fail(f"{key}.plane", f"expected one of {', '.join(PLANES)}, got {shown(plane)}")
    resolution = spec.get("resolution", DEFAULT_RESOLUTION)
    if (isinstance(resolution, bool) or not isinstance(resolution, int)
            or not RESOLUTIONS[0] <= resolution <= RESOLUTIONS[1]):
        raise ctx.fail(f"{key}.resolution", "expected a whole number of elements across a "
                       f"section, {RESOLUTIONS[0]}..{RESOLUTIONS[1]}, got {shown(resolution)}")
    return {"shape": name, "geometry": geometry, "E": E, "nu": nu, "plane": plane,
            "resolution": resolution}


def fe_stiffness(ctx: Ctx, key: str, spec: dict, sigma_y,
                 strengths: dict) -> tuple[np.ndarray, Any]:
    """
    Return (K, StressGeometry or None) of a ``model: fe`` spec, solving or from the cache.

    ``strengths``: the other strength fields of the StressGeometry (stiffness_block.py).
    """
    v = fe_numbers(ctx, key, spec)
    name, geo = v["shape"], v["geometry"]
    sharp = name == "leaf" and float(hd.real(geo["fillet"])) == 0
    if sigma_y is not None and sharp:  # checked before solving
        raise ctx.fail(f"{key}.sigma_y", "a leaf without fillets has a stress singularity at "
                       "its clamped corners: give it a fillet radius > 0 for the stress "
                       "analyses")
    try:
        K, peak, fibres = fe_model.hinge(name, geo, v["E"], v["nu"], v["plane"], v["resolution"])
    except ShapeError as exc:
        raise ctx.fail(key, str(exc)) from None
    except MeshError as exc:
        raise ctx.fail(key, f"the finite-element model failed: {exc}") from None
    # floats, or HyperDual entries where a design (mechanism/parameters.py) seeds derivatives
    # no finite peak stress in a sharp leaf: no stress
    geometry = (None if sharp else StressGeometry(
        "fe", (*peak, tuple(tuple(row) for row in fibres)), sigma_y, **strengths))
    return hd.asarray(K), geometry


#: Strength keys a ``model: fe`` block may carry; the 3-D engine has no stress outputs yet.
STRENGTHS = ("material", "sigma_y", "sigma_u", "sigma_e")
#: Elements across the neck of the 3-D (tetrahedral) model: the range and its default.
SOLID_RESOLUTIONS = (2, 8)


def fe_stiffness6(ctx: Ctx, key: str, spec: dict, planar_file: bool = False) -> np.ndarray:
    """
    Return the 6x6 stiffness of a ``model: fe`` spec from the 3-D solid (hinges/fe/solid.py).

    The keys are the planar block's; ``plane`` is not used (the solid needs no plane
    assumption). ``resolution`` in a 3-D file is the tetrahedral mesh's elements across the
    neck (2..8, default solid.DEFAULT_RESOLUTION); in a planar file opened in 3-D it is the
    planar mesh's and the 3-D model takes its default.
    """
    from flexure_sim.engine.hinges.fe import solid

    spec = {k: v for k, v in spec.items() if k not in STRENGTHS}
    n = spec.pop("resolution", None) if not planar_file else None
    if n is None:
        n = solid.DEFAULT_RESOLUTION
    elif (isinstance(n, bool) or not isinstance(n, int)
          or not SOLID_RESOLUTIONS[0] <= n <= SOLID_RESOLUTIONS[1]):
        raise ctx.fail(f"{key}.resolution", "expected a whole number of elements across the "
                       f"neck of the 3-D mesh, {SOLID_RESOLUTIONS[0]}..{SOLID_RESOLUTIONS[1]}, "
                       f"got {shown(n)}")
    v = fe_numbers(ctx, key, spec)
    try:
        return solid.stiffness(v["shape"], v["geometry"], float(v["E"]), float(v["nu"]), n)
    except ShapeError as exc:
        raise ctx.fail(key, str(exc)) from None
    except MeshError as exc:
        raise ctx.fail(key, f"the finite-element model failed: {exc}") from None
