"""
``flexure-sim modes | frf | linearize``: the designer's linear analyses (engine/linear.py).

flexure-sim modes microstage [--input U] [--count N] [--json] [-o DIR]
flexure-sim frf microstage --from drive --to output [--to hinges.a.force_x] [--fmin F --fmax F
                --points N] [-o DIR] [--csv]
flexure-sim linearize microstage --input U -o model.npz|model.mat|model.json
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

from ..engine import linear
from ..engine.config import ConfigError, load_mechanism
from ..engine.design import ParameterError
from ..engine.solver import Simulation, SolverError

EXIT_OK, EXIT_USAGE = 0, 2


def _model(args, wrenches: bool = True) -> tuple:
    mech = load_mechanism(args.mechanism)
    sim = Simulation(mech)
    if not np.isfinite(args.input):
        raise ValueError(f"--input {args.input!r}: must be a finite number of metres")
    if args.input and sim.drive is None:
        raise ValueError(f"--input: mechanism {mech.name!r} has no drive")
    return mech, linear.linearize(sim, args.input, wrenches=wrenches)


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
        "input": model.u0,
        "undamped_frequencies_hz": md.frequencies.tolist(),
        "modal_damping_ratios": md.modal_damping.tolist(),
        "modes": mech_modes,
        "poles": poles,
    }


def run_modes(args) -> int:
    def work():
        if args.count < 0:
            raise ValueError(f"--count {args.count}: must not be negative")
        mech, model = _model(args, wrenches=False)
        md = linear.modes(model)
        out = modes_summary(mech, model, md, args.count)
        if args.output:
            out["plots"] = [
                str(p) for p in plot_modes(mech, model, md, args.count, Path(args.output))
            ]
        if args.json:
            print(json.dumps(out))
            return EXIT_OK
        where = f"drive input {model.u0 * 1e6:.6g} um" if model.input_names else "rest (no drive)"
        print(f"mechanism: {mech.name}   linearised at the static equilibrium at {where}")
        print("mode  undamped f [Hz]  modal damping ratio")
        for k, (f, z) in enumerate(zip(md.frequencies, md.modal_damping), 1):
            print(f"{k:4d} {f:16.6g} {z:20.4g}")
        print("poles of the damped system (upper half-plane), by |pole|:")
        print("   real [1/s]     imag [1/s]   |pole|/2pi [Hz]   damping ratio")
        for p in out["poles"]:
            kind = f"{p['damping_ratio']:14.4g}" if p["imag"] else "   (real pole)"
            print(f"{p['real']:13.6g}  {p['imag']:13.6g}  {p['frequency_hz']:15.6g}  {kind}")
        for path in out.get("plots", []):
            print(f"plot: {path}")
        return EXIT_OK

    return _guarded("flexure-sim modes", work)


def plot_modes(mech, model, md, count: int, out_dir: Path) -> list[Path]:
    """
    One PNG per mode.

    Bodies (lines from each body's centre to its hinge points) at rest in grey and displaced by the
    mode shape (scaled to 12 % of the mechanism's size).
    """
    import matplotlib

    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt

    out_dir.mkdir(parents=True, exist_ok=True)
    z_rest = model.z
    size = max(float(np.ptp(z_rest.reshape(-1, 3)[:, :2])), 1e-3)
    points = {b.name: [] for b in mech.bodies}
    for h in mech.hinges:
        points[h.a.body].append(h.a.position)
        points[h.b.body].append(h.b.position)
    paths = []
    for k in range(min(count, len(md.frequencies))):
        dz = np.zeros_like(z_rest)
        dz[model.free] = md.shapes[:, k]
        pts = _mode_points(mech, points, z_rest, dz)
        span = max(np.max(np.abs(d - r)) for r, d in pts.values())
        scale = 0.12 * size / span if span > 0 else 1.0
        fig, ax = plt.subplots(figsize=(6, 5))
        for name, (rest, disp) in pts.items():
            moved = rest + scale * (disp - rest)
            for arr, style in ((rest, dict(color="0.7", lw=1.5)), (moved, dict(color="C0", lw=2))):
                for q in arr[1:]:
                    ax.plot([arr[0, 0] * 1e3, q[0] * 1e3], [arr[0, 1] * 1e3, q[1] * 1e3], **style)
            ax.plot(moved[1:, 0] * 1e3, moved[1:, 1] * 1e3, "o", color="C3", ms=5)
            ax.annotate(name, moved[0] * 1e3, fontsize=8, ha="center", va="bottom")
        ax.set_aspect("equal")
        ax.set_xlabel("x [mm]")
        ax.set_ylabel("y [mm]")
        ax.set_title(
            f"{mech.name}: mode {k + 1}, {md.frequencies[k]:.6g} Hz\n"
            "grey: at rest; blue: displaced (scaled to be visible); red: hinges",
            fontsize=10,
        )
        path = out_dir / f"mode_{k + 1}.png"
        fig.tight_layout()
        fig.savefig(path, dpi=110)
        plt.close(fig)
        paths.append(path)
    return paths


def _mode_points(mech, points, z, dz):
    """
    Per body.

    (rest, displaced) arrays of [centre, hinge points...] in the root frame (the displacement to
    first order: d(P + R c) = dP + dtheta J R c).
    """
    out = {}
    for i, body in enumerate(mech.bodies):
        x, y, th = z[3 * i:3 * i + 3]
        c, s = np.cos(th), np.sin(th)
        rest = [np.array([x, y])] + [
            np.array([x + c * p[0] - s * p[1], y + s * p[0] + c * p[1]]) for p in points[body.name]
        ]
        dx, dy, dth = dz[3 * i:3 * i + 3]
        disp = [q + np.array([dx, dy]) + dth * np.array([-(q[1] - y), q[0] - x]) for q in rest]
        out[body.name] = (np.array(rest), np.array(disp))
    return out


# -------------------------------------------------------------------------- frf


def run_frf(args) -> int:
    def work():
        if args.source != "drive":
            raise ValueError(f"--from {args.source!r}: the only input is 'drive'")
        if not (0 < args.fmin < args.fmax) or args.points < 2:
            raise ValueError("need 0 < --fmin < --fmax and --points >= 2")
        wanted = args.to or ["output"]
        mech, model = _model(args, wrenches=any(o.startswith("hinges.") for o in wanted))
        if not model.input_names:
            raise ValueError(f"mechanism {mech.name!r} has no drive input")
        outputs = args.to or ["output"]
        for o in outputs:
            model.output_index(o)
        f = np.logspace(np.log10(args.fmin), np.log10(args.fmax), args.points)
        G = linear.frf(model, f, outputs)
        out_dir = Path(args.output)
        out_dir.mkdir(parents=True, exist_ok=True)
        png = plot_bode(mech, model, f, G, outputs, out_dir / "frf.png")
        written = [png]
        if args.csv:
            written.append(write_frf_csv(f, G, outputs, out_dir / "frf.csv"))
        gains = linear.static_gain(model, outputs)
        for name, g, g0 in zip(outputs, G[:, 0], gains):
            print(
                f"{name}: |G| {abs(g):.6g} at {f[0]:.3g} Hz (static gain {g0:.6g}), "
                f"|G| {abs(G[outputs.index(name), -1]):.3g} at {f[-1]:.3g} Hz"
            )
        for path in written:
            print(f"wrote {path}")
        return EXIT_OK

    return _guarded("flexure-sim frf", work)


def write_frf_csv(f, G, outputs, path: Path) -> Path:
    cols = ["frequency_hz"]
    data = [f]
    for name, row in zip(outputs, G):
        cols += [f"{name}.magnitude", f"{name}.phase_deg", f"{name}.real", f"{name}.imag"]
        data += [np.abs(row), np.degrees(np.unwrap(np.angle(row))), row.real, row.imag]
    np.savetxt(
        path, np.column_stack(data), delimiter=",", header=",".join(cols), comments="", fmt="%.10g"
    )
    return path


def plot_bode(mech, model, f, G, outputs, path: Path) -> Path:
    import matplotlib

    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt

    fig, (ax1, ax2) = plt.subplots(2, 1, sharex=True, figsize=(7, 6))
    for name, row in zip(outputs, G):
        unit = (
            "m/m" if name in ("output", "compression") else ("N/m" if "force" in name else "N m/m")
        )
        ax1.loglog(f, np.abs(row), label=f"{name} [{unit}]")
        ax2.semilogx(f, np.degrees(np.unwrap(np.angle(row))), label=name)
    ax1.set_ylabel("magnitude")
    ax2.set_ylabel("phase [deg]")
    ax2.set_xlabel("frequency [Hz]")
    ax1.legend(fontsize=8)
    ax1.grid(True, which="both", alpha=0.3)
    ax2.grid(True, which="both", alpha=0.3)
    ax1.set_title(f"{mech.name}: drive command -> outputs, linearised at {model.u0 * 1e6:.4g} um")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


# -------------------------------------------------------------------- linearize


def export_model(model: linear.LinearModel, path: Path, mechanism: str) -> Path:
    """Return a, B, C, D with names: .npz (numpy), .mat (MATLAB, scipy.io.savemat), .json."""
    meta = {
        "mechanism": mechanism,
        "input_u0": model.u0,
        "state_names": model.state_names,
        "input_names": model.input_names,
        "output_names": model.output_names,
        "y0": model.y0.tolist(),
        "units": "SI; states are deviations of (z_F, v_F, u) from the equilibrium, outputs "
        "deviations from y0; the input is the drive command (m)",
    }
    arrays = {"A": model.A, "B": model.B, "C": model.C, "D": model.D}
    suffix = path.suffix.lower()
    if suffix == ".npz":
        np.savez(path, **arrays, **{k: np.array(v) for k, v in meta.items()})
    elif suffix == ".mat":
        import scipy.io

        scipy.io.savemat(
            path,
            {
                **arrays,
                **{
                    k: (np.array(v, dtype=object) if isinstance(v, list) else v)
                    for k, v in meta.items()
                },
            },
        )
    elif suffix == ".json":
        path.write_text(json.dumps({**{k: v.tolist() for k, v in arrays.items()}, **meta}))
    else:
        raise ValueError(f"-o {path}: the file name must end in .npz, .mat or .json")
    return path


def run_linearize(args) -> int:
    def work():
        mech, model = _model(args)
        path = export_model(model, Path(args.output), mech.name)
        print(
            f"{mech.name}: {len(model.state_names)} states, {len(model.input_names)} input, "
            f"{len(model.output_names)} outputs at drive input {model.u0:.6g} m -> {path}"
        )
        return EXIT_OK

    return _guarded("flexure-sim linearize", work)


# ---------------------------------------------------------------------- parsers


def _common(p) -> None:
    p.add_argument("mechanism", help="built-in name or YAML path")
    p.add_argument(
        "--input",
        type=float,
        default=0.0,
        help="drive input (m) of the static equilibrium (default 0)",
    )


def register(subparsers) -> None:
    p = subparsers.add_parser("modes", help="natural frequencies, mode shapes and damped poles")
    _common(p)
    p.add_argument("--count", type=int, default=4, help="mode shapes to list and plot (default 4)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument("-o", "--output", help="directory for mode-shape plots (mode_<k>.png)")
    p.set_defaults(handler=run_modes)

    p = subparsers.add_parser(
        "frf", help="frequency response (Bode plot, CSV) from the exact linearisation"
    )
    _common(p)
    p.add_argument("--from", dest="source", default="drive", help="input (only 'drive')")
    p.add_argument(
        "--to",
        action="append",
        help="output: output, compression, drive_force, "
        "hinges.<h>.moment|force_x|force_y (repeatable; default output)",
    )
    p.add_argument("--fmin", type=float, default=1.0, help="Hz (default 1)")
    p.add_argument("--fmax", type=float, default=1e5, help="Hz (default 1e5)")
    p.add_argument(
        "--points", type=int, default=1000, help="log-spaced frequencies (default 1000)"
    )
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
