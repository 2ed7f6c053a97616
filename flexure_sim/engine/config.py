"""Loading mechanisms from YAML, with validation that names the file, the key and the problem.

Format (SI units; see config/microstage.yaml for a complete example)::

    name: microstage
    defaults: {law: twistor, damping: {t_char: 1.0e-3}}
    stiffness_models:                        # optional named stiffness specifications
      notch: {model: notch, D: 0.003, h: 0.00025, t: 0.02, E: 69.0e9, nu: 0.33}
    bodies:
      - {name: body1, mass: 0.0712, inertia: 8.8e-6, pose: [0, 0, 0]}     # pose: x, y, theta
    hinges:
      - name: a
        a: {body: body2, at: [0.007, 0.012]}  # frame on body A, body coordinates [x, y(, angle)]
        b: {body: body6, at: [-0.007, 0.0]}
        stiffness: notch                      # a name above, or an inline {model: ...}
        law: twistor                          # twistor (Ch. 4) | twist (Ch. 3) | {polynomial: FILE}
        damping: {t_char: 1.0e-3}             # B = t_char K, or {B: [[...], [...], [...]]}
    constraints:
      - {type: fixed, body: body1}
      - {type: drive, body: body6, axis: [1, 0], response_time: 1.0e-3,
         stroke: [0.0, 2.0e-6], slew_rate: 0.01}
      - {type: sine_rate, body: link2, coordinate: theta, amplitude: 4.9348, frequency: 5.0}
    output: {body: body4, axis: [1, 0]}
    compression_hinge: a

Stiffness models: ``notch`` (D, h, t, E, nu), ``cantilever`` (length, thickness, width, E,
nu), ``matrix`` (K: 3x3, or Ko, Kt: [kx, ky] and optional Kc: [cx, cy]).

``law: {polynomial: FILE}`` uses a polynomial law fitted by ``flexure-sim fit`` (FILE relative
to the mechanism file); such a hinge has no ``stiffness`` key: K is the law's Hessian at rest,
and ``damping: {t_char}`` means B = t_char K as for the other laws.
"""
from __future__ import annotations

import math
from pathlib import Path
from typing import Any, Callable, Optional

import numpy as np

from . import stiffness as stiffness_models
from .yaml_files import read_yaml
from .hinge_laws import COORDINATES, QuadraticLaw
from .mechanism import (
    COORDINATE_NAMES,
    Body,
    Drive,
    Fixed,
    Frame,
    Hinge,
    Mechanism,
    Output,
    SineRate,
)
from .polynomial import PolynomialFileError, PolynomialLaw
from .polynomial import load_law as load_polynomial_law

#: Directory of the built-in mechanisms (installed to share/flexure_sim/config too).
BUILTIN_DIRS = (
    Path(__file__).resolve().parents[2] / "config",
)

#: Largest mismatch (m) allowed between a hinge's two frames in the unstressed pose.
COINCIDENCE_TOLERANCE = 1e-9


class ConfigError(ValueError):
    """A mechanism file is invalid; the message names the file, the key and the problem."""


class _Ctx:
    """Builds error messages that name the file and the key path."""

    def __init__(self, source: str):
        self.source = source

    def fail(self, key: str, problem: str) -> ConfigError:
        return ConfigError(f"{self.source}: {key}: {problem}")


# ---------------------------------------------------------------- primitive checks

def _number(ctx: _Ctx, key: str, value: Any, *, positive=False, nonnegative=False) -> float:
    if isinstance(value, str):
        # PyYAML (YAML 1.1) reads 69.0e9 (no exponent sign) as a string: accept it.
        try:
            value = float(value)
        except ValueError:
            pass
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ctx.fail(key, f"expected a number, got {value!r}")
    v = float(value)
    if not math.isfinite(v):
        raise ctx.fail(key, f"must be finite, got {value!r}")
    if positive and v <= 0:
        raise ctx.fail(key, f"must be positive, got {value!r}")
    if nonnegative and v < 0:
        raise ctx.fail(key, f"must not be negative, got {value!r}")
    return v


def _vector(ctx: _Ctx, key: str, value: Any, lengths: tuple[int, ...]) -> list[float]:
    if not isinstance(value, (list, tuple)) or len(value) not in lengths:
        want = " or ".join(str(n) for n in lengths)
        raise ctx.fail(key, f"expected a list of {want} numbers, got {value!r}")
    return [_number(ctx, f"{key}[{i}]", v) for i, v in enumerate(value)]


def _mapping(ctx: _Ctx, key: str, value: Any) -> dict:
    if not isinstance(value, dict):
        raise ctx.fail(key, f"expected a mapping, got {type(value).__name__}")
    return value


def _require(ctx: _Ctx, key: str, data: dict, name: str) -> Any:
    if name not in data:
        raise ctx.fail(f"{key}.{name}" if key else name, "missing required key")
    return data[name]


def _no_unknown(ctx: _Ctx, key: str, data: dict, allowed: set[str]) -> None:
    unknown = sorted(set(data) - allowed)
    if unknown:
        where = f"{key}.{unknown[0]}" if key else unknown[0]
        raise ctx.fail(where, f"unknown key (allowed: {', '.join(sorted(allowed))})")


def _name(ctx: _Ctx, key: str, value: Any) -> str:
    if not isinstance(value, str) or not value:
        raise ctx.fail(key, f"expected a non-empty name, got {value!r}")
    if not (value[0].isalpha() and all(ch.isalnum() or ch == "_" for ch in value)):
        raise ctx.fail(
            key, f"{value!r} is not a valid name (letters, digits, '_', starting with a letter;"
            " names become ROS topic and frame names)"
        )
    return value


# ---------------------------------------------------------------------- stiffness

_STIFFNESS_KEYS: dict[str, tuple[Callable[..., np.ndarray], tuple[str, ...]]] = {
    "notch": (stiffness_models.notch_stiffness, ("D", "h", "t", "E", "nu")),
    "cantilever": (stiffness_models.cantilever_stiffness, ("length", "thickness", "width", "E", "nu")),
}


def _stiffness(ctx: _Ctx, key: str, spec: Any) -> tuple[np.ndarray, str]:
    spec = _mapping(ctx, key, spec)
    model = _require(ctx, key, spec, "model")
    if model in _STIFFNESS_KEYS:
        fn, names = _STIFFNESS_KEYS[model]
        _no_unknown(ctx, key, spec, {"model", *names})
        args = [_number(ctx, f"{key}.{n}", _require(ctx, key, spec, n), positive=n != "nu") for n in names]
        if model in ("notch", "cantilever"):
            nu = args[-1]
            if not 0 <= nu < 0.5:
                raise ctx.fail(f"{key}.nu", f"Poisson's ratio must be in [0, 0.5), got {nu}")
        return fn(*args), model
    if model == "matrix":
        _no_unknown(ctx, key, spec, {"model", "K", "Ko", "Kt", "Kc"})
        if "K" in spec:
            rows = spec["K"]
            if not isinstance(rows, list) or len(rows) != 3:
                raise ctx.fail(f"{key}.K", "expected a 3x3 matrix (three rows of three numbers)")
            K = np.array([_vector(ctx, f"{key}.K[{i}]", r, (3,)) for i, r in enumerate(rows)])
        else:
            Ko = _number(ctx, f"{key}.Ko", _require(ctx, key, spec, "Ko"))
            kt = _vector(ctx, f"{key}.Kt", _require(ctx, key, spec, "Kt"), (2,))
            kc = _vector(ctx, f"{key}.Kc", spec.get("Kc", [0.0, 0.0]), (2,))
            K = np.array([[Ko, kc[0], kc[1]], [kc[0], kt[0], 0.0], [kc[1], 0.0, kt[1]]])
        return K, "matrix"
    raise ctx.fail(f"{key}.model", f"unknown stiffness model {model!r} (notch, cantilever, matrix)")


def _check_spd(ctx: _Ctx, key: str, M: np.ndarray, what: str) -> None:
    if not np.allclose(M, M.T, rtol=1e-12, atol=0.0):
        raise ctx.fail(key, f"{what} matrix is not symmetric: {M.tolist()}")
    if np.any(np.linalg.eigvalsh(M) <= 0):
        raise ctx.fail(key, f"{what} matrix is not positive definite: {M.tolist()}")


# ------------------------------------------------------------------------ loading

def load_mechanism(name_or_path: str | Path) -> Mechanism:
    """Load a built-in mechanism by name (``microstage``) or a YAML file by path."""
    path = resolve_mechanism_path(name_or_path)
    return mechanism_from_dict(read_yaml(path, ConfigError), source=str(path))


def builtin_names() -> list[str]:
    """Names of the mechanisms shipped in config/."""
    names: set[str] = set()
    for d in _builtin_dirs():
        names.update(p.stem for p in d.glob("*.yaml"))
    return sorted(names)


def _builtin_dirs() -> list[Path]:
    dirs = [d for d in BUILTIN_DIRS if d.is_dir()]
    import sys

    share = Path(sys.prefix) / "share" / "flexure_sim" / "config"
    if share.is_dir():
        dirs.append(share)
    return dirs


def resolve_mechanism_path(name_or_path: str | Path) -> Path:
    """A path as given if it exists or looks like a file; else a built-in name."""
    candidate = Path(name_or_path)
    if candidate.suffix in (".yaml", ".yml") or candidate.exists() or "/" in str(name_or_path):
        if not candidate.exists():
            raise ConfigError(f"{candidate}: no such mechanism file")
        return candidate
    for d in _builtin_dirs():
        p = d / f"{name_or_path}.yaml"
        if p.exists():
            return p
    raise ConfigError(
        f"{name_or_path}: no such built-in mechanism (built-ins: {', '.join(builtin_names())})"
    )


def mechanism_from_dict(data: Any, source: str = "<dict>") -> Mechanism:
    """Validate a parsed YAML document and build the Mechanism."""
    ctx = _Ctx(source)
    if not isinstance(data, dict):
        raise ConfigError(f"{source}: the document must be a mapping, got {type(data).__name__}")
    _no_unknown(ctx, "", data, {
        "name", "description", "source", "defaults", "stiffness_models", "bodies", "hinges",
        "constraints", "output", "compression_hinge", "metadata",
    })
    name = _name(ctx, "name", _require(ctx, "", data, "name"))
    defaults = _mapping(ctx, "defaults", data.get("defaults", {}))
    _no_unknown(ctx, "defaults", defaults, {"law", "damping"})

    named_stiffness = {
        _name(ctx, f"stiffness_models.{k}", k): _stiffness(ctx, f"stiffness_models.{k}", v)
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
        output = Output(_body_ref(ctx, "output.body", spec, by_name), _axis(ctx, "output.axis", spec.get("axis", [1, 0])))
    compression = data.get("compression_hinge")
    if compression is not None and compression not in {h.name for h in hinges}:
        raise ctx.fail("compression_hinge", f"unknown hinge {compression!r}")
    if compression is not None and not any(isinstance(c, Drive) for c in constraints):
        raise ctx.fail("compression_hinge", "needs a drive constraint (measured along the drive axis)")
    metadata = _mapping(ctx, "metadata", data.get("metadata", {}))
    return Mechanism(
        name=name,
        bodies=tuple(bodies),
        hinges=tuple(hinges),
        constraints=tuple(constraints),
        output=output,
        compression_hinge=compression,
        description=str(data.get("description", "")),
        source=str(data.get("source", source)),
        metadata=dict(metadata),
    )


def _bodies(ctx: _Ctx, raw: Any) -> list[Body]:
    if not isinstance(raw, list) or not raw:
        raise ctx.fail("bodies", "expected a non-empty list of bodies")
    bodies, seen = [], set()
    for i, spec in enumerate(raw):
        key = f"bodies[{i}]"
        spec = _mapping(ctx, key, spec)
        _no_unknown(ctx, key, spec, {"name", "mass", "inertia", "pose", "description"})
        name = _name(ctx, f"{key}.name", _require(ctx, key, spec, "name"))
        if name in seen:
            raise ctx.fail(f"{key}.name", f"duplicate body name {name!r}")
        seen.add(name)
        mass = _number(ctx, f"{key}.mass", _require(ctx, key, spec, "mass"), positive=True)
        inertia = _number(ctx, f"{key}.inertia", _require(ctx, key, spec, "inertia"), positive=True)
        pose = _vector(ctx, f"{key}.pose", spec.get("pose", [0, 0, 0]), (2, 3))
        if len(pose) == 2:
            pose.append(0.0)
        bodies.append(Body(name, mass, inertia, (pose[0], pose[1], pose[2])))
    return bodies


def _body_ref(ctx: _Ctx, key: str, spec: dict, by_name: dict[str, Body]) -> str:
    name = spec.get("body")
    if name is None:
        raise ctx.fail(key, "missing required key")
    if name not in by_name:
        raise ctx.fail(key, f"unknown body {name!r} (bodies: {', '.join(by_name)})")
    return name


def _axis(ctx: _Ctx, key: str, value: Any) -> tuple[float, float]:
    v = np.array(_vector(ctx, key, value, (2,)))
    n = np.linalg.norm(v)
    if n == 0:
        raise ctx.fail(key, "axis must not be zero")
    v = v / n
    return float(v[0]), float(v[1])


def _frame(ctx: _Ctx, key: str, spec: Any, by_name: dict[str, Body]) -> Frame:
    spec = _mapping(ctx, key, spec)
    _no_unknown(ctx, key, spec, {"body", "at"})
    body = _body_ref(ctx, f"{key}.body", spec, by_name)
    at = _vector(ctx, f"{key}.at", _require(ctx, key, spec, "at"), (2, 3))
    return Frame(body, (at[0], at[1]), at[2] if len(at) == 3 else 0.0)


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
        _no_unknown(ctx, key, spec, {"name", "a", "b", "stiffness", "law", "damping", "description"})
        name = _name(ctx, f"{key}.name", _require(ctx, key, spec, "name"))
        if name in seen:
            raise ctx.fail(f"{key}.name", f"duplicate hinge name {name!r}")
        seen.add(name)
        fa = _frame(ctx, f"{key}.a", _require(ctx, key, spec, "a"), by_name)
        fb = _frame(ctx, f"{key}.b", _require(ctx, key, spec, "b"), by_name)
        if fa.body == fb.body:
            raise ctx.fail(f"{key}.b.body", f"hinge joins body {fa.body!r} to itself")
        pa, tha = frame_pose_at_rest(fa, by_name[fa.body])
        pb, thb = frame_pose_at_rest(fb, by_name[fb.body])
        gap = float(np.linalg.norm(pa - pb))
        turn = abs(math.remainder(tha - thb, 2 * math.pi))
        if gap > COINCIDENCE_TOLERANCE or turn > 1e-9:
            raise ctx.fail(
                key, f"frames a and b do not coincide in the unstressed pose: a at "
                f"({pa[0]:.6g}, {pa[1]:.6g}, {tha:.6g} rad), b at ({pb[0]:.6g}, {pb[1]:.6g}, {thb:.6g} rad)"
            )
        law_key = f"{key}.law" if "law" in spec else "defaults.law"
        law_name = spec.get("law", defaults.get("law", "twistor"))
        poly = _polynomial_law(ctx, law_key, law_name, polynomials) if isinstance(law_name, dict) else None
        if poly is not None:
            if "stiffness" in spec:
                raise ctx.fail(f"{key}.stiffness", "a polynomial law defines the stiffness (its Hessian at rest): "
                               "remove this key")
            K, source = poly.stiffness_at_rest(), f"polynomial:{poly.source}"
            _check_spd(ctx, law_key, K, "stiffness at rest (Hessian of the polynomial law)")
        else:
            sspec = _require(ctx, key, spec, "stiffness")
            if isinstance(sspec, str):
                if sspec not in named_stiffness:
                    raise ctx.fail(f"{key}.stiffness", f"unknown stiffness model name {sspec!r}")
                K, source = named_stiffness[sspec]
            else:
                K, source = _stiffness(ctx, f"{key}.stiffness", sspec)
            _check_spd(ctx, f"{key}.stiffness", K, "stiffness")
            if not isinstance(law_name, str) or law_name not in COORDINATES:
                raise ctx.fail(law_key,
                               f"unknown law {law_name!r} ({', '.join(COORDINATES)}, or {{polynomial: FILE}})")
        B = _damping(ctx, f"{key}.damping", spec.get("damping", defaults.get("damping")), K)
        law = poly.with_damping(B) if poly is not None else QuadraticLaw(law_name, K, B)
        hinges.append(Hinge(name, fa, fb, law, source))
    return hinges


def _polynomial_law(ctx: _Ctx, key: str, spec: dict, cache: dict) -> PolynomialLaw:
    """``law: {polynomial: FILE}``: a fitted polynomial law (flexure-sim fit), FILE relative
    to the mechanism file (to the working directory for documents without a file)."""
    _no_unknown(ctx, key, spec, {"polynomial"})
    ref = _require(ctx, key, spec, "polynomial")
    if not isinstance(ref, str) or not ref:
        raise ctx.fail(f"{key}.polynomial", f"expected the path of a polynomial hinge file, got {ref!r}")
    origin = Path(ctx.source)
    path = (origin.parent if origin.is_file() else Path.cwd()) / ref
    if path not in cache:
        try:
            cache[path] = load_polynomial_law(path)
        except PolynomialFileError as exc:
            raise ctx.fail(f"{key}.polynomial", str(exc)) from None
    return cache[path]


def _damping(ctx: _Ctx, key: str, spec: Any, K: np.ndarray) -> np.ndarray:
    if spec is None:
        raise ctx.fail(key, "missing damping (give {t_char: seconds} or {B: 3x3}, here or in defaults)")
    spec = _mapping(ctx, key, spec)
    _no_unknown(ctx, key, spec, {"t_char", "B"})
    if "t_char" in spec:
        return _number(ctx, f"{key}.t_char", spec["t_char"], nonnegative=True) * K
    if "B" in spec:
        rows = spec["B"]
        if not isinstance(rows, list) or len(rows) != 3:
            raise ctx.fail(f"{key}.B", "expected a 3x3 matrix")
        B = np.array([_vector(ctx, f"{key}.B[{i}]", r, (3,)) for i, r in enumerate(rows)])
        if not np.allclose(B, B.T) or np.any(np.linalg.eigvalsh(B) < 0):
            raise ctx.fail(f"{key}.B", "damping matrix must be symmetric positive semi-definite")
        return B
    raise ctx.fail(key, "give t_char or B")


def _constraints(ctx, raw, by_name) -> list:
    if not isinstance(raw, list):
        raise ctx.fail("constraints", "expected a list of constraints")
    out: list = []
    held: dict[tuple[str, int], str] = {}
    for i, spec in enumerate(raw):
        key = f"constraints[{i}]"
        spec = _mapping(ctx, key, spec)
        kind = _require(ctx, key, spec, "type")
        body = _body_ref(ctx, f"{key}.body", spec, by_name)
        if kind == "fixed":
            _no_unknown(ctx, key, spec, {"type", "body"})
            c: Any = Fixed(body)
            coords = (0, 1, 2)
        elif kind == "drive":
            _no_unknown(ctx, key, spec, {"type", "body", "axis", "response_time", "stroke", "slew_rate"})
            stroke = _vector(ctx, f"{key}.stroke", _require(ctx, key, spec, "stroke"), (2,))
            if stroke[0] >= stroke[1]:
                raise ctx.fail(f"{key}.stroke", f"expected [min, max] with min < max, got {stroke}")
            c = Drive(
                body,
                _axis(ctx, f"{key}.axis", _require(ctx, key, spec, "axis")),
                _number(ctx, f"{key}.response_time", _require(ctx, key, spec, "response_time"), positive=True),
                (stroke[0], stroke[1]),
                _number(ctx, f"{key}.slew_rate", _require(ctx, key, spec, "slew_rate"), positive=True),
            )
            coords = (0, 1, 2)
            if any(isinstance(o, Drive) for o in out):
                raise ctx.fail(key, "only one drive constraint is supported")
        elif kind == "sine_rate":
            _no_unknown(ctx, key, spec, {"type", "body", "coordinate", "amplitude", "frequency", "phase"})
            coord = _require(ctx, key, spec, "coordinate")
            if coord not in COORDINATE_NAMES:
                raise ctx.fail(f"{key}.coordinate", f"expected one of {COORDINATE_NAMES}, got {coord!r}")
            c = SineRate(
                body, coord,
                _number(ctx, f"{key}.amplitude", _require(ctx, key, spec, "amplitude")),
                _number(ctx, f"{key}.frequency", _require(ctx, key, spec, "frequency"), positive=True),
                _number(ctx, f"{key}.phase", spec.get("phase", 0.0)),
            )
            coords = (COORDINATE_NAMES.index(coord),)
        else:
            raise ctx.fail(f"{key}.type", f"unknown constraint type {kind!r} (fixed, drive, sine_rate)")
        for k in coords:
            if (body, k) in held:
                raise ctx.fail(key, f"coordinate {COORDINATE_NAMES[k]} of body {body!r} is already "
                               f"constrained by {held[(body, k)]}")
            held[(body, k)] = key
        out.append(c)
    if not any(isinstance(c, Fixed) for c in out):
        raise ctx.fail("constraints", "the mechanism has no fixed body (add {type: fixed, body: ...})")
    return out


def builtin_path(name: str) -> Optional[Path]:
    """Path of a built-in mechanism file, or None."""
    try:
        return resolve_mechanism_path(name)
    except ConfigError:
        return None
