"""
What a sweep computes for each design: the output registry and the batch evaluation.

Every output is one small function of a ``Design`` (the mechanism of one sample with its
simulation and lazily computed, shared results), registered with ``@output``. Adding one
(first natural frequency, damping ratio, peak stress ratio, ...) is one function here.

With several drives (docs/sweeps.md, "Several drives") an output declared ``per`` drive,
output or (output, drive) pair gives a column each, ``<name>.<drive>``, ``<name>.<output>``
or ``<name>.<output>.<drive>`` (``columns``), and its function returns their values in that
order; with one drive every output is one column, named as the output.

``evaluate_batch`` is the task the runner sends to workers: it needs nothing but the study,
builds each design's mechanism from the study's parsed base document (only the containers
along the changed paths are copied) and never raises for a design that fails: the row gets
status ``failed`` and the error, and the batch goes on.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Optional, Sequence, Union

import numpy as np

from flexure_sim.engine.analysis import linear, spatial_linear
from flexure_sim.engine.mechanism.parts import Mechanism
from flexure_sim.engine.solver.simulation import Simulation, StaticResult
from flexure_sim.engine.solver.spatial_simulation import SpatialSimulation
from flexure_sim.engine.hinges import fatigue
from flexure_sim.engine.hinges.stress import peak_ratio, stress_table, stroke_limit
from flexure_sim.engine.analysis.study import Study
from flexure_sim.tools.run import response_metrics
from flexure_sim.tools.run.run_channels import gain_unit

#: What an output's function returns: one value, or one per column with several drives.
Values = Union[Optional[float], Sequence[Optional[float]]]


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
        #: ``space: 3d``: the spatial engine (``SpatialSimulation``) builds every result.
        self.spatial = study.space == "3d"
        self.sim = (SpatialSimulation(mechanism, dt=study.step["dt"]) if self.spatial
                    else Simulation(mechanism, dt=study.step["dt"]))
        drives = mechanism.drives
        if not drives:
            raise ValueError(f"mechanism {mechanism.name!r} has no drive")
        #: Several drives: the outputs declared per drive/output give a column each.
        self.several = len(drives) > 1
        #: Drive input: the study's, else every drive's full stroke (stroke max); a number
        #: (m, or the drive's unit) for one drive, {drive name: value} for several.
        self.input = study.input
        if self.input is None:
            self.input = ({d.name: d.stroke[1] for d in drives} if self.several
                          else drives[0].stroke[1])
        self._static: Optional[StaticResult] = None
        self._step = None
        self._modes: Optional[linear.Modes] = None
        self._linear: Optional[spatial_linear.SpatialLinearModel] = None
        self._rest: Optional[StaticResult] = None
        self._fatigue: Optional[dict] = None

    def static(self) -> StaticResult:
        """Return static equilibrium at the study's drive input (its ``snapshot`` in 3-D)."""
        if self._static is None:
            self._static = (SpatialStatic.at(self.sim, self.input) if self.spatial
                            else self.sim.static(self.input))
        return self._static

    def rest(self) -> StaticResult:
        """Return the static equilibrium with every drive at 0: the fatigue cycle's start."""
        if self._rest is None:
            zero = ({d.name: 0.0 for d in self.mechanism.drives} if self.several else 0.0)
            self._rest = self.sim.static(zero)
        return self._rest

    def fatigue(self) -> dict:
        """Return the fatigue of cycling every drive between 0 and the input (fatigue.between)."""
        if self._fatigue is None:
            self._fatigue = fatigue.between(self.mechanism, self.rest().snapshot.wrenches,
                                            self.static().snapshot.wrenches)
        return self._fatigue

    def modes(self) -> linear.Modes:
        """
        Return the undamped modes and damped poles about the static equilibrium at the input.

        As ``flexure-sim modes --input`` computes them (engine/analysis/linear.py).
        """
        if self._modes is None and self.spatial:
            model = self.sim.model
            self._linear = spatial_linear.linearize(model, model.drive_inputs(self.input),
                                                    wrenches=False)
            self._modes = spatial_linear.modes(self._linear)
        elif self._modes is None:
            self._modes = linear.modes(linear.linearize(self.sim, self.input, wrenches=False,
                                                        static=self.static()))
        return self._modes

    def step_response(self):
        """
        Output response to a step of the command from 0 to the input.

        The step starts from rest and runs over the study's ``step.duration`` at ``step.dt``;
        metrics as ``flexure-sim analyse``. With several drives every drive steps together,
        each to its input, and the result is a list: every output's response (mechanism order).
        """
        if self._step is None:
            dt, duration = self.study.step["dt"], self.study.step["duration"]
            n = int(round(duration / dt))
            sim = self.sim  # the static solve leaves its state at rest; this run moves it
            sim.set_command(self.input)
            y = np.empty((n, len(sim.model.outputs)) if self.several else n)
            for k in range(n):
                sim.step()
                y[k] = (sim.model.output_values(sim.state.z) if self.several
                        else output_displacement(sim))
            t = dt * np.arange(1, n + 1)
            band = self.study.step["band"]
            self._step = ([response_metrics.step_response(t, yo, 0.0, 0.0, band=band)
                           for yo in y.T] if self.several
                          else response_metrics.step_response(t, y, 0.0, 0.0, band=band))
        return self._step


def output_displacement(sim) -> float:
    """
    Output body's displacement from rest along the output axis (m), planar or spatial.

    It is that of the current state (Snapshot.output without the rest of the snapshot, for sampling
    every step).
    """
    value = sim.model.output_displacement(sim.state.z)
    if value is None:
        raise ValueError(f"mechanism {sim.mechanism.name!r} names no output body")
    return value


@dataclass(frozen=True)
class SpatialStatic:
    """The static figures of a 3-D design the outputs read (as ``StaticResult.snapshot``)."""

    snapshot: "SpatialStatic.Figures"

    @dataclass(frozen=True)
    class Figures:
        """output (the first output's displacement), outputs, drive_force(s), compression."""

        output: Optional[float]
        outputs: dict
        drive_force: float
        drive_forces: np.ndarray
        compression: None = None

    @classmethod
    def at(cls, sim: SpatialSimulation, value) -> "SpatialStatic":
        """Return the figures of the static equilibrium at the drive input ``value``."""
        snap = sim.static_snapshot(sim.model.drive_inputs(value))
        first = next(iter(snap.outputs.values()), None)
        return cls(cls.Figures(first, snap.outputs, float(snap.drive_forces[0]),
                               snap.drive_forces))


@dataclass(frozen=True)
class Output:
    """
    A registered output: column ``name``, SI ``unit``, what it is, and its function.

    ``per``: with several drives, a column per ``drive``, ``output`` or ``pair`` (output,
    drive), or one column (""); ``each_unit``: then the unit of each column, a template of
    ``{drive}`` (the drive's input unit), ``{force}`` (its force unit), ``{output}`` (the
    output's unit) and ``{gain}`` (output per unit of the drive's input). ``nan_means``: what a
    NaN (or None) of this output says, if it is one of its values (``settling_time``: not
    settled); otherwise a design whose output is NaN is recorded as failed, with the reason.
    """

    name: str
    unit: str
    description: str
    compute: Callable[[Design], Values]
    per: str = ""
    each_unit: str = ""
    nan_means: str = ""


@dataclass(frozen=True)
class Column:
    """One result column: its name, the output that gives it, and its SI unit."""

    name: str
    output: str
    unit: str


#: The outputs a study may ask for, by name (docs/sweeps.md lists them).
OUTPUTS: dict[str, Output] = {}


def output(name: str, unit: str, description: str, per: str = "", each_unit: str = "",
           nan_means: str = ""):
    """
    Register a function of a ``Design`` as a sweep output, an ``Output``.

    It returns a float (None: no value, stored as NaN), or with several drives and ``per`` one
    value per column, in ``columns`` order.
    """
    def register(fn: Callable[[Design], Values]):
        OUTPUTS[name] = Output(name, unit, description, fn, per, each_unit, nan_means)
        return fn
    return register


def columns(study: Study) -> tuple[Column, ...]:
    """
    Return the output columns of ``study``, in order.

    One per output with one drive; with several, one per drive (``<name>.<drive>``), output
    (``<name>.<output>``) or pair (``<name>.<output>.<drive>``, outputs major) of an output
    declared ``per`` them.
    """
    ch, out = study.channels, []
    for name in study.outputs:
        spec = OUTPUTS[name]
        if not ch.several or not spec.per:
            out.append(Column(name, name, spec.unit))
        elif spec.per == "drive":
            out += [Column(f"{name}.{d}", name, spec.each_unit.format(drive=u, force=f))
                    for d, u, f in ch.drives]
        elif spec.per == "output":
            out += [Column(f"{name}.{o}", name, spec.each_unit.format(output=u))
                    for o, u in ch.outputs]
        else:
            out += [Column(f"{name}.{o}.{d}", name, spec.each_unit.format(gain=gain_unit(ou, du)))
                    for o, ou in ch.outputs for d, du, _ in ch.drives]
    return tuple(out)


@output("gain", "", "static output displacement / drive input, at the input; several drives: "
        "each output per unit input of each drive, exact at rest", per="pair", each_unit="{gain}")
def _gain(d: Design) -> Values:
    if d.several:  # the static gain matrix of `flexure-sim simulate --static`, outputs major
        return d.sim.static_gain().ravel()
    out = d.static().snapshot.output
    return None if out is None or d.input == 0.0 else out / d.input


@output("output_displacement", "m", "static output displacement at the input", per="output",
        each_unit="{output}")
def _output_displacement(d: Design) -> Values:
    if d.several:
        outputs = d.static().snapshot.outputs
        return [outputs[o] for o in d.sim.model.output_names]
    return d.static().snapshot.output


@output("compression", "m", "static compression of the compression hinge at the input")
def _compression(d: Design) -> Values:
    return d.static().snapshot.compression


@output("drive_force", "N", "static force of the drive at the input (full stroke by default)",
        per="drive", each_unit="{force}")
def _drive_force(d: Design) -> Values:
    if d.several:  # Model.drive_forces, drive order
        return d.static().snapshot.drive_forces
    return d.static().snapshot.drive_force


@output("first_mode", "Hz", "first undamped natural frequency about the static equilibrium "
        "at the input")
def _first_mode(d: Design) -> Values:
    return float(d.modes().frequencies[0])


@output("first_mode_damping", "", "modal damping ratio of the first mode (as flexure-sim modes)")
def _first_mode_damping(d: Design) -> Values:
    return float(d.modes().modal_damping[0])


@output("first_out_of_plane_mode", "Hz", "lowest natural frequency whose mode moves mostly "
        "out of the plane (z, rx, ry carry over half its kinetic energy; space: 3d)")
def _first_out_of_plane_mode(d: Design) -> Values:
    md = d.modes()
    out = np.flatnonzero(spatial_linear.out_of_plane_shares(d._linear, md) > 0.5)
    return float(md.frequencies[out[0]]) if len(out) else None


@output("peak_stress_ratio", "", "largest hinge stress / yield strength at the input (no "
        "value if no hinge has sigma_y)")
def _peak_stress_ratio(d: Design) -> Values:
    found = peak_ratio(stress_table(d.static().snapshot.wrenches, d.mechanism))
    return None if found is None else found[1]


@output("stroke_limit", "m", "drive input at which the first hinge reaches its yield strength "
        "(flexure-sim simulate --stroke-limit)")
def _stroke_limit(d: Design) -> Values:
    return stroke_limit(d.sim)[0]


@output("fatigue_safety", "", "Goodman safety factor of the critical hinge, the drive cycling "
        "between 0 and the input (engine/hinges/fatigue.py)")
def _fatigue_safety(d: Design) -> Values:
    found = fatigue.critical(d.fatigue(), "goodman")
    return None if found is None else found[1]


@output("fatigue_safety_soderberg", "", "Soderberg safety factor of the critical hinge, the "
        "drive cycling between 0 and the input")
def _fatigue_safety_soderberg(d: Design) -> Values:
    found = fatigue.critical(d.fatigue(), "soderberg")
    return None if found is None else found[1]


@output("infinite_life_stroke", "m", "largest drive input that, cycled from 0, keeps the "
        "critical hinge's Goodman safety factor at 1 or above")
def _infinite_life_stroke(d: Design) -> Values:
    return fatigue.infinite_life_input(d.sim, 0.0, d.input)[0]


@output("settling_time", "s", "2 % settling time of the output after a step to the input",
        per="output", each_unit="s", nan_means="not settled within step.duration")
def _settling_time(d: Design) -> Values:
    if d.several:
        return [r.settling_time for r in d.step_response()]
    return d.step_response().settling_time


@output("overshoot", "", "overshoot of the output after a step to the input (fraction)",
        per="output", each_unit="")
def _overshoot(d: Design) -> Values:
    if d.several:
        return [r.overshoot for r in d.step_response()]
    return d.step_response().overshoot


# ------------------------------------------------------------------------------ batches
#: Status column values.
OK, FAILED = "ok", "failed"


def evaluate_batch(study: Study, start: int, stop: int) -> dict:
    """
    Designs ``start``..``stop - 1`` as columns.

    ``sample`` (int64), one float64 column per parameter and per output column (``columns``;
    NaN where there is no value), ``status`` and ``error``.
    """
    n = stop - start
    table = columns(study)
    names = [c.name for c in table]
    spans = []  # the columns of each output, consecutive
    for name in study.outputs:
        at = [k for k, c in enumerate(table) if c.output == name]
        spans.append((name, slice(at[0], at[-1] + 1)))
    cols: dict = {"sample": np.arange(start, stop, dtype=np.int64)}
    params = np.empty((n, len(study.parameters)))
    outs = np.full((n, len(names)), np.nan)
    status, errors = [OK] * n, [""] * n
    for r, i in enumerate(range(start, stop)):
        params[r] = study.sample(i)
        try:
            design = Design(study.mechanism(params[r]), study)
            for name, where in spans:
                outs[r, where] = _floats(OUTPUTS[name].compute(design), where.stop - where.start)
                if not OUTPUTS[name].nan_means and np.isnan(outs[r, where]).any():
                    bad = [names[k] for k in range(where.start, where.stop)
                           if np.isnan(outs[r, k])]
                    raise FloatingPointError(f"{', '.join(bad)}: no value (NaN)")
        except Exception as exc:  # noqa: BLE001 - a design that fails is recorded, not fatal
            outs[r] = np.nan
            status[r], errors[r] = FAILED, f"{type(exc).__name__}: {exc}"
    for j, p in enumerate(study.parameters):
        cols[p.name] = params[:, j].copy()
    for j, name in enumerate(names):
        cols[name] = outs[:, j].copy()
    cols["status"], cols["error"] = status, errors
    return cols


def _floats(value: Values, size: int) -> np.ndarray:
    """Return an output's value(s) as ``size`` floats, None as NaN."""
    many = value if size > 1 or isinstance(value, (list, tuple, np.ndarray)) else [value]
    out = np.array([np.nan if v is None else float(v) for v in many], dtype=float)
    if out.shape != (size,):
        raise ValueError(f"{len(out)} values for {size} columns")
    return out
