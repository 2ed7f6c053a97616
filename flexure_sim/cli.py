"""
The ``flexure-sim`` command.

Offline simulation without ROS (and, from the tools package, analysis of recorded runs).

    flexure-sim simulate microstage --drive step:1.35e-6 --duration 0.05 [--json]
    flexure-sim simulate microstage --drive step:1.35e-6 --static [--json]
    flexure-sim simulate microstage --drive cycloid:1.35e-6:2e-3 --duration 0.01
    flexure-sim simulate config/fourbar_mixed.yaml --duration 0.2
    flexure-sim simulate xy_stage --drive x=step:1e-5 --drive y=ramp:5e-6:2e-3 [--static]
    flexure-sim simulate xy_stage --static [--json]     # several drives: the gain matrix
    flexure-sim simulate microstage --space 3d --static # with its out-of-plane freedoms
    flexure-sim simulate tiptilt_stage --drive step:p1=1e-5,p2=0,p3=0 --duration 0.01

``--drive`` takes one program per drive (tools/drive_programs.py); a 3-D mechanism takes one
``--drive step:...`` for all its drives (tools/run/simulate_spatial.py).
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from typing import Optional, Sequence

import numpy as np

from flexure_sim.console import quiet_pipe
from flexure_sim.errors import FlexureSimError
from flexure_sim.engine.mechanism.loader import load_mechanism, resolve_mechanism_path
from flexure_sim.engine.solver.simulation import DEFAULT_STEP, Simulation, Snapshot
from flexure_sim.tools import drive_programs
from flexure_sim.tools.run import simulate_limits

#: Times (s) at which the step response is reported, as in the acceptance figures.
REPORT_TIMES = (1e-3, 2e-3, 5e-3)


class UsageError(FlexureSimError, ValueError):
    """A command-line argument is invalid (the message names it)."""


def summarize(sim: Simulation, snap: Snapshot, amplitude: float, programs=None) -> dict:
    """Return the figures the command prints, as a JSON-ready dict (SI units)."""
    mech = sim.mechanism
    gain = None
    if snap.output is not None and amplitude != 0.0:
        gain = snap.output / amplitude
    out = {
        "mechanism": mech.name,
        "t": snap.t,
        "input": amplitude if sim.drive else None,
        "drive_input": snap.drive_input if sim.drive else None,
        "output_displacement": snap.output,
        "gain": gain,
        "joint_a_compression": snap.compression,
        "drive_force": snap.drive_force if sim.drive else None,
        "hinges": {
            h.name: {
                "rotation": float(snap.deflections[i, 0]),
                "x": float(snap.deflections[i, 1]),
                "y": float(snap.deflections[i, 2]),
                "wrench_on_b": [float(w) for w in snap.wrenches[i]],
            }
            for i, h in enumerate(mech.hinges)
        },
        "bodies": {b.name: [float(x) for x in snap.poses[i]] for i, b in enumerate(mech.bodies)},
        "energy": {
            "kinetic": snap.kinetic_energy,
            "potential": snap.potential_energy,
            "dissipated": snap.dissipated,
            "drive_work": snap.drive_work,
        },
    }
    if sim.model.drives.actuation:
        out["actuators"] = actuator_figures(sim, snap)
    if len(sim.model.drives):
        out["drives"] = drive_programs.drive_figures(sim, snap, programs or {})
    if sim.model.outputs:
        out["outputs"] = dict(snap.outputs)
        out["output_units"] = {o.name: "rad" if o.coordinate == "theta" else "m"
                               for o in sim.model.outputs}
    return out


def actuator_figures(sim: Simulation, snap: Snapshot) -> dict:
    """
    Return the figures of each drive with a piezo actuator (engine/solver/actuation.py).

    Its command (V or m, ``unit``), amplifier voltage (V), free stroke and applied
    displacement (m), stack force (N).
    """
    out = {}
    for a in sim.model.drives.actuation:
        k = a.drive
        out[snap.drive_names[k]] = {
            "command": float(snap.drive_commands[k]),
            "unit": "V" if a.spec.command == "voltage" else "m",
            "voltage": float(snap.drive_voltages[k]),
            "free_stroke": float(snap.drive_free_strokes[k]),
            "applied": float(snap.drive_positions[k]),
            "stack_force": float(snap.drive_stack_forces[k]),
            "stack_stiffness": a.spec.stiffness}
    return out


def _single_command(sim: Simulation) -> bool:
    """Tell whether ``--drive step:A`` commands the mechanism's one drive (with an actuator)."""
    drives = sim.model.drives
    return sim.drive is not None or (len(drives) == 1 and bool(drives.actuation))


def run_simulate(args: argparse.Namespace) -> dict:
    path = resolve_mechanism_path(args.mechanism)
    if args.duration <= 0 or not np.isfinite(args.duration):
        raise UsageError(f"--duration {args.duration!r}: must be a positive number of seconds")
    if args.dt <= 0 or not np.isfinite(args.dt):
        raise UsageError(f"--dt {args.dt!r}: must be a positive number of seconds")
    if spatial(args, path):
        from flexure_sim.tools.run import simulate_spatial
        if args.stroke_limit:
            raise UsageError("--stroke-limit: not available for 3-D mechanisms yet")
        args.drive = _spatial_drive(args.drive)
        return simulate_spatial.run(args, path, UsageError)
    mech = load_mechanism(path)
    try:
        sim = Simulation(mech, dt=args.dt, relinearize_tol=args.relinearize_tol)
    except ValueError as exc:
        raise UsageError(f"{mech.name}: {exc}") from None
    names = sim.model.drives.names
    programs = drive_programs.parse_drives(args.drive, names)
    given = {n: p for n, p in programs.items() if p is not None}
    several = len(names) > 1 or len(sim.model.outputs) > 1
    inputs = drive_programs.static_inputs(programs, names) if args.static else None
    amplitude = 0.0     # a single drive's input, for the gain
    if len(names) == 1 and inputs is not None:
        amplitude = float(inputs[0])
    elif len(names) == 1 and names[0] in given:
        amplitude = given[names[0]].final or 0.0
    if args.static and len(sim.model.drives.stack):
        raise UsageError(f"--static: mechanism {mech.name!r} has a drive with a finite-stiffness "
                         "piezo stack (its input is the actuator's free stroke, a dynamic "
                         "state): simulate without --static to a steady state")
    drive_programs.check_strokes(mech, given)  # the rule of every analysis (mechanism/stroke.py)
    start = time.perf_counter()
    if args.stroke_limit:
        return simulate_limits.stroke_limit(args, sim, UsageError)
    if args.static and len(names) > 1 and not given:
        return _gain_only(sim, path, time.perf_counter() - start)
    if args.static:
        result = sim.static(inputs if len(names) else 0.0)
        out = summarize(sim, result.snapshot, amplitude, programs)
        if several:
            out["gain_matrix"] = gain_matrix(sim)
        wall = time.perf_counter() - start
        out.update(mechanism_file=str(path), mode="static", newton_iterations=result.iterations,
                   residual=result.residual, wall_s=wall)
        out.update(simulate_limits.static_limits(args, sim, result.snapshot, amplitude,
                                                 UsageError))
        return out
    drive_programs.apply(sim, programs)
    n_steps = int(round(args.duration / args.dt))
    samples, outputs_at = {}, {}
    marks = {int(round(t / args.dt)): t for t in REPORT_TIMES if t <= args.duration}
    done = 0
    for k in sorted(marks) + [n_steps]:
        if k > done:
            sim.step(k - done)
            done = k
        if k in marks and sim.model.outputs:
            snap = sim.snapshot()
            outputs_at[f"{marks[k]:g}"] = dict(snap.outputs)
            if mech.output is not None:
                samples[f"{marks[k]:g}"] = snap.output
    wall = time.perf_counter() - start
    out = summarize(sim, sim.snapshot(), amplitude, programs)
    if len(sim.model.outputs) > 1:
        out["outputs_at"] = outputs_at
    if _single_command(sim) and sim.drive is None:  # one actuated drive: the scalar figures
        snap = sim.snapshot()
        out.update(input=amplitude, drive_input=float(snap.drive_positions[0]),
                   drive_force=float(snap.drive_forces[0]))
    out.update(
        mechanism_file=str(path),
        mode="dynamic",
        duration=args.duration,
        dt=args.dt,
        steps=n_steps,
        output_at=samples,
        wall_s=wall,
        real_time_factor=args.duration / wall if wall > 0 else None,
        linearizations=sim.stats.linearizations,
    )
    return out


def _gain_only(sim: Simulation, path, wall: float) -> dict:
    """
    Return ``--static`` of several drives without a program: the gain matrix, and what to give.

    At rest there is nothing else to report (hinge deflections and stresses are rounding).
    """
    names = sim.model.drives.names
    example = " ".join(f"--drive {n}=step:A" for n in names)
    return {"mechanism": sim.mechanism.name, "mechanism_file": str(path), "mode": "gain",
            "drives": list(names), "gain_matrix": gain_matrix(sim), "wall_s": wall,
            "hint": f"for the nonlinear static solution at given inputs (its outputs, drive "
                    f"forces and hinge stresses) give one program per drive: {example}"}


def spatial(args: argparse.Namespace, path) -> bool:
    """Tell whether to simulate in 3-D: ``--space 3d``, or a ``space: 3d`` file (auto)."""
    from flexure_sim.engine.mechanism.spatial_loader import is_spatial
    three_d = is_spatial(path)
    if args.space == "2d" and three_d:
        raise UsageError(f"--space 2d: {path} is a 3-D mechanism (space: 3d)")
    return args.space == "3d" or three_d


def _spatial_drive(specs) -> list:
    """Return the ``--drive`` specs of a 3-D run (``["none"]`` without any)."""
    return list(specs) if specs else ["none"]


def gain_matrix(sim: Simulation) -> dict:
    """
    Return the exact static gain at rest, each output (rows) against each drive (columns).

    ``Simulation.static_gain``, as JSON (m/m, rad/m, m/N, ... per the pair's units).
    """
    G = sim.static_gain()
    return {"outputs": list(sim.model.output_names), "drives": list(sim.model.drives.names),
            "matrix": [[float(g) for g in row] for row in G]}


def _fmt(v: Optional[float], unit: str, scale: float = 1.0, digits: int = 6) -> str:
    return "n/a" if v is None else f"{v * scale:.{digits}g} {unit}"


def print_table(out: dict) -> None:
    if out.get("space") == "3d":
        from flexure_sim.tools.run import simulate_spatial
        simulate_spatial.print_table(out)
        return
    if out["mode"] == "stroke_limit":
        simulate_limits.print_stroke_limit(out)
        return
    if out["mode"] == "gain":
        print(f"mechanism: {out['mechanism']}   several drives, no input given")
        print(f"file:      {out['mechanism_file']}")
        _print_gain(out["gain_matrix"])
        print(out["hint"])
        return
    print(f"mechanism: {out['mechanism']}   mode: {out['mode']}   t = {out['t']:.6g} s")
    print(f"file:      {out['mechanism_file']}")
    volts = any(a["unit"] == "V" for a in out.get("actuators", {}).values())
    if out["input"] is not None:
        shown = _fmt(out["input"], "V") if volts else _fmt(out["input"], "um", 1e6)
        print(f"input:               {shown}")
        print(f"output displacement: {_fmt(out['output_displacement'], 'um', 1e6)}")
        print(f"gain:                {_fmt(out['gain'], 'm/V' if volts else '')}")
        print(f"joint-a compression: {_fmt(out['joint_a_compression'], 'nm', 1e9)}")
        print(f"drive force:         {_fmt(out['drive_force'], 'N')}")
    if out.get("gain_matrix"):
        _print_gain(out["gain_matrix"])
    for name, a in out.get("actuators", {}).items():
        command = _fmt(a["command"], "V") if a["unit"] == "V" else _fmt(a["command"], "um", 1e6)
        print(f"actuator {name}: command {command}, amplifier {_fmt(a['voltage'], 'V')}, free "
              f"stroke {_fmt(a['free_stroke'], 'um', 1e6)}, applied "
              f"{_fmt(a['applied'], 'um', 1e6)}, stack force {_fmt(a['stack_force'], 'N')}")
    drive_programs.print_drives(out, _fmt)
    for t, v in out.get("output_at", {}).items():
        print(f"output at {float(t) * 1e3:g} ms:      {_fmt(v, 'um', 1e6)}")
    units = out.get("output_units", {})
    for t, values in out.get("outputs_at", {}).items():
        shown = ", ".join(f"{name} " + (_fmt(v, "urad", 1e6) if units.get(name) == "rad"
                                        else _fmt(v, "um", 1e6)) for name, v in values.items())
        print(f"outputs at {float(t) * 1e3:g} ms: {shown}")
    print("hinge deflection, frame b in frame a:  rotation [urad]  x [nm]  y [nm]")
    for name, h in out["hinges"].items():
        print(f"{name:6s} {h['rotation'] * 1e6:14.6g} {h['x'] * 1e9:11.6g} {h['y'] * 1e9:11.6g}")
    simulate_limits.print_stress(out)
    e = out["energy"]
    print(f"energy [J]: kinetic {e['kinetic']:.6g}, potential {e['potential']:.6g}, "
          f"dissipated {e['dissipated']:.6g}, drive work {e['drive_work']:.6g}")
    extra = (
        f", real-time factor {out['real_time_factor']:.3g}" if out.get("real_time_factor") else ""
    )
    print(f"wall time: {out['wall_s']:.4g} s{extra}")


def _print_gain(g: dict) -> None:
    print("static gain (output per unit input of each drive, exact linearisation at rest):")
    print("output   " + "".join(f"{d:>14s}" for d in g["drives"]))
    for name, row in zip(g["outputs"], g["matrix"]):
        print(f"{name:8s} " + "".join(f"{v:14.6g}" for v in row))


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="flexure-sim", description=__doc__.split("\n\n")[0])
    sub = parser.add_subparsers(dest="command", required=True)
    sim = sub.add_parser("simulate", help="simulate a mechanism offline (no ROS)")
    sim.add_argument(
        "mechanism",
        help="built-in name (microstage, fourbar_cantilever, fourbar_mixed) or YAML path",
    )
    sim.add_argument("--drive", action="append", metavar="[NAME=]PROGRAM",
                     help="a drive's program, once per drive: step:A, ramp:A:T, cycloid:A:T, "
                     "sine:A:F (A in m, rad, N or V; T in s; F in Hz), each optionally @START "
                     "(s); NAME= names the drive of a mechanism with several (default: every "
                     "drive at rest; --static without it reports the gain of several drives)")
    sim.add_argument(
        "--duration", type=float, default=0.05, help="simulated time in seconds (default 0.05)"
    )
    sim.add_argument(
        "--dt",
        type=float,
        default=DEFAULT_STEP,
        help=f"fixed step in seconds (default {DEFAULT_STEP:g})",
    )
    sim.add_argument(
        "--relinearize-tol",
        type=float,
        default=None,
        help="also re-linearize when the configuration moved this much (rad, or m per "
        "mechanism size; 0: every step). Default: only when the step's iteration needs it",
    )
    sim.add_argument("--static", action="store_true", help="solve the static equilibrium instead")
    sim.add_argument("--space", choices=("2d", "3d"), default=None,
                     help="3d: open a planar file with its out-of-plane freedoms (the spatial "
                     "engine); default: 3d for a space: 3d file, else 2d")
    sim.add_argument(
        "--stroke-limit",
        action="store_true",
        help="report the drive input at which the first hinge reaches its yield strength",
    )
    sim.add_argument("--cycle-from", type=float, default=0.0,
                     help="fatigue: the drive cycles between this input (m, default 0) and the "
                     "static input (--static) or the input found (--stroke-limit)")
    sim.add_argument("--json", action="store_true", help="print one JSON object")
    _add_tool_commands(sub)
    return parser


def _add_tool_commands(sub) -> None:
    """Tools that work on recorded runs, fitting, etc. (see tools/registry.py)."""
    from flexure_sim.tools import registry as commands

    commands.register(sub)


@quiet_pipe
def main(argv: Optional[Sequence[str]] = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.command != "simulate":
        return args.handler(args)
    try:
        out = run_simulate(args)
    except FlexureSimError as exc:  # ConfigError, UsageError, SolverError, ...: one line
        print(f"flexure-sim: error: {exc}", file=sys.stderr)
        return 2
    if args.json:
        print(json.dumps(out))
    else:
        print_table(out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
