"""
Optimisation study files of ``flexure-sim optimize`` (docs/optimization.md), checked on load.

::

    name: stage_first_mode           # optional (default: the file's stem)
    mechanism: microstage            # built-in name, or a YAML path relative to this file
    input: 2.0e-6                    # drive input of the outputs (default: full stroke;
                                     # several drives: {x: ..., y: ...}, as in sweeps)
    cycle_from: 0.0                  # fatigue: the drive cycles between this and `input`
    variables:                       # design variables by path (as sweep parameters)
      - {name: h_c, path: hinges.c.stiffness.h, lower: 1.5e-4, upper: 4.0e-4}
      - {name: h_all, paths: [...], lower: ..., upper: ..., start: ...}   # start: default
                                     # the file's value; offset: true -> a deviation from it
    objective: {maximize: first_mode}          # or {minimize: ...}
    constraints:
      - {output: gain, min: 25.0}
      - {output: peak_stress_ratio, max: 0.3}
    method: SLSQP                    # or trust-constr
    max_iterations: 100
    tolerance: 1.0e-9                # on the KKT conditions of the scaled problem
    starts: 1                        # > 1: multi-start (Sobol points within the bounds)
    seed: 0                          # of the multi-start points

Outputs (objective and constraints) are the columns of engine/analysis/design_outputs.py (the
sweeps' names: ``gain.y.x`` is the XY stage's cross-coupling); outputs without an exact
gradient (settling_time, overshoot, first_mode_damping) are refused by name. Every problem is
one line naming the file, the key and the problem (``StudyError``), before any work.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, Optional

import numpy as np

from flexure_sim.engine.analysis import design_outputs
from flexure_sim.engine.analysis.study import StudyError, _read, study_head
from flexure_sim.engine.analysis.study_checks import (
    check_outputs, drive_input, number, spec_paths,
)
from flexure_sim.engine.mechanism.doc_paths import apply
from flexure_sim.engine.mechanism.loader import ConfigError, mechanism_from_dict
from flexure_sim.engine.mechanism.parameters import ParameterError, Parameters
from flexure_sim.engine.solver.drives import stacked

METHODS = ("SLSQP", "trust-constr")
_TOP_KEYS = {"name", "description", "mechanism", "input", "cycle_from", "variables",
             "objective", "constraints", "method", "max_iterations", "tolerance", "starts",
             "seed"}
_VARIABLE_KEYS = {"name", "path", "paths", "lower", "upper", "start", "offset"}
#: Sweep outputs the optimiser cannot differentiate exactly, and why.
NO_GRADIENT = {"settling_time": "a dynamic run's threshold crossing",
               "overshoot": "a dynamic run's maximum",
               "first_mode_damping": "not differentiated by the sensitivities"}


@dataclass(frozen=True)
class Variable:
    """One design variable: its column ``name``, resolved paths, bounds and start (SI)."""

    name: str
    paths: tuple[tuple, ...]
    through: tuple[Optional[tuple], ...]
    base: tuple[float, ...]
    offset: bool
    lower: float
    upper: float
    start: float


@dataclass(frozen=True)
class Constraint:
    """``output`` (a column) between ``min`` and ``max`` (either may be None)."""

    output: str
    min: Optional[float]
    max: Optional[float]

    def text(self) -> str:
        """Return the constraint as the user reads it (``gain >= 25``)."""
        parts = [f"{self.output} >= {self.min:g}"] if self.min is not None else []
        parts += [f"{self.output} <= {self.max:g}"] if self.max is not None else []
        return " and ".join(parts)


@dataclass(frozen=True)
class OptimizeStudy:
    """A validated optimisation study (module docstring)."""

    name: str
    source: str
    mechanism_source: str
    base: dict
    variables: tuple[Variable, ...]
    sense: str                      # "minimize" | "maximize"
    objective: str                  # a column
    constraints: tuple[Constraint, ...]
    input: Any
    cycle_from: Any
    method: str
    max_iterations: int
    tolerance: float
    starts: int
    seed: int
    setup: design_outputs.Setup

    @property
    def lower(self) -> np.ndarray:
        return np.array([v.lower for v in self.variables])

    @property
    def upper(self) -> np.ndarray:
        return np.array([v.upper for v in self.variables])

    @property
    def start(self) -> np.ndarray:
        return np.array([v.start for v in self.variables])

    def document(self, x) -> dict:
        """Return the mechanism document of design ``x`` (one value per variable, SI)."""
        return apply(self.base, [
            (path, through, base + float(v) if var.offset else float(v))
            for var, v in zip(self.variables, x)
            for path, base, through in zip(var.paths, var.base, var.through)])

    def evaluate(self, x, gradients: bool) -> dict:
        """Return every needed column's design_outputs.Value at design ``x``."""
        return design_outputs.Evaluation(self.setup, self.document(x)).run(gradients)


def load_optimize_study(path: str | Path) -> OptimizeStudy:
    """Read and validate an optimisation study file (module docstring)."""
    path = Path(path)
    return optimize_study_from_dict(_read(path, StudyError), str(path), path.parent)


def optimize_study_from_dict(data: Any, source: str,
                             base_dir: Optional[Path] = None) -> OptimizeStudy:
    """Validate a parsed optimisation study (module docstring)."""
    fail, mech_path, base = study_head(data, source, _TOP_KEYS, base_dir)
    try:
        mech = mechanism_from_dict(base, source=str(mech_path))
        Parameters(str(mech_path), data=base).twistor  # the laws the sensitivities cover
    except (ConfigError, ParameterError) as exc:
        raise fail("mechanism", f"the base mechanism does not load: {exc}") from None
    if not mech.drives:
        raise fail("mechanism", f"{mech.name!r} has no drive constraint: the outputs are "
                   "responses to the drive input")
    stacks = [d.name for d in mech.drives if stacked(d)]
    if stacks:
        raise fail("mechanism", f"drive {stacks[0]} has a piezo stack of finite stiffness: the "
                   "exact sensitivities cover displacement and force drives only")
    u = drive_input(data.get("input"), mech, fail)
    if u is None:
        u = ({d.name: d.stroke[1] for d in mech.drives} if len(mech.drives) > 1
             else mech.drives[0].stroke[1])
    lower = drive_input(data.get("cycle_from", 0.0 if len(mech.drives) == 1 else {
        d.name: 0.0 for d in mech.drives}), mech, lambda k, p: fail("cycle_from" + k[5:], p))
    raw = data.get("variables")
    if not isinstance(raw, list) or not raw:
        raise fail("variables", "expected a non-empty list of design variables")
    variables = [_variable(spec, f"variables[{i}]", base, fail) for i, spec in enumerate(raw)]
    _unique(variables, fail)
    sense, objective = _objective(data.get("objective"), mech, fail)
    constraints = _constraints(data.get("constraints", []), mech, fail)
    used = [objective] + [c.output for c in constraints]
    names = list(dict.fromkeys(c.split(".")[0] for c in used))
    check_outputs(tuple(names), mech, lambda key, problem: fail("objective/constraints",
                                                                problem))
    for name in names:
        if name in ("gain", "output_displacement") and not mech.all_outputs:
            raise fail("objective/constraints", f"{name}: {mech.name!r} names no output")
        if name == "compression" and mech.compression_hinge is None:
            raise fail("objective/constraints", f"compression: {mech.name!r} names no "
                       "compression_hinge")
    method = data.get("method", "SLSQP")
    if method not in METHODS:
        raise fail("method", f"expected one of {', '.join(METHODS)}, got {method!r}")
    seeds = _seeds(variables, base, str(mech_path), fail)
    as_array = (lambda v: np.array([v[d.name] for d in mech.drives]) if isinstance(v, dict)
                else v)
    setup = design_outputs.Setup(str(mech_path), seeds, tuple(names), as_array(u),
                                 as_array(lower))
    return OptimizeStudy(
        name=str(data.get("name", Path(source).stem)), source=source,
        mechanism_source=str(mech_path), base=base, variables=tuple(variables), sense=sense,
        objective=objective, constraints=tuple(constraints), input=u, cycle_from=lower,
        method=method, max_iterations=_count(data, "max_iterations", 100, fail),
        tolerance=number(data.get("tolerance", 1e-9), "tolerance", fail, positive=True),
        starts=_count(data, "starts", 1, fail), seed=_count(data, "seed", 0, fail, zero=True),
        setup=setup)


def _count(data: dict, key: str, default: int, fail, zero: bool = False) -> int:
    v = data.get(key, default)
    if isinstance(v, bool) or not isinstance(v, int) or v < (0 if zero else 1):
        raise fail(key, f"expected a {'non-negative' if zero else 'positive'} integer, "
                   f"got {v!r}")
    return v


def _variable(spec: Any, key: str, doc: dict, fail) -> Variable:
    texts, paths, through, bases, offset = spec_paths(
        spec, key, doc, _VARIABLE_KEYS, "path, lower, upper", fail)
    for bound in ("lower", "upper"):
        if bound not in spec:
            raise fail(f"{key}.{bound}", "missing required key (the variable's bounds)")
    lo = number(spec["lower"], f"{key}.lower", fail)
    hi = number(spec["upper"], f"{key}.upper", fail)
    if not lo < hi:
        raise fail(f"{key}.upper", f"must be above lower ({lo}), got {hi}")
    start = number(spec.get("start", 0.0 if offset else bases[0]), f"{key}.start", fail)
    if not lo <= start <= hi:
        what = "start" if "start" in spec else "the file's value (the default start)"
        raise fail(f"{key}.start", f"{what} {start} is outside [{lo}, {hi}]")
    name = spec.get("name", ",".join(texts))
    if not isinstance(name, str) or not name:
        raise fail(f"{key}.name", f"expected a non-empty name, got {name!r}")
    return Variable(name, paths, through, bases, offset, lo, hi, start)


def _unique(variables: list[Variable], fail) -> None:
    seen: dict = {}
    for i, v in enumerate(variables):
        for path in v.paths:
            if path in seen:
                raise fail(f"variables[{i}]", f"sets {'.'.join(map(str, path))}, which "
                           f"variables[{seen[path]}] sets already")
            seen[path] = i
    names = [v.name for v in variables]
    if len(set(names)) != len(names):
        raise fail("variables", f"two variables have the same name: {names}")


def _column(raw: Any, key: str, mech, fail) -> str:
    """
    Return the column an objective or constraint names.

    An output of one column, or a column; else fail listing them.
    """
    known = design_outputs.columns(mech, design_outputs.OUTPUTS)
    if raw in NO_GRADIENT:
        raise fail(key, f"{raw}: no exact gradient ({NO_GRADIENT[raw]}); the optimiser takes "
                   f"{', '.join(design_outputs.OUTPUTS)}")
    if raw in known:
        return raw
    if isinstance(raw, str) and raw in design_outputs.OUTPUTS:
        cols = design_outputs.columns(mech, [raw])
        raise fail(key, f"{raw} has a column per drive or output with {len(mech.drives)} "
                   f"drives: name one ({', '.join(cols)})")
    raise fail(key, f"unknown output {raw!r} (known: {', '.join(known)})")


def _objective(raw: Any, mech, fail) -> tuple[str, str]:
    if not isinstance(raw, dict) or len(raw) != 1 or next(iter(raw)) not in (
            "minimize", "maximize"):
        raise fail("objective", f"expected {{minimize: OUTPUT}} or {{maximize: OUTPUT}}, "
                   f"got {raw!r}")
    sense, name = next(iter(raw.items()))
    return sense, _column(name, f"objective.{sense}", mech, fail)


def _constraints(raw: Any, mech, fail) -> list[Constraint]:
    if not isinstance(raw, list):
        raise fail("constraints", f"expected a list of {{output, min, max}}, got {raw!r}")
    out = []
    for i, spec in enumerate(raw):
        key = f"constraints[{i}]"
        if not isinstance(spec, dict) or "output" not in spec:
            raise fail(key, f"expected {{output: NAME, min: ..., max: ...}}, got {spec!r}")
        unknown = sorted(set(spec) - {"output", "min", "max"})
        if unknown:
            raise fail(f"{key}.{unknown[0]}", "unknown key (allowed: max, min, output)")
        if "min" not in spec and "max" not in spec:
            raise fail(key, "give min, max or both")
        lo = number(spec["min"], f"{key}.min", fail) if "min" in spec else None
        hi = number(spec["max"], f"{key}.max", fail) if "max" in spec else None
        if lo is not None and hi is not None and not lo <= hi:
            raise fail(f"{key}.max", f"must not be below min ({lo}), got {hi}")
        out.append(Constraint(_column(spec["output"], f"{key}.output", mech, fail), lo, hi))
    return out


def _dotted(doc: dict, steps: tuple) -> str:
    """Return a resolved path as mechanism/parameters.py names it (list items by name)."""
    out, node = [], doc
    for step in steps:
        if isinstance(node, list) and out and out[-1] in ("bodies", "hinges"):
            out.append(str(node[step]["name"]))
        else:
            out.append(str(step))
        node = node[step]
    return ".".join(out)


def _seeds(variables: list[Variable], doc: dict, source: str, fail) -> tuple:
    """
    Return each variable's paths for the sensitivities, in the document of a design.

    A hinge given its own copy of a shared model (by another variable's path through it) no
    longer follows the shared model: a variable of ``stiffness_models.M.k`` also seeds
    ``hinges.X.stiffness.k`` of every such copy of M, unless a variable sets that key.
    """
    own = {through for v in variables for through in v.through if through is not None}
    set_paths = {path for v in variables for path in v.paths}
    design_doc = apply(doc, [(p, t, b) for v in variables
                             for p, t, b in zip(v.paths, v.through, v.base)])
    params = Parameters(source, data=design_doc)
    out = []
    for i, v in enumerate(variables):
        seeds = [_dotted(design_doc, p) for p in v.paths]
        for p in v.paths:
            if p[0] == "stiffness_models":
                for hinge_steps, model in own:
                    copy = tuple(hinge_steps) + tuple(p[2:])
                    if model == p[1] and copy not in set_paths:
                        seeds.append(_dotted(design_doc, copy))
        for s in seeds:
            try:
                params.check(s)
            except ParameterError as exc:
                raise fail(f"variables[{i}]", f"{exc}") from None
        out.append(tuple(dict.fromkeys(seeds)))
    return tuple(out)
