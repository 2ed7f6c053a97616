"""
Figures of a run with several drives or outputs (``flexure-sim plot``; issue 13).

``drives_outputs.png`` "Drives and outputs": one panel per drive, its command (dashed, held
until the next one) and applied input, then one panel per output, all against simulation
time, each labelled with the drive's or output's name and unit (µm for m, µrad for rad, N,
N·m; a command in volts on a second axis, V); a command beyond the drive's recorded
stroke is drawn where the node clamped it and marked (`draw_command`). ``drive_forces.png``
"Drive forces": one panel per drive with its other recorded signal, the actuator force of a
displacement drive or the body's displacement of a force drive.
"""
from __future__ import annotations

from typing import Any, Callable, Iterator, Optional

import numpy as np

from flexure_sim.tools.run.analyse_drives import drive_steps
from flexure_sim.tools.run.run_channels import recorded_stroke, stroke_keys
from flexure_sim.tools.run.runlog import Run

#: Unit -> (unit shown, factor) of the axes.
DISPLAY = {"m": ("µm", 1e6), "rad": ("µrad", 1e6), "N": ("N", 1.0), "N m": ("N·m", 1.0)}
TITLES = {"drives_outputs": "Drives and outputs", "drive_forces": "Drive forces"}


def display(unit: str) -> tuple[str, float]:
    """Return the axis unit and factor for values in SI ``unit``."""
    return DISPLAY.get(unit, (unit, 1.0))


def staircase(t: np.ndarray, v: np.ndarray, t_end: float) -> tuple[np.ndarray, np.ndarray]:
    """Step-plot points of a command held until the next one (non-finite ones dropped)."""
    keep = np.isfinite(v)
    t, v = t[keep], v[keep]
    if t.shape[0] == 0:
        return t, v
    tt = np.append(t, max(t_end, float(t[-1])))
    vv = np.append(v, v[-1])
    return np.repeat(tt, 2)[1:-1], np.repeat(vv, 2)[:-2]


def draw_command(ax: Any, tx: Callable[[np.ndarray], np.ndarray], cmd: Any,
                 before: Optional[tuple[float, float]], stroke: Optional[tuple[float, float]],
                 factor: float, t_end: float, label: str, prefix: str = "") -> None:
    """
    Draw a drive's command (dashed, held until the next one) as the node applied it.

    ``cmd``: the recorded command `Series`; ``before``: (time, target) before the first
    command, or None. With the ``stroke`` (min, max) the node recorded, a command beyond it is
    drawn at the stroke's end it was clamped to, and marked there with an ``x`` labelled ``N
    commands beyond the stroke, clamped``: the axis then spans what the drive was given,
    not a mistyped 1e6 um. NaN and infinite commands (rejected by the node) are not drawn.
    """
    ct, cv = cmd.t, cmd.values
    if stroke is not None:
        lo, hi = stroke
        with np.errstate(invalid="ignore"):
            beyond = np.isfinite(cv) & ((cv < lo) | (cv > hi))
        cv = np.clip(cv, lo, hi)
        n = int(np.count_nonzero(beyond))
        if n:
            ax.plot(tx(ct[beyond]), cv[beyond] * factor, linestyle="none", marker="x",
                    color="C3", label=f"{prefix}{n} command{'s' if n > 1 else ''} beyond the "
                    "stroke, clamped")
    if before is not None:
        ct, cv = np.append(before[0], ct), np.append(before[1], cv)
    ct, cv = staircase(ct, cv, t_end)
    ax.plot(tx(ct), cv * factor, color="C1", linestyle="--", linewidth=1, label=label)


def plot_drives(plt: Any, run: Run, tx: Callable[[np.ndarray], np.ndarray], tlabel: str,
                mark_steps: Callable[[Any], None]) -> Iterator[tuple[Any, str, str]]:
    """Yield (figure, file stem, title) of each figure of a run with several drives/outputs."""
    drives, outputs = run.drives(), run.outputs()
    n = len(drives) + len(outputs)
    if n:
        fig, axes = plt.subplots(n, 1, sharex=True, figsize=(8, 1.9 * n + 1.2), squeeze=False)
        axes = axes[:, 0]
        for ax, d in zip(axes, drives):
            unit, f = display(d.unit)
            u, cmd = run.scalar(d.input), run.scalar(d.command)
            what = "force" if d.kind == "force" else "input"
            if u is not None and not u.empty:
                ax.plot(tx(u.t), u.values * f, color="C0", label=f"drive {d.name}: applied {what}")
            cax, cf = ax, f
            if d.command_unit != d.unit:  # volts: the command on an axis of its own
                cax = ax.twinx()
                cunit, cf = display(d.command_unit)
                cax.set_ylabel(f"command [{cunit}]")
            if cmd is not None and not cmd.empty:
                before = None
                if u is not None and not u.empty and u.t[0] < cmd.t[0]:
                    # the target before the first command: the rest input (volts: the
                    # analysis's rest voltage, the first step's starting target)
                    first = drive_steps(run, d)[0]
                    before = (u.t[0], u.values[0] if cax is ax or not first
                              else first[0].previous)
                stroke = (recorded_stroke(run.metadata, stroke_keys(d)) if cax is ax
                          else None)  # a stroke in m, a command in volts: not comparable
                draw_command(cax, tx, cmd, before, stroke, cf, run.end_ns / 1e9,
                             f"drive {d.name}: command", f"drive {d.name}: ")
            ax.set_ylabel(f"drive {d.name} [{unit}]")
            handles = ax.get_legend_handles_labels()
            if cax is not ax:
                more = cax.get_legend_handles_labels()
                handles = (handles[0] + more[0], handles[1] + more[1])
            ax.legend(*handles, loc="best", fontsize="small")
        for k, (ax, o) in enumerate(zip(axes[len(drives):], outputs)):
            unit, f = display(o.unit)
            y = run.scalar(o.topic)
            if y is not None:
                ax.plot(tx(y.t), y.values * f, color=f"C{2 + k}", label=f"output {o.name}")
            ax.set_ylabel(f"output {o.name} [{unit}]")
            ax.legend(loc="best", fontsize="small")
        for ax in axes:
            ax.grid(alpha=0.3)
            mark_steps(ax)
        axes[-1].set_xlabel(tlabel)
        yield fig, "drives_outputs", TITLES["drives_outputs"]
    forces = [(d, run.scalar(d.response)) for d in drives if d.response is not None]
    forces = [(d, s) for d, s in forces if s is not None and not s.empty]
    if forces:
        fig, axes = plt.subplots(len(forces), 1, sharex=True, squeeze=False,
                                 figsize=(8, 1.9 * len(forces) + 1.2))
        axes = axes[:, 0]
        for ax, (d, s) in zip(axes, forces):
            unit, f = display(d.response_unit)
            what = "body displacement" if d.kind == "force" else "actuator force"
            ax.plot(tx(s.t), s.values * f, color="C4", label=f"drive {d.name}: {what}")
            ax.set_ylabel(f"drive {d.name} [{unit}]")
            ax.legend(loc="best", fontsize="small")
            ax.grid(alpha=0.3)
            mark_steps(ax)
        axes[0].set_title("force each displacement drive's actuator applies to its body, along "
                          "its axis; a force drive's body displacement", fontsize="small")
        axes[-1].set_xlabel(tlabel)
        yield fig, "drive_forces", TITLES["drive_forces"]
