"""
``flexure-sim piezo-loop``: the hysteresis loop of a drive's piezo (engine/actuators/piezo.py).

flexure-sim piezo-loop config/examples/piezo_stage.yaml [--drive NAME] [--frequency HZ]
                [--cycles N] [--load N/m] [--dynamic [--dt S]] [-o loop.png] [--json]

A triangular command over the actuator's full range (v_min .. v_max, or the stroke's ends for
a displacement command) drives the actuator against the stage's stiffness along the drive (the
exact tangent at rest, or ``--load``); the applied displacement is plotted against the command
and the loop's width at the centre of the range is printed with the analytic steady Bouc-Wen
loop's (the series spring's share of it, P8), which it equals when there is no creep and the
amplifier is fast compared with the triangle.

``--dynamic`` steps the whole mechanism instead (the engine's stepping with the actuator,
engine/solver/actuation.py: the stage's mass and damping, the stack as a spring), the command held
over each step of ``--dt``; the load is then the mechanism itself (``--load`` is refused).
"""
from __future__ import annotations

import json
import math
import sys
from pathlib import Path

import numpy as np

from flexure_sim.engine.actuators import piezo, piezo_run
from flexure_sim.engine.mechanism.loader import load_mechanism
from flexure_sim.engine.mechanism.parts import Drive
from flexure_sim.engine.solver.simulation import DEFAULT_STEP, Simulation
from flexure_sim.errors import FlexureSimError

EXIT_OK, EXIT_USAGE = 0, 2


def loop_summary(args) -> tuple[dict, piezo_run.PiezoRun]:
    """Simulate the triangle and return the printed figures (SI) and the run."""
    mech = load_mechanism(args.mechanism)
    drives = [c for c in mech.constraints if isinstance(c, Drive) and c.actuator is not None]
    if args.drive is not None:
        drives = [d for d in drives if d.name == args.drive]
    if len(drives) != 1:
        which = f"drive {args.drive!r} with" if args.drive else "exactly one drive with"
        raise ValueError(f"{args.mechanism}: needs {which} an actuator: block (drives with one: "
                         f"{', '.join(d.name for d in drives) or 'none'}; see --drive)")
    drive = drives[0]
    spec = drive.actuator
    if args.load is None:
        k_load = piezo_run.load_stiffness(Simulation(mech))
    else:
        k_load = args.load
    if not (k_load >= 0 and not math.isnan(k_load)):
        raise ValueError(f"--load {k_load!r}: must be a stiffness >= 0 N/m (inf: blocked)")
    if args.cycles < 2:
        raise ValueError(f"--cycles {args.cycles}: need at least 2 (the first loop starts "
                         "at rest)")
    if args.points < 100:
        raise ValueError(f"--points {args.points}: need at least 100 per cycle")
    times, commands = piezo_run.triangle(spec, args.frequency, args.cycles)
    if args.dynamic:
        if args.load is not None:
            raise ValueError("--load: not with --dynamic (the stepped stage is the load)")
        sim = Simulation(mech, dt=args.dt)
        steps = int(round(args.cycles / args.frequency / sim.dt))
        if steps > 2_000_000:
            raise ValueError(f"--dynamic: {steps} steps of {sim.dt:g} s; raise --frequency or "
                             "--dt, or lower --cycles")
        every = max(1, steps // (args.points * args.cycles))
        run = piezo_run.stepped(sim, sim.model.drives.names.index(drive.name), times, commands,
                                every)
    else:
        t_eval = np.linspace(times[0], times[-1], args.points * args.cycles + 1)
        run = piezo_run.simulate(spec, times, commands, k_load, t_eval)
    centre = 0.5 * (spec.v_min + spec.v_max)
    width = piezo_run.loop_width(run.voltage, run.output, centre)
    half = piezo.steady_loop_half_width(spec, 0.5 * (spec.v_max - spec.v_min))
    analytic = 2.0 * float(piezo.series_output(spec.stiffness, k_load, half))
    stroke = spec.gain * (spec.v_max - spec.v_min)
    out = {
        "mechanism": mech.name, "drive": drive.name, "command": spec.command,
        "load_stiffness": k_load, "stack_stiffness": spec.stiffness,
        "frequency": args.frequency, "cycles": args.cycles, "centre_voltage": centre,
        "loop_width": width, "loop_width_analytic": analytic,
        "loop_width_fraction": width / stroke, "stroke": stroke,
        "peak_output": float(np.max(run.output)), "peak_force": float(np.max(run.force)),
        "creep": bool(spec.creep), "bandwidth": spec.bandwidth,
        "dynamic": bool(args.dynamic), "dt": args.dt if args.dynamic else None,
    }
    return out, run


def plot_loop(out: dict, run: piezo_run.PiezoRun, spec, path: Path) -> None:
    """Plot the applied displacement (m) against the command (V or m); the ideal line dotted."""
    from flexure_sim.tools.run.plot import _pyplot

    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(6.4, 4.8))
    unit = "V" if spec.command == "voltage" else "m"
    ax.plot(run.command, run.output, color="C0", lw=1.2, label="applied displacement x_out")
    ideal = piezo.series_output(spec.stiffness, out["load_stiffness"],
                                piezo.nominal_displacement(spec, run.voltage))
    ax.plot(run.command, ideal, ":", color="0.5", lw=1.0, label="without hysteresis and creep")
    ax.set_xlabel(f"command [{unit}]")
    ax.set_ylabel("applied displacement [m]")
    how = f"stepped, dt {out['dt']:g} s" if out["dynamic"] else "quasi-static"
    ax.set_title(f"{out['mechanism']}, drive {out['drive']!r} ({how}): {out['cycles']} cycles at "
                 f"{out['frequency']:g} Hz, load {out['load_stiffness']:.4g} N/m\n"
                 f"loop width at {out['centre_voltage']:g} V: {out['loop_width']:.4g} m "
                 f"({100 * out['loop_width_fraction']:.3g} % of stroke)", fontsize=9)
    ax.grid(True, color="0.9")
    ax.legend(loc="upper left", fontsize=8)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110, metadata={"Title": "piezo hysteresis loop",
                                         "Software": "flexure_sim"})
    plt.close(fig)


def run_loop(args) -> int:
    """Handle ``flexure-sim piezo-loop``: one line on stderr and exit 2 on bad input."""
    try:
        out, run = loop_summary(args)
        spec = [c for c in load_mechanism(args.mechanism).constraints
                if isinstance(c, Drive) and c.name == out["drive"]][0].actuator
        path = Path(args.output)
        plot_loop(out, run, spec, path)
    except (FlexureSimError, ValueError, RuntimeError, OSError) as exc:
        print(f"flexure-sim piezo-loop: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    out["plot"] = str(path)
    if args.json:
        print(json.dumps(out))
        return EXIT_OK
    print(f"mechanism: {out['mechanism']}   drive: {out['drive']}   command: {out['command']}")
    print(f"load stiffness: {out['load_stiffness']:.6g} N/m   stack: "
          f"{out['stack_stiffness']:.6g} N/m")
    print(f"loop width at {out['centre_voltage']:g} V: {out['loop_width']:.6g} m "
          f"({100 * out['loop_width_fraction']:.4g} % of the {out['stroke']:.4g} m stroke)")
    note = " (hysteresis alone: creep and amplifier lag widen it)" if (
        out["creep"] or out["bandwidth"]) else ""
    print(f"steady Bouc-Wen loop (analytic): {out['loop_width_analytic']:.6g} m{note}")
    print(f"peak applied displacement {out['peak_output']:.6g} m, peak force "
          f"{out['peak_force']:.6g} N")
    print(f"plot: {path}")
    return EXIT_OK


def register(subparsers) -> None:
    """Add the ``piezo-loop`` subcommand."""
    p = subparsers.add_parser(
        "piezo-loop", help="hysteresis loop of a drive's piezo actuator (triangular command)")
    p.add_argument("mechanism", help="mechanism file (or built-in) with a drive's actuator block")
    p.add_argument("--drive", help="drive name (default: the one drive with an actuator)")
    p.add_argument("--frequency", type=float, default=1.0, help="triangle frequency, Hz "
                   "(default 1)")
    p.add_argument("--cycles", type=int, default=3, help="triangle periods (default 3)")
    p.add_argument("--points", type=int, default=2000, help="samples per period (default 2000)")
    p.add_argument("--load", type=float, default=None, help="load stiffness along the drive, "
                   "N/m (default: the mechanism's exact tangent at rest; inf: blocked)")
    p.add_argument("-o", "--output", default="piezo_loop.png", help="PNG file (default "
                   "piezo_loop.png)")
    p.add_argument("--dynamic", action="store_true", help="step the whole mechanism (mass, "
                   "damping, stack spring) instead of the quasi-static series spring")
    p.add_argument("--dt", type=float, default=DEFAULT_STEP, help="step with --dynamic, s "
                   f"(default {DEFAULT_STEP:g})")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(handler=run_loop)
