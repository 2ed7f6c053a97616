"""
Measured (displacement, wrench) pairs of a hinge and their CSV files.

Rows of r = (alpha, px, py) -- rotation (rad) and translation (m) of frame b relative to frame
a, in frame a -- and m_b = (m, fx, fy) -- the wrench exerted by body B on the elastic element,
in frame b coordinates, moment about b's origin (N m, N; eqs. 4.34-4.35, Chapter 7). The data
``fitting.fit_polynomial`` fits; ``read_wrench_csv`` names the file, line and column of every
problem.
"""
from __future__ import annotations

import csv
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from flexure_sim.errors import FlexureSimError, as_array
from flexure_sim.engine.mechanism.yaml_files import read_text

#: Required CSV columns: displacement of b in a, then the wrench m_b on the element.
COLUMNS = ("alpha", "px", "py", "m", "fx", "fy")


class DataError(FlexureSimError, ValueError):
    """A data file is invalid; the message names the file, the line or column and the problem."""


@dataclass(frozen=True)
class WrenchData:
    """
    Measured pairs.

    Alpha (n,), p (n, 2) of frame b in frame a; wrench (n, 3) = m_b (m, fx, fy) on the element in
    frame b, moment about b's origin.
    """

    alpha: np.ndarray
    p: np.ndarray
    wrench: np.ndarray
    source: str = "<data>"

    def __post_init__(self) -> None:
        alpha = as_array("alpha", self.alpha, (None,))
        n = len(alpha)
        p = as_array("p", self.p, (n, 2))
        w = as_array("wrench", self.wrench, (n, 3))
        object.__setattr__(self, "alpha", alpha)
        object.__setattr__(self, "p", p)
        object.__setattr__(self, "wrench", w)

    def __len__(self) -> int:
        return len(self.alpha)

    def subset(self, index) -> "WrenchData":
        """Rows ``index`` (anything NumPy can index with)."""
        return WrenchData(self.alpha[index], self.p[index], self.wrench[index], self.source)


# --------------------------------------------------------------------------- CSV

#: Largest magnitude accepted in a data file: the fit squares and multiplies the values
#: (RMS weights, energy scale), which must stay finite in double precision (max ~1.8e308).
MAX_ABS_VALUE = 1e150


def read_wrench_csv(path: str | Path) -> WrenchData:
    """
    Read a data CSV.

    A header naming at least the columns alpha, px, py, m, fx, fy (any order; other columns are
    ignored), then one row per measurement. Lines starting with '#' are comments. The file must be
    UTF-8 text; every value must be a finite number of magnitude at most MAX_ABS_VALUE, and |alpha|
    < pi. Errors name the file, line and column.
    """
    path = Path(path)
    text = read_text(path, DataError)
    lines = [
        (i + 1, line) for i, line in enumerate(text.splitlines())
        if line.strip() and not line.lstrip().startswith("#")
    ]
    for lineno, line in lines:
        if "\0" in line:
            raise DataError(f"{path}: line {lineno}: contains a NUL byte "
                            "(a binary file, not a CSV?)")
    if not lines:
        raise DataError(f"{path}: no header and no data (need columns {', '.join(COLUMNS)})")
    reader = csv.reader([line for _, line in lines], skipinitialspace=True)
    try:
        rows = list(reader)
    except csv.Error as exc:
        lineno = lines[reader.line_num - 1][0]
        raise DataError(f"{path}: line {lineno}: not valid CSV: {exc}") from None
    header = [h.strip() for h in rows[0]]
    dup = sorted({h for h in header if header.count(h) > 1})
    if dup:
        raise DataError(f"{path}: line {lines[0][0]}: column {dup[0]!r} appears more than once")
    missing = [c for c in COLUMNS if c not in header]
    if missing:
        found = ", ".join(h if h.isprintable() else repr(h) for h in header)
        raise DataError(
            f"{path}: missing column{'s' if len(missing) > 1 else ''} {', '.join(missing)} "
            f"(the header must name {', '.join(COLUMNS)}; found {found or 'nothing'})"
        )
    if len(rows) == 1:
        raise DataError(f"{path}: the header has no data rows")
    where = [header.index(c) for c in COLUMNS]
    values = np.empty((len(rows) - 1, len(COLUMNS)))
    for r, (row, (lineno, _)) in enumerate(zip(rows[1:], lines[1:])):
        if len(row) != len(header):
            raise DataError(
                f"{path}: line {lineno}: expected {len(header)} fields, got {len(row)}"
            )
        for c, (name, col) in enumerate(zip(COLUMNS, where)):
            values[r, c] = _cell(path, lineno, name, row[col].strip())
    bad = np.nonzero(np.abs(values[:, 0]) >= math.pi)[0]
    if len(bad):
        alpha = float(values[bad[0], 0])  # a float: np.float64's repr differs in NumPy 2
        raise DataError(
            f"{path}: line {lines[1 + bad[0]][0]}, column 'alpha': {alpha!r} rad is "
            "outside (-pi, pi)"
        )
    return WrenchData(values[:, 0], values[:, 1:3], values[:, 3:6], str(path))


def _cell(path: Path, lineno: int, name: str, cell: str) -> float:
    """One CSV value: a finite number no larger in magnitude than MAX_ABS_VALUE."""
    where = f"{path}: line {lineno}, column {name!r}"
    shown = repr(cell) if len(cell) <= 40 else repr(cell[:37]) + "..."
    try:
        v = float(cell)
    except ValueError:
        raise DataError(f"{where}: {shown} is not a number") from None
    if not math.isfinite(v):
        raise DataError(f"{where}: {shown} (every value must be finite)")
    if abs(v) > MAX_ABS_VALUE:
        raise DataError(f"{where}: {v:g} is out of range (|value| <= {MAX_ABS_VALUE:g}, "
                        "so that the fit's sums of squares stay finite; check the units: SI)")
    return v


def write_wrench_csv(path: str | Path, data: WrenchData, comment: str = "") -> None:
    """Write data in the format ``read_wrench_csv`` reads (full double precision)."""
    lines = [f"# {line}" for line in comment.splitlines()]
    lines.append(",".join(COLUMNS))
    table = np.column_stack([data.alpha, data.p, data.wrench])
    lines += [",".join(repr(float(v)) for v in row) for row in table]
    Path(path).write_text("\n".join(lines) + "\n")


__all__ = [
    "COLUMNS", "MAX_ABS_VALUE", "DataError", "WrenchData", "read_wrench_csv", "write_wrench_csv",
]
