"""
Study files: design sweeps (a grid) and Monte Carlo tolerance studies of one mechanism.

A study names a base mechanism, parameters addressed by their path in the mechanism's YAML
document, and the outputs wanted (see docs/sweeps.md)::

    mechanism: microstage            # built-in name or path (relative to the study file)
    samples: 10000                   # Monte Carlo only; a grid has as many designs as points
    seed: 20261124                   # Monte Carlo only
    batch_size: 250                  # designs per task (default 100)
    input: 2.0e-6                    # drive input (m) of the static outputs and the step;
                                     # several drives: {x: 1.0e-6, y: 0.0}
                                     # (analysis/study_checks.py)
    outputs: [gain, compression, drive_force]
    space: 3d                        # optional: each design in 3-D (the spatial engine);
                                     # default: the mechanism's own (3d for a space: 3d file)
    step: {duration: 0.05, dt: 1.0e-4, band: 0.02}   # dynamic run of settling_time/overshoot
    parameters:
      - {path: hinges.a.stiffness.h, normal: {std: 5.0e-6}}              # mean: the base value
      - {path: stiffness_models.notch.D, uniform: {low: 2.9e-3, high: 3.1e-3}}
      - {name: hinge_a_x, paths: [hinges.a.a.at.0, hinges.a.b.at.0], offset: true,
         normal: {std: 1.0e-5}}                                           # moves both frames
      # a grid instead: {path: ..., values: [...]} or {path: ..., range: {start, stop, num}}

Paths are dot-separated: mapping keys, list indices, or the ``name`` of an element of a
list of named items (``hinges.a`` is the hinge named a). A path through a hinge's
``stiffness`` that names a shared stiffness model gives that hinge its own copy of the
model, so ``hinges.a.stiffness.h`` changes hinge a only (engine/mechanism/doc_paths.py).

Samples depend on the seed and the sample index only: design i draws its values from
``numpy.random.default_rng(SeedSequence(seed, spawn_key=(i,)))``, so any batching and any
number of workers give the same designs. This module has no scheduler: it describes the
designs; ``flexure_sim.tools.design.sweep`` runs them.
"""
from __future__ import annotations

import hashlib
import json
import math
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Iterable, Optional, Sequence

import numpy as np

from flexure_sim.errors import FlexureSimError
from flexure_sim.engine.mechanism.loader import (
    ConfigError, mechanism_from_dict, resolve_mechanism_path,
)
from flexure_sim.engine.mechanism.doc_paths import apply
from flexure_sim.engine.mechanism.spatial_loader import spatial_from_dict
from flexure_sim.engine.analysis.study_checks import (
    Channels, DriveInput, check_defined, check_outputs, check_space, drive_input,
    number as _number, spec_paths, study_space,
)
from flexure_sim.engine.analysis.study_size import Batches, Range, built, check_fits
from flexure_sim.engine.mechanism.yaml_files import read_yaml

#: Designs per task unless the study says otherwise.
DEFAULT_BATCH_SIZE = 100
#: Column names the runner adds to every row.
RESERVED_COLUMNS = ("sample", "status", "error")
#: Dynamic run of the step-response outputs unless the study says otherwise.
DEFAULT_STEP = {"duration": 0.05, "dt": 1.0e-4, "band": 0.02}

_TOP_KEYS = {"name", "description", "mechanism", "samples", "seed", "batch_size", "input",
             "step", "outputs", "parameters", "space"}
_PARAM_KEYS = {"name", "path", "paths", "offset", "values", "range", "normal", "uniform"}
_SOURCES = ("values", "range", "normal", "uniform")


class StudyError(FlexureSimError, ValueError):
    """A study file is invalid; the message names the file, the key and the problem."""


@dataclass(frozen=True)
class Parameter:
    """
    One varied quantity.

    Its column ``name``, the resolved ``paths`` it sets, their ``base`` values, and where its
    values come from (``kind``: values | normal | uniform). ``offset``: the value is a deviation
    added to each path's base value.
    """

    name: str
    paths: tuple[tuple, ...]
    base: tuple[float, ...]
    through: tuple[Optional[tuple], ...]
    offset: bool
    kind: str
    values: tuple[float, ...] = ()
    loc: float = 0.0    # normal: mean; uniform: low
    scale: float = 0.0  # normal: standard deviation; uniform: high - low


@dataclass(frozen=True)
class Study:
    """
    A validated study: the base mechanism document, parameters, outputs and batching.

    ``input``: the drive input (``study_checks.drive_input``: a number for one drive, a mapping
    drive name -> value for several; None: every drive's full stroke); ``channels``: the base
    mechanism's drives and outputs (the names of the columns per drive or output).
    """

    name: str
    source: str
    mechanism_source: str
    base: dict
    parameters: tuple[Parameter, ...]
    outputs: tuple[str, ...]
    monte_carlo: bool
    samples: int
    seed: Optional[int]
    batch_size: int
    input: Optional[DriveInput]
    step: dict
    channels: Channels = Channels()
    #: Which engine builds and analyses each design: ``2d`` (planar) or ``3d`` (spatial).
    space: str = "2d"

    @property
    def grid_shape(self) -> tuple[int, ...]:
        return tuple(len(p.values) for p in self.parameters)

    def batches(self) -> Batches:
        """(start, stop) sample ranges of the batches, in order (computed on demand)."""
        return Batches(self.samples, self.batch_size)

    def sample(self, index: int) -> np.ndarray:
        """Parameter values of design ``index`` (column order of ``parameters``)."""
        if not 0 <= index < self.samples:
            raise IndexError(f"sample {index} outside 0..{self.samples - 1}")
        if not self.monte_carlo:
            point = np.unravel_index(index, self.grid_shape)
            return np.array([p.values[k] for p, k in zip(self.parameters, point)])
        rng = np.random.default_rng(np.random.SeedSequence(self.seed, spawn_key=(index,)))
        out = np.empty(len(self.parameters))
        for j, p in enumerate(self.parameters):
            if p.kind == "normal":
                out[j] = p.loc + p.scale * rng.standard_normal()
            else:
                out[j] = p.loc + p.scale * rng.random()
        return out

    def design(self, values: Sequence[float]) -> dict:
        """Return the base document with the parameter values applied (the base is not changed)."""
        return apply(self.base, [
            (path, through, base + float(v) if p.offset else float(v))
            for p, v in zip(self.parameters, values)
            for path, base, through in zip(p.paths, p.base, p.through)])

    def mechanism(self, values: Sequence[float]):
        """
        Build (and validate) the mechanism of one design; ConfigError if it is invalid.

        A planar ``Mechanism``, or with ``space`` 3d a ``spatial_parts.Mechanism`` (a 3-D file,
        or a planar one opened in 3-D with its out-of-plane freedoms).
        """
        if self.space == "3d":
            return spatial_from_dict(self.design(values), source=self.mechanism_source)
        return mechanism_from_dict(self.design(values), source=self.mechanism_source)

    def fingerprint(self) -> str:
        """
        Return a hash of everything that determines the results.

        Used to refuse resuming another study.
        """
        text = json.dumps([self.base, [p.__dict__ for p in self.parameters], self.outputs,
                           self.monte_carlo, self.samples, self.seed, self.batch_size,
                           self.input, self.step], sort_keys=True, default=str)
        return hashlib.sha256(text.encode()).hexdigest()


# ----------------------------------------------------------------------------- loading
def load_study(path: str | Path, output_names: Iterable[str]) -> Study:
    """Read and validate a study file; ``output_names``: the outputs the runner provides."""
    path = Path(path)
    data = _read(path, StudyError)
    return study_from_dict(data, str(path), output_names, base_dir=path.parent)


def study_head(data: Any, source: str, top_keys: set,
               base_dir: Optional[Path]) -> tuple[Any, Path, dict]:
    """
    Check what every study file starts with: a mapping of ``top_keys`` naming its mechanism.

    Returns (fail, the mechanism's path, its parsed document); ``fail(key, problem)`` builds
    the StudyError naming the file and key (sweeps here, optimisation in optimize_study.py).
    """
    def fail(key: str, problem: str) -> StudyError:
        return StudyError(f"{source}: {key}: {problem}")

    if not isinstance(data, dict):
        raise StudyError(f"{source}: the study must be a mapping, got {type(data).__name__}")
    unknown = sorted(set(data) - top_keys)
    if unknown:
        raise fail(unknown[0], f"unknown key (allowed: {', '.join(sorted(top_keys))})")
    if "mechanism" not in data:
        raise fail("mechanism", "missing required key (a built-in name or a YAML path)")
    mech_path, base = _base_mechanism(data["mechanism"], base_dir, fail)
    return fail, mech_path, base


def study_from_dict(data: Any, source: str, output_names: Iterable[str],
                    base_dir: Optional[Path] = None) -> Study:
    """Validate a parsed study document (see the module docstring)."""
    fail, mech_path, base = study_head(data, source, _TOP_KEYS, base_dir)
    outputs = _outputs(data.get("outputs"), set(output_names), fail)
    raw = data.get("parameters")
    if not isinstance(raw, list) or not raw:
        raise fail("parameters", "expected a non-empty list of parameters")
    params = [_parameter(spec, f"parameters[{i}]", base, fail) for i, spec in enumerate(raw)]
    _unique_paths(params, fail)
    _unique_columns(params, outputs, fail)
    kinds = {p.kind == "values" for p in params}
    if len(kinds) > 1:
        raise fail("parameters", "mixes grid values/range with distributions: a study is "
                   "either a grid or a Monte Carlo study")
    monte_carlo = kinds == {False}
    if monte_carlo:
        samples = _count(data, "samples", fail, required=True)
        seed = data.get("seed")
        if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
            raise fail("seed", "a Monte Carlo study needs a non-negative integer seed, "
                       f"got {seed!r}")
    else:
        for key in ("samples", "seed"):
            if key in data:
                raise fail(key, "only for Monte Carlo studies (a grid has one design per point)")
        samples, seed = math.prod(len(p.values) for p in params), None  # exact: no int64
    batch = _count(data, "batch_size", fail, default=DEFAULT_BATCH_SIZE)
    study = Study(
        name=str(data.get("name", Path(source).stem)), source=source,
        mechanism_source=str(mech_path), base=base, parameters=tuple(params),
        outputs=outputs, monte_carlo=monte_carlo, samples=samples, seed=seed,
        batch_size=batch, input=None, step=_step(data.get("step"), fail),
        space=study_space(data.get("space"), base, fail),
    )
    try:
        base_mech = study.mechanism([0.0 if p.offset else p.base[0] for p in params])
    except ConfigError as exc:
        raise fail("mechanism", f"the base mechanism does not load: {exc}") from None
    if not base_mech.drives:  # every output is a response to the drive input
        raise fail("mechanism", f"{base_mech.name!r} has no drive constraint: the outputs are "
                   "responses to the drive input")
    check_space(outputs, study.space, fail)
    check_outputs(outputs, base_mech, fail)
    study = replace(study, channels=Channels.of(base_mech))
    check_fits(study, fail)
    value = drive_input(data.get("input"), base_mech, fail)
    check_defined(outputs, base_mech, value, fail)
    return replace(study, parameters=built(study.parameters), input=value)


def _read(path: Path, error: type[Exception]) -> Any:
    """read_yaml, with a file that is not UTF-8 text refused by name too."""
    try:
        return read_yaml(path, error)
    except UnicodeDecodeError as exc:
        raise error(f"{path}: not a text file ({exc.reason} at byte {exc.start})") from None


def _base_mechanism(ref: Any, base_dir: Optional[Path], fail) -> tuple[Path, dict]:
    if not isinstance(ref, str) or not ref:
        raise fail("mechanism", f"expected a built-in name or a YAML path, got {ref!r}")
    candidate = ref
    if base_dir is not None and (ref.endswith((".yaml", ".yml")) or "/" in ref):
        candidate = str(base_dir / ref) if not Path(ref).is_absolute() else ref
    try:
        path = resolve_mechanism_path(candidate)
        doc = _read(path, ConfigError)
    except ConfigError as exc:
        raise fail("mechanism", str(exc)) from None
    if not isinstance(doc, dict):
        raise fail("mechanism", f"{path}: the document must be a mapping")
    return path, doc


def _outputs(raw: Any, known: set[str], fail) -> tuple[str, ...]:
    if not isinstance(raw, list) or not raw:
        raise fail("outputs", f"expected a non-empty list of outputs ({', '.join(sorted(known))})")
    for i, name in enumerate(raw):
        if name not in known:
            raise fail(f"outputs[{i}]",
                       f"unknown output {name!r} (known: {', '.join(sorted(known))})")
    if len(set(raw)) != len(raw):
        raise fail("outputs", f"lists an output twice: {raw}")
    return tuple(raw)


def _count(data: dict, key: str, fail, required: bool = False, default: int = 0) -> int:
    if key not in data:
        if required:
            raise fail(key, "missing required key (number of designs)")
        return default
    v = data[key]
    if isinstance(v, bool) or not isinstance(v, int) or v < 1:
        raise fail(key, f"expected a positive integer, got {v!r}")
    return v


def _step(raw: Any, fail) -> dict:
    if raw is None:
        return dict(DEFAULT_STEP)
    if not isinstance(raw, dict):
        raise fail("step", f"expected a mapping (duration, dt, band), got {raw!r}")
    unknown = sorted(set(raw) - set(DEFAULT_STEP))
    if unknown:
        raise fail(f"step.{unknown[0]}", "unknown key (allowed: band, dt, duration)")
    out = {k: _number(raw.get(k, v), f"step.{k}", fail, positive=True)
           for k, v in DEFAULT_STEP.items()}
    if out["dt"] > out["duration"]:
        raise fail("step.dt", f"{out['dt']} s is longer than the duration {out['duration']} s")
    return out


def _parameter(spec: Any, key: str, doc: dict, fail) -> Parameter:
    texts, paths, through, bases, offset = spec_paths(
        spec, key, doc, _PARAM_KEYS, "path and values/range/normal/uniform", fail)
    sources = [s for s in _SOURCES if s in spec]
    if len(sources) != 1:
        raise fail(key, f"give exactly one of {', '.join(_SOURCES)} (got {sources or 'none'})")
    name = spec.get("name", ",".join(texts))
    if not isinstance(name, str) or not name:
        raise fail(f"{key}.name", f"expected a non-empty column name, got {name!r}")
    centre = 0.0 if offset else bases[0]
    kind, values, loc, scale = _source(sources[0], spec[sources[0]], f"{key}.{sources[0]}",
                                       centre, fail)
    return Parameter(name, paths, bases, through, offset, kind, values, loc, scale)


def _source(kind: str, raw: Any, key: str, centre: float, fail) -> tuple:
    """(kind, grid values, loc, scale) of a parameter's values or distribution."""
    if kind == "values":
        if not isinstance(raw, list) or not raw:
            raise fail(key, f"expected a non-empty list of numbers, got {raw!r}")
        values = tuple(_number(v, f"{key}[{i}]", fail) for i, v in enumerate(raw))
        return "values", values, 0.0, 0.0
    if not isinstance(raw, dict):
        raise fail(key, f"expected a mapping, got {raw!r}")
    allowed = {"range": {"start", "stop", "num"}, "normal": {"mean", "std"},
               "uniform": {"low", "high", "half_width"}}[kind]
    unknown = sorted(set(raw) - allowed)
    if unknown:
        raise fail(f"{key}.{unknown[0]}", f"unknown key (allowed: {', '.join(sorted(allowed))})")

    def need(name: str) -> Any:
        if name not in raw:
            raise fail(f"{key}.{name}", "missing required key")
        return raw[name]

    if kind == "range":
        num = need("num")
        if isinstance(num, bool) or not isinstance(num, int) or num < 1:
            raise fail(f"{key}.num", f"expected a positive integer, got {num!r}")
        a = _number(need("start"), f"{key}.start", fail)
        b = _number(need("stop"), f"{key}.stop", fail)
        return "values", Range(a, b, num), 0.0, 0.0  # built once the study is known to fit
    if kind == "normal":
        mean = _number(raw.get("mean", centre), f"{key}.mean", fail)
        return "normal", (), mean, _number(need("std"), f"{key}.std", fail, positive=True)
    if "half_width" in raw:
        if "low" in raw or "high" in raw:
            raise fail(f"{key}.half_width", "give low and high, or half_width, not both")
        w = _number(raw["half_width"], f"{key}.half_width", fail, positive=True)
        return "uniform", (), centre - w, 2.0 * w
    low = _number(need("low"), f"{key}.low", fail)
    high = _number(need("high"), f"{key}.high", fail)
    if not low < high:
        raise fail(f"{key}.high", f"must be above low ({low}), got {high}")
    return "uniform", (), low, high - low


def _unique_columns(params: list[Parameter], outputs: tuple[str, ...], fail) -> None:
    seen: dict[str, str] = {c: "a column the runner adds" for c in RESERVED_COLUMNS}
    seen.update({o: "an output" for o in outputs})
    for i, p in enumerate(params):
        if p.name in seen:
            raise fail(f"parameters[{i}].name", f"column {p.name!r} is already {seen[p.name]}")
        split = [o for o in outputs if p.name.startswith(o + ".")]
        if split:  # with several drives, an output has a column per drive or output
            raise fail(f"parameters[{i}].name", f"column {p.name!r} is named like a column of "
                       f"the output {split[0]} ({split[0]}.<name>)")
        seen[p.name] = f"parameters[{i}]"


def _unique_paths(params: list[Parameter], fail) -> None:
    seen: dict[tuple, int] = {}
    for i, p in enumerate(params):
        for path in p.paths:
            if path in seen:
                raise fail(f"parameters[{i}]", f"sets {'.'.join(map(str, path))}, which "
                           f"parameters[{seen[path]}] sets already")
            seen[path] = i
