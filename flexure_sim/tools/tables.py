"""Plain-text formatting shared by the tools: numbers with units, time axes, tables."""
from __future__ import annotations

from collections.abc import Sequence
from typing import Optional

import numpy as np


def format_si(value: Optional[float], unit: str, scale: float = 1.0, digits: int = 5) -> str:
    """``value * scale`` to ``digits`` significant digits, with ``unit`` ("-" if missing)."""
    if value is None or not np.isfinite(value):
        return "-"
    return f"{value * scale:.{digits}g}" + (f" {unit}" if unit else "")


def time_unit(duration_s: float) -> tuple[str, float]:
    """Return unit and scale for a time axis spanning ``duration_s``."""
    if duration_s < 2.0:
        return "ms", 1e3
    return "s", 1.0


def columns(rows: Sequence[Sequence[str]], header: Sequence[str], align: str = "") -> str:
    """Return a plain text table (first column left-aligned, the rest right-aligned)."""
    table = [list(header)] + [list(r) for r in rows]
    widths = [max(len(r[i]) for r in table) for i in range(len(header))]
    out = []
    for k, r in enumerate(table):
        cells = []
        for i, cell in enumerate(r):
            left = (align[i] == "<") if i < len(align) else (i == 0)
            cells.append(cell.ljust(widths[i]) if left else cell.rjust(widths[i]))
        out.append("  ".join(cells).rstrip())
        if k == 0:
            out.append("  ".join("-" * w for w in widths))
    return "\n".join(out)
