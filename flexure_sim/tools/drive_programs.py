"""
``flexure-sim simulate --drive``: one program per drive, and the per-drive figures of a run.

``--drive [NAME=]KIND[:ARGS][@START]``, repeated once per drive (the name may be left out for a
mechanism's only drive):

- ``step:A`` -- A from START (default 0 s);
- ``ramp:A:T`` -- linearly to A over T seconds;
- ``cycloid:A:T`` -- to A over T seconds along the cycloidal motion law (rate and acceleration
  zero at both ends);
- ``sine:A:F`` -- A sin(2 pi F t), F in Hz (no static value);
- ``none`` -- the drive held at 0.

A is in the drive's unit (m, rad on theta, N for a force drive, V for a voltage-commanded piezo
actuator). A static run solves the equilibrium at each program's final value (drives not named
at 0); a dynamic run steps each drive along its program (``engine/solver/programs.py``): a
lagged drive's command, a force drive's force, or a prescribed drive's displacement itself
(``response_time: 0``). A step from 0 s is the drive's command, held, as before programs existed.
"""
from __future__ import annotations

from typing import Optional

import numpy as np

from flexure_sim.errors import FlexureSimError
from flexure_sim.engine.mechanism import stroke
from flexure_sim.engine.solver.programs import Program
from flexure_sim.engine.solver.simulation import Simulation, Snapshot

#: Arguments after the kind, per kind: (their names, units) for the messages.
_ARGS = {"step": ("A",), "ramp": ("A", "T"), "cycloid": ("A", "T"), "sine": ("A", "F")}


class DriveSpecError(FlexureSimError, ValueError):
    """A ``--drive`` value that is not a program (the message names it and the syntax)."""


def parse_program(text: str) -> Optional[Program]:
    """Return the program of ``KIND[:ARGS][@START]`` (None for ``none``); DriveSpecError else."""
    body, at, start_text = text.partition("@")
    kind, *values = body.split(":")
    if kind == "none" and not values and not at:
        return None
    if kind not in _ARGS or len(values) != len(_ARGS[kind]):
        raise DriveSpecError(
            f"--drive {text!r}: expected step:A, ramp:A:T, cycloid:A:T, sine:A:F or none, each "
            "optionally @START (seconds), after NAME= for one of several drives")
    numbers = [_number(v, text) for v in values + ([start_text] if at else [])]
    start = numbers.pop() if at else 0.0
    if start < 0:
        raise DriveSpecError(f"--drive {text!r}: the start must not be negative")
    amplitude = numbers[0]
    try:
        if kind == "ramp" or kind == "cycloid":
            return Program(kind, amplitude, duration=numbers[1], start=start)
        if kind == "sine":
            return Program(kind, amplitude, frequency=numbers[1], start=start)
        return Program(kind, amplitude, start=start)
    except ValueError as exc:
        raise DriveSpecError(f"--drive {text!r}: {exc}") from None


def _number(value: str, text: str) -> float:
    try:
        out = float(value)
    except ValueError:
        raise DriveSpecError(f"--drive {text!r}: {value!r} is not a number") from None
    if not np.isfinite(out):
        raise DriveSpecError(f"--drive {text!r}: {value!r} must be finite")
    return out


def parse_drives(specs, names: tuple) -> dict:
    """
    Return {drive name: Program or None} of the ``--drive`` values for drives ``names``.

    A value without ``NAME=`` belongs to the only drive; each drive at most once; DriveSpecError
    naming the problem (an unknown drive lists the mechanism's).
    """
    out: dict = {}
    for spec in specs or ():
        if spec == "none":
            continue
        if not names:
            raise DriveSpecError(f"--drive {spec!r}: the mechanism has no drive")
        name, eq, text = spec.partition("=")
        if not eq:
            if len(names) != 1:
                raise DriveSpecError(
                    f"--drive {spec!r}: the mechanism has {len(names)} drives "
                    f"({', '.join(names) or 'none'}); name the one each program is for: "
                    + (" ".join(f"--drive {n}=step:A" for n in names) or "none to drive"))
            name, text = names[0], spec
        name = name.strip()
        if name not in names:
            raise DriveSpecError(f"--drive {spec!r}: no drive {name!r} (drives: "
                                 f"{', '.join(names) or 'none'})")
        if name in out:
            raise DriveSpecError(f"--drive {spec!r}: drive {name!r} is given twice")
        out[name] = parse_program(text.strip())
    return out


def static_inputs(programs: dict, names: tuple) -> np.ndarray:
    """Return each drive's static input: its program's final value (0 without a program)."""
    out = np.zeros(len(names))
    for name, program in programs.items():
        if program is None:
            continue
        if program.final is None:
            raise DriveSpecError(f"--drive {name}={program.kind}: a sine has no static value; "
                                 "give --static a step, ramp or cycloid")
        out[names.index(name)] = program.final
    return out


def check_strokes(mechanism, programs: dict) -> None:
    """
    Refuse a program that takes its drive outside the stroke (``mechanism.stroke``'s rule).

    The values checked: a step's, ramp's or cycloid's final value, a sine's extremes (the
    program's commands; a piezo actuator taking volts is checked against its voltage range).
    """
    alone = len(mechanism.drives) == 1
    for drive in mechanism.drives:
        program = programs.get(drive.name)
        if program is None:
            continue
        values = ([program.final] if program.final is not None else
                  [program.initial - program.amplitude, program.initial + program.amplitude])
        for value in values:
            reason = stroke.outside(drive, value, alone, command=True)
            if reason is not None:
                option = f"--drive {'' if alone else drive.name + '='}{program.describe()}"
                raise stroke.StrokeError(f"{option}: {reason}: {stroke.REASON}")


def apply(sim: Simulation, programs: dict) -> None:
    """
    Start each drive on its program in ``sim`` (at its state's time).

    A step from the start of the run is the drive's command, held (``set_command``: what a
    mechanism's single drive always took); anything else a program (``set_programs``).
    """
    drives = sim.model.drives
    held = {n: p.final for n, p in programs.items() if p is not None and p.kind == "step"
            and p.start <= sim.state.t}
    timed = {n: p for n, p in programs.items() if p is not None and n not in held}
    if held:
        command = np.array(sim.state.command, dtype=float)
        for name, value in held.items():
            command[drives.names.index(name)] = value
        sim.set_command(command)
    if timed:
        sim.set_programs(timed)


def drive_figures(sim: Simulation, snap: Snapshot, programs: dict) -> dict:
    """
    Return each drive's figures: input, command, force along its axis, position, full wrench.

    ``wrench``: what the drive applies to its body (``Snapshot.drive_wrenches``), in the body's
    frame (``frame``), moment about its origin (N m) and force along its x and y axes (N);
    ``program``: the program it followed (text), if any.
    """
    out = {}
    for k, d in enumerate(sim.model.drives):
        moment, fx, fy = (float(w) for w in snap.drive_wrenches[k])
        program = programs.get(d.name)
        out[d.name] = {"kind": d.kind, "body": d.body,
                       "prescribed": d.kind == "displacement" and d.response_time == 0.0,
                       "program": program.describe() if program is not None else None,
                       "input": float(snap.drive_inputs[k]),
                       "command": float(snap.drive_commands[k]),
                       "force": float(snap.drive_forces[k]),
                       "position": float(snap.drive_positions[k]),
                       "wrench": {"frame": d.body, "force_x": fx, "force_y": fy,
                                  "moment": moment}}
    return out


def print_drives(out: dict, fmt) -> None:
    """Print each drive's and output's lines of ``simulate``'s table (``fmt``: cli._fmt)."""
    several = len(out.get("drives", {})) > 1
    for name, d in out.get("drives", {}).items():
        label = "drive" if name == "drive" else f"drive {name}"
        if several:
            unit, scale = ("N", 1.0) if d["kind"] == "force" else ("um", 1e6)
            program = f" ({d['program']})" if d["program"] else ""
            print(f"{label}: input {fmt(d['input'], unit, scale)}{program}, force "
                  f"{fmt(d['force'], 'N')}")
        w = d["wrench"]
        print(f"{label} wrench on {w['frame']} (its frame, about its origin): force x "
              f"{fmt(w['force_x'], 'N')}, y {fmt(w['force_y'], 'N')}, moment "
              f"{fmt(w['moment'], 'N m')}")
    if several or len(out.get("outputs", {})) > 1:
        units = out.get("output_units", {})
        for name, value in out.get("outputs", {}).items():
            unit, scale = ("urad", 1e6) if units.get(name) == "rad" else ("um", 1e6)
            print(f"output {name}: {fmt(value, unit, scale)}")
