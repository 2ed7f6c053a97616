"""
``flexure-sim analyse RUN.mcap``.

Per step of the drive, the gain, 2 % settling time, overshoot, steady-state joint-a compression,
peak wrench per hinge, peak drive force and the peak hinge stress ratio sigma / sigma_y
(engine/hinges/stress.py, from the recorded wrenches and the recorded mechanism's Hinge.stress
geometry).

    flexure-sim analyse runs/stage.mcap [--json] [--recover] [--strict] [--band 0.02] [--no-static]

The gain of each step is compared with the engine's static solve of the recorded mechanism
at the same inputs (column ``static gain``). Definitions: `flexure_sim.tools.run.step_analysis`.
"""
from __future__ import annotations

import argparse
import json
import math
from typing import Any, Optional

import numpy as np

from flexure_sim.recording.command_line import report_reading, tool_errors, warn
from flexure_sim.recording.exceptions import EXIT_OK, EXIT_USAGE, RunError
from flexure_sim.topics import COMMAND, DRIVE_FORCE, DRIVE_INPUT, OUTPUT
from flexure_sim.tools.run import step_analysis as analysis
from flexure_sim.tools.run.analyse_drives import analyse_drives, format_drives
from flexure_sim.tools.run.command_counts import command_counts, format_command_counts
from flexure_sim.tools.run.run_channels import is_single_drive, recorded_stroke
from flexure_sim.tools.options import add_file_arguments
from flexure_sim.tools.run.response_metrics import DEFAULT_BAND
from flexure_sim.tools.run.runlog import Run, load_run, require_stage_run
from flexure_sim.tools.tables import columns, format_si

PROG = "flexure-sim analyse"


def register(subparsers: Any) -> None:
    p = subparsers.add_parser(
        "analyse",
        aliases=["analyze"],
        help="gain, settling time, overshoot, hinge loads and drive force per step of a "
        "recorded run",
        description=__doc__.split("\n\n")[0].replace("``", ""),
    )
    add_file_arguments(p)
    p.add_argument("--json", action="store_true",
                   help="print a JSON list of steps (SI units; overshoot as a fraction); with "
                   "several drives or outputs an object with the gain matrix, pairs and steps")
    p.add_argument("--band", type=float, default=DEFAULT_BAND,
                   help="settling band as a fraction of the change (default 0.02)")
    p.add_argument("--no-static", action="store_true",
                   help="do not compare with the engine's static solve of the recorded mechanism")
    p.set_defaults(handler=run)


def run(args: argparse.Namespace) -> int:
    return tool_errors(PROG, lambda: _run(args), can_recover=not args.recover)


def _run(args: argparse.Namespace) -> int:
    if not (0.0 < args.band < 1.0):
        raise RunError(f"--band {args.band!r}: must be between 0 and 1 (0.02 is 2 %)", EXIT_USAGE)
    run_ = load_run(args.run, recover=args.recover, namespace=args.namespace, strict=args.strict,
                    poses=False)
    report_reading(PROG, run_)
    if not is_single_drive(run_.topics, run_.topic) and run_.drives():
        result = analyse_drives(run_, band=args.band, static=not args.no_static)
        for note in result["notes"]:
            warn(PROG, note)
        result["commands"] = counts = command_counts(run_, [d.name for d in run_.drives()])
        print(json.dumps(_jsonable(result), indent=1) if args.json
              else format_drives(run_, result) + "\n" + format_command_counts(counts))
        return EXIT_OK
    result = analyse_run(run_, band=args.band, static=not args.no_static)
    for note in result["notes"]:
        warn(PROG, note)
    if args.json:
        print(json.dumps([_jsonable(s) for s in result["steps"]], indent=1))
    else:
        print(format_result(run_, result) + "\n" + format_command_counts(command_counts(run_)))
    return EXIT_OK


def _jsonable(value: Any) -> Any:
    if isinstance(value, dict):
        return {k: _jsonable(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_jsonable(v) for v in value]
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def _signal(run: Run, topic: str) -> Optional[tuple[np.ndarray, np.ndarray]]:
    s = run.scalar(topic)
    return None if s is None else (s.t, s.values)


def find_steps(run: Run) -> tuple[list[analysis.Step], str]:
    """Return the steps of the drive and where they were found (a topic name)."""
    return steps_of(run, COMMAND, DRIVE_INPUT, ("stroke_min", "stroke_max"))


def steps_of(run: Run, command: str, applied: str, stroke_keys: tuple[str, str],
             same_unit: bool = True) -> tuple[list[analysis.Step], str]:
    """
    Return the steps of one drive and where they were found (a topic name).

    From its ``command`` topic if recorded (clamped to the stroke the metadata keys
    ``stroke_keys`` give), else from its ``applied`` input (`analysis`). The target before
    the first command is the first applied input if ``same_unit`` (command and input in one
    unit), else 0 clamped to the stroke (a command in volts).
    """
    u = run.scalar(applied)
    cmd = run.scalar(command)
    if cmd is not None and not cmd.empty:
        stroke = recorded_stroke(run.metadata, stroke_keys)
        initial = float(u.values[0]) if same_unit and u is not None and not u.empty else (
            min(max(0.0, stroke[0]), stroke[1]) if stroke else 0.0)
        return analysis.command_steps(
            cmd.t, cmd.values, initial=initial, stroke=stroke
        ), run.topic(command)
    if u is None or u.empty:
        return [], run.topic(applied)
    return analysis.input_steps(u.t, u.values), run.topic(applied)


def static_gains(run: Run, steps: list[analysis.StepMetrics]) -> tuple[dict[int, float], str]:
    """Gain of the engine's static solve between each step's applied inputs (by step index)."""
    mech = run.mechanism()
    if mech is None:
        return (
            {},
            f"no static comparison: cannot load the run's mechanism ({run.mechanism_problem})",
        )
    if not mech.drives or not mech.all_outputs:
        return {}, f"no static comparison: mechanism {mech.name} has no drive or no output"
    from flexure_sim.engine.solver.simulation import SolverError
    from flexure_sim.tools.run.run_engine import RunEngine

    sim = RunEngine(mech)
    first = sim.output_names[0]
    outputs: dict[float, float] = {}

    def out(u: float) -> float:
        if u not in outputs:
            outputs[u] = 0.0 if u == 0.0 else float(sim.static_outputs(u)[first])
        return outputs[u]

    gains = {}
    try:
        for s in steps:
            u0, u1 = s.applied_input_before, s.applied_input
            if u0 is None or u1 is None or u1 == u0:
                continue
            gains[s.index] = (out(u1) - out(u0)) / (u1 - u0)
    except SolverError as exc:
        return gains, f"static solve failed: {exc}"
    return gains, ""


def analyse_run(run: Run, band: float = DEFAULT_BAND, static: bool = True) -> dict:
    """Step and their metrics as dicts, with notes for the user."""
    require_stage_run(run, "analyse")
    notes: list[str] = []
    if run.clock_mapped:
        notes.append(f"the log times of {run.path} are not simulation time (recorded on the wall "
                     "clock?): simulation time is taken from the recorded /clock, to one tick")
    steps, source = find_steps(run)
    if source != run.topic(COMMAND) and steps:
        notes.append(f"no drive command recorded ({run.topic(COMMAND)}): steps found in {source}")
    comp_topic = run.compression_topic()
    wrenches = {h: (s.t, s.values) for h, s in run.wrenches().items()}
    output = _signal(run, OUTPUT)
    assert output is not None
    metrics = analysis.analyse_steps(
        steps, output,
        drive_input=_signal(run, DRIVE_INPUT),
        compression=_signal(run, comp_topic) if comp_topic else None,
        drive_force=_signal(run, DRIVE_FORCE),
        wrenches=wrenches,
        t_end=run.end_ns / 1e9,
        compression_hinge=run.compression_hinge(),
        band=band,
    )
    gains: dict[int, float] = {}
    if static and metrics:
        gains, problem = static_gains(run, metrics)
        if problem:
            notes.append(problem)
    if not run.complete and metrics:
        metrics[-1].notes.append("the file was cut short: this step may be incomplete")
    out = []
    for m in metrics:
        d = m.as_dict()
        d["static_gain"] = gains.get(m.index)
        out.append(d)
    mech = run.mechanism()
    # The spatial engine's hinges carry no stress model: no stress or fatigue of a 3-D run.
    stressed = mech is not None and all(hasattr(h, "stress") for h in mech.hinges)
    peaks, problem = (stress_peaks(run, out, mech) if stressed else (
        {}, f"no hinge stress: {run.mechanism_problem}" if mech is None else
        "no hinge stress: the spatial engine has no hinge stress model"))
    if problem and out:
        notes.append(problem)
    lives, whole, problem = (fatigue_of_steps(run, out, mech) if stressed
                             else ({}, None, ""))
    if problem and out:
        notes.append(problem)
    for d in out:
        d["peak_stress"] = peaks.get(d["index"])
        d["fatigue"] = lives.get(d["index"])
    return {"steps": out, "source": source, "notes": notes, "band": band,
            "duration": (run.end_ns - run.start_ns) / 1e9, "fatigue": whole}


def fatigue_of_steps(run: Run, steps: list[dict], mech) -> tuple[dict, Optional[dict], str]:
    """
    Return the fatigue of each step and of the whole run, and a note if there is none.

    Each point of a hinge's section cycles between its extreme stresses over the step's wrench
    samples (over all samples for the run: its largest cycle), engine/hinges/fatigue.py. Per
    step index and for the run: the critical hinge's {"hinge", "goodman", "soderberg",
    "amplitude", "mean"}, or None.
    """
    from flexure_sim.engine.hinges import fatigue

    wrenches = run.wrenches()
    recorded = [h for _, h in fatigue.with_strengths(mech) if h.name in wrenches]
    advice = fatigue.no_fatigue_advice(mech)

    def worst(inside) -> Optional[dict]:
        entries = []
        for h in recorded:
            series = wrenches[h.name]
            values = series.values[inside(series)]
            if len(values):
                entries.append((h.name, h.stress, fatigue.envelope(h.stress, values)))
        table = fatigue.table(entries)
        found = fatigue.critical(table)
        return None if found is None else {"hinge": found[0], **table[found[0]]}

    per_step = {s["index"]: worst(lambda series, s=s: (series.t > s["t"])
                                  & (series.t <= s["t"] + s["duration"])) for s in steps}
    whole = worst(lambda series: np.ones(len(series.t), dtype=bool))
    note = f"no fatigue: {advice}" if whole is None and advice else ""
    return per_step, whole, note


def stress_peaks(run: Run, steps: list[dict], mech) -> tuple[dict[int, Optional[dict]], str]:
    """
    Per step index.

    The hinge with the largest stress ratio sigma / sigma_y over the step's wrench samples,
    {"hinge", "stress" (Pa), "ratio"}, or None; and a note if there is none.
    """
    from flexure_sim.engine.hinges.stress import no_yield_advice

    wrenches = run.wrenches()
    hinges = [(h.name, h.stress) for h in mech.hinges
              if h.name in wrenches and h.stress is not None and h.stress.sigma_y is not None]
    if not hinges:
        return {}, f"no hinge stress: {no_yield_advice(mech) or 'no recorded notch or leaf hinge'}"
    out: dict[int, Optional[dict]] = {}
    for s in steps:
        t0, t1 = s["t"], s["t"] + s["duration"]
        best = None
        for name, g in hinges:
            series = wrenches[name]
            inside = (series.t > t0) & (series.t <= t1)  # the step's window, as analysis._window
            if not inside.any():
                continue
            peak = float(np.max(g.stress(series.values[inside])))
            ratio = peak / g.sigma_y
            if best is None or ratio > best["ratio"]:
                best = {"hinge": name, "stress": peak, "ratio": ratio}
        out[s["index"]] = best
    return out, ""


def _stress_cell(peak: Optional[dict]) -> str:
    return "-" if not peak else f"{peak['ratio']:.4f} ({peak['hinge']})"


def _fatigue_cell(life: Optional[dict]) -> str:
    return "-" if not life else f"{life['goodman']:.4g} ({life['hinge']})"


def _fixed(v: Optional[float], scale: float, decimals: int) -> str:
    """Fixed-point text of v * scale ("-" for None); -0.000 shows as 0.000."""
    if v is None or not math.isfinite(v):
        return "-"
    text = f"{v * scale:.{decimals}f}"
    return text[1:] if text.startswith("-") and not text.strip("-0.") else text


def format_result(run: Run, result: dict) -> str:
    steps = result["steps"]
    mech = run.mechanism_name or "unknown mechanism"
    lines = [
        f"{run.path}: {mech}, {len(steps)} step(s) in {result['duration']:.6g} s of simulation "
        f"time (steps of {result['source']})"
    ]
    if not steps:
        lines.append("no steps: the drive command never changed")
        return "\n".join(lines)
    hinge = steps[0].get("compression_hinge") or "a"
    header = [
        "step",
        "t [ms]",
        "input [um]",
        "gain",
        "static gain",
        "settling [ms]",
        "overshoot [%]",
        "rise [ms]",
        f"joint-{hinge} compr. [nm]",
        "drive force [N]",
        "peak drive force [N]",
        "peak stress/yield",
        "fatigue n",
    ]
    rows = []
    for s in steps:
        rows.append([
            str(s["index"]) + ("" if s["settled"] else "*"),
            _fixed(s["t"], 1e3, 3),
            f"{_fixed(s['input_before'], 1e6, 3)} -> {_fixed(s['input'], 1e6, 3)}",
            format_si(s["gain"], "", 1.0, 6),
            format_si(s["static_gain"], "", 1.0, 6),
            _fixed(s["settling_time"], 1e3, 3),
            _fixed(s["overshoot"], 100.0, 3),
            _fixed(s["rise_time"], 1e3, 3),
            _fixed(s["joint_a_compression"], 1e9, 3),
            _fixed(s["drive_force"], 1.0, 4),
            _fixed(s["peak_drive_force"], 1.0, 4),
            _stress_cell(s.get("peak_stress")),
            _fatigue_cell(s.get("fatigue")),
        ])
    lines.append(columns(rows, header))
    hinges = sorted({h for s in steps for h in s["peak_wrench"]},
                    key=lambda h: run.hinge_names().index(h) if h in run.hinge_names() else 99)
    if hinges:
        lines.append("")
        lines.append("peak hinge load per step: in-plane force |f| [N] / moment [mN m] "
                     "(wrench on body B, in frame b)")
        rows = []
        for s in steps:
            row = [str(s["index"])]
            for h in hinges:
                w = s["peak_wrench"].get(h)
                row.append("-" if w is None else f"{w['force']:.4g} / {w['moment'] * 1e3:.4g}")
            rows.append(row)
        lines.append(columns(rows, ["step"] + hinges))
    notes = [(s["index"], n) for s in steps for n in s["notes"]]
    lines.append("")
    if notes:
        lines += [f"step {i}: {n}" for i, n in notes]
    if any(not s["settled"] for s in steps):
        lines.append("* not settled before the next step (or the end): no gain reported")
    lines.append(
        f"gain = output change / applied input change between settled values; settling "
        f"time to within {result['band'] * 100:g} % of the output change, from the command; "
        "static gain: the engine's static solve at the same inputs; peak stress/yield: "
        "the largest hinge stress ratio sigma/sigma_y during the step (hinge); fatigue n: the "
        "Goodman safety factor of the step's largest stress cycle, critical hinge "
        "(engine/hinges/fatigue.py)."
    )
    life = result.get("fatigue")
    if life:
        lines.append(
            f"fatigue over the whole run (each fibre between its extreme stresses): critical "
            f"hinge {life['hinge']}, Goodman n = {life['goodman']:.4g}, Soderberg n = "
            f"{life['soderberg']:.4g} (amplitude {life['amplitude'] / 1e6:.4g} MPa, mean "
            f"{life['mean'] / 1e6:.4g} MPa; S_e {life['sigma_e'] / 1e6:.4g} MPa at "
            f"{life['cycles']:.3g} cycles, {life['material'] or 'sigma_e of the file'})")
    return "\n".join(lines)
