"""
A planar mechanism file opened in 3-D: the same mechanism with its out-of-plane freedoms.

The planar loader checks the document first (its messages, its rules). Then every body and
hinge is placed in the plane z = 0: a body's pose (x, y, theta) becomes position (x, y, 0) and
the rotation theta about z, a hinge frame (x, y, angle) likewise; drives, force drives and
outputs keep their axes (in the plane) or coordinates (``theta`` is ``rz``). Each hinge gets
the 6x6 stiffness of its ``notch`` or ``cantilever`` model (``hinges.spatial_stiffness``),
whose in-plane block is the planar 3x3 exactly, or of its ``model: fe`` block from the 3-D
solid (``hinges.fe.solid``: its in-plane block is the solid's, not the planar solve's), and
B = t_char K6 for ``damping: {t_char}``.

What the plane does not say, and how it is chosen:

- the plate thickness T of a body: the largest out-of-plane width of its hinges (a notch's
  ``t``, a leaf's ``width``), the thickness the stage is cut from;
- the inertia about the in-plane axes: I_xx = I_yy = I_zz / 2 + m T^2 / 12, a plate of
  thickness T whose in-plane second moments are equal (exact for a square or round outline;
  a plate's I_xx + I_yy = I_zz + m T^2 / 6 holds for any outline).

Refused by name: hinges with a ``matrix`` stiffness (3x3: no out-of-plane terms) or a
polynomial law, a hinge damping matrix ``B`` (3x3), ``sine_rate`` constraints and displacement
drives on ``theta`` (a prescribed rotation with the body's other rotations free), piezo
``actuator`` blocks and the mechanism ``damping`` block.
"""
from __future__ import annotations

from typing import Any

from flexure_sim.engine.hinges import spatial_stiffness as stiffness
from flexure_sim.engine.hinges.fe.shapes import SHAPES
from flexure_sim.engine.kinematics import hyperdual as hd
from flexure_sim.engine.kinematics import quaternion as rotation
from flexure_sim.engine.mechanism.fe_block import fe_stiffness6
from flexure_sim.engine.mechanism.loader import mechanism_from_dict
from flexure_sim.engine.mechanism.parts import Drive as PlanarDrive
from flexure_sim.engine.mechanism.parts import Fixed, SineRate
from flexure_sim.engine.mechanism.spatial_loader import hinge_law
from flexure_sim.engine.mechanism.spatial_parts import PLANAR_NAMES, Body, Drive, Frame
from flexure_sim.engine.mechanism.spatial_parts import Hinge, Mechanism, Output
from flexure_sim.engine.mechanism.values import Ctx


def opened_in_space(data: Any, source: str) -> Mechanism:
    """Return the spatial mechanism of a planar document (module docstring)."""
    planar = mechanism_from_dict(data, source)
    ctx = Ctx(source)
    if "damping" in data:
        raise ctx.fail("damping", "the mechanism damping block is not supported in 3-D yet "
                       "(use the hinges' damping: {t_char})")
    defaults = data.get("defaults", {})
    named = data.get("stiffness_models", {})
    hinges: list = []
    widths: dict[str, Any] = {b.name: 0.0 for b in planar.bodies}  # float or HyperDual
    for i, (h, spec) in enumerate(zip(planar.hinges, data["hinges"])):
        key = f"hinges[{i}]"
        if not isinstance(spec.get("law", defaults.get("law", "twistor")), str):
            raise ctx.fail(f"{key}.law", "a polynomial law has no out-of-plane terms: the 3-D "
                           "model needs the twistor or twist law")
        sspec = spec["stiffness"]
        where = f"stiffness_models.{sspec}" if isinstance(sspec, str) else f"{key}.stiffness"
        sspec = named[sspec] if isinstance(sspec, str) else sspec
        model = sspec["model"]
        width: Any  # the plate thickness: a float, or HyperDual (design sensitivities)
        if model == "fe":
            K6 = fe_stiffness6(ctx, where, sspec, planar_file=True)
            width = float(sspec[SHAPES[sspec["shape"]].plate])
        elif model in ("notch", "cantilever"):
            formula, names = stiffness.MODELS[model]
            # The planar loader checked these; HyperDual values (design sensitivities) stay so.
            args = [v if isinstance(v, hd.HyperDual) else float(v)
                    for v in (sspec[n] for n in names)]
            K6 = hd.asarray(formula(*args))
            width = args[names.index("t" if model == "notch" else "width")]
        else:
            raise ctx.fail(f"{where}.model", f"a {model} stiffness (3x3) has no out-of-plane "
                           "terms: open the file in 3-D with notch, cantilever or fe hinges, "
                           "or write a 3-D file with a 6x6 matrix")
        for frame in (h.a, h.b):
            if hd.real(width) > hd.real(widths[frame.body]):
                widths[frame.body] = width
        law = spec.get("law", defaults.get("law", "twistor"))
        hinges.append(Hinge(h.name, _frame(h.a), _frame(h.b),
                            hinge_law(ctx, key, law, K6, spec, defaults), model))
    bodies = tuple(_body(b, widths[b.name]) for b in planar.bodies)
    constraints = tuple(_constraint(ctx, i, c) for i, c in enumerate(planar.constraints))
    outputs = tuple(Output(o.body, (*o.axis, 0.0), o.name,
                           None if o.coordinate is None else PLANAR_NAMES[o.coordinate])
                    for o in planar.all_outputs)
    return Mechanism(planar.name, bodies, tuple(hinges), constraints, outputs,
                     planar.description, planar.source, dict(planar.metadata), planar)


def _body(body, thickness: float) -> Body:
    x, y, theta = body.pose
    Izz = body.inertia
    Ixy = 0.5 * Izz + body.mass * thickness**2 / 12.0
    inertia = ((Ixy, 0.0, 0.0), (0.0, Ixy, 0.0), (0.0, 0.0, Izz))
    return Body(body.name, body.mass, inertia, (x, y, 0.0), _about_z(theta))


def _about_z(angle: float) -> tuple[float, float, float, float]:
    """Return the unit quaternion (w, x, y, z) of a rotation by ``angle`` about z."""
    w, qx, qy, qz = (float(c) for c in rotation.quaternion_of_rpy(0.0, 0.0, angle))
    return w, qx, qy, qz


def _frame(frame) -> Frame:
    return Frame(frame.body, (*frame.position, 0.0), _about_z(frame.angle))


def _constraint(ctx: Ctx, i: int, c):
    key = f"constraints[{i}]"
    if isinstance(c, Fixed):
        return c
    if isinstance(c, SineRate):
        raise ctx.fail(key, "a sine_rate constraint (a prescribed rotation rate with the body's "
                       "other rotations free) is not supported in 3-D")
    assert isinstance(c, PlanarDrive)
    if c.actuator is not None:
        raise ctx.fail(f"{key}.actuator", "piezo actuator blocks are not supported in 3-D yet")
    coordinate = None if c.coordinate is None else PLANAR_NAMES[c.coordinate]
    if coordinate == "rz" and c.kind == "displacement":
        raise ctx.fail(f"{key}.axis", "a displacement drive on theta (a prescribed rotation with "
                       "the body's other rotations free) is not supported in 3-D")
    ax, ay, az = (float(a) for a in ((*c.axis, 0.0) if coordinate is None else (1.0, 0.0, 0.0)))
    return Drive(c.body, (ax, ay, az), c.response_time, c.stroke,
                 c.slew_rate, c.name, coordinate, c.kind)
