"""
Loading spatial mechanisms: ``space: 3d`` files, and planar files opened in 3-D.

A 3-D file (SI units, REP-103 axes; see config/tiptilt_stage.yaml)::

    name: tiptilt_stage
    space: 3d
    defaults: {law: twistor, damping: {t_char: 1.0e-4}}
    stiffness_models:
      leaf: {model: cantilever, length: 0.01, thickness: 0.0005, width: 0.008, E: 7.1e10,
             nu: 0.33}
    bodies:                  # pose: [x, y, z] or [x, y, z, roll, pitch, yaw] (rad, fixed axes)
      - {name: platform, mass: 0.02, inertia: [2.0e-6, 2.0e-6, 3.9e-6], pose: [0, 0, 0.01]}
    hinges:                  # frames: at [x, y, z] (+ rpy) in body coordinates
      - {name: leg1, a: {body: base, at: [0.015, 0, 0.005], rpy: [0, 0, 0]},
         b: {body: platform, at: [0.015, 0, -0.005]}, stiffness: leaf}
    constraints:
      - {type: fixed, body: base}
      - {type: drive, name: p1, body: pusher1, axis: [0, 0, 1], response_time: 1.0e-4,
         stroke: [0.0, 1.5e-5], slew_rate: 0.1}
    outputs:
      - {name: tip, body: platform, coordinate: rx}

``inertia``: [Ixx, Iyy, Izz] (principal, body axes) or a 3x3 tensor, about the mass centre.
Stiffness models: ``notch``, ``cantilever`` (6x6 from ``hinges.spatial_stiffness``), any
``spatial_stiffness.register``-ed model, ``fe`` (the planar ``model: fe`` block, its 6x6 from
the 3-D solid of ``hinges.fe.solid``: ``fe_block.fe_stiffness6``), and ``matrix`` with ``K``
6x6. A drive moves
its body along ``axis`` (its other coordinates held) or along one translation coordinate
(``axis: z``: the others free); ``type: force`` applies a force along an axis or a translation
coordinate, or a torque about a root axis (``axis: rx``). Other planar keys (sine rates,
piezo actuator blocks, the mechanism damping block, a compression hinge) are refused by name.

A planar file opened in 3-D (``load_spatial``) is checked by the planar loader, then each body
and hinge is placed in the plane z = 0 (``planar_in_space``).
"""
from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from flexure_sim.engine.hinges import spatial_stiffness as stiffness
from flexure_sim.engine.mechanism.fe_block import fe_stiffness6
from flexure_sim.engine.kinematics import quaternion as rotation
from flexure_sim.engine.kinematics import hyperdual as hd
from flexure_sim.engine.laws.spatial import SpatialLaw
from flexure_sim.engine.mechanism.damping_block import hinge_damping
from flexure_sim.engine.mechanism.loader import COINCIDENCE_TOLERANCE
from flexure_sim.engine.mechanism.loader import resolve_mechanism_path
from flexure_sim.engine.mechanism.parts import Fixed
from flexure_sim.engine.mechanism.spatial_parts import COORDINATE_NAMES, Body, Drive, Frame
from flexure_sim.engine.mechanism.spatial_parts import Hinge, Mechanism, Output
from flexure_sim.engine.mechanism.stiffness_block import check_spd
from flexure_sim.engine.mechanism.values import ConfigError, Ctx, body_ref, key_text, mapping
from flexure_sim.engine.mechanism.values import name, no_unknown, number, require, shown
from flexure_sim.engine.mechanism.values import vector
from flexure_sim.engine.mechanism.yaml_files import read_yaml


def load_spatial(name_or_path: str | Path) -> Mechanism:
    """Load a built-in or a file as a spatial mechanism (a planar one gets its z dofs)."""
    path = resolve_mechanism_path(name_or_path)
    return spatial_from_dict(read_yaml(path, ConfigError), source=str(path))


def is_spatial(name_or_path: str | Path) -> bool:
    """Tell whether a built-in or a file is a 3-D mechanism (``space: 3d``)."""
    data = read_yaml(resolve_mechanism_path(name_or_path), ConfigError)
    return isinstance(data, dict) and "space" in data


def spatial_from_dict(data: Any, source: str = "<dict>") -> Mechanism:
    """Validate a parsed document (3-D, or planar opened in 3-D) and build the Mechanism."""
    if isinstance(data, dict) and "space" in data:
        if data["space"] != "3d":
            raise Ctx(source).fail("space", f"expected 3d, got {shown(data['space'])}")
        return _spatial(Ctx(source), data)
    from flexure_sim.engine.mechanism.planar_in_space import opened_in_space
    return opened_in_space(data, source)


def _spatial(ctx: Ctx, data: dict) -> Mechanism:
    no_unknown(ctx, "", data, {"name", "space", "description", "source", "defaults",
                               "stiffness_models", "bodies", "hinges", "constraints",
                               "output", "outputs", "metadata"})
    defaults = mapping(ctx, "defaults", data.get("defaults", {}))
    no_unknown(ctx, "defaults", defaults, {"law", "damping"})
    named = {name(ctx, f"stiffness_models.{key_text(k)}", k):
             stiffness6(ctx, f"stiffness_models.{key_text(k)}", v)
             for k, v in mapping(ctx, "stiffness_models",
                                 data.get("stiffness_models", {})).items()}
    raw = require(ctx, "", data, "bodies")
    if not isinstance(raw, list) or not raw:
        raise ctx.fail("bodies", "expected a non-empty list of bodies")
    bodies: list[Body] = []
    for i, spec in enumerate(raw):
        bodies.append(_body(ctx, f"bodies[{i}]", spec, {b.name for b in bodies}))
    by_name = {b.name: b for b in bodies}
    raw = require(ctx, "", data, "hinges")
    if not isinstance(raw, list) or not raw:
        raise ctx.fail("hinges", "expected a non-empty list of hinges")
    hinges: list[Hinge] = []
    for i, spec in enumerate(raw):
        key = f"hinges[{i}]"
        spec = mapping(ctx, key, spec)
        no_unknown(ctx, key, spec, {"name", "a", "b", "stiffness", "law", "damping",
                                    "description"})
        hname = name(ctx, f"{key}.name", require(ctx, key, spec, "name"))
        if hname in {h.name for h in hinges}:
            raise ctx.fail(f"{key}.name", f"duplicate hinge name {hname!r}")
        fa = _frame(ctx, f"{key}.a", require(ctx, key, spec, "a"), by_name)
        fb = _frame(ctx, f"{key}.b", require(ctx, key, spec, "b"), by_name)
        coincide(ctx, key, fa, fb, by_name)
        sspec = require(ctx, key, spec, "stiffness")
        if isinstance(sspec, str):
            if sspec not in named:
                raise ctx.fail(f"{key}.stiffness", f"unknown stiffness model name {shown(sspec)}")
            K, source = named[sspec]
        else:
            K, source = stiffness6(ctx, f"{key}.stiffness", sspec)
        law = spec.get("law", defaults.get("law", "twistor"))
        hinges.append(Hinge(hname, fa, fb, hinge_law(ctx, key, law, K, spec, defaults), source))
    constraints = _constraints(ctx, require(ctx, "", data, "constraints"), by_name)
    if "output" in data and "outputs" in data:
        raise ctx.fail("outputs", "give either output or outputs, not both")
    outputs: tuple = ()
    if "output" in data:
        outputs = (_output(ctx, "output", data["output"], by_name, "output"),)
    elif "outputs" in data:
        outputs = _outputs(ctx, data["outputs"], by_name)
    return Mechanism(name(ctx, "name", require(ctx, "", data, "name")), tuple(bodies),
                     tuple(hinges), tuple(constraints), outputs,
                     str(data.get("description", "")), str(data.get("source", ctx.source)),
                     dict(mapping(ctx, "metadata", data.get("metadata", {}))))


def hinge_law(ctx: Ctx, key: str, law: Any, K: np.ndarray, spec: dict,
              defaults: dict) -> SpatialLaw:
    """Return a hinge's law: its coordinates, K and B (``{t_char}``: B = t_char K)."""
    law_key = f"{key}.law" if "law" in spec else "defaults.law"
    if not isinstance(law, str) or law not in ("twistor", "twist"):
        raise ctx.fail(law_key, f"expected twistor or twist in a 3-D mechanism, got {shown(law)}")
    dspec = spec.get("damping", defaults.get("damping"))
    dkey = f"{key}.damping" if "damping" in spec else "defaults.damping"
    if isinstance(dspec, dict) and "B" in dspec:
        raise ctx.fail(f"{dkey}.B", "a 3-D hinge's damping is {t_char: seconds} (B = t_char K)")
    return SpatialLaw(law, K, hinge_damping(ctx, dkey, dspec, K))


def stiffness6(ctx: Ctx, key: str, spec: Any) -> tuple[np.ndarray, str]:
    """Return (K 6x6, model name) of a stiffness specification, checked."""
    spec = mapping(ctx, key, spec)
    model = require(ctx, key, spec, "model")
    known = ", ".join([*stiffness.MODELS, "fe", "matrix"])
    if model == "matrix":
        no_unknown(ctx, key, spec, {"model", "K"})
        rows = require(ctx, key, spec, "K")
        if not isinstance(rows, list) or len(rows) != 6:
            raise ctx.fail(f"{key}.K", "expected a 6x6 matrix (six rows of six numbers, "
                           "rotations first)")
        K = hd.asarray([vector(ctx, f"{key}.K[{i}]", r, (6,)) for i, r in enumerate(rows)])
    elif model == "fe":
        K = fe_stiffness6(ctx, key, spec)
    elif isinstance(model, str) and model in stiffness.MODELS:
        formula, names = stiffness.MODELS[model]
        no_unknown(ctx, key, spec, {"model", "sigma_y", *names})
        args = [number(ctx, f"{key}.{n}", require(ctx, key, spec, n), positive=n != "nu")
                for n in names]
        if "nu" in names and not 0 <= args[names.index("nu")] < 0.5:
            raise ctx.fail(f"{key}.nu", "Poisson's ratio must be in [0, 0.5)")
        with np.errstate(all="ignore"):
            K = hd.asarray(formula(*args))  # HyperDual when a design parameter is seeded
    else:
        raise ctx.fail(f"{key}.model", f"unknown stiffness model {shown(model)} ({known})")
    check_spd(ctx, key, K, "stiffness")
    return K, str(model)


def _body(ctx: Ctx, key: str, spec: Any, seen: set) -> Body:
    spec = mapping(ctx, key, spec)
    no_unknown(ctx, key, spec, {"name", "mass", "inertia", "pose", "description"})
    bname = name(ctx, f"{key}.name", require(ctx, key, spec, "name"))
    if bname in seen:
        raise ctx.fail(f"{key}.name", f"duplicate body name {bname!r}")
    mass = number(ctx, f"{key}.mass", require(ctx, key, spec, "mass"), positive=True)
    raw = require(ctx, key, spec, "inertia")
    if isinstance(raw, list) and raw and isinstance(raw[0], list):
        if len(raw) != 3:
            raise ctx.fail(f"{key}.inertia", "expected [Ixx, Iyy, Izz] or a 3x3 tensor")
        inertia = np.array([vector(ctx, f"{key}.inertia[{i}]", r, (3,))
                            for i, r in enumerate(raw)])
    else:
        inertia = np.diag(vector(ctx, f"{key}.inertia", raw, (3,)))
    check_spd(ctx, f"{key}.inertia", inertia, "inertia")
    pose = vector(ctx, f"{key}.pose", spec.get("pose", [0.0, 0.0, 0.0]), (3, 6))
    x, y, z = pose[:3]
    return Body(bname, mass, tuple(tuple(float(v) for v in row) for row in inertia),
                (x, y, z), _quaternion(pose[3:] if len(pose) == 6 else (0.0, 0.0, 0.0)))


def _quaternion(rpy) -> tuple[float, float, float, float]:
    """Return the unit quaternion (w, x, y, z) of roll, pitch, yaw ``rpy``."""
    w, qx, qy, qz = (float(c) for c in rotation.quaternion_of_rpy(*rpy))
    return w, qx, qy, qz


def _frame(ctx: Ctx, key: str, spec: Any, by_name: dict) -> Frame:
    spec = mapping(ctx, key, spec)
    no_unknown(ctx, key, spec, {"body", "at", "rpy"})
    body = body_ref(ctx, f"{key}.body", spec, by_name)
    at = vector(ctx, f"{key}.at", require(ctx, key, spec, "at"), (3,))
    rpy = vector(ctx, f"{key}.rpy", spec.get("rpy", [0.0, 0.0, 0.0]), (3,))
    x, y, z = at
    return Frame(body, (x, y, z), _quaternion(rpy))


def frame_at_rest(frame: Frame, body: Body) -> tuple[np.ndarray, np.ndarray]:
    """Return a frame's position (root) and quaternion when its body is at rest."""
    R = rotation.matrix(body.quaternion)
    q = np.array(rotation.qmul(body.quaternion, frame.quaternion))
    return np.asarray(body.position) + R @ np.asarray(frame.position), q


def coincide(ctx: Ctx, key: str, fa: Frame, fb: Frame, by_name: dict) -> None:
    """Refuse a hinge whose frames do not coincide at rest (names the hinge's key)."""
    if fa.body == fb.body:
        raise ctx.fail(f"{key}.b.body", f"hinge joins body {fa.body!r} to itself")
    with np.errstate(all="ignore"):
        pa, qa = frame_at_rest(fa, by_name[fa.body])
        pb, qb = frame_at_rest(fb, by_name[fb.body])
        gap = float(np.linalg.norm(pa - pb))
        turn = float(np.linalg.norm(np.array(rotation.qconj_mul(tuple(qa), tuple(qb)))[1:]))
    if not np.isfinite(gap + turn):
        raise ctx.fail(key, "the frames' poses at rest are not finite (check the units)")
    if gap > COINCIDENCE_TOLERANCE or turn > 1e-9:
        raise ctx.fail(key, f"frames a and b do not coincide in the unstressed pose: a at "
                       f"{np.round(pa, 9).tolist()}, b at {np.round(pb, 9).tolist()} "
                       f"(rotated {2 * np.arcsin(min(turn, 1.0)):.3g} rad apart)")


def _axis3(ctx: Ctx, key: str, value: Any) -> tuple[float, float, float]:
    v = np.array(vector(ctx, key, value, (3,)))
    largest = np.max(np.abs(v))
    if largest == 0:
        raise ctx.fail(key, "axis must not be zero")
    v = v / largest
    v = v / np.linalg.norm(v)
    return float(v[0]), float(v[1]), float(v[2])


def _output(ctx: Ctx, key: str, spec: Any, by_name: dict, default: str) -> Output:
    spec = mapping(ctx, key, spec)
    no_unknown(ctx, key, spec, {"name", "body", "axis", "coordinate"})
    oname = name(ctx, f"{key}.name", spec["name"]) if "name" in spec else default
    body = body_ref(ctx, f"{key}.body", spec, by_name)
    if ("axis" in spec) == ("coordinate" in spec):
        raise ctx.fail(key, "give either axis or coordinate")
    coord = spec.get("coordinate")
    if coord is not None and coord not in COORDINATE_NAMES:
        raise ctx.fail(f"{key}.coordinate",
                       f"expected one of {', '.join(COORDINATE_NAMES)}, got {shown(coord)}")
    axis = (1.0, 0.0, 0.0) if coord is not None else _axis3(ctx, f"{key}.axis", spec["axis"])
    return Output(body, axis, oname, coord)


def _outputs(ctx: Ctx, raw: Any, by_name: dict) -> tuple[Output, ...]:
    if not isinstance(raw, list) or not raw:
        raise ctx.fail("outputs", "expected a non-empty list of outputs")
    out: list[Output] = []
    for i, spec in enumerate(raw):
        if not isinstance(spec, dict) or "name" not in spec:
            raise ctx.fail(f"outputs[{i}].name", "missing required key")
        o = _output(ctx, f"outputs[{i}]", spec, by_name, "")
        if o.name in {p.name for p in out}:
            raise ctx.fail(f"outputs[{i}].name", f"duplicate output name {o.name!r}")
        out.append(o)
    return tuple(out)


def _constraints(ctx: Ctx, raw: Any, by_name: dict) -> list:
    if not isinstance(raw, list):
        raise ctx.fail("constraints", "expected a list of constraints")
    out: list = []
    held: dict[tuple[str, int], str] = {}
    for i, spec in enumerate(raw):
        key = f"constraints[{i}]"
        spec = mapping(ctx, key, spec)
        kind = require(ctx, key, spec, "type")
        body = body_ref(ctx, f"{key}.body", spec, by_name)
        if kind == "fixed":
            no_unknown(ctx, key, spec, {"type", "body"})
            out.append(Fixed(body))
            coords: tuple = tuple(range(6))
        elif kind in ("drive", "force"):
            c = drive(ctx, key, spec, kind, [d for d in out if isinstance(d, Drive)])
            out.append(c)
            coords = drive_coordinates(c)
        else:
            raise ctx.fail(f"{key}.type", f"unknown constraint type {shown(kind)} in a 3-D "
                           "mechanism (fixed, drive, force)")
        for k in coords:
            if (body, k) in held:
                raise ctx.fail(key, f"coordinate {COORDINATE_NAMES[k]} of body {body!r} is "
                               f"already constrained by {held[(body, k)]}")
            held[(body, k)] = key
    for d in out:
        if isinstance(d, Drive) and d.kind == "force":
            for k in force_coordinates(d):
                if (d.body, k) in held:
                    raise ctx.fail("constraints", f"force drive {d.name!r} needs coordinate "
                                   f"{COORDINATE_NAMES[k]} of body {d.body!r} free")
    if not any(isinstance(c, Fixed) for c in out):
        raise ctx.fail("constraints", "the mechanism has no fixed body")
    return out


def drive(ctx: Ctx, key: str, spec: dict, kind: str, earlier: list) -> Drive:
    """Return the checked constraint of ``type: drive`` or ``type: force``."""
    no_unknown(ctx, key, spec, {"type", "name", "body", "axis", "response_time", "stroke",
                                "slew_rate"})
    stroke = vector(ctx, f"{key}.stroke", require(ctx, key, spec, "stroke"), (2,))
    if stroke[0] >= stroke[1]:
        raise ctx.fail(f"{key}.stroke", f"expected [min, max] with min < max, got {stroke}")
    axis_spec = require(ctx, key, spec, "axis")
    coord = axis_spec if isinstance(axis_spec, str) else None
    allowed = COORDINATE_NAMES if kind == "force" else COORDINATE_NAMES[:3]
    if coord is not None and coord not in allowed:
        why = (" (a displacement drive on a rotation coordinate with the body's other "
               "coordinates free is not supported in 3-D: hold the body or use a force drive)"
               if coord in COORDINATE_NAMES else "")
        raise ctx.fail(f"{key}.axis", f"expected a vector [x, y, z] or one of "
                       f"{', '.join(allowed)}, got {shown(coord)}{why}")
    dname = name(ctx, f"{key}.name", spec["name"]) if "name" in spec else "drive"
    if any(d.name == dname for d in earlier):
        raise ctx.fail(f"{key}.name", f"duplicate drive name {dname!r}"
                       + ("" if "name" in spec else ": name every drive"))
    return Drive(spec["body"],
                 (1.0, 0.0, 0.0) if coord is not None else _axis3(ctx, f"{key}.axis", axis_spec),
                 number(ctx, f"{key}.response_time", require(ctx, key, spec, "response_time"),
                        positive=True),
                 (stroke[0], stroke[1]),
                 number(ctx, f"{key}.slew_rate", require(ctx, key, spec, "slew_rate"),
                        positive=True),
                 dname, coord, "force" if kind == "force" else "displacement")


def drive_coordinates(d: Drive) -> tuple:
    """Return the body coordinates a drive prescribes (none for a force drive)."""
    if d.kind == "force":
        return ()
    return tuple(range(6)) if d.coordinate is None else (COORDINATE_NAMES.index(d.coordinate),)


def force_coordinates(d: Drive) -> tuple:
    """Return the body coordinates a force drive acts on (they must stay free)."""
    if d.coordinate is not None:
        return (COORDINATE_NAMES.index(d.coordinate),)
    return tuple(k for k in range(3) if d.axis[k] != 0.0)
