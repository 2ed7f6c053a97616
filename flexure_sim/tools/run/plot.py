"""
``flexure-sim plot RUN.mcap -o DIR``: PNG figures of a recorded run.

    flexure-sim plot runs/stage.mcap -o runs/plots [--recover] [--strict] [--dpi 120]

Figures (those the run's topics allow):

- ``input_output.png``  "Input and output displacement": drive command and applied input,
  and the output, against time, with the gain of every settled step (cf. Figure 6.3); a
  command beyond the recorded stroke drawn where the node clamped it, and marked;
- ``joint_<h>.png``     "Joint <h> displacement on <body A> and <body B>": x-displacement of
  the compression hinge's frames on its two bodies, and their difference, the compression
  (cf. Figure 6.4);
- ``hinge_wrenches.png`` "Hinge wrenches": moment and force components of every hinge (all
  six of a run of the spatial engine);
- ``drive_force.png``   "Drive force": the force the actuator applies;
- ``body_poses.png``    "Body poses" (runs without a drive, e.g. the four-bars).

A run with several drives or outputs (issue 13: ``drive/<name>/...``, ``output/<name>/...``)
gets, instead of the input/output and drive force figures (`plot_drives`):

- ``drives_outputs.png`` "Drives and outputs": one panel per drive (command and applied
  input) and one per output, each labelled with its name and unit;
- ``drive_forces.png``   "Drive forces": per drive, its actuator force (or, for a force
  drive, its body's displacement).

Each PNG carries its title in its metadata (``Title``). Matplotlib runs with the Agg backend.
Matplotlib is optional (setup.py's extra ``plot``): without it the command says so in one
line, before reading the run.
"""
from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any, Optional

import numpy as np

from flexure_sim.recording.command_line import report_reading, tool_errors
from flexure_sim.recording.exceptions import EXIT_OK, RunError
from flexure_sim.topics import COMMAND, DRIVE_FORCE, DRIVE_INPUT, OUTPUT
from flexure_sim.tools.run.run_channels import is_single_drive, recorded_stroke, stroke_keys
from flexure_sim.tools.options import add_file_arguments
from flexure_sim.tools.run.plot_drives import TITLES as DRIVE_TITLES, draw_command, plot_drives
from flexure_sim.tools.run.runlog import Run, load_run
from flexure_sim.tools.tables import time_unit

PROG = "flexure-sim plot"
TITLES = {
    "input_output": "Input and output displacement",
    "hinge_wrenches": "Hinge wrenches",
    "drive_force": "Drive force",
    "body_poses": "Body poses",
    **DRIVE_TITLES,
}


def register(subparsers: Any) -> None:
    p = subparsers.add_parser("plot", help="PNG figures of a recorded run",
                              description=__doc__.split("\n\n")[0].replace("``", ""))
    add_file_arguments(p)
    p.add_argument(
        "-o",
        "--output",
        metavar="DIR",
        required=True,
        help="directory for the PNG files (created)",
    )
    p.add_argument("--dpi", type=int, default=120, help="resolution (default 120)")
    p.set_defaults(handler=run)


def run(args: argparse.Namespace) -> int:
    return tool_errors(PROG, lambda: _run(args), can_recover=not args.recover)


def _run(args: argparse.Namespace) -> int:
    if args.dpi <= 0:
        raise RunError(f"--dpi {args.dpi}: must be positive", 2)
    _pyplot()
    run_ = load_run(args.run, recover=args.recover, namespace=args.namespace, strict=args.strict)
    report_reading(PROG, run_)
    out_dir = Path(args.output)
    if out_dir.exists() and not out_dir.is_dir():
        raise RunError(f"-o {out_dir}: exists and is not a directory", 2)
    written = plot_run(run_, out_dir, dpi=args.dpi)
    if not written:
        raise RunError(f"{run_.path}: nothing to plot: none of the stage's topics are in the file "
                       f"(topics: {', '.join(sorted(run_.topics)) or 'none'})")
    print(f"wrote {len(written)} figure(s) to {out_dir}/:")
    for path, title in written:
        print(f"  {path.name:22s} {title}")
    return EXIT_OK


#: What to tell a user who has no matplotlib.
MISSING_MATPLOTLIB = ("plotting needs matplotlib (flexure_sim's extra 'plot'), which is not "
                      "installed: pip install matplotlib, or pip install '.[plot]' in the "
                      "source; on ROS: apt install python3-matplotlib")


def _pyplot():
    try:
        import matplotlib
    except ImportError:
        raise RunError(MISSING_MATPLOTLIB) from None

    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt

    return plt


def plot_run(run: Run, out_dir: Path, dpi: int = 120,
             figures: Optional[dict[str, Any]] = None) -> list[tuple[Path, str]]:
    """
    Write every figure the run allows; returns (path, title) of each.

    With ``figures`` (a dict), each figure is also left open and stored in it under its file
    stem (e.g. ``drives_outputs``), for a caller that reads the drawn lines; it closes them.
    """
    plt = _pyplot()
    out_dir.mkdir(parents=True, exist_ok=True)
    unit, scale = time_unit((run.end_ns - run.start_ns) / 1e9)
    tlabel = f"simulation time [{unit}]"
    steps = _step_times(run)
    written: list[tuple[Path, str]] = []

    def save(fig, name: str, title: str) -> None:
        fig.suptitle(title)
        fig.tight_layout()
        path = out_dir / f"{name}.png"
        fig.savefig(path, dpi=dpi, metadata={"Title": title, "Software": "flexure_sim"})
        if figures is None:
            plt.close(fig)
        else:
            figures[name] = fig
        written.append((path, title))

    def mark_steps(ax) -> None:
        for ts in steps:
            ax.axvline(ts * scale, color="0.75", linestyle=":", linewidth=0.8, zorder=0)

    def tx(t: np.ndarray) -> np.ndarray:
        return t * scale

    # ---- input and output (Figure 6.3)
    multi = not is_single_drive(run.topics, run.topic) and bool(run.drives() or run.outputs())
    out = run.scalar(OUTPUT)
    u = run.scalar(DRIVE_INPUT)
    cmd = run.scalar(COMMAND)
    if multi:  # several drives or outputs: one panel each (plot_drives)
        for fig, name, title in plot_drives(plt, run, tx, tlabel, mark_steps):
            save(fig, name, title)
    elif out is not None or u is not None:
        fig, (ax_in, ax_out) = plt.subplots(2, 1, sharex=True, figsize=(8, 6))
        if u is not None:
            ax_in.plot(tx(u.t), u.values * 1e6, label="drive input (applied)", color="C0")
        if cmd is not None and not cmd.empty:
            before = (u.t[0], u.values[0]) if u is not None and not u.empty and (
                u.t[0] < cmd.t[0]) else None
            draw_command(ax_in, tx, cmd, before, recorded_stroke(run.metadata, stroke_keys(None)),
                         1e6, run.end_ns / 1e9, "drive command")
        ax_in.set_ylabel("input displacement [µm]")
        ax_in.legend(loc="best", fontsize="small")
        ax_in.grid(alpha=0.3)
        mark_steps(ax_in)
        if out is not None:
            ax_out.plot(
                tx(out.t), out.values * 1e6, color="C2", label="output displacement (body x)"
            )
            for s in _settled_gains(run):
                ax_out.annotate(
                    f"gain {s['gain']:.4g}",
                    (s["t_end"] * scale, s["output"] * 1e6),
                    textcoords="offset points",
                    xytext=(-4, 6),
                    ha="right",
                    fontsize="small",
                )
        ax_out.margins(y=0.12)  # room for the gain labels
        ax_out.set_ylabel("output displacement [µm]")
        ax_out.set_xlabel(tlabel)
        ax_out.grid(alpha=0.3)
        mark_steps(ax_out)
        save(fig, "input_output", TITLES["input_output"])

    # ---- joint displacement on its two bodies (Figure 6.4)
    hinge = run.compression_hinge()
    comp = run.scalar(run.compression_topic()) if hinge else None
    if hinge is not None:
        frames = run.hinge_frame_displacements(hinge)
        if frames is not None:
            ft, da, db, body_a, body_b = frames
            title = f"Joint {hinge} displacement on {body_a} and {body_b}"
            fig, (ax1, ax2) = plt.subplots(2, 1, sharex=True, figsize=(8, 6))
            ax1.plot(tx(ft), da[:, 0] * 1e6, label=f"frame of joint {hinge} on {body_a}")
            ax1.plot(
                tx(ft), db[:, 0] * 1e6, label=f"frame of joint {hinge} on {body_b}", linestyle="--"
            )
            ax1.set_ylabel("x-displacement [µm]")
            ax1.legend(loc="best", fontsize="small")
            ax1.grid(alpha=0.3)
            mark_steps(ax1)
            if comp is not None:
                ax2.plot(
                    tx(comp.t),
                    comp.values * 1e9,
                    color="C3",
                    label="compression (as recorded: drive side - far side)",
                )
            else:
                ax2.plot(
                    tx(ft), (db[:, 0] - da[:, 0]) * 1e9, color="C3", label=f"{body_b} - {body_a}"
                )
            ax2.set_ylabel(f"joint {hinge} compression [nm]")
            ax2.set_xlabel(tlabel)
            ax2.legend(loc="best", fontsize="small")
            ax2.grid(alpha=0.3)
            mark_steps(ax2)
        elif comp is not None:
            title = f"Joint {hinge} compression"
            fig, ax2 = plt.subplots(figsize=(8, 4))
            ax2.plot(tx(comp.t), comp.values * 1e9, color="C3")
            ax2.set_ylabel(f"joint {hinge} compression [nm]")
            ax2.set_xlabel(tlabel)
            ax2.grid(alpha=0.3)
            mark_steps(ax2)
            ax2.set_title(
                "(frame displacements need the mechanism: "
                f"{run.mechanism_problem or 'poses missing'})",
                fontsize="small",
            )
        else:
            title = ""
        if title:
            save(fig, f"joint_{hinge}", title)

    # ---- hinge wrenches
    wrenches = run.wrenches(every_component=True)
    if wrenches:
        six = next(iter(wrenches.values())).values.shape[1] == 6
        fig, axes = plt.subplots(6 if six else 3, 1, sharex=True, figsize=(8, 12 if six else 8))
        labels: tuple[str, ...] = ("moment [mN·m]", "force $f_x$ [N]", "force $f_y$ [N]")
        if six:
            labels = ("moment $m_z$ [mN·m]", "force $f_x$ [N]", "force $f_y$ [N]",
                      "moment $m_x$ [mN·m]", "moment $m_y$ [mN·m]", "force $f_z$ [N]")
        factors = (1e3, 1.0, 1.0, 1e3, 1e3, 1.0)
        for name, w in wrenches.items():
            for k, ax in enumerate(axes):
                ax.plot(tx(w.t), w.values[:, k] * factors[k], label=f"hinge {name}")
        for ax, label in zip(axes, labels):
            ax.set_ylabel(label)
            ax.grid(alpha=0.3)
            mark_steps(ax)
        axes[0].legend(loc="upper left", bbox_to_anchor=(1.0, 1.0), fontsize="small")
        axes[0].set_title(
            "wrench each hinge exerts on its body B, in its frame b", fontsize="small"
        )
        axes[-1].set_xlabel(tlabel)
        save(fig, "hinge_wrenches", TITLES["hinge_wrenches"])

    # ---- drive force
    force = run.scalar(DRIVE_FORCE)
    if force is not None and not force.empty and not multi:
        fig, ax = plt.subplots(figsize=(8, 4))
        ax.plot(tx(force.t), force.values, color="C4")
        ax.set_ylabel("drive force [N]")
        ax.set_xlabel(tlabel)
        ax.set_title(
            "force the actuator applies to the driven body, along the drive axis", fontsize="small"
        )
        ax.grid(alpha=0.3)
        mark_steps(ax)
        save(fig, "drive_force", TITLES["drive_force"])

    # ---- body poses (runs without a drive)
    poses = run.poses()
    if poses and out is None and u is None and not run.drives():
        fig, axes = plt.subplots(3, 1, sharex=True, figsize=(8, 8))
        for name, p in poses.items():
            rest = p.values[0]
            for k, (ax, f) in enumerate(zip(axes, (1e3, 1e3, 1.0))):
                ax.plot(tx(p.t), (p.values[:, k] - rest[k]) * f, label=name)
        for ax, label in zip(
            axes, ("x - x(start) [mm]", "y - y(start) [mm]", "yaw - yaw(start) [rad]")
        ):
            ax.set_ylabel(label)
            ax.grid(alpha=0.3)
        axes[0].legend(loc="upper left", bbox_to_anchor=(1.0, 1.0), fontsize="small")
        axes[-1].set_xlabel(tlabel)
        save(fig, "body_poses", TITLES["body_poses"])
    return written


def _step_times(run: Run) -> list[float]:
    from flexure_sim.tools.run.analyse import find_steps
    from flexure_sim.tools.run.analyse_drives import drive_steps

    try:
        if is_single_drive(run.topics, run.topic):
            steps, _ = find_steps(run)
        else:
            steps = [s for d in run.drives() for s in drive_steps(run, d)[0]]
    except RunError:
        return []
    return sorted(s.t for s in steps)


def _settled_gains(run: Run) -> list[dict]:
    """t_end, settled output and gain of every settled step (for the annotations)."""
    from flexure_sim.tools.run.analyse import analyse_run

    try:
        result = analyse_run(run, static=False)
    except RunError:
        return []
    out: list[dict] = []
    for s in result["steps"]:
        if s["gain"] is not None and s["output"] is not None:
            out.append({"t_end": s["t"] + s["duration"], "output": s["output"], "gain": s["gain"]})
    return out


def figure_title(path: Path) -> Optional[str]:
    """Return the title stored in a PNG written by `plot_run` (for tests and scripts)."""
    from PIL import Image

    with Image.open(path) as img:
        return img.text.get("Title")
