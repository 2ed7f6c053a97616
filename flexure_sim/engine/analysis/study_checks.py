"""
A study's checks against its base mechanism: the drive input, and the outputs it can give.

The study's ``input`` (docs/sweeps.md, "Several drives") is the drives' static input, as
``Simulation.static`` takes it (``Model.drive_inputs``): a number for a mechanism with one
drive, or a mapping drive name -> value naming every drive (also accepted for one drive).
Each value is in its drive's unit (m, rad on theta; N, N m for a force drive) and must lie
within that drive's stroke (the rule of every analysis, engine/mechanism/stroke.py).
Omitted: every drive at the top of its stroke.

Outputs a mechanism cannot give are refused at load, rather than failing in every design:
``first_mode`` and ``first_mode_damping`` come from the linear model (engine/analysis/linear.py),
which takes any number of displacement and force drives but no piezo stack (its input would be the
applied displacement, not the actuator's command); the outputs
measured per output need the mechanism to name one when it has several drives;
``peak_stress_ratio`` and ``stroke_limit`` need a hinge with a yield strength, the fatigue
outputs a hinge with fatigue strengths (engine/hinges/fatigue.py), the strokes a single
displacement drive. Outputs that would have no value in any design are refused too
(``check_defined``): ``compression`` without a ``compression_hinge``, the outputs measured
at an output of a mechanism without one, and at a zero input the ratio ``gain`` (one
drive) and the response to a step of size zero (``settling_time``, ``overshoot``).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Optional, Union

from flexure_sim.engine.hinges import fatigue
from flexure_sim.engine.hinges.stress import no_yield_advice
from flexure_sim.engine.solver.drives import stacked
from flexure_sim.engine.mechanism.doc_paths import resolve_path
from flexure_sim.engine.mechanism.parts import Mechanism, coordinate_unit
from flexure_sim.engine.mechanism.stroke import REASON, outside

#: A study's drive input: one number (one drive), or {drive name: value} (several drives).
DriveInput = Union[float, dict]
#: Outputs of the linear model, which takes drives without a piezo stack (``linear.linearize``).
LINEAR_OUTPUTS = ("first_mode", "first_mode_damping")
#: Outputs measured per output (a column each) with several drives: they need an output.
PER_OUTPUT = ("gain", "output_displacement", "settling_time", "overshoot")
#: Outputs that need a yield strength, fatigue strengths, a single displacement drive.
YIELD_OUTPUTS = ("peak_stress_ratio", "stroke_limit")
FATIGUE_OUTPUTS = ("fatigue_safety", "fatigue_safety_soderberg", "infinite_life_stroke")
STROKE_OUTPUTS = ("stroke_limit", "infinite_life_stroke")


@dataclass(frozen=True)
class Channels:
    """
    The base mechanism's drives and outputs, in ``Model`` order, with their units.

    ``drives``: (name, input unit, force unit) per drive; ``outputs``: (name, unit) per output.
    They name the columns of the outputs measured per drive or per output (tools/sweep_outputs).
    """

    drives: tuple[tuple[str, str, str], ...] = ()
    outputs: tuple[tuple[str, str], ...] = ()

    @property
    def several(self) -> bool:
        """Tell whether the mechanism has several drives (outputs then get a column each)."""
        return len(self.drives) > 1

    @classmethod
    def of(cls, mech: Mechanism) -> "Channels":
        """Return the channels of ``mech``."""
        return cls(tuple((d.name, coordinate_unit(d.coordinate, d.kind == "force"),
                          coordinate_unit(d.coordinate, True)) for d in mech.drives),
                   tuple((o.name, coordinate_unit(o.coordinate)) for o in mech.all_outputs))


def number(value: Any, key: str, fail, positive: bool = False) -> float:
    """Return ``value`` as a finite float (a numeric string too), else ``fail(key, problem)``."""
    if isinstance(value, str):
        try:
            value = float(value)
        except ValueError:
            pass
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise fail(key, f"expected a finite number, got {value!r}")
    if positive and value <= 0:
        raise fail(key, f"must be positive, got {value!r}")
    return float(value)


def spec_paths(spec: Any, key: str, doc: dict, allowed: set, expected: str, fail) -> tuple:
    """
    Check a sweep parameter's or an optimisation variable's mapping and resolve its paths.

    ``allowed``: its keys; ``expected``: what the mapping holds, for the message. Returns
    (texts, paths, through, bases, offset): the path texts, and per path the concrete steps,
    the hinge stiffness it reaches through and the base value (doc_paths.resolve_path), and
    whether the values are offsets from the bases.
    """
    if not isinstance(spec, dict):
        raise fail(key, f"expected a mapping ({expected}), got {spec!r}")
    unknown = sorted(set(spec) - allowed)
    if unknown:
        raise fail(f"{key}.{unknown[0]}", f"unknown key (allowed: {', '.join(sorted(allowed))})")
    if ("path" in spec) == ("paths" in spec):
        raise fail(key, "give either path or paths")
    texts = [spec["path"]] if "path" in spec else spec["paths"]
    pkey = f"{key}.path" if "path" in spec else f"{key}.paths"
    if not isinstance(texts, list) or not texts:
        raise fail(pkey, f"expected a non-empty list of paths, got {texts!r}")
    resolved = []
    for j, text in enumerate(texts):
        k = pkey if "path" in spec else f"{pkey}[{j}]"
        resolved.append(resolve_path(doc, text, lambda problem, k=k: fail(k, problem)))
    paths, through, bases = zip(*resolved)
    offset = spec.get("offset", False)
    if not isinstance(offset, bool):
        raise fail(f"{key}.offset", f"expected true or false, got {offset!r}")
    return texts, paths, through, bases, offset


def drive_input(raw: Any, mech: Mechanism, fail) -> Optional[DriveInput]:
    """
    Return the study's validated ``input`` (module doc); None: every drive's full stroke.

    A number for one drive, or that drive's value of a one-entry mapping; a mapping in drive
    order for several drives. ``fail(key, problem)`` builds the error, naming ``input`` or
    ``input.<drive>``.
    """
    if raw is None:
        return None
    drives = mech.drives
    names = [d.name for d in drives]
    listed = ", ".join(names)
    if isinstance(raw, dict):
        for key in raw:
            if key not in names:
                raise fail(f"input.{key}", f"unknown drive {key!r} (drives of {mech.name!r}: "
                           f"{listed})")
        missing = [n for n in names if n not in raw]
        if missing:
            raise fail("input", f"no value for drive {', '.join(missing)}: give every drive's "
                       f"input ({listed})")
        values = {d.name: _within(d, number(raw[d.name], f"input.{d.name}", fail),
                                  f"input.{d.name}", fail) for d in drives}
        return values[names[0]] if len(drives) == 1 else values
    if isinstance(raw, (list, tuple)):
        raise fail("input", f"expected a number (one drive) or a mapping drive name -> value "
                   f"(drives of {mech.name!r}: {listed}), got {raw!r}")
    if len(drives) > 1:
        shown = raw if isinstance(raw, (int, float)) else "VALUE"
        example = ", ".join(f"{n}: {shown}" if k == 0 else f"{n}: 0.0"
                            for k, n in enumerate(names))
        raise fail("input", f"one number for the {len(drives)} drives of {mech.name!r} "
                   f"({listed}): give one value per drive by name, e.g. input: {{{example}}}")
    value = number(raw, "input", fail)
    return _within(drives[0], value, "input", fail) if drives else value


def _within(drive, value: float, key: str, fail) -> float:
    """Return ``value`` if it lies within the drive's stroke, else fail naming both (stroke.py)."""
    reason = outside(drive, value, alone=key == "input")
    if reason is not None:
        raise fail(key, f"{reason}: {REASON}")
    return value


#: Outputs the spatial engine gives (``space: 3d``), and those only it gives.
SPATIAL_OUTPUTS = ("gain", "output_displacement", "drive_force", "first_mode",
                   "first_mode_damping", "first_out_of_plane_mode", "settling_time", "overshoot")
ONLY_SPATIAL = ("first_out_of_plane_mode",)


def study_space(raw: Any, base: dict, fail) -> str:
    """
    Return the study's engine: its ``space`` key, else the mechanism's own (3d for a 3-D file).

    ``space: 2d`` cannot open a 3-D file; ``space: 3d`` opens a planar one with its
    out-of-plane freedoms.
    """
    own = "3d" if "space" in base else "2d"
    if raw is None:
        return own
    if raw not in ("2d", "3d"):
        raise fail("space", f"expected 2d or 3d, got {raw!r}")
    if raw == "2d" and own == "3d":
        raise fail("space", "2d: the mechanism is a 3-D file (space: 3d)")
    return raw


def check_space(outputs: tuple[str, ...], space: str, fail) -> None:
    """Refuse the outputs the study's engine (``space``) does not give, naming the output."""
    for name in outputs:
        if space == "3d" and name not in SPATIAL_OUTPUTS:
            raise fail("outputs", f"{name}: not available in 3-D (space: 3d gives "
                       f"{', '.join(SPATIAL_OUTPUTS)})")
        if space == "2d" and name in ONLY_SPATIAL:
            raise fail("outputs", f"{name}: out-of-plane modes need the spatial engine; give "
                       "the study space: 3d")


def check_outputs(outputs: tuple[str, ...], mech: Mechanism, fail) -> None:
    """Refuse the outputs ``mech`` cannot give (module doc), naming the output."""
    drives = mech.drives
    for name in outputs:
        if name in LINEAR_OUTPUTS and any(stacked(d) for d in drives):
            kinds = ", ".join(repr(d.name) for d in drives if stacked(d))
            raise fail("outputs", f"{name}: the linear model (engine/analysis/linear.py, "
                       f"flexure-sim modes) takes no drive with a piezo stack (actuator: block); "
                       f"{mech.name!r} has one on drive {kinds}")
        if name in PER_OUTPUT and len(drives) > 1 and not mech.all_outputs:
            raise fail("outputs", f"{name}: {mech.name!r} has several drives and no output "
                       "(outputs: in the mechanism file)")
    yielding = [o for o in outputs if o in YIELD_OUTPUTS]
    if yielding and not any(
            h.stress is not None and h.stress.sigma_y is not None for h in mech.hinges):
        raise fail("outputs", f"{yielding[0]}: no hinge of {mech.name!r} has a yield "
                   f"strength: {no_yield_advice(mech) or 'no notch or leaf hinge'}")
    tiring = [o for o in outputs if o in FATIGUE_OUTPUTS]
    if tiring and not fatigue.with_strengths(mech):
        raise fail("outputs", f"{tiring[0]}: no hinge of {mech.name!r} has fatigue strengths: "
                   f"{fatigue.no_fatigue_advice(mech) or 'no notch or leaf hinge'}")
    strokes = [o for o in outputs if o in STROKE_OUTPUTS]
    if strokes and (len(drives) != 1 or drives[0].kind != "displacement" or stacked(drives[0])):
        raise fail("outputs", f"{strokes[0]}: a stroke is the input of one displacement drive "
                   f"without a piezo stack; {mech.name!r} has {len(drives)} drive(s)")


def check_defined(outputs: tuple[str, ...], mech: Mechanism, value: Optional[DriveInput],
                  fail) -> None:
    """
    Refuse the outputs that would be NaN in every design (module doc), naming the output.

    ``value``: the study's validated input (None: every drive at the top of its stroke).
    """
    if "compression" in outputs and mech.compression_hinge is None:
        raise fail("outputs", f"compression: {mech.name!r} names no compression_hinge (the "
                   "hinge whose compression is measured, a key of the mechanism file)")
    for name in outputs:
        if name in PER_OUTPUT and not mech.all_outputs:
            raise fail("outputs", f"{name}: {mech.name!r} has no output (output: or outputs: "
                       "in the mechanism file)")
    if value is None:
        value = {d.name: d.stroke[1] for d in mech.drives}
    zero = all(v == 0.0 for v in (value.values() if isinstance(value, dict) else [value]))
    for name in outputs:
        single_gain = name == "gain" and len(mech.drives) == 1
        if zero and (single_gain or name in ("settling_time", "overshoot")):
            what = ("gain = output / input is 0 / 0" if name == "gain"
                    else "a step from 0 to 0 has no settling time or overshoot")
            raise fail("input", f"every drive input is 0 and the outputs ask for {name}: {what}; "
                       "give a non-zero input")
