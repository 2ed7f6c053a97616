"""
Design outputs with their exact gradients in the design variables: what the optimiser asks.

The outputs are those of the sweeps (docs/sweeps.md, tools/design/sweep_outputs.py) that have a
derivative, with the same names and definitions, so a design's value here equals the sweep's
column (a test checks it): ``gain`` (one drive: output / input at the input; several: the
static gain matrix at rest, ``gain.<output>.<drive>``), ``output_displacement``,
``compression``, ``drive_force``, ``first_mode``, ``peak_stress_ratio``, ``fatigue_safety``
and ``fatigue_safety_soderberg`` (the drive cycling between ``cycle_from``, default rest, and
the input; engine/hinges/fatigue.py), ``stroke_limit`` and ``infinite_life_stroke``.

Gradients come from the hyper-dual sensitivities (engine/analysis/sensitivity.py), not from
differences: two variables per evaluation, each seeded on its own infinitesimal (p_i + e1,
p_j + e2; a variable setting several paths seeds them all), the equilibria solved by
``Sensitivity.equilibrium`` and the outputs evaluated in hyper-dual arithmetic, so the e1 and
e2 parts are d/dp_i and d/dp_j. Outputs that are an extreme over hinges (the largest stress
ratio, the smallest safety factor) keep every hinge's value and gradient (``Value.parts``): the
extreme has a kink where two hinges tie, the parts are smooth, and the optimiser constrains
the parts. A stroke u*(p) -- where a measure g(u, p) of its critical hinge reaches 1 (the
stress ratio for ``stroke_limit``, the Goodman 1/n for ``infinite_life_stroke``) -- has the
gradient of the implicit function theorem, du*/dp = -g_p / g_u: g_p from the hyper-dual
equilibrium at u*, g_u from the tangent dz/du there (``Sensitivity.tangent``).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Optional, Sequence

import numpy as np

from flexure_sim.engine.analysis.parametric import forces
from flexure_sim.engine.analysis.sensitivity import Sensitivity, gain_keys
from flexure_sim.engine.hinges import fatigue
from flexure_sim.engine.hinges.stress import stroke_limit
from flexure_sim.engine.kinematics import hyperdual as hd
from flexure_sim.engine.mechanism.parameters import Parameters

#: Outputs with exact gradients, by name (with several drives some have a column per drive
#: or output, as in the sweeps).
OUTPUTS = ("gain", "output_displacement", "compression", "drive_force", "first_mode",
           "peak_stress_ratio", "fatigue_safety", "fatigue_safety_soderberg", "stroke_limit",
           "infinite_life_stroke")
#: Outputs that are an extreme of per-hinge parts, and which.
EXTREMES = {"peak_stress_ratio": max, "fatigue_safety": min, "fatigue_safety_soderberg": min}
STROKES = ("stroke_limit", "infinite_life_stroke")


def columns(mech, outputs: Sequence[str]) -> list[str]:
    """Return the columns of ``outputs`` for a mechanism (sweep names; module docstring)."""
    several = len(mech.drives) > 1
    out = []
    for name in outputs:
        if not several or name not in ("gain", "output_displacement", "drive_force"):
            out.append(name)
        elif name == "gain":
            out += gain_keys(mech)
        elif name == "output_displacement":
            out += [f"{name}.{o.name}" for o in mech.all_outputs]
        else:
            out += [f"{name}.{d.name}" for d in mech.drives]
    return out


@dataclass(frozen=True)
class Setup:
    """
    What to evaluate.

    The mechanism file's ``source`` (for messages and relative files), the ``seeds`` of each
    variable (the dotted paths it sets in the document, mechanism/parameters paths), the
    ``outputs`` (names of OUTPUTS), the drive ``input`` (a number, or one value per drive) and
    the fatigue cycle's lower input ``cycle_from``.
    """

    source: str
    seeds: tuple[tuple[str, ...], ...]
    outputs: tuple[str, ...]
    input: Any
    cycle_from: Any = 0.0


@dataclass
class Value:
    """
    One column's value and gradient.

    ``gradient``: per variable, None if not asked; for an extreme over hinges, ``parts``: hinge
    name -> [value, gradient].
    """

    value: float
    gradient: Optional[np.ndarray] = None
    parts: dict = field(default_factory=dict)


class _State:
    """A static equilibrium of the design at one input, ready for hyper-dual evaluation."""

    def __init__(self, params: Parameters, u: Any, static: bool):
        self.sens = Sensitivity(params, u, static_outputs=static)
        self.model = self.sens.sim.model

    def wrench(self, design, z):
        return forces(design, self.sens.twistor, self.sens.ia, self.sens.ib, z).wrench

    def tangent_z(self, design) -> hd.HyperDual:
        """Return z with dz/du of the single drive in its e1 part (real design)."""
        z = hd.HyperDual(self.sens.z)
        w = hd.real(self.sens.tangent(design, z, 0))
        return hd.HyperDual(self.sens.z, w, 0.0, 0.0)


class _Variant:
    """One design (real, or with two variables seeded) and its equilibria, solved on demand."""

    def __init__(self, design, hyper: bool):
        self.design, self.hyper = design, hyper
        self._z: dict[int, Any] = {}

    def z(self, state: _State):
        if id(state) not in self._z:
            self._z[id(state)] = (state.sens.equilibrium(self.design) if self.hyper
                                  else hd.HyperDual(state.sens.z))
        return self._z[id(state)]


class Evaluation:
    """The outputs of one design document (``Setup``), values and on request gradients."""

    def __init__(self, setup: Setup, doc: dict):
        self.setup = setup
        self.params = Parameters(setup.source, data=doc)
        self.mech = self.params.mechanism
        self.several = len(self.mech.drives) > 1
        self.names = [h.name for h in self.mech.hinges]
        self._states: dict = {}
        self.base = self.params.design()
        self.strokes: dict = {}  # name -> (u*, critical hinge, g_u)

    def state(self, key: str) -> _State:
        """Return the equilibrium ``main`` (input), ``rest``, ``lower`` or a stroke's."""
        if key not in self._states:
            s = self.setup
            u = {"main": s.input, "rest": np.zeros(len(self.mech.drives)) if self.several
                 else 0.0, "lower": s.cycle_from}.get(key)
            if u is None:
                u = self._stroke(key)[0]
            if key == "lower" and np.array_equal(np.asarray(u, dtype=float),
                                                 np.zeros(np.shape(u))):
                self._states[key] = self.state("rest")
            else:
                self._states[key] = _State(self.params, u, static=key == "main")
        return self._states[key]

    def _stroke(self, name: str) -> tuple:
        if name not in self.strokes:
            sim = self.state("main").sens.sim
            if name == "stroke_limit":
                u, hinge = stroke_limit(sim)
            else:
                u, hinge = fatigue.infinite_life_input(sim, self.setup.cycle_from,
                                                       self.setup.input)
            self.strokes[name] = [u, hinge, None]
        return self.strokes[name]

    # ------------------------------------------------------------------ per output
    def compute(self, v: _Variant, name: str) -> dict:
        """Return {column: hyper-dual value, or {hinge: value} for an extreme}."""
        main = self.state("main")
        if name == "gain" and self.several:
            rest = self.state("rest")
            return rest.sens.outputs(v.design, v.z(rest), gain_keys(self.mech))
        if name in ("compression", "first_mode"):
            return main.sens.outputs(v.design, v.z(main), [name])
        if name in ("gain", "output_displacement"):
            # Model.output_displacement / output_values: the outputs' rows times z - z0; one
            # drive: the first output, the gain per unit of its input (as the sweeps)
            dz = v.z(main) - main.sens.sim.z0
            rows = main.model.output_matrix
            if name == "gain":
                return {name: (dz * rows[0]).sum() / float(self.setup.input)}
            cols = columns(self.mech, [name])
            return {c: (dz * row).sum() for c, row in zip(cols, rows)}
        if name == "drive_force":
            return dict(zip(columns(self.mech, [name]), self._drive_forces(v, main)))
        if name == "peak_stress_ratio":
            w = main.wrench(v.design, v.z(main))
            return {name: {self.names[k]: g.stress(w[..., k, :]) / g.sigma_y
                           for k, g in enumerate(v.design.geometry)
                           if g is not None and g.sigma_y is not None}}
        if name in ("fatigue_safety", "fatigue_safety_soderberg"):
            lower = self.state("lower")
            u = self._utilisations(v, v.z(lower), v.z(main), lower, main,
                                   "goodman" if name == "fatigue_safety" else "soderberg")
            return {name: {h: 1.0 / x for h, x in u.items() if hd.real(x) > 0}}
        if name in STROKES:
            return {name: self._stroke_measure(v, name)}
        raise ValueError(f"{name}: no exact gradient (outputs: {', '.join(OUTPUTS)})")

    def _drive_forces(self, v: _Variant, main: _State) -> list:
        """Each drive's force, -D_d^T Q_P (a displacement drive), or its commanded force."""
        model = main.model
        Q = forces(v.design, main.sens.twistor, main.sens.ia, main.sens.ib, v.z(main)).Q
        Q = hd.HyperDual(*(np.asarray(p)[model.part.prescribed] for p in hd.parts_of(Q)))
        inputs = model.drives.inputs(self.setup.input)
        displacement = list(model.drives.displacement)
        out = []
        for d in range(len(model.drives)):
            if d in displacement:
                k = displacement.index(d)
                out.append(-(Q * model.part.D[:, k]).sum())
            else:
                out.append(hd.HyperDual(float(inputs[d])))
        return out

    def _utilisations(self, v: _Variant, z1, z2, s1: _State, s2: _State, criterion: str) -> dict:
        """Per hinge with strengths, its worst point's 1/n for the cycle between z1 and z2."""
        w1, w2 = s1.wrench(v.design, z1), s2.wrench(v.design, z2)
        out = {}
        for k, g in enumerate(v.design.geometry):
            if g is None or not g.has_fatigue:
                continue
            amplitude, mean = fatigue.cycle(g, w1[..., k, :], w2[..., k, :])
            out[self.names[k]] = fatigue.worst(fatigue.utilisations(g, amplitude,
                                                                    mean)[criterion])[0]
        return out

    def _stroke_measure(self, v: _Variant, name: str):
        """Return the stroke's measure g(u*, p) of its critical hinge (module docstring)."""
        u, hinge, _ = self._stroke(name)
        at = self.state(name)
        if name == "stroke_limit":
            k = self.names.index(hinge)
            g = v.design.geometry[k]
            return g.stress(at.wrench(v.design, v.z(at))[..., k, :]) / g.sigma_y
        lower = self.state("lower")
        return self._utilisations(v, v.z(lower), v.z(at), lower, at, "goodman")[hinge]

    def _stroke_slope(self, name: str) -> float:
        """g_u: the measure's derivative in the drive input at u*, from the tangent dz/du."""
        u, hinge, _ = self._stroke(name)
        at = self.state(name)
        zu = at.tangent_z(self.base)
        if name == "stroke_limit":
            k = self.names.index(hinge)
            g = self.base.geometry[k]
            ratio = g.stress(at.wrench(self.base, zu)[..., k, :]) / g.sigma_y
            return float(hd.parts_of(ratio)[1])
        lower = self.state("lower")
        z1 = hd.HyperDual(lower.sens.z)
        return float(hd.parts_of(self._utilisations(_Variant(self.base, False), z1, zu, lower,
                                                    at, "goodman")[hinge])[1])

    # ------------------------------------------------------------------ all together
    def run(self, gradients: bool) -> dict[str, Value]:
        """Return every column's Value (gradients in the variables' order if asked)."""
        n = len(self.setup.seeds)
        raw = {}
        base = _Variant(self.base, hyper=False)
        for name in self.setup.outputs:
            raw.update(self.compute(base, name))
        out = {}
        for col, x in raw.items():
            if isinstance(x, dict):
                parts: dict[str, list[Any]] = {
                    h: [float(hd.real(p)), np.zeros(n) if gradients else None]
                    for h, p in x.items()}
                out[col] = Value(EXTREMES[col](p[0] for p in parts.values()) if parts
                                 else float("nan"), np.zeros(n) if gradients else None, parts)
            else:
                value = self.strokes[col][0] if col in STROKES else float(hd.real(x))
                out[col] = Value(float(value), np.zeros(n) if gradients else None)
        if not gradients:
            return out
        for i in range(0, n, 2):
            pair = [i] if i + 1 == n else [i, i + 1]
            variant = _Variant(self._seeded(pair), hyper=True)
            for name in self.setup.outputs:
                for col, x in self.compute(variant, name).items():
                    items = x.items() if isinstance(x, dict) else [(None, x)]
                    for h, val in items:
                        seeded = hd.parts_of(val)
                        target = out[col].gradient if h is None else out[col].parts[h][1]
                        assert target is not None  # gradients asked for: zeros above
                        for slot, k in zip((1, 2), pair):
                            target[k] = float(seeded[slot])
        for col, v in out.items():
            if col in STROKES:
                assert v.gradient is not None  # gradients asked for: zeros above
                v.gradient = -v.gradient / self._stroke_slope(col)
            if v.parts:
                best = min if EXTREMES[col] is min else max
                v.gradient = best(v.parts.values(), key=lambda p: p[0])[1].copy()
        return out

    def _seeded(self, pair: list[int]):
        """Return the design with variable pair[0] on e1 and pair[1] on e2."""
        overrides = {}
        for slot, k in enumerate(pair):
            for path in self.setup.seeds[k]:
                overrides[path] = hd.HyperDual(self.params.value(path), float(slot == 0),
                                               float(slot == 1), 0.0)
        return self.params.design(overrides)
