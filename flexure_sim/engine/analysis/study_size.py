"""
How big a study is: its designs and batches, and the memory its results take.

A study is refused at load when its results cannot fit in memory (``engine/memory.py``), with
the estimate, before any value of a grid is built: ``samples: 1e15``, a ``range`` of 10^9
values or a 10^4 x 10^4 x 10^4 grid are one line each, not a process that grows until it
dies. Nothing else grows with the study: a ``range`` is kept as its three numbers until the
study is known to fit (``Range``), the batches are computed on demand (``Batches``), the
runner keeps a bounded number of tasks in flight and merges the finished batches one at a
time (tools/design/sweep_run.py).

The estimate (``results_bytes``): every value of a result row (sample, parameters, outputs;
float64) held about three times over while the results are merged and summarised (the
merged table, the summary's NumPy copies and masks), plus ~200 B for the row's status and
error, plus ~200 B per batch of bookkeeping.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Iterator, Sequence, overload

import numpy as np

from flexure_sim.engine.memory import too_large

BYTES_PER_VALUE = 24
BYTES_PER_ROW = 200
BYTES_PER_BATCH = 200


@dataclass(frozen=True)
class Range:
    """A grid parameter's ``range: {start, stop, num}`` before its values are built."""

    start: float
    stop: float
    num: int

    def __len__(self) -> int:
        return self.num

    def values(self) -> tuple[float, ...]:
        """Return the ``num`` evenly spaced values from start to stop, both included."""
        return tuple(float(x) for x in np.linspace(self.start, self.stop, self.num))


class Batches(Sequence):
    """The (start, stop) sample ranges of a study's batches, in order, computed on demand."""

    def __init__(self, samples: int, size: int) -> None:
        self.samples, self.size = samples, size

    def __len__(self) -> int:
        return -(-self.samples // self.size)

    @overload
    def __getitem__(self, k: int) -> tuple[int, int]: ...

    @overload
    def __getitem__(self, k: slice) -> list[tuple[int, int]]: ...

    def __getitem__(self, k):
        if isinstance(k, slice):
            return [self[i] for i in range(*k.indices(len(self)))]
        n = len(self)
        if k < 0:
            k += n
        if not 0 <= k < n:
            raise IndexError(f"batch {k} outside 0..{n - 1}")
        start = k * self.size
        return start, min(start + self.size, self.samples)

    def __iter__(self) -> Iterator[tuple[int, int]]:
        return (self[k] for k in range(len(self)))


def results_bytes(designs: int, columns: int, batches: int) -> int:
    """Return the estimated memory (bytes) of a study's results (module doc)."""
    return designs * (BYTES_PER_VALUE * (1 + columns) + BYTES_PER_ROW) + batches * BYTES_PER_BATCH


def columns_bound(study) -> int:
    """
    Return an upper bound of a result row's parameter and output columns.

    With several drives an output has at most a column per (output, drive) pair
    (tools/design/sweep_outputs.py).
    """
    ch = study.channels
    per_output = max(1, len(ch.outputs)) * len(ch.drives) if ch.several else 1
    return len(study.parameters) + per_output * len(study.outputs)


def check_fits(study, fail) -> None:
    """
    Refuse a study whose results cannot fit in memory, naming the key that makes it so.

    ``study``: the ``Study`` as loaded so far (its ranges not yet built, its channels known);
    ``fail(key, problem)`` builds the error.
    """
    sizes = [study.samples] if study.monte_carlo else [len(p.values) for p in study.parameters]
    designs, columns = math.prod(sizes), columns_bound(study)
    batches = -(-designs // study.batch_size)
    reason = too_large(results_bytes(designs, columns, batches))
    if reason is None:
        return
    each = BYTES_PER_VALUE * (1 + columns) + BYTES_PER_ROW
    if study.monte_carlo:
        key, what = "samples", f"{designs} designs"
    else:
        key = "parameters"
        shape = " x ".join(str(n) for n in sizes)
        what = (f"a grid of {shape} = {designs} designs" if len(sizes) > 1
                else f"a grid of {designs} designs")
    raise fail(key, f"{what}: their results would need {reason} (about {each} B a design, "
               f"{columns} columns, and {batches} batches); make the study smaller or split it")


def built(parameters) -> tuple:
    """Return the parameters with each ``Range`` replaced by its values (the study fits)."""
    return tuple(replace(p, values=p.values.values()) if isinstance(p.values, Range) else p
                 for p in parameters)
