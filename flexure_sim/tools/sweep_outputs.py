"""
What a sweep computes for each design: the output registry and the batch evaluation.

Every output is one small function of a ``Design`` (the mechanism of one sample with its
simulation and lazily computed, shared results), registered with ``@output``. Adding one
(first natural frequency, damping ratio, peak stress ratio, ...) is one function here.

``evaluate_batch`` is the task the runner sends to workers: it needs nothing but the study,
builds each design's mechanism from the study's parsed base document (only the containers
along the changed paths are copied) and never raises for a design that fails: the row gets
status ``failed`` and the error, and the batch goes on.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Optional

import numpy as np

from ..engine import linear
from ..engine.mechanism import Mechanism
from ..engine.solver import Simulation, StaticResult
from ..engine.stress import peak_ratio, stress_table
from ..engine.study import Study
from . import response_metrics


class Design:
    """
    One design.

    Its simulation (one model for the static solve and the dynamic run), the drive input of the
    study, and results computed once and shared by the outputs that need them (the static solve,
    the step response). The static solve starts from the unstressed pose whatever the state, so the
    outputs do not depend on their order.
    """

    def __init__(self, mechanism: Mechanism, study: Study):
        self.mechanism = mechanism
        self.study = study
        self.sim = Simulation(mechanism, dt=study.step["dt"])
        drive = mechanism.drive
        if drive is None:
            raise ValueError(f"mechanism {mechanism.name!r} has no drive")
        #: Drive input (m): the study's, else the drive's full stroke.
        self.input = study.input if study.input is not None else drive.stroke[1]
        self._static: Optional[StaticResult] = None
        self._step: Optional[response_metrics.Response] = None
        self._modes: Optional[linear.Modes] = None

    def static(self) -> StaticResult:
        """Return static equilibrium at the study's drive input."""
        if self._static is None:
            self._static = self.sim.static(self.input)
        return self._static

    def modes(self) -> linear.Modes:
        """
        Return the undamped modes and damped poles about the static equilibrium at the input.

        As ``flexure-sim modes --input`` computes them (engine/linear.py).
        """
        if self._modes is None:
            self._modes = linear.modes(linear.linearize(self.sim, self.input, wrenches=False,
                                                        static=self.static()))
        return self._modes

    def step_response(self) -> response_metrics.Response:
        """
        Output response to a step of the command from 0 to the input.

        The step starts from rest and runs over the study's ``step.duration`` at ``step.dt``;
        metrics as ``flexure-sim analyse``.
        """
        if self._step is None:
            dt, duration = self.study.step["dt"], self.study.step["duration"]
            n = int(round(duration / dt))
            sim = self.sim  # the static solve leaves its state at rest; this run moves it
            sim.set_command(self.input)
            y = np.empty(n)
            for k in range(n):
                sim.step()
                y[k] = output_displacement(sim)
            t = dt * np.arange(1, n + 1)
            self._step = response_metrics.step_response(
                t, y, 0.0, 0.0, band=self.study.step["band"]
            )
        return self._step


def output_displacement(sim: Simulation) -> float:
    """
    Output body's displacement from rest along the output axis (m).

    It is that of the current state (Snapshot.output without the rest of the snapshot, for sampling
    every step).
    """
    mech = sim.mechanism
    if mech.output is None:
        raise ValueError(f"mechanism {mech.name!r} names no output body")
    return float(sim.model.output_displacement(sim.state.z))


@dataclass(frozen=True)
class Output:
    """A registered output: column ``name``, SI ``unit``, what it is, and its function."""

    name: str
    unit: str
    description: str
    compute: Callable[[Design], Optional[float]]


#: The outputs a study may ask for, by name (docs/sweeps.md lists them).
OUTPUTS: dict[str, Output] = {}


def output(name: str, unit: str, description: str):
    """Register ``fn(design) -> float | None`` as an output; None means no value, stored as NaN."""
    def register(fn: Callable[[Design], Optional[float]]):
        OUTPUTS[name] = Output(name, unit, description, fn)
        return fn
    return register


@output("gain", "", "static output displacement / drive input, at the input")
def _gain(d: Design) -> Optional[float]:
    out = d.static().snapshot.output
    return None if out is None or d.input == 0.0 else out / d.input


@output("output_displacement", "m", "static output displacement at the input")
def _output_displacement(d: Design) -> Optional[float]:
    return d.static().snapshot.output


@output("compression", "m", "static compression of the compression hinge at the input")
def _compression(d: Design) -> Optional[float]:
    return d.static().snapshot.compression


@output("drive_force", "N", "static force of the drive at the input (full stroke by default)")
def _drive_force(d: Design) -> Optional[float]:
    return d.static().snapshot.drive_force


@output("first_mode", "Hz", "first undamped natural frequency about the static equilibrium "
        "at the input")
def _first_mode(d: Design) -> Optional[float]:
    return float(d.modes().frequencies[0])


@output("first_mode_damping", "", "modal damping ratio of the first mode (as flexure-sim modes)")
def _first_mode_damping(d: Design) -> Optional[float]:
    return float(d.modes().modal_damping[0])


@output("peak_stress_ratio", "", "largest hinge stress / yield strength at the input (no "
        "value if no hinge has sigma_y)")
def _peak_stress_ratio(d: Design) -> Optional[float]:
    found = peak_ratio(stress_table(d.static().snapshot.wrenches, d.mechanism))
    return None if found is None else found[1]


@output("settling_time", "s", "2 % settling time of the output after a step to the input")
def _settling_time(d: Design) -> Optional[float]:
    return d.step_response().settling_time


@output("overshoot", "", "overshoot of the output after a step to the input (fraction)")
def _overshoot(d: Design) -> Optional[float]:
    return d.step_response().overshoot


# ------------------------------------------------------------------------------ batches
#: Status column values.
OK, FAILED = "ok", "failed"


def evaluate_batch(study: Study, start: int, stop: int) -> dict:
    """
    Designs ``start``..``stop - 1`` as columns.

    ``sample`` (int64), one float64 column per parameter and per output (NaN where there is no
    value), ``status`` and ``error``.
    """
    n = stop - start
    cols: dict = {"sample": np.arange(start, stop, dtype=np.int64)}
    params = np.empty((n, len(study.parameters)))
    outs = np.full((n, len(study.outputs)), np.nan)
    status, errors = [OK] * n, [""] * n
    for r, i in enumerate(range(start, stop)):
        params[r] = study.sample(i)
        try:
            design = Design(study.mechanism(params[r]), study)
            for j, name in enumerate(study.outputs):
                value = OUTPUTS[name].compute(design)
                outs[r, j] = np.nan if value is None else float(value)
        except Exception as exc:  # noqa: BLE001 - a design that fails is recorded, not fatal
            outs[r] = np.nan
            status[r], errors[r] = FAILED, f"{type(exc).__name__}: {exc}"
    for j, p in enumerate(study.parameters):
        cols[p.name] = params[:, j].copy()
    for j, name in enumerate(study.outputs):
        cols[name] = outs[:, j].copy()
    cols["status"], cols["error"] = status, errors
    return cols
