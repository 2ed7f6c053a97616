"""
``flexure-sim export RUN --csv DIR --signals``: the drives and outputs of a run in one table.

``signals.csv`` has one row per time stamp of the drives' and outputs' samples (one per tick
for stage_node), in time order: ``time`` (simulation time, s, nanosecond digits), then per
drive (`channels`, in the order the mechanism lists them) its command (the last command at or
before the row, as the node holds it; empty before the first), applied input and its force
(displacement drive) or position (force drive), then per output its displacement. Each column
is named after its topic relative to the run's namespace (``drive/x/input``,
``output/theta/displacement``; a single drive: ``drive/displacement``, ``drive/input``...);
values in SI units (m, rad, N, N m: ``info`` lists each drive's and output's unit), full
precision. A sample missing at a row's time leaves its cell empty.
"""
from __future__ import annotations

import csv
from pathlib import Path
from typing import Optional

import numpy as np

from flexure_sim.recording.exceptions import RunError
from flexure_sim.tools.run.runlog import Run
from flexure_sim.tools.run.series import FLOAT64

FILE_NAME = "signals.csv"


def signal_columns(run: Run) -> list[tuple[str, str]]:
    """Return (column, kind) of the table: kind ``held`` for commands, ``sample`` otherwise."""
    cols: list[tuple[str, str]] = []
    for d in run.drives():
        if run.has(d.command):
            cols.append((d.command, "held"))
        cols.append((d.input, "sample"))
        if d.response is not None:
            cols.append((d.response, "sample"))
    cols += [(o.topic, "sample") for o in run.outputs() if run.has(o.topic)]
    return [(c, k) for c, k in cols if run.has(c)]


def _ns(run: Run, rel: str) -> tuple[np.ndarray, np.ndarray]:
    t, values, _ = run._raw(rel, FLOAT64)
    return run.timebase.sim_ns(t), values


def _cell(v: Optional[float]) -> str:
    return "" if v is None else repr(float(v))


def write_signals(run: Run, out_dir: Path) -> tuple[Path, int]:
    """Write ``signals.csv`` of ``run`` into ``out_dir``; returns its path and row count."""
    cols = signal_columns(run)
    if not any(k == "sample" for _, k in cols):
        raise RunError(f"{run.path}: --signals: the run records no drive input or output "
                       f"(topics: {', '.join(sorted(run.topics)) or 'none'})")
    data = {c: _ns(run, c) for c, _ in cols}
    times = np.unique(np.concatenate([data[c][0] for c, k in cols if k == "sample"]))
    columns = []
    for c, kind in cols:
        t, v = data[c]
        order = np.argsort(t, kind="stable")
        t, v = t[order], v[order]
        k = np.searchsorted(t, times, side="right") - 1   # last sample at or before the row
        ok = k >= 0
        if kind == "sample":
            ok &= t[np.clip(k, 0, None)] == times if t.shape[0] else False
        cells = [None] * times.shape[0]
        if t.shape[0]:
            cells = [float(v[i]) if good else None for i, good in zip(k, ok)]
        columns.append(cells)
    path = out_dir / FILE_NAME
    with path.open("w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(["time"] + [c for c, _ in cols])
        for r, ns in enumerate(times.tolist()):
            writer.writerow([f"{ns // 1_000_000_000}.{ns % 1_000_000_000:09d}"]
                            + [_cell(col[r]) for col in columns])
    return path, int(times.shape[0])
