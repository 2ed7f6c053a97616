"""
The ``flexure-sim`` command.

Offline simulation without ROS (and, from the tools package, analysis of recorded runs).

    flexure-sim simulate microstage --drive step:1.35e-6 --duration 0.05 [--json]
    flexure-sim simulate microstage --drive step:1.35e-6 --static [--json]
    flexure-sim simulate config/fourbar_mixed.yaml --duration 0.2
    flexure-sim simulate xy_stage --static [--json]     # several drives: the gain matrix
    flexure-sim simulate microstage --space 3d --static # with its out-of-plane freedoms
    flexure-sim simulate tiptilt_stage --drive step:p1=1e-5,p2=0,p3=0 --duration 0.01
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
from flexure_sim.engine.hinges.stress import no_yield_advice
from flexure_sim.engine.mechanism.loader import load_mechanism, resolve_mechanism_path
from flexure_sim.engine.mechanism.stroke import check as check_stroke
from flexure_sim.engine.solver.simulation import DEFAULT_STEP, Simulation, Snapshot

#: Times (s) at which the step response is reported, as in the acceptance figures.
REPORT_TIMES = (1e-3, 2e-3, 5e-3)


class UsageError(FlexureSimError, ValueError):
    """A command-line argument is invalid (the message names it)."""


def parse_drive(spec: str) -> float:
    """``step:AMPLITUDE`` (m) -> AMPLITUDE; ``none`` -> 0."""
    if spec == "none":
        return 0.0
    kind, _, value = spec.partition(":")
    if kind != "step" or not value:
        raise UsageError(f"--drive {spec!r}: expected step:AMPLITUDE (metres) or none")
    try:
        amplitude = float(value)
    except ValueError:
        raise UsageError(f"--drive {spec!r}: {value!r} is not a number") from None
    if not np.isfinite(amplitude):
        raise UsageError(f"--drive {spec!r}: amplitude must be finite")
    return amplitude


def summarize(sim: Simulation, snap: Snapshot, amplitude: float) -> dict:
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
    if sim.model.actuation:
        out["actuators"] = actuator_figures(sim, snap)
    if len(sim.model.drives) > 1 or len(sim.model.outputs) > 1:
        out["drives"] = {name: {"input": float(snap.drive_inputs[k]),
                                "force": float(snap.drive_forces[k]),
                                "position": float(snap.drive_positions[k])}
                         for k, name in enumerate(snap.drive_names)}
        out["outputs"] = dict(snap.outputs)
    return out


def actuator_figures(sim: Simulation, snap: Snapshot) -> dict:
    """
    Return the figures of each drive with a piezo actuator (engine/solver/actuation.py).

    Its command (V or m, ``unit``), amplifier voltage (V), free stroke and applied
    displacement (m), stack force (N).
    """
    out = {}
    for a in sim.model.actuation:
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
    return sim.drive is not None or (len(sim.model.drives) == 1 and bool(sim.model.actuation))


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
        return simulate_spatial.run(args, path, UsageError)
    mech = load_mechanism(path)
    amplitude = parse_drive(args.drive)
    sim = Simulation(mech, dt=args.dt, relinearize_tol=args.relinearize_tol)
    several = len(sim.model.drives) > 1 or len(sim.model.outputs) > 1
    if amplitude and several and len(sim.model.drives) > 1:
        raise UsageError(f"--drive: mechanism {mech.name!r} has {len(sim.model.drives)} drives "
                         f"({', '.join(sim.model.drive_names)}); --static without --drive "
                         "reports the gain of every output against every drive")
    if amplitude and sim.drive is None and not sim.model.drives:
        raise UsageError(f"--drive: mechanism {mech.name!r} has no drive")
    if args.static and len(sim.model.stack_index):
        raise UsageError(f"--static: mechanism {mech.name!r} has a drive with a finite-stiffness "
                         "piezo stack (its input is the actuator's free stroke, a dynamic "
                         "state): simulate without --static to a steady state")
    if amplitude and mech.drives:  # the stroke rule of every analysis (mechanism/stroke.py)
        check_stroke(mech.drives[:1], [amplitude], f"--drive {args.drive}", command=True)
    start = time.perf_counter()
    if args.stroke_limit:
        return _stroke_limit(args, sim)
    if args.static:
        result = sim.static(amplitude if len(sim.model.drives) <= 1 else
                            np.zeros(len(sim.model.drives)))
        out = summarize(sim, result.snapshot, amplitude)
        if several:
            out["gain_matrix"] = gain_matrix(sim)
        wall = time.perf_counter() - start
        out.update(mechanism_file=str(path), mode="static", newton_iterations=result.iterations,
                   residual=result.residual, wall_s=wall)
        out["hinge_stress"] = _stress(sim, result.snapshot)
        out["stress_note"] = no_yield_advice(sim.mechanism)
        out["fatigue"] = _fatigue(args, sim, amplitude)
        return out
    if _single_command(sim):
        sim.set_command(amplitude)
    n_steps = int(round(args.duration / args.dt))
    samples = {}
    marks = {int(round(t / args.dt)): t for t in REPORT_TIMES if t <= args.duration}
    for k in range(1, n_steps + 1):
        sim.step()
        if k in marks and mech.output is not None:
            samples[f"{marks[k]:g}"] = sim.snapshot().output
    wall = time.perf_counter() - start
    out = summarize(sim, sim.snapshot(), amplitude)
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


def spatial(args: argparse.Namespace, path) -> bool:
    """Tell whether to simulate in 3-D: ``--space 3d``, or a ``space: 3d`` file (auto)."""
    from flexure_sim.engine.mechanism.spatial_loader import is_spatial
    three_d = is_spatial(path)
    if args.space == "2d" and three_d:
        raise UsageError(f"--space 2d: {path} is a 3-D mechanism (space: 3d)")
    return args.space == "3d" or three_d


def gain_matrix(sim: Simulation) -> dict:
    """
    Return the exact static gain at rest, each output (rows) against each drive (columns).

    ``Simulation.static_gain``, as JSON (m/m, rad/m, m/N, ... per the pair's units).
    """
    G = sim.static_gain()
    return {"outputs": list(sim.model.output_names), "drives": list(sim.model.drive_names),
            "matrix": [[float(g) for g in row] for row in G]}


def _stress(sim: Simulation, snap: Snapshot) -> dict:
    """Peak stress and stress ratio per notch/leaf hinge (engine/hinges/stress.py)."""
    from flexure_sim.engine.hinges.stress import stress_table

    return stress_table(snap.wrenches, sim.mechanism)


def _fatigue(args, sim: Simulation, amplitude: float) -> Optional[dict]:
    """
    Return the fatigue of cycling the drive between --cycle-from and the static input.

    engine/hinges/fatigue.py; None without a single drive or a cycle (input equal to
    --cycle-from).
    """
    from flexure_sim.engine.hinges import fatigue

    lower = args.cycle_from
    if not np.isfinite(lower):
        raise UsageError(f"--cycle-from {lower!r}: must be a finite drive input")
    if sim.drive is None or amplitude == lower:
        return None
    try:
        return fatigue.static_report(sim, lower, amplitude)
    except ValueError as exc:
        raise UsageError(f"fatigue: {exc}") from None


def _stroke_limit(args, sim: Simulation) -> dict:
    """--stroke-limit: the drive input at which the first hinge reaches its yield strength."""
    from flexure_sim.engine.hinges.stress import stroke_limit

    if sim.drive is None:
        names = sim.model.drive_names
        has = (f"{len(names)} drives ({', '.join(names)})" if len(names) > 1 else
               "no drive" if not names else f"the drive {names[0]!r}, not a displacement drive")
        raise UsageError(f"--stroke-limit: mechanism {sim.mechanism.name!r} has {has}: the "
                         "stroke limit is the input of a single displacement drive at which "
                         "the first hinge yields")
    from flexure_sim.engine.hinges import fatigue

    try:
        u, hinge = stroke_limit(sim)
    except ValueError as exc:
        raise UsageError(f"--stroke-limit: {exc}") from None
    life, note = {}, fatigue.no_fatigue_advice(sim.mechanism)
    if any(h.stress is not None and h.stress.has_fatigue for h in sim.mechanism.hinges):
        for criterion in fatigue.CRITERIA:  # cycling from --cycle-from up to the input found
            point, where = fatigue.infinite_life_input(sim, args.cycle_from, u, criterion)
            life[criterion] = {"input": point, "hinge": where}
    return {"mechanism": sim.mechanism.name, "mechanism_file": str(resolve_mechanism_path(
                args.mechanism)), "mode": "stroke_limit", "stroke_limit": u, "hinge": hinge,
            "actuator_stroke": list(sim.drive.stroke), "cycle_from": args.cycle_from,
            "infinite_life": life, "fatigue_note": note}


def _fmt(v: Optional[float], unit: str, scale: float = 1.0, digits: int = 6) -> str:
    return "n/a" if v is None else f"{v * scale:.{digits}g} {unit}"


def print_table(out: dict) -> None:
    if out.get("space") == "3d":
        from flexure_sim.tools.run import simulate_spatial
        simulate_spatial.print_table(out)
        return
    if out["mode"] == "stroke_limit":
        print(f"mechanism: {out['mechanism']}   stroke limit (first hinge at yield): "
              f"{out['stroke_limit'] * 1e6:.6g} um at hinge {out['hinge']} "
              f"(actuator stroke {out['actuator_stroke'][1] * 1e6:g} um)")
        for criterion, v in out["infinite_life"].items():
            print(f"infinite life ({criterion.capitalize()}, cycling from "
                  f"{out['cycle_from'] * 1e6:g} um): up to {v['input'] * 1e6:.6g} um, "
                  f"hinge {v['hinge']} first")
        if out["fatigue_note"]:
            print(f"fatigue: {out['fatigue_note']}")
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
        g = out["gain_matrix"]
        print("static gain (output per unit input of each drive, exact linearisation at rest):")
        print("output   " + "".join(f"{d:>14s}" for d in g["drives"]))
        for name, row in zip(g["outputs"], g["matrix"]):
            print(f"{name:8s} " + "".join(f"{v:14.6g}" for v in row))
    for name, a in out.get("actuators", {}).items():
        command = _fmt(a["command"], "V") if a["unit"] == "V" else _fmt(a["command"], "um", 1e6)
        print(f"actuator {name}: command {command}, amplifier {_fmt(a['voltage'], 'V')}, free "
              f"stroke {_fmt(a['free_stroke'], 'um', 1e6)}, applied "
              f"{_fmt(a['applied'], 'um', 1e6)}, stack force {_fmt(a['stack_force'], 'N')}")
    for t, v in out.get("output_at", {}).items():
        print(f"output at {float(t) * 1e3:g} ms:      {_fmt(v, 'um', 1e6)}")
    print("hinge deflection, frame b in frame a:  rotation [urad]  x [nm]  y [nm]")
    for name, h in out["hinges"].items():
        print(f"{name:6s} {h['rotation'] * 1e6:14.6g} {h['x'] * 1e9:11.6g} {h['y'] * 1e9:11.6g}")
    if out.get("hinge_stress"):
        print("hinge stress:  peak [MPa]  sigma_y [MPa]  ratio")
        for name, h in out["hinge_stress"].items():
            sy = "n/a" if h["sigma_y"] is None else f"{h['sigma_y'] / 1e6:.4g}"
            ratio = "n/a" if h["ratio"] is None else f"{h['ratio']:.4g}"
            print(f"{name:6s} {h['stress'] / 1e6:17.5g} {sy:>14s} {ratio:>6s}")
        if out.get("stress_note"):
            print(f"stress: {out['stress_note']}")
    if out.get("fatigue"):
        print_fatigue(out["fatigue"])
    e = out["energy"]
    print(f"energy [J]: kinetic {e['kinetic']:.6g}, potential {e['potential']:.6g}, "
          f"dissipated {e['dissipated']:.6g}, drive work {e['drive_work']:.6g}")
    extra = (
        f", real-time factor {out['real_time_factor']:.3g}" if out.get("real_time_factor") else ""
    )
    print(f"wall time: {out['wall_s']:.4g} s{extra}")


def print_fatigue(f: dict) -> None:
    """Print the fatigue of a static cycle (``fatigue.static_report``)."""
    lo, hi = f["cycle"]
    print(f"fatigue, cycling the drive {lo * 1e6:g} -> {hi * 1e6:g} um (Shigley 6-12; stress of "
          "the hinge's worst fibre):")
    if f["hinges"]:
        print("hinge  amplitude [MPa]  mean [MPa]  Goodman n  Soderberg n  S_e [MPa] at cycles")
    for name, h in f["hinges"].items():
        n = ["inf" if h[c] is None else f"{h[c]:.4g}" for c in ("goodman", "soderberg")]
        print(f"{name:6s} {h['amplitude'] / 1e6:15.5g} {h['mean'] / 1e6:11.5g} {n[0]:>10s} "
              f"{n[1]:>12s} {h['sigma_e'] / 1e6:10.4g} at {h['cycles']:.3g}")
    for criterion, c in f["critical"].items():
        life = f["infinite_life"][criterion]
        if c is not None:
            print(f"critical hinge ({criterion.capitalize()}): {c['hinge']}, n = "
                  f"{c['safety']:.4g}; infinite life up to {life['input'] * 1e6:.6g} um of "
                  f"drive input (hinge {life['hinge']})")
    if f["note"]:
        print(f"fatigue: {f['note']}")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="flexure-sim", description=__doc__.split("\n\n")[0])
    sub = parser.add_subparsers(dest="command", required=True)
    sim = sub.add_parser("simulate", help="simulate a mechanism offline (no ROS)")
    sim.add_argument(
        "mechanism",
        help="built-in name (microstage, fourbar_cantilever, fourbar_mixed) or YAML path",
    )
    sim.add_argument("--drive", default="none", help="step:AMPLITUDE in metres (volts for a "
                     "drive whose actuator takes a voltage), or none (default)")
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
