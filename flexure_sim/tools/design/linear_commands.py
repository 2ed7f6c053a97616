"""
``flexure-sim modes | frf | linearize``: the linear analyses (engine/analysis/linear.py).

A ``space: 3d`` file, or any file with ``--space 3d``, is analysed by the spatial engine
(engine/analysis/spatial_linear.py): six coordinates per body, hinge wrenches
hinges.<h>.moment_x .. force_z.

flexure-sim modes microstage [--input U] [--count N] [--json] [-o DIR]
flexure-sim frf microstage --from drive --to output [--to hinges.a.force_x] [--fmin F --fmax F
                --points N | --frequencies F1,F2,...] [-o DIR] [--csv]
flexure-sim linearize microstage --input U -o model.npz|model.mat|model.json
flexure-sim frf microstage --input-kind displacement ...   # the drive's displacement as input

With several drives (config/xy_stage.yaml) ``--input`` takes one value per drive (``x=1e-6,y=0``
or ``1e-6,0``; default every drive at 0), ``frf --from`` names the drive and the model has one
input per drive (engine/analysis/linear.py).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

from flexure_sim.engine.analysis import linear, spatial_linear
from flexure_sim.engine.memory import too_large
from flexure_sim.engine.mechanism.loader import ConfigError, load_mechanism
from flexure_sim.engine.mechanism.parameters import ParameterError
from flexure_sim.engine.mechanism.spatial_loader import is_spatial, load_spatial
from flexure_sim.engine.mechanism.stroke import check as check_stroke
from flexure_sim.engine.solver.simulation import Simulation, SolverError
from flexure_sim.engine.solver.spatial_model import SpatialModel
from flexure_sim.tools.design.linear_export import export_model
from flexure_sim.tools.design.linear_plots import input_text, plot_bode, plot_modes, write_frf_csv
from flexure_sim.tools.options import count, parse_drive_inputs

EXIT_OK, EXIT_USAGE = 0, 2
#: Memory per frequency of ``frf`` (bytes): the frequency, and per output its response, its
#: plot's lines and its CSV columns, with a margin of two (measured with --csv: 1e6
#: frequencies add 205 MB to the peak with one output, 814 MB with four).
FRF_BYTES, FRF_BYTES_PER_OUTPUT = 100, 400


def _model(args, wrenches: bool = True) -> tuple:
    if _spatial(args):
        return _spatial_model(args, wrenches)
    mech = load_mechanism(args.mechanism)
    sim = Simulation(mech)
    actuated = [sim.model.drives.names[a.drive] for a in sim.model.drives.actuation]
    if actuated:
        raise ValueError(f"mechanism {mech.name!r}: drive {', '.join(actuated)} has a piezo "
                         "actuator block, whose amplifier, hysteresis and creep the linear model "
                         "does not include; analyse the stage without the actuator: block")
    value = parse_drive_inputs(args.input)
    if not sim.model.drives:
        if value is not None and np.any(np.asarray(list(value.values()) if isinstance(
                value, dict) else value, dtype=float) != 0):
            raise ValueError(f"--input: mechanism {mech.name!r} has no drive")
        value = None
    elif value is not None:
        try:
            value = sim.model.drives.inputs(value)
        except ValueError as exc:
            raise ValueError(f"--input {args.input!r}: {exc}") from None
        check_stroke(mech.drives, value, f"--input {args.input!r}")
        value = float(value[0]) if len(value) == 1 else value
    return mech, linear.linearize(sim, value, wrenches=wrenches, input_kind=args.input_kind)


def _spatial(args) -> bool:
    """Tell whether to analyse in 3-D: ``--space 3d``, or a ``space: 3d`` file (auto)."""
    three_d = is_spatial(args.mechanism)
    if args.space == "2d" and three_d:
        raise ValueError(f"--space 2d: {args.mechanism} is a 3-D mechanism (space: 3d)")
    return args.space == "3d" or three_d


def _spatial_model(args, wrenches: bool) -> tuple:
    """Return (mechanism, linear model) of the spatial engine (analysis/spatial_linear.py)."""
    mech = load_spatial(args.mechanism)
    model = SpatialModel(mech)
    value = parse_drive_inputs(args.input)
    if value is not None and not model.drives:
        raise ValueError(f"--input: mechanism {mech.name!r} has no drive")
    if value is not None:
        try:
            value = model.drive_inputs(value)
        except ValueError as exc:
            raise ValueError(f"--input {args.input!r}: {exc}") from None
    return mech, spatial_linear.linearize(model, value, wrenches=wrenches)


def _modes(model):
    """Return the modes of a planar or a spatial linear model."""
    if isinstance(model, spatial_linear.SpatialLinearModel):
        return spatial_linear.modes(model)
    return linear.modes(model)


def _u0(model):
    """Return the model's drive input as JSON: a number (one drive), else {drive: value}."""
    if np.ndim(model.u0) == 0:
        return float(model.u0)
    return {n: float(v) for n, v in zip(model.drive_names, model.u0)}


def _guarded(prog: str, work) -> int:
    try:
        return work()
    except (ConfigError, ParameterError, SolverError, ValueError, OSError) as exc:
        print(f"{prog}: error: {exc}", file=sys.stderr)
        return EXIT_USAGE


# ------------------------------------------------------------------------ modes


def modes_summary(mech, model, md, count: int) -> dict:
    mech_modes = [
        {
            "frequency_hz": float(f),
            "modal_damping_ratio": float(md.modal_damping[k]),
            "shape": {name: float(v) for name, v in zip(model.state_names, md.shapes[:, k])},
        }
        for k, f in enumerate(md.frequencies[:count])
    ]
    poles = [
        {
            "real": float(p.real),
            "imag": float(p.imag),
            "frequency_hz": float(f),
            "damping_ratio": float(z),
        }
        for p, f, z in zip(md.poles, md.pole_frequencies, md.damping_ratios)
        if p.imag >= 0
    ]
    return {
        "mechanism": mech.name,
        "input": _u0(model),
        "undamped_frequencies_hz": md.frequencies.tolist(),
        "modal_damping_ratios": md.modal_damping.tolist(),
        "modes": mech_modes,
        "poles": poles,
    }


def run_modes(args) -> int:
    def work():
        mech, model = _model(args, wrenches=False)
        md = _modes(model)
        out = modes_summary(mech, model, md, args.count)
        spatial = isinstance(model, spatial_linear.SpatialLinearModel)
        if spatial:
            out["out_of_plane_shares"] = spatial_linear.out_of_plane_shares(model, md).tolist()
        if args.output and isinstance(model, spatial_linear.SpatialLinearModel):
            raise ValueError("-o: mode-shape plots are drawn for planar mechanisms only; "
                             "--json lists the 3-D mode shapes")
        if args.output:
            out["plots"] = [
                str(p) for p in plot_modes(mech, model, md, args.count, Path(args.output))
            ]
        if args.json:
            print(json.dumps(out))
            return EXIT_OK
        print(f"mechanism: {mech.name}   linearised at the static equilibrium at "
              f"{input_text(mech, model.u0)}")
        shares = out.get("out_of_plane_shares")
        print("mode  undamped f [Hz]  modal damping ratio"
              + ("  out of plane (z, rx, ry)" if shares else ""))
        for k, (f, z) in enumerate(zip(md.frequencies, md.modal_damping), 1):
            share = f"{shares[k - 1] * 100:20.1f} %" if shares else ""
            print(f"{k:4d} {f:16.6g} {z:20.4g}{share}")
        print("poles of the damped system (upper half-plane), by |pole|:")
        print("   real [1/s]     imag [1/s]   |pole|/2pi [Hz]   damping ratio")
        for p in out["poles"]:
            kind = f"{p['damping_ratio']:14.4g}" if p["imag"] else "   (real pole)"
            print(f"{p['real']:13.6g}  {p['imag']:13.6g}  {p['frequency_hz']:15.6g}  {kind}")
        for path in out.get("plots", []):
            print(f"plot: {path}")
        return EXIT_OK

    return _guarded("flexure-sim modes", work)


# -------------------------------------------------------------------------- frf


def run_frf(args) -> int:
    def work():
        f = frequencies(args)
        wanted = args.to or []
        mech, model = _model(args, wrenches=any(o.startswith("hinges.") for o in wanted))
        k = _source(mech, model, args.source)
        outputs = args.to or [o.name for o in mech.all_outputs]
        if not outputs:
            raise ValueError(f"mechanism {mech.name!r} has no output: name one with --to "
                             f"({', '.join(model.output_names[:6])}, ...)")
        for o in outputs:
            model.output_index(o)
        reason = too_large(len(f) * (FRF_BYTES + FRF_BYTES_PER_OUTPUT * len(outputs)))
        if reason is not None:
            raise ValueError(f"{len(f)} frequencies of {len(outputs)} output(s): the response, "
                             f"its plot and CSV would need {reason}; ask for fewer frequencies")
        source = model.input_names[k]
        G = linear.frf(model, f, outputs, source)
        out_dir = Path(args.output)
        out_dir.mkdir(parents=True, exist_ok=True)
        png = plot_bode(mech, model, f, G, outputs, out_dir / "frf.png", source)
        written = [png]
        if args.csv:
            written.append(write_frf_csv(f, G, outputs, out_dir / "frf.csv"))
        gains = linear.static_gain(model, outputs, source)
        if len(model.input_names) > 1:
            print(f"from drive {source}:")
        listed = args.frequencies is not None or len(f) == 1
        for name, row, g0 in zip(outputs, G, gains):
            if listed:  # every frequency asked for
                print(f"{name}: static gain {g0:.6g}")
                for fk, g in zip(f, row):
                    print(f"  {fk:.6g} Hz: |G| {abs(g):.6g}, phase {np.degrees(np.angle(g)):.4g} "
                          "deg")
            else:
                print(f"{name}: |G| {abs(row[0]):.6g} at {f[0]:.3g} Hz (static gain {g0:.6g}), "
                      f"|G| {abs(row[-1]):.3g} at {f[-1]:.3g} Hz")
        for path in written:
            print(f"wrote {path}")
        return EXIT_OK

    return _guarded("flexure-sim frf", work)


def frequencies(args) -> np.ndarray:
    """
    Return the FRF's frequencies in Hz, as the command line gives them.

    ``--frequencies F1,F2,...`` (ascending, each once), or ``--points`` log-spaced from
    ``--fmin`` to ``--fmax``, both included: one frequency when they are equal and ``--points``
    is 1. ValueError naming the option for anything else (not positive, not finite, ...).
    """
    if args.frequencies is not None:
        if any(v is not None for v in (args.fmin, args.fmax, args.points)):
            raise ValueError("--frequencies lists the frequencies: give it without --fmin, "
                             "--fmax and --points")
        values = []
        for text in args.frequencies.split(","):
            try:
                values.append(float(text))
            except ValueError:
                raise ValueError(f"--frequencies {args.frequencies!r}: {text.strip()!r} is not "
                                 "a number") from None
            if not (np.isfinite(values[-1]) and values[-1] > 0):
                raise ValueError(f"--frequencies {args.frequencies!r}: {text.strip()!r} is not "
                                 "a positive, finite frequency (Hz)")
        return np.unique(values)
    fmin = 1.0 if args.fmin is None else args.fmin
    fmax = 1e5 if args.fmax is None else args.fmax
    points = 1000 if args.points is None else args.points
    for option, v in (("--fmin", fmin), ("--fmax", fmax)):
        if not (np.isfinite(v) and v > 0):
            raise ValueError(f"{option} {v!r}: must be a positive, finite frequency (Hz)")
    if fmin > fmax:
        raise ValueError(f"--fmin {fmin:g} Hz is above --fmax {fmax:g} Hz")
    if (fmin == fmax) != (points == 1):
        raise ValueError(f"--fmin {fmin:g}, --fmax {fmax:g}, --points {points}: one frequency "
                         "is --fmin F --fmax F --points 1 (or --frequencies F); a range needs "
                         "--fmin below --fmax and --points 2 or more")
    return np.logspace(np.log10(fmin), np.log10(fmax), points)


def _source(mech, model, name) -> int:
    """B's column of ``--from`` (None: the only drive); ValueError listing the drives."""
    if not model.input_names:
        raise ValueError(f"mechanism {mech.name!r} has no drive input")
    drives = ", ".join(model.drive_names)
    if name is None and len(model.input_names) > 1:
        raise ValueError(f"--from: mechanism {mech.name!r} has {len(model.input_names)} drives "
                         f"({drives}): name one")
    try:
        return model.input_index(name)
    except ValueError:
        has = (f"has drives {drives}" if len(model.input_names) > 1 else
               f"has one drive, {drives!r}" + (" (input 'drive')" if drives != "drive" else ""))
        raise ValueError(f"--from {name!r}: no such drive; mechanism {mech.name!r} "
                         f"{has}") from None


# -------------------------------------------------------------------- linearize


def run_linearize(args) -> int:
    def work():
        mech, model = _model(args)
        path = export_model(model, Path(args.output), mech.name)
        n_in = len(model.input_names)
        print(
            f"{mech.name}: {len(model.state_names)} states, {n_in} input"
            f"{'' if n_in == 1 else 's'} ({', '.join(model.input_names) or 'none'}), "
            f"{len(model.output_names)} outputs at {input_text(mech, model.u0)} -> {path}"
        )
        return EXIT_OK

    return _guarded("flexure-sim linearize", work)


# ---------------------------------------------------------------------- parsers


def _common(p) -> None:
    p.add_argument("mechanism", help="built-in name or YAML path")
    p.add_argument("--space", choices=("2d", "3d"), default=None,
                   help="3d: analyse a planar file with its out-of-plane freedoms (the spatial "
                   "engine); default: 3d for a space: 3d file, else 2d")
    p.add_argument(
        "--input",
        default=None,
        help="drive input (m) of the static equilibrium; with several drives one per drive: "
        "NAME=VALUE,... or V1,V2,... (default: every drive at 0)",
    )
    p.add_argument(
        "--input-kind", choices=linear.INPUT_KINDS, default="command",
        help="a displacement drive's input: its command, through the drive's response_time lag "
        "(default), or its displacement itself (no lag: what a model with a prescribed "
        "displacement has; a drive with response_time 0 takes it either way)")


def register(subparsers) -> None:
    p = subparsers.add_parser("modes", help="natural frequencies, mode shapes and damped poles")
    _common(p)
    p.add_argument("--count", type=count, default=4,
                   help="mode shapes to list and plot, 1 or more (default 4)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument("-o", "--output", help="directory for mode-shape plots (mode_<k>.png)")
    p.set_defaults(handler=run_modes)

    p = subparsers.add_parser(
        "frf", help="frequency response (Bode plot, CSV) from the exact linearisation"
    )
    _common(p)
    p.add_argument("--from", dest="source", default=None,
                   help="input: the drive's name (default: the only drive; 'drive' for a "
                   "single drive)")
    p.add_argument(
        "--to",
        action="append",
        help="output: output (or each named output), compression, drive_force "
        "(drive_force.<drive> with several drives), hinges.<h>.moment|force_x|force_y "
        "(repeatable; default: the mechanism's outputs)",
    )
    p.add_argument("--fmin", type=float, default=None, help="Hz (default 1)")
    p.add_argument("--fmax", type=float, default=None, help="Hz (default 1e5)")
    p.add_argument("--points", type=count, default=None,
                   help="log-spaced frequencies from --fmin to --fmax, both included (default "
                   "1000; 1 with --fmin equal to --fmax)")
    p.add_argument("--frequencies", default=None, metavar="F1,F2,...",
                   help="the frequencies (Hz), comma-separated, instead of --fmin, --fmax and "
                   "--points")
    p.add_argument(
        "-o", "--output", default="frf", help="directory for frf.png / frf.csv (default ./frf)"
    )
    p.add_argument("--csv", action="store_true", help="also write frf.csv")
    p.set_defaults(handler=run_frf)

    p = subparsers.add_parser(
        "linearize", help="state-space model (A, B, C, D, names) for control design"
    )
    _common(p)
    p.add_argument("-o", "--output", required=True, help="model.npz, model.mat or model.json")
    p.set_defaults(handler=run_linearize)
