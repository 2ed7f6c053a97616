"""
``flexure-sim analyse`` of a run with several drives or outputs: the gain matrix.

Every output against every drive, from the steps of each drive while the others hold
(definitions: `gain_matrix`), with settling time and overshoot per (drive, output) pair and
the response of every output to every step. Compared with the engine's static solve of the
recorded mechanism: per step at the same applied inputs (``static_gain``), and as the exact
linearisation at rest (``static_gain_matrix``, what ``flexure-sim simulate --static``
reports as ``gain_matrix``).
"""
from __future__ import annotations

import math
from typing import Optional

import numpy as np

from flexure_sim.recording.exceptions import RunError
from flexure_sim.tools.run import step_analysis as analysis
from flexure_sim.tools.run.run_channels import DriveChannel, gain_unit, stroke_keys
from flexure_sim.tools.run.gain_matrix import DriveStep, analyse_drive_steps, gain_pairs, matrix
from flexure_sim.tools.run.runlog import Run
from flexure_sim.tools.tables import columns, format_si


def drive_steps(run: Run, drive: DriveChannel) -> tuple[list[analysis.Step], str]:
    """Return the steps of one drive and where they were found (a topic), as `find_steps`."""
    from flexure_sim.tools.run.analyse import steps_of

    return steps_of(run, drive.command, drive.input, stroke_keys(drive),
                    drive.command_unit == drive.unit)


def _matrix_dict(drives: list[str], outputs: list[str], rows) -> dict:
    return {"outputs": list(outputs), "drives": list(drives),
            "matrix": [[None if v is None else float(v) for v in row] for row in rows]}


def static_comparison(run: Run, steps: list[DriveStep], drives: list[str],
                      outputs: list[str]) -> tuple[Optional[dict], str]:
    """
    Compare with the engine's static solve of the recorded mechanism.

    Sets each step's ``outputs[o].static_gain`` (static output change between the applied
    inputs of every drive before and after the step, per applied input change of the stepped
    drive) and returns the exact gain matrix at rest, or (None, why not).
    """
    mech = run.mechanism()
    if mech is None:
        return None, f"no static comparison: cannot load the run's mechanism " \
                     f"({run.mechanism_problem})"
    from flexure_sim.engine.solver.simulation import SolverError
    from flexure_sim.tools.run.run_engine import RunEngine

    sim = RunEngine(mech)
    names, onames = list(sim.drive_names), list(sim.output_names)
    if sorted(names) != sorted(drives) or sorted(onames) != sorted(outputs):
        return None, (f"no static comparison: the recorded mechanism's drives ({', '.join(names)})"
                      f" and outputs ({', '.join(onames)}) are not the run's")
    try:
        g = sim.static_gain()
    except SolverError as exc:
        return None, f"static solve failed: {exc}"
    at_rest = [[float(g[onames.index(o), names.index(d)]) for d in drives] for o in outputs]
    held: dict[str, float] = {d: 0.0 for d in names}
    cache: dict[tuple, dict] = {}

    def solve(u: dict[str, float]) -> dict:
        key = tuple(u[d] for d in names)
        if key not in cache:
            cache[key] = sim.static_outputs({d: u[d] for d in names})
        return cache[key]

    try:
        for s in steps:
            u0, u1 = s.applied_input_before, s.applied_input
            if u0 is None or u1 is None or u0 == u1 or not s.clean:
                if u1 is not None:
                    held[s.drive] = u1
                continue
            before, after = solve({**held, s.drive: u0}), solve({**held, s.drive: u1})
            for o, r in s.outputs.items():
                r.static_gain = (after[o] - before[o]) / (u1 - u0)
            held[s.drive] = u1
    except SolverError as exc:
        return _matrix_dict(drives, outputs, at_rest), f"static solve failed: {exc}"
    return _matrix_dict(drives, outputs, at_rest), ""


def _finite(run: Run, topic: str, notes: list[str]) -> tuple[np.ndarray, np.ndarray]:
    """(t, values) of a Float64 topic without its non-finite samples (counted in ``notes``)."""
    s = run.scalar(topic)
    keep = np.isfinite(s.values)
    if not keep.all():
        notes.append(f"{run.topic(topic)}: {int((~keep).sum())} non-finite sample(s) ignored")
    return s.t[keep], s.values[keep]


def analyse_drives(run: Run, band: float, static: bool = True) -> dict:
    """Return the gain matrix, pairs and steps of a run with several drives/outputs (dict)."""
    drives, outputs = run.drives(), run.outputs()
    if not drives or not outputs:
        raise RunError(f"{run.path}: analyse needs a drive and an output; this run has "
                       f"drives: {', '.join(d.name for d in drives) or 'none'}, outputs: "
                       f"{', '.join(o.name for o in outputs) or 'none'}")
    notes: list[str] = []
    steps, inputs, sources = {}, {}, {}
    for d in drives:
        steps[d.name], sources[d.name] = drive_steps(run, d)
        if steps[d.name] and sources[d.name] != run.topic(d.command):
            notes.append(f"drive {d.name}: no command recorded ({run.topic(d.command)}): "
                         f"steps found in {sources[d.name]}")
        inputs[d.name] = _finite(run, d.input, notes)
    signals = {o.name: _finite(run, o.topic, notes) for o in outputs}
    dnames, onames = [d.name for d in drives], [o.name for o in outputs]
    result = analyse_drive_steps(steps, inputs, signals, run.end_ns / 1e9, band=band)
    static_matrix = None
    if static and result:
        static_matrix, problem = static_comparison(run, result, dnames, onames)
        if problem:
            notes.append(problem)
    if not run.complete and result:
        result[-1].notes.append("the file was cut short: this step may be incomplete")
    pairs = gain_pairs(result, dnames, onames)
    units = {d.name: d.unit for d in drives}
    ounits = {o.name: o.unit for o in outputs}
    return {
        "drives": [{"name": d.name, "kind": d.kind, "unit": d.unit, "command":
                    run.topic(d.command), "command_unit": d.command_unit,
                    "input": run.topic(d.input),
                    "steps_from": sources[d.name]} for d in drives],
        "outputs": [{"name": o.name, "unit": o.unit, "topic": run.topic(o.topic)}
                    for o in outputs],
        "gain_matrix": _matrix_dict(dnames, onames, matrix(pairs, dnames, onames)),
        "static_gain_matrix": static_matrix,
        "pairs": [{"drive": p.drive, "output": p.output, "gain": p.gain,
                   "unit": gain_unit(ounits[p.output], units[p.drive]), "steps": p.steps,
                   "settling_time": p.settling_time, "overshoot": p.overshoot}
                  for p in pairs],
        "steps": [s.as_dict() for s in result],
        "notes": notes,
        "band": band,
        "duration": (run.end_ns - run.start_ns) / 1e9,
    }


def _num(v: Optional[float], digits: int = 6, scale: float = 1.0) -> str:
    return format_si(v, "", scale, digits)


def _ms(v: Optional[float]) -> str:
    return "-" if v is None or not math.isfinite(v) else f"{v * 1e3:.3f}"


def _si(v: Optional[float], unit: str, ref: Optional[float] = None) -> str:
    """
    Format a value with a readable prefix (um, urad, mN...).

    The prefix is chosen by |v|, or with ``ref`` by the larger of |v| and |ref|, and the value
    rounded to 6 digits of that size: both ends of a step read in one unit and to one
    resolution, so an input that decayed to a denormal reads 0 (``10 um -> 0 um``).
    """
    if v is None or not math.isfinite(v):
        return "-"
    size = abs(v) if ref is None or not math.isfinite(ref) else max(abs(v), abs(ref))
    base = unit.split()[0] if unit else ""
    rest = unit[len(base):]
    for prefix, scale in (("", 1.0), ("m", 1e3), ("u", 1e6), ("n", 1e9)):
        if size * scale >= 1.0 or prefix == "n":
            break
    x = v * scale
    if ref is not None and size > 0.0:
        quantum = 10.0 ** (math.floor(math.log10(size * scale)) - 5)
        x = round(x / quantum) * quantum + 0.0  # + 0.0: no "-0"
    return f"{x:.6g} {prefix}{base}{rest}"


def _step_inputs(before: Optional[float], after: Optional[float], unit: str) -> str:
    """Return ``before -> after`` of a step's applied input, in one unit (``_si``)."""
    return f"{_si(before, unit, after)} -> {_si(after, unit, before)}"


def format_drives(run: Run, result: dict) -> str:
    """Text report: gain matrix, static matrix, pairs, then every step."""
    dnames = [d["name"] for d in result["drives"]]
    onames = [o["name"] for o in result["outputs"]]
    units = {d["name"]: d["unit"] for d in result["drives"]}
    ounits = {o["name"]: o["unit"] for o in result["outputs"]}
    steps = result["steps"]
    mech = run.mechanism_name or "unknown mechanism"
    lines = [f"{run.path}: {mech}, drives {', '.join(dnames)}, outputs {', '.join(onames)}; "
             f"{len(steps)} step(s) in {result['duration']:.6g} s of simulation time"]
    if not steps:
        lines.append("no steps: no drive command ever changed")
        return "\n".join(lines)
    header = ["output \\ drive"] + [f"{d} [{units[d]}]" for d in dnames]

    def table(m: dict) -> str:
        rows = [[f"{o} [{ounits[o]}]"] + [_num(v) for v in row]
                for o, row in zip(m["outputs"], m["matrix"])]
        return columns(rows, header)

    lines += ["", "gain matrix (output change / input change over the steps of each drive, "
              "the others held):", table(result["gain_matrix"])]
    if result["static_gain_matrix"] is not None:
        gm = np.array([[np.nan if v is None else v for v in row]
                       for row in result["gain_matrix"]["matrix"]], dtype=float)
        sm = np.array(result["static_gain_matrix"]["matrix"], dtype=float)
        scale = float(np.nanmax(np.abs(sm))) if sm.size else 0.0
        diff = float(np.nanmax(np.abs(gm - sm))) / scale if scale and np.isfinite(gm).any() \
            else float("nan")
        lines += ["", "static gain at rest (engine's exact linearisation, as `flexure-sim "
                  "simulate --static`):", table(result["static_gain_matrix"]),
                  f"largest difference: {diff:.3g} of the largest static gain"
                  + (" (a step's gain is its secant: nonlinearity shows with larger steps)"
                     if diff > 1e-4 else "") if diff == diff else
                  "no measured gain to compare (no clean, settled step)"]
    rows = [[p["drive"], p["output"], _num(p["gain"]), p["unit"], str(p["steps"]),
             _ms(p["settling_time"]),
             "-" if p["overshoot"] is None else f"{p['overshoot'] * 100:.3f}"]
            for p in result["pairs"]]
    lines += ["", "per pair (settling time and overshoot: the largest over the drive's steps):",
              columns(rows, ["drive", "output", "gain", "unit", "steps", "settling [ms]",
                             "overshoot [%]"])]
    rows = []
    for s in steps:
        for k, o in enumerate(onames):
            r = s["outputs"][o]
            rows.append([
                (str(s["index"]) + ("" if s["clean"] else "!")) if k == 0 else "",
                s["drive"] if k == 0 else "",
                _ms(s["t"]) if k == 0 else "",
                _step_inputs(s["applied_input_before"], s["applied_input"],
                             units[s["drive"]]) if k == 0 else "",
                o, _si(r["change"], ounits[o]),
                _num(r["gain"]) + ("" if r["settled"] else "*"), _num(r.get("static_gain")),
                _ms(r["settling_time"]),
                "-" if r["overshoot"] is None else f"{r['overshoot'] * 100:.3f}",
            ])
    lines += ["", "steps:", columns(rows, ["step", "drive", "t [ms]", "applied input",
                                           "output", "change", "gain", "static gain",
                                           "settling [ms]", "overshoot [%]"])]
    lines.append("")
    lines += [f"step {s['index']}: {n}" for s in steps for n in s["notes"]]
    if any(not s["clean"] for s in steps):
        lines.append("! another drive moved during the step: not in the gain matrix")
    if any(not r["settled"] for s in steps for r in s["outputs"].values()):
        lines.append("* not settled before the next step (or the end): no gain")
    lines.append(
        f"gain = output change / applied input change of the stepped drive between settled "
        f"values; settling time to within {result['band'] * 100:g} % of the output change, "
        "from the command; static gain: the engine's static solve at the same inputs.")
    return "\n".join(lines)
