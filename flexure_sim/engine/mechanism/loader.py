"""
Loading mechanisms from YAML, with validation that names the file, the key and the problem.

Format (SI units; see config/microstage.yaml for a complete example)::

    name: microstage
    defaults: {law: twistor, damping: {t_char: 1.0e-3}}
    stiffness_models:                        # optional named stiffness specifications
      notch: {model: notch, D: 0.003, h: 0.00025, t: 0.02, E: 69.0e9, nu: 0.33}
    bodies:
      - {name: body1, mass: 0.0712, inertia: 8.8e-6, pose: [0, 0, 0]}     # pose: x, y, theta
      - {name: lever, material: 7075-T6, thickness: 0.01,                 # or a plate: mass and
         shape: {rectangle: [-0.02, -0.005, 0.02, 0.005]}}               # inertia of the outline
    hinges:
      - name: a
        a: {body: body2, at: [0.007, 0.012]} # frame on body A, body coordinates [x, y(, angle)]
        b: {body: body6, at: [-0.007, 0.0]}
        stiffness: notch                     # a name above, or an inline {model: ...}
        law: twistor                         # twistor (Ch. 4) | twist (Ch. 3) | {polynomial: FILE}
        damping: {t_char: 1.0e-3}            # B = t_char K, or {B: [[...], [...], [...]]}
    constraints:
      - {type: fixed, body: body1}
      - {type: drive, body: body6, axis: [1, 0], response_time: 1.0e-3,
         stroke: [0.0, 2.0e-6], slew_rate: 0.01}
      - {type: sine_rate, body: link2, coordinate: theta, amplitude: 4.9348, frequency: 5.0}
    output: {body: body4, axis: [1, 0]}

A ``drive`` may carry a piezo actuator block ``actuator: {command, v_min, v_max, bandwidth,
stiffness, hysteresis: {alpha, beta, gamma}, creep: [{ratio, tau}, ...]}``: see
engine/mechanism/actuator_block.py and engine/actuators/piezo.py.

Several drives: give each a ``name`` (a single unnamed drive is named ``drive``). ``axis``
may name one coordinate instead (``axis: theta``: a tangential piezo turning the body; input
in rad; the body's other coordinates stay free). ``type: force``: a force-controlled drive,
the commanded force (N; N m on theta; ``stroke`` is the force range) acts on the body along
its axis, whose coordinates stay free. Several outputs::

    outputs:
      - {name: x, body: platform, axis: [1, 0]}
      - {name: theta, body: platform, coordinate: theta}
    compression_hinge: a
    sensor: {noise_rms: 2.0e-9, resolution: 1.0e-9, bandwidth: 5000.0, latency: 1, seed: 0}
                                              # optional, needs output; see
                                              # engine/actuators/sensor.py
    damping: {model: modal, ratio: 0.01}     # optional, besides the hinges' own: a damping
                                              # matrix C at rest; see
                                              # engine/mechanism/damping_block.py

Stiffness models: ``notch`` (D, h, t, E, nu), ``cantilever`` (length, thickness, width, E,
nu), ``matrix`` (K: 3x3, or Ko, Kt: [kx, ky] and optional Kc: [cx, cy]). A notch or
cantilever model may name its ``material`` (engine/hinges/materials.py: E, nu and strengths it
does not give itself) and give the strengths ``sigma_y``, ``sigma_u``, ``sigma_e`` with
``fatigue_cycles`` (Pa); its hinges get ``Hinge.stress`` (the dimensions given to the stiffness
formula, and the strengths) for the stress and fatigue analyses.

``law: {polynomial: FILE}`` uses a polynomial law fitted by ``flexure-sim fit`` (FILE relative
to the mechanism file); such a hinge has no ``stiffness`` key: K is the law's Hessian at rest,
and ``damping: {t_char}`` means B = t_char K as for the other laws.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path
from typing import Any

import numpy as np

from flexure_sim.engine.kinematics.hyperdual import real
from flexure_sim.engine.mechanism.builtins import builtin_names, find_builtin
from flexure_sim.engine.mechanism.body_block import mass_and_inertia
from flexure_sim.engine.mechanism.constraints_block import _constraints, _outputs, _sensor
from flexure_sim.engine.mechanism.damping_block import hinge_damping, mechanism_damping
from flexure_sim.engine.mechanism.stiffness_block import check_spd as _check_spd
from flexure_sim.engine.mechanism.stiffness_block import stiffness as _stiffness
from flexure_sim.engine.mechanism.values import ConfigError  # noqa: F401 (re-exported)
from flexure_sim.engine.mechanism.values import axis as _axis
from flexure_sim.engine.mechanism.values import body_ref as _body_ref
from flexure_sim.engine.mechanism.values import Ctx as _Ctx
from flexure_sim.engine.mechanism.values import key_text as _key_text
from flexure_sim.engine.mechanism.values import mapping as _mapping
from flexure_sim.engine.mechanism.values import name as _name
from flexure_sim.engine.mechanism.values import no_unknown as _no_unknown
from flexure_sim.engine.mechanism.values import require as _require
from flexure_sim.engine.mechanism.values import shown as _shown
from flexure_sim.engine.mechanism.values import vector as _vector
from flexure_sim.engine.mechanism.builtins import searched as builtin_search_places
from flexure_sim.engine.mechanism.yaml_files import read_yaml
from flexure_sim.engine.laws.coordinates import COORDINATES
from flexure_sim.engine.laws.quadratic import QuadraticLaw
from flexure_sim.engine.mechanism.parts import Body, Drive, Frame, Hinge, Mechanism, Output
from flexure_sim.engine.laws.polynomial import PolynomialLaw
from flexure_sim.engine.mechanism.polynomial_files import PolynomialFileError
from flexure_sim.engine.mechanism.polynomial_files import load_law as load_polynomial_law

#: Largest mismatch (m) allowed between a hinge's two frames in the unstressed pose.
COINCIDENCE_TOLERANCE = 1e-9


# ------------------------------------------------------------------------ loading

def load_mechanism(name_or_path: str | Path) -> Mechanism:
    """Load a built-in mechanism by name (``microstage``) or a YAML file by path."""
    return mechanism_from_dict(*load_document(name_or_path))


def load_document(name_or_path: str | Path) -> tuple[Any, str]:
    """
    Return the parsed YAML document of a mechanism (built-in name or path) and its source.

    The source is the file's path: messages name it, and files the mechanism refers to are
    relative to it. ``mechanism_from_dict(*load_document(x))`` is ``load_mechanism(x)``.
    """
    path = resolve_mechanism_path(name_or_path)
    return read_yaml(path, ConfigError), str(path)


def resolve_mechanism_path(name_or_path: str | Path) -> Path:
    """
    Return a path as given if it exists or looks like a file; else a built-in name.

    Built-ins come from the running install's own share/flexure_sim/config (or the source
    checkout's config/), else from the ament index: engine/mechanism/builtins.py says why.
    """
    candidate = Path(name_or_path)
    if candidate.suffix in (".yaml", ".yml") or candidate.exists() or "/" in str(name_or_path):
        if not candidate.exists():
            raise ConfigError(f"{candidate}: no such mechanism file")
        return candidate
    path = find_builtin(str(name_or_path))
    if path is not None:
        return path
    names = builtin_names()
    known = f"built-ins: {', '.join(names)}" if names else (
        f"no built-ins found in {builtin_search_places()}")
    raise ConfigError(f"{name_or_path}: no such built-in mechanism ({known})")


def mechanism_from_dict(data: Any, source: str = "<dict>") -> Mechanism:
    """Validate a parsed YAML document and build the Mechanism."""
    ctx = _Ctx(source)
    if not isinstance(data, dict):
        raise ConfigError(f"{source}: the document must be a mapping, got {type(data).__name__}")
    if "space" in data:
        raise ctx.fail("space", "a 3-D mechanism: the planar engine does not load it (the "
                       "spatial engine does: engine/mechanism/spatial_loader.py; flexure-sim "
                       "simulate, modes, frf and linearize pick it for such files)")
    _no_unknown(ctx, "", data, {
        "name", "description", "source", "defaults", "stiffness_models", "bodies", "hinges",
        "constraints", "output", "outputs", "compression_hinge", "metadata", "sensor",
        "damping",
    })
    name = _name(ctx, "name", _require(ctx, "", data, "name"))
    defaults = _mapping(ctx, "defaults", data.get("defaults", {}))
    _no_unknown(ctx, "defaults", defaults, {"law", "damping"})

    named_stiffness = {
        _name(ctx, f"stiffness_models.{_key_text(k)}", k):
            _stiffness(ctx, f"stiffness_models.{_key_text(k)}", v)
        for k, v in _mapping(ctx, "stiffness_models", data.get("stiffness_models", {})).items()
    }

    bodies = _bodies(ctx, _require(ctx, "", data, "bodies"))
    by_name = {b.name: b for b in bodies}
    hinges = _hinges(ctx, _require(ctx, "", data, "hinges"), by_name, named_stiffness, defaults)
    constraints = _constraints(ctx, _require(ctx, "", data, "constraints"), by_name)

    output = None
    if "output" in data:
        spec = _mapping(ctx, "output", data["output"])
        _no_unknown(ctx, "output", spec, {"body", "axis"})
        output = Output(
            _body_ref(ctx, "output.body", spec, by_name),
            _axis(ctx, "output.axis", spec.get("axis", [1, 0])),
        )
    outputs = _outputs(ctx, data["outputs"], by_name) if "outputs" in data else ()
    if outputs and output is not None:
        raise ctx.fail("outputs", "give either output or outputs, not both")
    compression = data.get("compression_hinge")
    if compression is not None and not isinstance(compression, str):
        raise ctx.fail("compression_hinge", f"expected a hinge name, got {_shown(compression)}")
    if compression is not None and compression not in {h.name for h in hinges}:
        raise ctx.fail("compression_hinge", f"unknown hinge {_shown(compression)} (hinges: "
                       f"{', '.join(h.name for h in hinges)})")
    if compression is not None and not any(isinstance(c, Drive) for c in constraints):
        raise ctx.fail(
            "compression_hinge", "needs a drive constraint (measured along the drive axis)"
        )
    metadata = _mapping(ctx, "metadata", data.get("metadata", {}))
    sensor = _sensor(ctx, data["sensor"], output) if "sensor" in data else None
    mech = Mechanism(
        name=name,
        bodies=tuple(bodies),
        hinges=tuple(hinges),
        constraints=tuple(constraints),
        output=output,
        compression_hinge=compression,
        description=str(data.get("description", "")),
        source=str(data.get("source", source)),
        metadata=dict(metadata),
        sensor=sensor,
        outputs=outputs,
    )
    if "damping" not in data:
        return mech
    # The modes are those of the free coordinates.
    from flexure_sim.engine.solver.model import partition
    n_modes = len(partition(mech).free)
    return dataclasses.replace(mech, damping=mechanism_damping(ctx, data["damping"], n_modes))


def _bodies(ctx: _Ctx, raw: Any) -> list[Body]:
    if not isinstance(raw, list) or not raw:
        raise ctx.fail("bodies", "expected a non-empty list of bodies")
    bodies, seen = [], set()
    for i, spec in enumerate(raw):
        key = f"bodies[{i}]"
        spec = _mapping(ctx, key, spec)
        _no_unknown(ctx, key, spec, {"name", "mass", "inertia", "pose", "shape", "description",
                                     "material", "density", "thickness"})
        name = _name(ctx, f"{key}.name", _require(ctx, key, spec, "name"))
        if name in seen:
            raise ctx.fail(f"{key}.name", f"duplicate body name {name!r}")
        seen.add(name)
        pose = _vector(ctx, f"{key}.pose", spec.get("pose", [0, 0, 0]), (2, 3))
        if len(pose) == 2:
            pose.append(0.0)
        shape = _shape(ctx, f"{key}.shape", spec["shape"]) if "shape" in spec else None
        # given, or of a plate of a material cut to the shape (body_block.py)
        mass, inertia = mass_and_inertia(ctx, key, spec, shape)
        bodies.append(Body(name, mass, inertia, (pose[0], pose[1], pose[2]), shape))
    return bodies


def _shape(ctx: _Ctx, key: str, spec: Any) -> tuple[tuple[float, float], ...]:
    """
    Read a body's display outline: ``{rectangle: [x0, y0, x1, y1]}`` or ``{polygon: [[x, y]...]}``.

    Coordinates are in the body frame (m); a rectangle becomes its four corners.
    """
    spec = _mapping(ctx, key, spec)
    if len(spec) != 1 or next(iter(spec)) not in ("rectangle", "polygon"):
        raise ctx.fail(key, "expected {rectangle: [x0, y0, x1, y1]} or {polygon: [[x, y], ...]}")
    if "rectangle" in spec:
        x0, y0, x1, y1 = _vector(ctx, f"{key}.rectangle", spec["rectangle"], (4,))
        if x0 == x1 or y0 == y1:
            raise ctx.fail(f"{key}.rectangle", "has no area (x0 == x1 or y0 == y1)")
        return ((x0, y0), (x1, y0), (x1, y1), (x0, y1))
    raw = spec["polygon"]
    if not isinstance(raw, list) or len(raw) < 3:
        raise ctx.fail(f"{key}.polygon", "expected a list of at least 3 points [x, y]")
    points = []
    for i, v in enumerate(raw):
        x, y = _vector(ctx, f"{key}.polygon[{i}]", v, (2,))
        points.append((x, y))
    return tuple(points)


def _frame(ctx: _Ctx, key: str, spec: Any, by_name: dict[str, Body]) -> Frame:
    spec = _mapping(ctx, key, spec)
    _no_unknown(ctx, key, spec, {"body", "at"})
    body = _body_ref(ctx, f"{key}.body", spec, by_name)
    at = _vector(ctx, f"{key}.at", _require(ctx, key, spec, "at"), (2, 3))
    return Frame(body, (at[0], at[1]), at[2] if len(at) == 3 else 0.0)


def _real_frame(frame: Frame) -> Frame:
    """Return the frame with the real parts of hyper-dual numbers (values.py)."""
    return Frame(frame.body, (float(real(frame.position[0])), float(real(frame.position[1]))),
                 float(real(frame.angle)))


def frame_pose_at_rest(frame: Frame, body: Body) -> tuple[np.ndarray, float]:
    """Position (root frame) and angle of a frame when its body is at its initial pose."""
    x, y, th = body.pose
    c, s = math.cos(th), math.sin(th)
    fx, fy = frame.position
    return np.array([x + c * fx - s * fy, y + s * fx + c * fy]), th + frame.angle


def _hinges(ctx, raw, by_name, named_stiffness, defaults) -> list[Hinge]:
    if not isinstance(raw, list) or not raw:
        raise ctx.fail("hinges", "expected a non-empty list of hinges")
    hinges, seen = [], set()
    polynomials: dict[Path, PolynomialLaw] = {}
    for i, spec in enumerate(raw):
        key = f"hinges[{i}]"
        spec = _mapping(ctx, key, spec)
        _no_unknown(
            ctx, key, spec, {"name", "a", "b", "stiffness", "law", "damping", "description"}
        )
        name = _name(ctx, f"{key}.name", _require(ctx, key, spec, "name"))
        if name in seen:
            raise ctx.fail(f"{key}.name", f"duplicate hinge name {name!r}")
        seen.add(name)
        fa = _frame(ctx, f"{key}.a", _require(ctx, key, spec, "a"), by_name)
        fb = _frame(ctx, f"{key}.b", _require(ctx, key, spec, "b"), by_name)
        if fa.body == fb.body:
            raise ctx.fail(f"{key}.b.body", f"hinge joins body {fa.body!r} to itself")
        with np.errstate(all="ignore"):  # a design's frames: their real parts (values.py)
            pa, tha = frame_pose_at_rest(_real_frame(fa), by_name[fa.body])
            pb, thb = frame_pose_at_rest(_real_frame(fb), by_name[fb.body])
            gap = float(np.linalg.norm(pa - pb))
        if not np.all(np.isfinite([*pa, *pb, tha - thb])):
            raise ctx.fail(key, "the frames' poses at rest are not finite (body poses or frame "
                           "positions too large: check the units)")
        turn = abs(math.remainder(tha - thb, 2 * math.pi))
        if gap > COINCIDENCE_TOLERANCE or turn > 1e-9:
            raise ctx.fail(
                key,
                f"frames a and b do not coincide in the unstressed pose: a at "
                f"({pa[0]:.6g}, {pa[1]:.6g}, {tha:.6g} rad), b at ({pb[0]:.6g}, {pb[1]:.6g}, "
                f"{thb:.6g} rad)",
            )
        law_key = f"{key}.law" if "law" in spec else "defaults.law"
        law_name = spec.get("law", defaults.get("law", "twistor"))
        poly = (
            _polynomial_law(ctx, law_key, law_name, polynomials)
            if isinstance(law_name, dict)
            else None
        )
        if poly is not None:
            if "stiffness" in spec:
                raise ctx.fail(
                    f"{key}.stiffness",
                    "a polynomial law defines the stiffness (its Hessian at rest): "
                    "remove this key",
                )
            K, source, geometry = poly.stiffness_at_rest(), f"polynomial:{poly.source}", None
            _check_spd(ctx, law_key, K, "stiffness at rest (Hessian of the polynomial law)")
        else:
            sspec = _require(ctx, key, spec, "stiffness")
            if isinstance(sspec, str):
                if sspec not in named_stiffness:
                    raise ctx.fail(f"{key}.stiffness",
                                   f"unknown stiffness model name {_shown(sspec)}")
                K, source, geometry = named_stiffness[sspec]
            else:
                K, source, geometry = _stiffness(ctx, f"{key}.stiffness", sspec)
            _check_spd(ctx, f"{key}.stiffness", K, "stiffness")
            if not isinstance(law_name, str) or law_name not in COORDINATES:
                raise ctx.fail(law_key,
                               f"unknown law {_shown(law_name)} ({', '.join(COORDINATES)}, "
                               "or {polynomial: FILE})")
        B = hinge_damping(ctx, f"{key}.damping", spec.get("damping", defaults.get("damping")),
                          K)
        law = poly.with_damping(B) if poly is not None else QuadraticLaw(law_name, K, B)
        hinges.append(Hinge(name, fa, fb, law, source, stress=geometry))
    return hinges


def _polynomial_law(ctx: _Ctx, key: str, spec: dict, cache: dict) -> PolynomialLaw:
    """
    Return the fitted polynomial law of ``law: {polynomial: FILE}`` (flexure-sim fit).

    FILE is relative to the mechanism file (to the working directory for documents without a
    file).
    """
    _no_unknown(ctx, key, spec, {"polynomial"})
    ref = _require(ctx, key, spec, "polynomial")
    if not isinstance(ref, str) or not ref or "\0" in ref:
        raise ctx.fail(f"{key}.polynomial",
                       f"expected the path of a polynomial hinge file, got {_shown(ref)}")
    origin = Path(ctx.source)
    path = (origin.parent if origin.is_file() else Path.cwd()) / ref
    if path not in cache:
        try:
            cache[path] = load_polynomial_law(path)
        except PolynomialFileError as exc:
            raise ctx.fail(f"{key}.polynomial", str(exc)) from None
    return cache[path]
