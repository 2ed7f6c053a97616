"""
What ``flexure-sim optimize`` writes and prints: the optimised mechanism, iterations, report.

Files (in the output directory, named after the study):

- ``<name>.yaml``: the optimised mechanism, the study's base document with the variables set
  (``<name>_least_violating.yaml`` when no design meets the constraints); it loads and runs
  like any mechanism file (``flexure-sim simulate <file> --static``);
- ``<name>_iterations.csv``: one row per iterate: objective, largest scaled violation, every
  variable and every output column;
- ``<name>_iterations.png``: the objective, the violation and the variables (as a fraction of
  their range) against the iteration;
- ``<name>_report.json``: the whole result (engine/analysis/optimize.py ``Result``), with the
  study and the files.
"""
from __future__ import annotations

import csv
import json
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from flexure_sim.engine.analysis.optimize import Result
from flexure_sim.engine.analysis.optimize_study import OptimizeStudy

UNITS = {"gain": "", "output_displacement": "m", "compression": "m", "drive_force": "N",
         "first_mode": "Hz", "peak_stress_ratio": "", "fatigue_safety": "",
         "fatigue_safety_soderberg": "", "stroke_limit": "m", "infinite_life_stroke": "m"}


def unit(column: str) -> str:
    """Return the SI unit of an output column (sweep units; gains and ratios have none)."""
    return UNITS.get(column.split(".")[0], "")


def mechanism_text(study: OptimizeStudy, result: Result) -> str:
    """Return the optimised mechanism file: a header saying what it is, then the document."""
    lines = [f"# {study.name}: {result.status} design of flexure-sim optimize "
             f"({study.source}), {study.sense} {study.objective} = {result.objective:.10g} "
             f"{unit(study.objective)}".rstrip(),
             f"# from {study.mechanism_source}; the variables as optimised:"]
    lines += [f"#   {v.name} = {float(x)!r}" for v, x in zip(study.variables, result.x)]
    lines += [f"# constraint {c['text']}: {c['value']:.10g}" for c in result.constraints
              if c["hinge"] is None or c["active"]]
    doc = study.document(result.x)
    return "\n".join(lines) + "\n" + yaml.safe_dump(doc, sort_keys=False, width=100)


def write_files(study: OptimizeStudy, result: Result, folder: Path, plots: bool) -> dict:
    """Write the files of the module docstring; return {kind: path}."""
    folder.mkdir(parents=True, exist_ok=True)
    stem = study.name
    mech = folder / (f"{stem}_least_violating.yaml" if result.status == "infeasible"
                     else f"{stem}.yaml")
    mech.write_text(mechanism_text(study, result), encoding="utf-8")
    table = folder / f"{stem}_iterations.csv"
    with table.open("w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh)
        cols = list(result.history[0]["values"]) if result.history else []
        w.writerow(["iteration", "objective", "violation"] + [v.name for v in study.variables]
                   + cols)
        for h in result.history:
            w.writerow([h["iteration"], repr(h["objective"]), repr(h["violation"])]
                       + [repr(x) for x in h["x"]] + [repr(h["values"][c]) for c in cols])
    files = {"mechanism": str(mech), "iterations": str(table)}
    if plots:
        files["plot"] = str(plot(study, result, folder / f"{stem}_iterations.png"))
    report = folder / f"{stem}_report.json"
    files["report"] = str(report)
    report.write_text(json.dumps(_jsonable({"study": study.source, "name": stem,
                                            "files": files, **result.as_dict()}), indent=1),
                      encoding="utf-8")
    return files


def _jsonable(value: Any) -> Any:
    if isinstance(value, dict):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_jsonable(v) for v in value]
    if isinstance(value, np.ndarray):
        return _jsonable(value.tolist())
    if isinstance(value, (np.floating, float)):
        return float(value) if np.isfinite(value) else None
    if isinstance(value, np.integer):
        return int(value)
    return value


def plot(study: OptimizeStudy, result: Result, path: Path) -> Path:
    """Draw the iterations (objective, violation, variables) into a PNG."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    k = [h["iteration"] for h in result.history]
    fig, axes = plt.subplots(3, 1, figsize=(7, 8), sharex=True)
    u = unit(study.objective)
    axes[0].plot(k, [h["objective"] for h in result.history], "o-")
    axes[0].set_ylabel(f"{study.objective}" + (f" [{u}]" if u else ""))
    axes[0].set_title(f"{study.name}: {study.sense} {study.objective} ({result.status})")
    axes[1].semilogy(k, [max(h["violation"], 1e-16) for h in result.history], "o-")
    axes[1].set_ylabel("largest scaled violation")
    lo, span = study.lower, study.upper - study.lower
    x = np.array([h["x"] for h in result.history]).reshape(len(k), -1)
    for j, v in enumerate(study.variables):
        axes[2].plot(k, (x[:, j] - lo[j]) / span[j], label=v.name)
    axes[2].set_ylabel("variable, fraction of its range")
    axes[2].set_xlabel("iteration")
    axes[2].legend(fontsize="small", loc="best")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def print_result(study: OptimizeStudy, result: Result, files: dict) -> None:
    """Print the iteration table, the result, constraints, bounds, KKT and sensitivities."""
    u = unit(study.objective)
    print(f"{study.name} ({study.source}): {study.sense} {study.objective} over "
          f"{len(study.variables)} variables, {len(study.constraints)} constraints; "
          f"{study.method}")
    print(f"iteration  {study.objective + (f' [{u}]' if u else ''):>22s}  max violation")
    for h in result.history:
        print(f"{h['iteration']:9d}  {h['objective']:22.10g}  {h['violation']:13.3g}")
    print(f"\nresult: {result.status}: {result.message}")
    print(f"{result.iterations} iterations, {result.evaluations} evaluations, "
          f"{result.gradients} exact gradients, {result.wall_s:.2f} s")
    start = result.history[0]["objective"] if result.history else float("nan")
    print(f"{study.objective}: {start:.8g} -> {result.objective:.10g} {u}".rstrip())
    print("\nvariable                          start          optimum     lower        upper"
          "   at bound  multiplier")
    for v, x0, x, b in zip(study.variables, result.start, result.x, result.bounds):
        print(f"{v.name:28s} {x0:12.6g} {x:16.10g} {v.lower:9.4g} {v.upper:12.4g}  "
              f"{b['at'] or '-':>8s}  {b['multiplier']:.4g}")
    if result.constraints:
        print("\nconstraint                                   value        limit  active  "
              "multiplier")
    for c in result.constraints:
        print(f"{c['text']:40s} {c['value']:12.8g} {c['limit']:12.6g}  "
              f"{'yes' if c['active'] else 'no':>6s}  {c['multiplier']:.4g}")
    k = result.kkt
    if "stationarity_relative" in k:
        print(f"\nKKT: stationarity {k['stationarity_relative']:.2g} (relative), largest "
              f"violation {k['violation']:.2g}, complementarity {k['complementarity']:.2g}; a "
              "multiplier is the objective's gain per unit the limit is relaxed "
              f"({u or '1'} per unit of the output)")
    else:
        print(f"\nno feasible design: the largest scaled violation is {k['violation']:.4g}; no "
              "multipliers (the objective's first-order conditions do not apply)")
    names = [v.name for v in study.variables]
    print("\nsensitivities at the optimum, d output / d variable (SI):")
    print(f"{'output':26s}" + "".join(f"{n[-14:]:>15s}" for n in names))
    for col, grads in result.sensitivities.items():
        print(f"{col:26s}" + "".join(f"{grads[n]:15.5g}" for n in names))
    print("\nwritten: " + ", ".join(files.values()))
