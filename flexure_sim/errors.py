"""
The root of the package's exceptions: catch `FlexureSimError` to catch them all.

Every error flexure_sim raises on purpose derives from `FlexureSimError`. Each keeps the
built-in base it had before (``ValueError`` for bad input, ``RuntimeError`` for failures at
run time, ``Exception`` for the recording layer), so ``except ValueError`` callers still work::

    from flexure_sim.errors import FlexureSimError
    try:
        sim = Simulation(load_mechanism(path))
    except FlexureSimError as exc:    # ConfigError, SolverError, RecordingError, ...
        print(f"error: {exc}")

The classes live with the code that raises them (``engine.config.ConfigError``,
``engine.solver.SolverError``, ``recording.errors.RecordingError``, ...). This module imports
nothing from the package, so any layer (the engine included) may import it.
"""

from __future__ import annotations

from typing import Any, Sequence

import numpy as np


class FlexureSimError(Exception):
    """Base class of every error raised on purpose by flexure_sim."""


def as_array(name: str, value, shape: Sequence[int | None], dtype=float) -> np.ndarray:
    """
    ``value`` as an array of ``shape`` (None: any length), or a ValueError naming ``name``.

    Public functions check their arguments with this instead of letting NumPy's reshape or
    broadcasting errors (which name neither the argument nor the expected shape) escape.
    """
    want = _shape_text(shape)
    try:
        array = np.asarray(value, dtype=dtype)
    except (TypeError, ValueError):
        raise ValueError(f"{name}: expected {want}, got {shown(value)}") from None
    if array.ndim != len(shape) or any(
        n is not None and have != n for have, n in zip(array.shape, shape)
    ):
        raise ValueError(f"{name}: expected {want}, got shape {array.shape}")
    return array


def _shape_text(shape: Sequence[int | None]) -> str:
    if not shape:
        return "a single number"
    dims = ["n" if d is None else str(d) for d in shape]
    return "shape (" + ", ".join(dims) + ("," if len(dims) == 1 else "") + ")"


def shown(value: Any, limit: int = 60) -> str:
    """Return the repr of a value a user gave, shortened so that a message stays one line."""
    text = repr(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."
