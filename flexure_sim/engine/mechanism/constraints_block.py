"""
Constraints, drives, outputs and the output sensor of a mechanism file, checked.

Part of the loader (`config.mechanism_from_dict`); messages name the file, key and problem.
"""
from __future__ import annotations

from typing import Any

from flexure_sim.engine.mechanism.actuator_block import actuator_spec
from flexure_sim.engine.mechanism.values import axis as _axis
from flexure_sim.engine.mechanism.values import body_ref as _body_ref
from flexure_sim.engine.mechanism.values import Ctx as _Ctx
from flexure_sim.engine.mechanism.values import mapping as _mapping
from flexure_sim.engine.mechanism.values import name as _name
from flexure_sim.engine.mechanism.values import no_unknown as _no_unknown
from flexure_sim.engine.mechanism.values import number as _number
from flexure_sim.engine.mechanism.values import require as _require
from flexure_sim.engine.mechanism.values import shown as _shown
from flexure_sim.engine.mechanism.values import vector as _vector
from flexure_sim.engine.mechanism.parts import (
    COORDINATE_NAMES, Body, Drive, Fixed, Output, SineRate,
)
from flexure_sim.engine.actuators.sensor import MAX_LATENCY, SensorSpec
from flexure_sim.engine.memory import human


def _sensor(ctx: _Ctx, raw: Any, output: Any) -> SensorSpec:
    """Read the ``sensor:`` block (actuators/sensor.py): every key optional, none negative."""
    spec = _mapping(ctx, "sensor", raw)
    _no_unknown(ctx, "sensor", spec, {"noise_rms", "resolution", "bandwidth", "latency", "seed"})
    if output is None:
        raise ctx.fail("sensor", "needs an output (the sensor reads output/displacement)")
    values: dict[str, Any] = {k: _number(ctx, f"sensor.{k}", spec[k], nonnegative=True)
                              for k in ("noise_rms", "resolution", "bandwidth") if k in spec}
    for k in ("latency", "seed"):
        if k in spec:
            v = spec[k]
            if isinstance(v, bool) or not isinstance(v, int) or v < 0:
                raise ctx.fail(f"sensor.{k}", f"expected an integer >= 0, got {_shown(v)}")
            if k == "latency" and v > MAX_LATENCY:
                raise ctx.fail("sensor.latency", f"{v} ticks: the delay line would hold {v} "
                               f"readings (~{human(32 * v)}); at most {MAX_LATENCY} ticks "
                               "(1000 s at 1 kHz)")
            values[k] = v
    return SensorSpec(**values)


def _actuator(ctx: _Ctx, key: str, spec: dict, kind: str, stroke: list) -> Any:
    """Read the drive's optional ``actuator:`` block (actuator_block.py), or None."""
    if "actuator" not in spec:
        return None
    if kind != "drive":
        raise ctx.fail(f"{key}.actuator", "a piezo actuator belongs on a displacement drive "
                       "(type: drive); its stack stiffness makes the force on the stage")
    return actuator_spec(ctx, f"{key}.actuator", spec["actuator"], (stroke[0], stroke[1]))


def _response_time(ctx: _Ctx, key: str, spec: dict, kind: str) -> float:
    """
    Read a drive's ``response_time`` (s): > 0, or 0 for a prescribed displacement.

    0 (``type: drive`` only): the displacement follows its command or program exactly
    (engine/solver/drives.py), so it takes no piezo ``actuator:`` block, whose stroke would
    drive a lag.
    """
    value = _number(ctx, f"{key}.response_time", _require(ctx, key, spec, "response_time"),
                    nonnegative=True, positive=kind == "force")
    if value == 0.0 and "actuator" in spec:
        raise ctx.fail(f"{key}.response_time", "0 (a prescribed displacement) takes no "
                       "actuator: block; give the actuator's lag a response_time > 0")
    return value


def _outputs(ctx: _Ctx, raw: Any, by_name: dict[str, Body]) -> tuple[Output, ...]:
    """
    Read the ``outputs:`` list.

    ``outputs: [{name, body, axis: [x, y]} | {name, body, coordinate: x|y|theta}]``.
    """
    if not isinstance(raw, list) or not raw:
        raise ctx.fail("outputs", "expected a non-empty list of outputs")
    out, seen = [], set()
    for i, spec in enumerate(raw):
        key = f"outputs[{i}]"
        spec = _mapping(ctx, key, spec)
        _no_unknown(ctx, key, spec, {"name", "body", "axis", "coordinate"})
        name = _name(ctx, f"{key}.name", _require(ctx, key, spec, "name"))
        if name in seen:
            raise ctx.fail(f"{key}.name", f"duplicate output name {name!r}")
        seen.add(name)
        body = _body_ref(ctx, f"{key}.body", spec, by_name)
        if "coordinate" in spec and "axis" in spec:
            raise ctx.fail(key, "give either axis or coordinate, not both")
        coord = spec.get("coordinate")
        if coord is not None and coord not in COORDINATE_NAMES:
            raise ctx.fail(f"{key}.coordinate",
                           f"expected one of {COORDINATE_NAMES}, got {_shown(coord)}")
        axis = (1.0, 0.0)
        if coord is None:
            axis = _axis(ctx, f"{key}.axis", _require(ctx, key, spec, "axis"))
        out.append(Output(body, axis, name, coord))
    return tuple(out)


def _constraints(ctx, raw, by_name) -> list:
    if not isinstance(raw, list):
        raise ctx.fail("constraints", "expected a list of constraints")
    out: list = []
    held: dict[tuple[str, int], str] = {}
    forced: list = []
    for i, spec in enumerate(raw):
        key = f"constraints[{i}]"
        spec = _mapping(ctx, key, spec)
        kind = _require(ctx, key, spec, "type")
        body = _body_ref(ctx, f"{key}.body", spec, by_name)
        if kind == "fixed":
            _no_unknown(ctx, key, spec, {"type", "body"})
            c: Any = Fixed(body)
            coords: tuple[int, ...] = (0, 1, 2)
        elif kind in ("drive", "force"):
            _no_unknown(ctx, key, spec, {"type", "name", "body", "axis", "response_time",
                                         "stroke", "slew_rate", "actuator"})
            stroke = _vector(ctx, f"{key}.stroke", _require(ctx, key, spec, "stroke"), (2,))
            if stroke[0] >= stroke[1]:
                raise ctx.fail(f"{key}.stroke",
                               f"expected [min, max] with min < max, got {stroke}")
            axis_spec = _require(ctx, key, spec, "axis")
            coord = axis_spec if isinstance(axis_spec, str) else None
            if coord is not None and coord not in COORDINATE_NAMES:
                raise ctx.fail(f"{key}.axis", f"expected a vector [x, y] or one of "
                               f"{COORDINATE_NAMES}, got {_shown(coord)}")
            drives = [o for o in out if isinstance(o, Drive)]
            dname = _name(ctx, f"{key}.name", spec["name"]) if "name" in spec else "drive"
            if any(d.name == dname for d in drives):
                raise ctx.fail(f"{key}.name", f"duplicate drive name {dname!r}"
                               + ("" if "name" in spec else ": name every drive"))
            c = Drive(
                body,
                (1.0, 0.0) if coord is not None else _axis(ctx, f"{key}.axis", axis_spec),
                _response_time(ctx, key, spec, kind),
                (stroke[0], stroke[1]),
                _number(ctx, f"{key}.slew_rate", _require(ctx, key, spec, "slew_rate"),
                        positive=True),
                dname, coord, "force" if kind == "force" else "displacement",
                _actuator(ctx, key, spec, kind, stroke),
            )
            if kind == "force":
                coords = ()  # the body stays free: checked against the held ones below
                forced.append((key, body, c))
            else:
                coords = (0, 1, 2) if coord is None else (COORDINATE_NAMES.index(coord),)
        elif kind == "sine_rate":
            _no_unknown(
                ctx, key, spec, {"type", "body", "coordinate", "amplitude", "frequency", "phase"}
            )
            coord = _require(ctx, key, spec, "coordinate")
            if coord not in COORDINATE_NAMES:
                raise ctx.fail(f"{key}.coordinate",
                               f"expected one of {COORDINATE_NAMES}, got {_shown(coord)}")
            c = SineRate(
                body,
                coord,
                _number(ctx, f"{key}.amplitude", _require(ctx, key, spec, "amplitude")),
                _number(
                    ctx, f"{key}.frequency", _require(ctx, key, spec, "frequency"), positive=True
                ),
                _number(ctx, f"{key}.phase", spec.get("phase", 0.0)),
            )
            coords = (COORDINATE_NAMES.index(coord),)
        else:
            raise ctx.fail(f"{key}.type", f"unknown constraint type {_shown(kind)} "
                           "(fixed, drive, force, sine_rate)")
        for k in coords:
            if (body, k) in held:
                raise ctx.fail(
                    key,
                    f"coordinate {COORDINATE_NAMES[k]} of body {body!r} is already "
                    f"constrained by {held[(body, k)]}",
                )
            held[(body, k)] = key
        out.append(c)
    for key, body, c in forced:
        acts = (0, 1) if c.coordinate is None else (COORDINATE_NAMES.index(c.coordinate),)
        for k in acts:
            if (body, k) in held:
                raise ctx.fail(key, f"a force drive needs coordinate {COORDINATE_NAMES[k]} of "
                               f"body {body!r} free, but {held[(body, k)]} constrains it")
    if not any(isinstance(c, Fixed) for c in out):
        raise ctx.fail(
            "constraints", "the mechanism has no fixed body (add {type: fixed, body: ...})"
        )
    return out
