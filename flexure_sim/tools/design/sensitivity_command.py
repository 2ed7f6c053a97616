"""
``flexure-sim sensitivity MECH --wrt PARAM[,PARAM...] --of OUTPUT[,OUTPUT...]``.

Exact first and second design sensitivities by hyper-dual numbers (engine/analysis/sensitivity.py)
of gain, compression, first_mode and peak_stress: each output's value, its gradient and its full
Hessian in the parameters (every entry exact, from one hyper-dual evaluation; JSON ``hessian``:
{output: rows in the order of --wrt}, and ``second``: {output: {"P|Q": d2/dP dQ}}).

PARAM is any numeric key of the mechanism file by path: ``stiffness_models.notch.h``,
``hinges.a.a.at.0``, ``bodies.body4.mass``; ``hinges.<h>.stiffness.<key>`` varies one hinge's
copy of a named stiffness model.

With several drives (config/xy_stage.yaml) ``--input`` takes one value per drive
(``x=1e-6,y=0`` or ``1e-6,0``; default: the top of every drive's stroke) and ``gain`` means
every ``gain.<output>.<drive>``, the static gain matrix's entries at that equilibrium (each may
be asked for alone: ``--of gain.y.x``).

In 3-D (``--space 3d``, or a ``space: 3d`` file; engine/analysis/spatial_sensitivity.py) the
outputs are gain (the gain matrix's entries at the equilibrium, or output / input for one
drive and one output) and first_mode (at rest), each with its exact gradient in the hinges'
stiffness parameters (no second derivatives).
"""

from __future__ import annotations

import json
import sys

from flexure_sim.engine.mechanism.loader import ConfigError
from flexure_sim.engine.mechanism.parameters import ParameterError, Parameters
from flexure_sim.engine.analysis import spatial_sensitivity as spatial
from flexure_sim.engine.analysis.sensitivity import OUTPUTS, sensitivities
from flexure_sim.engine.mechanism.stroke import check as check_stroke
from flexure_sim.engine.solver.simulation import Simulation, SolverError
from flexure_sim.tools.design.linear_commands import _spatial as three_d
from flexure_sim.tools.design.linear_plots import input_text
from flexure_sim.tools.options import parse_drive_inputs
from flexure_sim.tools.tables import columns


def run(args) -> int:
    try:
        if three_d(args):
            return _run_spatial(args)
        params = Parameters(args.mechanism)
        wrt = [p for p in args.wrt.split(",") if p]
        of = [o for o in args.of.split(",") if o]
        if not wrt:
            raise ParameterError("--wrt: give at least one parameter path")
        value = parse_drive_inputs(args.input)
        if value is not None and params.mechanism.drives:  # the stroke rule (stroke.py)
            try:
                inputs = Simulation(params.mechanism).model.drives.inputs(value)
            except ValueError:
                inputs = None  # sensitivities says what is wrong with it
            if inputs is not None:
                check_stroke(params.mechanism.drives, inputs, f"--input {args.input!r}")
        res = sensitivities(params, wrt, of, value, hessian=True)
    except (ConfigError, ParameterError, SolverError, ValueError) as exc:
        print(f"flexure-sim sensitivity: error: {exc}", file=sys.stderr)
        return 2
    res["mechanism"] = params.mechanism.name
    res["parameters"] = {p: params.value(p) for p in wrt}
    if args.json:
        print(json.dumps(res))
        return 0
    mech = params.mechanism
    u0 = list(res["input"].values()) if isinstance(res["input"], dict) else res["input"]
    where = input_text(mech, u0) if mech.drives else "rest"
    print(f"mechanism: {res['mechanism']}   static equilibrium at {where}")
    for k, (p, v) in enumerate(res["parameters"].items(), 1):
        print(f"parameter {k}: {p} = {v:.6g}")
    for o in res["values"]:
        print(f"{o} = {res['values'][o]:.10g}")
        for p, d in res["gradient"][o].items():
            print(f"  d/d {p}: {d:.10g}")
        print(hessian_table(res["hessian"][o]))
    return 0


def _run_spatial(args) -> int:
    """Print the 3-D sensitivities: values and gradients (module docstring)."""
    params = spatial.SpatialParameters(args.mechanism)
    wrt = [p for p in args.wrt.split(",") if p]
    of = [o for o in args.of.split(",") if o]
    if args.of == ",".join(OUTPUTS):
        of = list(spatial.OUTPUTS)
    if not wrt:
        raise ParameterError("--wrt: give at least one parameter path")
    value = parse_drive_inputs(args.input)
    mech = params.mechanism
    if value is not None and mech.drives:
        try:
            inputs = spatial.SpatialModel(mech).drive_inputs(value)
        except ValueError as exc:
            raise ParameterError(f"--input {args.input!r}: {exc}") from None
        check_stroke(mech.drives, inputs, f"--input {args.input!r}")
    res = spatial.sensitivities(params, wrt, of, value)
    res["mechanism"] = mech.name
    res["space"] = "3d"
    res["parameters"] = {p: params.value(p) for p in wrt}
    if args.json:
        print(json.dumps(res))
        return 0
    u0 = list(res["input"].values()) if isinstance(res["input"], dict) else res["input"]
    modes = "; modes at rest" if {"first_mode", "out_of_plane_mode"} & set(res["values"]) else ""
    print(f"mechanism: {mech.name} (3-D)   static equilibrium at "
          f"{input_text(mech, u0) if mech.drives else 'rest'}{modes}")
    for k, (p, v) in enumerate(res["parameters"].items(), 1):
        print(f"parameter {k}: {p} = {v:.6g}")
    for o, v in res["values"].items():
        print(f"{o} = {v:.10g}")
        for p, d in res["gradient"][o].items():
            print(f"  d/d {p}: {d:.10g}")
    return 0


def hessian_table(H) -> str:
    """Return the Hessian H[i][j] = d2/dP_i dP_j as an indented table, parameters by number."""
    header = ["d2/dPi dPj"] + [f"j={j}" for j in range(1, len(H) + 1)]
    rows = [[f"i={i}"] + [f"{d:.10g}" for d in row] for i, row in enumerate(H, 1)]
    return "\n".join("  " + line for line in columns(rows, header).splitlines())


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "sensitivity", help="exact design sensitivities (hyper-dual numbers)"
    )
    p.add_argument("mechanism", help="built-in name or YAML path")
    p.add_argument(
        "--wrt",
        required=True,
        help="parameter paths, comma-separated (e.g. stiffness_models.notch.h)",
    )
    p.add_argument(
        "--of", default=",".join(OUTPUTS),
        help=f"outputs, comma-separated ({', '.join(OUTPUTS)}, gain.<output>.<drive>)"
    )
    p.add_argument(
        "--input", default=None,
        help="drive input (m); with several drives one per drive: NAME=VALUE,... or V1,V2,... "
        "(default: the top of each drive's stroke)"
    )
    p.add_argument("--space", choices=("2d", "3d"), default=None,
                   help="2d: the planar engine; 3d: the spatial engine (gain and first_mode, "
                   "gradients in the hinges' stiffness parameters); default: 3d for a "
                   "space: 3d file, else 2d")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(handler=run)
