"""
``flexure-sim simulate`` for 3-D mechanisms: a step response or the static equilibrium.

Chosen by ``cli.run_simulate`` for a ``space: 3d`` file or with ``--space 3d`` (a planar file
with its out-of-plane freedoms). ``--drive step:A`` steps a single drive; with several drives
``step:NAME=VALUE,...`` or ``step:V1,V2,...`` (one per drive), or ``--drive NAME=step:V`` once
per drive stepped (as for planar mechanisms; drives not named stay at 0). ``--static`` solves the
equilibrium at that input and reports, besides the outputs and hinges, the exact static gain
of every output against every drive and the stiffness each output's body sees (6x6 at its
mass centre, the rest of the mechanism relaxed: ``spatial_statics.body_stiffness``).
"""
from __future__ import annotations

import time

import numpy as np

from flexure_sim.engine.mechanism.spatial_loader import load_spatial
from flexure_sim.engine.solver.spatial_simulation import SpatialSimulation
from flexure_sim.engine.solver.spatial_statics import body_stiffness, static_gain
from flexure_sim.tools.options import parse_drive_inputs

#: Times (s) at which the step response is reported (as the planar command).
REPORT_TIMES = (1e-3, 2e-3, 5e-3)
AXES = ("x", "y", "z", "rx", "ry", "rz")


def drive_value(specs, names, usage_error):
    """
    Return the drive inputs of the ``--drive`` options (``none``: None).

    One ``step:...`` for all drives, or ``NAME=step:V`` (or ``NAME=none``) per drive, the
    drives not named at 0; 3-D runs step their drives (no other programs).
    """
    if isinstance(specs, str):
        specs = [specs]
    per_drive = [s.partition("=") for s in specs if s.partition("=")[0].strip() in names]
    if per_drive:
        if len(per_drive) != len(specs):
            raise usage_error(f"--drive {' '.join(specs)!r}: give either NAME=step:V per drive "
                              "or one step:... for all drives, not both")
        inputs = dict.fromkeys(names, 0.0)
        seen = set()
        for name, _, program in per_drive:
            name = name.strip()
            if name in seen:
                raise usage_error(f"--drive: drive {name} is given twice")
            seen.add(name)
            if program.strip() == "none":
                continue
            value = _one_step(f"{name}={program}", program, usage_error)
            inputs[name] = value
        return inputs
    if len(specs) > 1:
        raise usage_error(f"--drive given {len(specs)} times: a 3-D mechanism takes one "
                          "--drive step:A, step:NAME=VALUE,... or step:V1,V2,... for all its "
                          f"drives, or NAME=step:V once per drive ({', '.join(names)})")
    spec = specs[0]
    if spec == "none":
        return None
    kind, _, value = spec.partition(":")
    if kind != "step" or not value:
        raise usage_error(f"--drive {spec!r}: expected step:AMPLITUDE, step:NAME=VALUE,... or "
                          "none")
    try:
        parsed = parse_drive_inputs(value, "--drive")
    except ValueError as exc:
        raise usage_error(str(exc)) from None
    return parsed


def _one_step(spec: str, program: str, usage_error) -> float:
    """Return V of one drive's ``step:V`` (``spec`` as given, for the message)."""
    kind, _, value = program.partition(":")
    if kind.strip() != "step" or not value.strip():
        raise usage_error(f"--drive {spec!r}: a 3-D run steps its drives: expected "
                          "NAME=step:VALUE")
    try:
        parsed = float(value)
    except ValueError:
        raise usage_error(f"--drive {spec!r}: {value.strip()!r} is not a number") from None
    if not np.isfinite(parsed):
        raise usage_error(f"--drive {spec!r}: the step must be a finite number")
    return parsed


def run(args, path, usage_error) -> dict:
    """Run the 3-D simulation the arguments ask for; return the figures as a dict."""
    mech = load_spatial(path)
    sim = SpatialSimulation(mech, dt=args.dt, relinearize_tol=args.relinearize_tol)
    model = sim.model
    value = drive_value(args.drive, list(model.drive_names), usage_error)
    if value is not None and not model.drives:
        raise usage_error(f"--drive: mechanism {mech.name!r} has no drive")
    try:
        inputs = (model.drive_inputs(value) if value is not None
                  else np.zeros(len(model.drives)))
    except ValueError as exc:
        raise usage_error(f"--drive {args.drive!r}: {exc}") from None
    start = time.perf_counter()
    out = {"mechanism": mech.name, "mechanism_file": str(path), "space": "3d"}
    if args.static:
        snap = sim.static_snapshot(inputs)
        out.update(mode="static", wall_s=time.perf_counter() - start)
        out.update(summary(sim, snap))
        if model.drives and model.outputs:
            G = static_gain(model)
            out["gain_matrix"] = {"outputs": list(model.output_names),
                                  "drives": list(model.drive_names),
                                  "matrix": G.tolist()}
        bodies = dict.fromkeys(o.body for o in mech.outputs)
        out["body_stiffness"] = {b: np.diag(body_stiffness(model, b, inputs)).tolist()
                                 for b in bodies}
        return out
    if value is not None:
        sim.set_command(inputs)
    n_steps = int(round(args.duration / args.dt))
    marks = {int(round(t / args.dt)): t for t in REPORT_TIMES if t <= args.duration}
    samples = {}
    done = 0
    for k in sorted(marks) + [n_steps]:
        if k > done:
            sim.step(k - done)
            done = k
        if k in marks:
            samples[f"{marks[k]:g}"] = sim.snapshot().outputs
    wall = time.perf_counter() - start
    out.update(mode="dynamic", duration=args.duration, dt=args.dt, steps=n_steps,
               output_at=samples, wall_s=wall,
               real_time_factor=args.duration / wall if wall > 0 else None,
               linearizations=sim.stats.linearizations)
    out.update(summary(sim, sim.snapshot()))
    return out


def summary(sim: SpatialSimulation, snap) -> dict:
    """Return a snapshot's figures as JSON-ready values (SI units)."""
    mech = sim.mechanism
    return {
        "t": snap.t,
        "outputs": dict(snap.outputs),
        "drives": {n: {"input": float(snap.drive_inputs[k]), "force": float(snap.drive_forces[k]),
                       "position": float(snap.drive_positions[k])}
                   for k, n in enumerate(snap.drive_names)},
        "bodies": {b.name: {"position": snap.positions[i].tolist(),
                            "rotation": snap.rotations[i].tolist(),
                            "quaternion": snap.quaternions[i].tolist()}
                   for i, b in enumerate(mech.bodies)},
        "hinges": {h.name: {"rotation": snap.deflections[i, :3].tolist(),
                            "position": snap.deflections[i, 3:].tolist(),
                            "wrench_on_b": snap.wrenches[i].tolist(),
                            "energy": float(snap.hinge_power[i, 0])}
                   for i, h in enumerate(mech.hinges)},
        "energy": {"kinetic": snap.kinetic_energy, "potential": snap.potential_energy},
    }


def print_table(out: dict) -> None:
    """Print the figures of ``run`` for a reader."""
    print(f"mechanism: {out['mechanism']} (3-D)   mode: {out['mode']}   t = {out['t']:.6g} s")
    print(f"file:      {out['mechanism_file']}")
    for name, d in out["drives"].items():
        print(f"drive {name}: input {d['input'] * 1e6:.6g} um, force {d['force']:.6g} N")
    for name, v in out["outputs"].items():
        print(f"output {name}: {v:.6g}")
    if out.get("gain_matrix"):
        g = out["gain_matrix"]
        print("static gain (output per unit input of each drive, exact linearisation at rest):")
        print("output   " + "".join(f"{d:>14s}" for d in g["drives"]))
        for name, row in zip(g["outputs"], g["matrix"]):
            print(f"{name:8s} " + "".join(f"{v:14.6g}" for v in row))
    for body, k in out.get("body_stiffness", {}).items():
        print(f"stiffness of {body} at its mass centre (N/m; N m/rad), the rest relaxed:")
        print("   " + "  ".join(f"{a}: {v:.4g}" for a, v in zip(AXES, k)))
    for t, values in out.get("output_at", {}).items():
        shown = ", ".join(f"{n} {v:.6g}" for n, v in values.items())
        print(f"outputs at {float(t) * 1e3:g} ms: {shown}")
    print("hinge deflection, frame b in frame a: rotation [urad] (x, y, z), position [nm]")
    for name, h in out["hinges"].items():
        r = " ".join(f"{v * 1e6:10.4g}" for v in h["rotation"])
        p = " ".join(f"{v * 1e9:10.4g}" for v in h["position"])
        print(f"{name:8s} {r}   {p}")
    e = out["energy"]
    print(f"energy [J]: kinetic {e['kinetic']:.6g}, potential {e['potential']:.6g}")
    extra = (f", real-time factor {out['real_time_factor']:.3g}"
             if out.get("real_time_factor") else "")
    print(f"wall time: {out['wall_s']:.4g} s{extra}")
