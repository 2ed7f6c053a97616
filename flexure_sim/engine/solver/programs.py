"""
Drive programs: a drive's input as a function of time (``Simulation.set_programs``).

A program gives a displacement drive's command (held over each step at its value at the step's
midpoint, which its first-order lag follows to second order in the step), a force drive's force
likewise, or a **prescribed** drive's displacement itself (``response_time: 0``), with its rate
and acceleration, at every instant the stepping evaluates (``piece_motion``, compiled).

Kinds, with amplitude A from the initial value p0, starting at t0:

- ``step``: p0 before t0, p0 + A from t0 (a prescribed displacement cannot jump: there a step
  rises over one engine step, linearly, ``for_prescribed``);
- ``ramp``: from p0 at t0 linearly to p0 + A at t0 + T (``duration`` T);
- ``cycloid``: p0 + A (s - sin(2 pi s) / (2 pi)), s = (t - t0) / T in [0, 1]: rate
  A / T (1 - cos 2 pi s) and acceleration 2 pi A / T^2 sin 2 pi s, both zero at the ends: the
  cycloidal motion law of cam design (no jump of velocity or acceleration at either end);
- ``sine``: p0 + A sin(2 pi f (t - t0)) from t0 (``frequency`` f).

A program is a list of pieces, each a smooth function on its interval: a constant, a line, a
cycloid, a sine (``pieces``). The stepping holds, over each step, the piece in force at the
step's midpoint, so a piece's end on the step grid is exact: the rate may jump there (a ramp's
corners), and the kinetic energy of the jump is counted as the drive's work
(``step_loop.switch_work``). Times are absolute simulation time (s).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Optional

import numpy as np

from flexure_sim.engine import jit as kernel_cache
from flexure_sim.engine.jit import njit

#: The kinds of program (``Program.kind``).
KINDS = ("step", "ramp", "cycloid", "sine")
#: Piece codes in a kernel row.
CONST, LINEAR, CYCLOID, SINE = 0.0, 1.0, 2.0, 3.0
#: Entries of a piece's kernel row: code, start t0, duration T, value p0, change A, omega.
PIECE_WIDTH = 6


@njit(cache=True, inline="always")
def piece_motion(row, t):
    """
    Return (p, dp/dt, d2p/dt2) of one piece at time t.

    ``row``: code, t0, T, p0, A, omega (``PIECE_WIDTH``). CONST: p0. LINEAR: p0 + A s with
    s = (t - t0) / T clamped to [0, 1], rate A / T on the closed interval. CYCLOID: p0 + A (s -
    sin(2 pi s) / (2 pi)), s clamped. SINE: p0 + A sin(omega (t - t0)).
    """
    code = row[0]
    if code == CONST:
        return row[3], 0.0, 0.0
    t0, T, p0, A = row[1], row[2], row[3], row[4]
    if code == SINE:
        w = row[5]
        ph = w * (t - t0)
        return p0 + A * math.sin(ph), A * w * math.cos(ph), -A * w * w * math.sin(ph)
    s = (t - t0) / T
    inside = 0.0 <= s <= 1.0
    s = min(max(s, 0.0), 1.0)
    if code == LINEAR:
        return p0 + A * s, A / T if inside else 0.0, 0.0
    a = 2.0 * math.pi * s
    return (p0 + A * (s - math.sin(a) / (2.0 * math.pi)), A / T * (1.0 - math.cos(a)),
            A * 2.0 * math.pi / (T * T) * math.sin(a))


@dataclass(frozen=True)
class Program:
    """
    One drive's input over time (module doc): ``kind``, ``amplitude`` A (m, rad, N or V).

    ``duration`` T (s) of a ramp or cycloid; ``frequency`` f (Hz) of a sine; ``start`` t0 (s,
    simulation time); ``initial`` p0, the value before t0. ValueError naming the field for a
    value that does not make a program.
    """

    kind: str
    amplitude: float
    duration: float = 0.0
    frequency: float = 0.0
    start: float = 0.0
    initial: float = 0.0

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise ValueError(f"program kind {self.kind!r}: expected one of {', '.join(KINDS)}")
        for name in ("amplitude", "duration", "frequency", "start", "initial"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not \
                    math.isfinite(value):
                raise ValueError(f"{self.kind} program: {name} must be a finite number, "
                                 f"got {value!r}")
        if self.kind in ("ramp", "cycloid") and not self.duration > 0:
            raise ValueError(f"{self.kind} program: duration must be > 0 s, got "
                             f"{self.duration!r}")
        if self.kind == "sine" and not self.frequency > 0:
            raise ValueError(f"sine program: frequency must be > 0 Hz, got {self.frequency!r}")

    # ------------------------------------------------------------------ pieces
    def pieces(self) -> tuple[tuple[float, np.ndarray], ...]:
        """Return (start time, kernel row) of each piece, in time order (the first from -inf)."""
        p0, A, t0, T = float(self.initial), float(self.amplitude), float(self.start), \
            float(self.duration)
        before = (-math.inf, _row(CONST, p0=p0))
        if self.kind == "step":
            return before, (t0, _row(CONST, p0=p0 + A))
        if self.kind == "sine":
            return before, (t0, _row(SINE, t0, 0.0, p0, A, 2.0 * math.pi * self.frequency))
        code = LINEAR if self.kind == "ramp" else CYCLOID
        return before, (t0, _row(code, t0, T, p0, A)), (t0 + T, _row(CONST, p0=p0 + A))

    def row(self, t: float) -> np.ndarray:
        """Return the kernel row of the piece in force at time t (the last one begun)."""
        out = self.pieces()[0][1]
        for start, row in self.pieces():
            if start <= t:
                out = row
        return out

    def rows(self, times: np.ndarray) -> np.ndarray:
        """Return the kernel rows at each of ``times``, shape (len(times), ``PIECE_WIDTH``)."""
        pieces = self.pieces()
        starts = np.array([s for s, _ in pieces])
        table = np.array([r for _, r in pieces])
        return table[np.searchsorted(starts, np.asarray(times, dtype=float), side="right") - 1]

    def motion(self, t: float) -> tuple[float, float, float]:
        """Return (value, rate, acceleration) at time t (``piece_motion`` of ``row``)."""
        p, v, a = piece_motion(self.row(t), float(t))
        return float(p), float(v), float(a)

    def value(self, t: float) -> float:
        """Return the program's value at time t."""
        return self.motion(t)[0]

    def values(self, times: np.ndarray) -> np.ndarray:
        """Return the values at each of ``times``."""
        return np.array([float(piece_motion(r, float(t))[0])
                         for r, t in zip(self.rows(times), np.asarray(times, dtype=float))])

    @property
    def final(self) -> Optional[float]:
        """Return the value the program settles to (None for a sine: it never settles)."""
        return None if self.kind == "sine" else float(self.initial + self.amplitude)

    # -------------------------------------------------------- prescribed drives
    def for_prescribed(self, dt: float) -> "Program":
        """
        Return the program a prescribed displacement follows: a step rises over one step ``dt``.

        A prescribed coordinate cannot jump (its viscously coupled neighbours would take an
        impulse and dissipate without bound), so a step becomes a ramp of one engine step, the
        fastest motion the fixed step resolves; the other kinds are continuous already.
        """
        if self.kind != "step":
            return self
        return replace(self, kind="ramp", duration=float(dt))

    def describe(self) -> str:
        """Return the program as text (``ramp 1e-05 over 0.002 s from 0 s``)."""
        text = f"{self.kind} {self.amplitude:g}"
        if self.kind in ("ramp", "cycloid"):
            text += f" over {self.duration:g} s"
        if self.kind == "sine":
            text += f" at {self.frequency:g} Hz"
        text += f" from {self.start:g} s"
        return text + (f" (initial {self.initial:g})" if self.initial else "")


def _row(code: float, t0: float = 0.0, T: float = 0.0, p0: float = 0.0, A: float = 0.0,
         w: float = 0.0) -> np.ndarray:
    return np.array([code, t0, T, p0, A, w], dtype=float)


def hold(value: float) -> np.ndarray:
    """Return the kernel row of a constant ``value`` (a prescribed drive held at its command)."""
    return _row(CONST, p0=float(value))


# Numba's cache of each kernel is keyed on its own file only (``kernel_cache``).
kernel_cache.revalidate(kernel_cache.dispatchers_of(globals()), __file__)
