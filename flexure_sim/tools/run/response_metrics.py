"""
Step-response metrics of one signal: settling time, overshoot, rise time, peak.

Pure functions on NumPy arrays (no files, no ROS); the definitions are those listed in
``analysis`` (and docs/tools.md), which applies them to every step of a run.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Optional, Sequence

import numpy as np

#: Settling band, as a fraction of the change.
DEFAULT_BAND = 0.02
#: Part of its window a response must spend inside the band to count as settled.
DEFAULT_HOLD = 0.2


@dataclass(frozen=True)
class Response:
    """Metrics of one signal's response to one step (units of the signal, times in s)."""

    initial: float
    final: float
    change: float
    settling_time: Optional[float]
    overshoot: float
    rise_time: Optional[float]
    peak: float
    settled: bool


def sample_arrays(
    t: Sequence[float], y: Sequence[float], name: str = "y"
) -> tuple[np.ndarray, np.ndarray]:
    t = np.asarray(t, dtype=float)
    y = np.asarray(y, dtype=float)
    if t.ndim != 1:
        raise ValueError(f"t: expected a 1-D array, got shape {t.shape}")
    if y.shape[:1] != t.shape:
        raise ValueError(f"{name}: expected {t.shape[0]} samples (as t), got shape {y.shape}")
    return t, y


# ---------------------------------------------------------------------------- response metrics
def settling_time(
    t: Sequence[float], y: Sequence[float], t0: float, initial: float, final: float,
    band: float = DEFAULT_BAND,
) -> Optional[float]:
    """
    Time from ``t0`` until ``y`` stays within ``band`` x |final - initial| of ``final``.

    ``t``, ``y``: samples after the step (t > t0), ending where the window ends. None if the
    change is zero or ``y`` is outside the band at the last sample.
    """
    t, y = sample_arrays(t, y)
    change = abs(final - initial)
    if change == 0.0 or t.shape[0] == 0:
        return None
    limit = band * change
    tt = np.concatenate(([t0], t))
    err = np.abs(np.concatenate(([initial], y)) - final)
    outside = np.nonzero(err > limit)[0]
    if outside.shape[0] == 0:
        return 0.0
    k = int(outside[-1])
    if k == tt.shape[0] - 1:
        return None
    e0, e1 = err[k], err[k + 1]
    frac = (e0 - limit) / (e0 - e1) if e0 != e1 else 1.0
    return float(tt[k] + frac * (tt[k + 1] - tt[k]) - t0)


def overshoot(y: Sequence[float], initial: float, final: float) -> float:
    """Largest excursion past ``final`` in the direction of the change, / |change| (>= 0)."""
    y = np.asarray(y, dtype=float)
    change = final - initial
    if change == 0.0 or y.shape[0] == 0:
        return 0.0
    excess = float(np.max((y - final) * math.copysign(1.0, change)))
    return max(0.0, excess) / abs(change)


def crossing_time(
    t: Sequence[float], y: Sequence[float], t0: float, initial: float, level: float
) -> Optional[float]:
    """
    Return the first time the signal reaches ``level``.

    The time is interpolated; the signal starts at ``initial`` at ``t0``.
    """
    t, y = sample_arrays(t, y)
    tt = np.concatenate(([t0], t))
    yy = np.concatenate(([initial], y))
    sign = 1.0 if level >= initial else -1.0
    reached = np.nonzero((yy - level) * sign >= 0.0)[0]
    if reached.shape[0] == 0:
        return None
    k = int(reached[0])
    if k == 0:
        return float(t0)
    y0, y1 = yy[k - 1], yy[k]
    frac = (level - y0) / (y1 - y0) if y1 != y0 else 1.0
    return float(tt[k - 1] + frac * (tt[k] - tt[k - 1]))


def rise_time(
    t: Sequence[float], y: Sequence[float], t0: float, initial: float, final: float,
    low: float = 0.1, high: float = 0.9,
) -> Optional[float]:
    """Time from ``low`` to ``high`` of the change (10 % to 90 % by default)."""
    change = final - initial
    if change == 0.0:
        return None
    t_low = crossing_time(t, y, t0, initial, initial + low * change)
    t_high = crossing_time(t, y, t0, initial, initial + high * change)
    if t_low is None or t_high is None:
        return None
    return t_high - t_low


def peak(values: Sequence[float]) -> Optional[float]:
    """Return the signed sample of largest magnitude (None for no samples)."""
    v = np.asarray(values, dtype=float)
    if v.shape[0] == 0:
        return None
    return float(v[int(np.argmax(np.abs(v)))])


def step_response(
    t: Sequence[float], y: Sequence[float], t0: float, initial: float,
    t_end: Optional[float] = None, band: float = DEFAULT_BAND, hold: float = DEFAULT_HOLD,
) -> Response:
    """
    Metrics of ``y`` (samples after the step, t > t0) for a step at ``t0`` from ``initial``.

    The final value is the last sample; ``t_end`` (default: the last sample time) is where
    the window ends, for the settled test.
    """
    t, y = sample_arrays(t, y)
    if t.shape[0] == 0:
        raise ValueError("y: no samples after the step")
    final = float(y[-1])
    t_end = float(t[-1]) if t_end is None else float(t_end)
    ts = settling_time(t, y, t0, initial, final, band)
    window = t_end - t0
    settled = ts is not None and (t_end - (t0 + ts)) >= hold * window - 1e-15 * max(
        1.0, abs(t_end)
    )
    if final == initial:
        settled = bool(np.all(y == final))
    return Response(
        initial=float(initial),
        final=final,
        change=final - float(initial),
        settling_time=ts,
        overshoot=overshoot(y, initial, final),
        rise_time=rise_time(t, y, t0, initial, final),
        peak=float(y[int(np.argmax(np.abs(y - initial)))]),
        settled=settled,
    )
