"""
Design parameters of a mechanism file by path, and the Design they build.

``Parameters`` names any numeric key of the mechanism file by its path
(``stiffness_models.notch.h``, ``hinges.a.a.at.0``, ``bodies.body4.mass``) and builds the
``Design`` -- stiffness, damping, hinge frames, masses -- with chosen keys replaced by
(hyper-dual) values.

Values may be floats or HyperDual numbers (kinematics/hyperdual.py); the stiffness formulas of
``hinges/stiffness.py`` are called unchanged with them. ``parametric.forces`` evaluates the
hinge forces of a Design.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, Optional

import numpy as np

from flexure_sim.errors import FlexureSimError
from flexure_sim.engine.kinematics import hyperdual as hd
from flexure_sim.engine.mechanism.loader import (
    ConfigError, mechanism_from_dict, resolve_mechanism_path,
)
from flexure_sim.engine.mechanism.parts import Mechanism
from flexure_sim.engine.hinges import materials
from flexure_sim.engine.hinges.stiffness import MODELS as _MODELS
from flexure_sim.engine.hinges.stress import STRESS_KEYS, StressGeometry
from flexure_sim.engine.mechanism.yaml_files import read_yaml

_LISTS_BY_NAME = ("bodies", "hinges")


class ParameterError(FlexureSimError, ValueError):
    """A parameter path does not name a numeric key the analyses can vary (names it)."""


@dataclass
class Design:
    """
    Per-hinge and per-body numbers, floats or HyperDual (n hinges, N = 3 n_bodies).

    K, B (n, 3, 3): stiffness and damping in the hinge frame; ca, cb (n, 2), phia, phib
    (n,): frame a on body A and frame b on body B; mass (N,): diagonal mass matrix;
    geometry: per hinge its stress.StressGeometry (None without one), built as mechanism/loader.py
    builds Hinge.stress, with the design's (hyper-dual) numbers.
    """

    K: Any
    B: Any
    ca: Any
    cb: Any
    phia: Any
    phib: Any
    mass: Any
    geometry: list


class Parameters:
    """
    A mechanism file's numbers, addressable by path.

    ``design(overrides)`` rebuilds the parametric parts with some of them replaced (hyper-dual or
    float).
    """

    def __init__(self, name_or_path: str | Path, data: Optional[dict] = None):
        """
        From a built-in name or YAML path.

        Or, with ``data``, from a parsed document whose name_or_path is only used in messages.
        """
        source = str(name_or_path)
        if data is None:
            path = resolve_mechanism_path(name_or_path)
            data = read_yaml(path, ConfigError)
            source = str(path)  # files a mechanism refers to are relative to it
        self.path = Path(source)
        self.data = data
        self.mechanism: Mechanism = mechanism_from_dict(data, source=source)

    @property
    def twistor(self) -> np.ndarray:
        """
        Per hinge.

        Twistor law (True) or twist law (False); ParameterError for laws the generic force chain
        does not cover (fitted polynomials).
        """
        return twistor_flags(self.mechanism)

    # ---------------------------------------------------------------- paths
    def _node(self, keys: list[str], data=None):
        node = self.data if data is None else data
        for depth, key in enumerate(keys):
            where = ".".join(keys[: depth + 1])
            if isinstance(node, str) and depth >= 1 and keys[depth - 1] == "stiffness":
                # hinges.<h>.stiffness.<key> of a hinge that names a model: that model's number
                node = (self.data.get("stiffness_models") or {}).get(node, node)
            if isinstance(node, dict):
                if key not in node:
                    raise ParameterError(f"{where}: no such key in the mechanism file")
                node = node[key]
            elif isinstance(node, list):
                if keys[depth - 1] in _LISTS_BY_NAME and depth == 1:
                    found = [x for x in node if isinstance(x, dict) and x.get("name") == key]
                    if not found:
                        raise ParameterError(f"{where}: no entry named {key!r}")
                    node = found[0]
                else:
                    try:
                        node = node[int(key)]
                    except (ValueError, IndexError):
                        raise ParameterError(
                            f"{where}: not an index of a list of {len(node)}"
                        ) from None
            else:
                raise ParameterError(
                    f"{where}: {'.'.join(keys[:depth])} is a number, not a mapping or list"
                )
        return node

    def value(self, path: str) -> float:
        """Return the number at ``path`` (ParameterError if missing or not numeric)."""
        node = self._node(path.split("."))
        try:
            if isinstance(node, bool):
                raise TypeError
            return float(node)
        except (TypeError, ValueError):
            raise ParameterError(f"{path}: not a number ({node!r})") from None

    def check(self, path: str) -> float:
        """Value of a parameter the analyses can vary; ParameterError naming the problem if not."""
        v = self.value(path)
        keys = path.split(".")
        head = keys[0]
        if head == "stiffness_models" and len(keys) >= 3:
            return v
        if head == "bodies" and len(keys) == 3 and keys[2] in ("mass", "inertia"):
            return v
        if head == "hinges" and len(keys) >= 3 and keys[2] in ("a", "b", "stiffness", "damping"):
            return v
        if head == "defaults" and keys[1:] == ["damping", "t_char"]:
            return v
        raise ParameterError(
            f"{path}: not a design parameter the analyses vary (stiffness models, "
            "hinge frames/stiffness/damping, body mass and inertia)"
        )

    # --------------------------------------------------------------- design
    def design(self, overrides: Optional[dict[str, Any]] = None) -> Design:
        """
        Return the Design with the numbers at the given paths replaced.

        The values may be HyperDual.
        """
        overrides = dict(overrides or {})
        for path in overrides:
            self.check(path)
        data = dict(self.data)
        for path in overrides:
            keys = path.split(".")
            if keys[0] == "hinges" and len(keys) >= 4 and keys[2] == "stiffness":
                # one hinge's own copy of a named model, so only that hinge changes
                entry = _writable(data, keys[:2])
                if isinstance(entry.get("stiffness"), str):
                    entry["stiffness"] = dict(data["stiffness_models"][entry["stiffness"]])
        for path, val in overrides.items():
            keys = path.split(".")
            parent = _writable(data, keys[:-1])
            parent[keys[-1] if isinstance(parent, dict) else int(keys[-1])] = val
        mech = self.mechanism
        models = data.get("stiffness_models", {}) or {}
        defaults = data.get("defaults", {}) or {}
        Ks, Bs, geometry, ca, cb, phia, phib = [], [], [], [], [], [], []
        for hinge, spec in zip(mech.hinges, data["hinges"]):
            sspec = spec.get("stiffness")
            sspec = models[sspec] if isinstance(sspec, str) else sspec
            sspec = None if sspec is None else materials.resolve(sspec)  # E, nu, strengths
            K = _stiffness(sspec) if sspec is not None else _law_stiffness(hinge)
            damping = spec.get("damping", defaults.get("damping"))
            B = (
                K * _num(damping["t_char"])
                if "t_char" in damping
                else np.array(_num(damping["B"]), dtype=object)
            )
            Ks.append(K)
            Bs.append(B)
            geometry.append(_stress_geometry(sspec))
            a_at, b_at = _num(spec["a"]["at"]), _num(spec["b"]["at"])
            ca.append(a_at[:2])
            cb.append(b_at[:2])
            phia.append(a_at[2] if len(a_at) > 2 else 0.0)
            phib.append(b_at[2] if len(b_at) > 2 else 0.0)
        mass = []
        for body, loaded in zip(data["bodies"], mech.bodies):
            # a plate of a material (body_block.py): the loaded numbers, not design parameters
            m, inertia = (_num(body.get(k, getattr(loaded, k))) for k in ("mass", "inertia"))
            mass += [m, m, inertia]
        return Design(
            _array(Ks),
            _array(Bs),
            _array(ca),
            _array(cb),
            _array(phia),
            _array(phib),
            _array(mass),
            geometry,
        )


def _writable(data: dict, keys: list):
    """
    Return the container at ``keys`` (names select entries of bodies/hinges).

    After replacing every container on the way by a shallow copy: the document itself stays
    unchanged.
    """
    node = data
    for depth, key in enumerate(keys):
        if isinstance(node, dict):
            ref = key
        elif depth == 1 and keys[0] in _LISTS_BY_NAME:
            ref = next(
                i for i, x in enumerate(node) if isinstance(x, dict) and x.get("name") == key
            )
        else:
            ref = int(key)
        child = node[ref]
        child = (
            dict(child)
            if isinstance(child, dict)
            else (list(child) if isinstance(child, list) else child)
        )
        node[ref] = child
        node = child
    return node


def _num(x):
    """Return a number of the YAML document (PyYAML reads 69.0e9 as a string) or a HyperDual."""
    if isinstance(x, hd.HyperDual):
        return x
    if isinstance(x, (list, tuple)):
        return [_num(v) for v in x]
    return float(x)


def _stiffness(spec: dict):
    model = spec["model"]
    if model in _MODELS:
        fn, names = _MODELS[model]
        return fn(*(_num(spec[n]) for n in names))
    if "K" in spec:
        return np.array(_num(spec["K"]), dtype=object)
    kc = _num(spec.get("Kc", [0.0, 0.0]))
    kt = _num(spec["Kt"])
    return np.array(
        [[spec["Ko"], kc[0], kc[1]], [kc[0], kt[0], 0.0], [kc[1], 0.0, kt[1]]], dtype=object
    )


def _law_stiffness(hinge) -> np.ndarray:
    """
    K (3x3) of a hinge's law.

    The quadratic laws hold it, a fitted polynomial law's is its Hessian at rest (so that a
    mechanism with one still reaches the check that refuses it).
    """
    K = getattr(hinge.law, "K", None)
    return np.asarray(K if K is not None else hinge.law.stiffness_at_rest(), dtype=float)


def _stress_geometry(spec: Optional[dict]) -> Optional[StressGeometry]:
    """Return the StressGeometry of a stiffness specification (mechanism/loader.py's numbers)."""
    if spec is None or spec.get("model") not in STRESS_KEYS:
        return None
    return StressGeometry.of(spec["model"], {k: _num(spec[k]) for k in STRESS_KEYS[spec["model"]]},
                             **materials.strengths(spec, lambda _, v: _num(v)))


def _array(values):
    """Return a float array, or a HyperDual array if any entry is hyper-dual."""
    arr = np.asarray(values, dtype=object) if not isinstance(values, np.ndarray) else values
    if any(isinstance(v, hd.HyperDual) for v in np.asarray(arr, dtype=object).ravel()):
        return hd.from_objects(arr)
    return np.asarray(arr, dtype=float)


# -------------------------------------------------------------------- the forces


def design_of(mechanism: Mechanism) -> Design:
    """Return the Design of a built mechanism (floats: its K, B, frames and masses as loaded)."""
    hinges = mechanism.hinges
    mass = np.array([[b.mass, b.mass, b.inertia] for b in mechanism.bodies], dtype=float).ravel()
    return Design(
        np.array([_law_stiffness(h) for h in hinges], dtype=float),
        np.array([h.law.B for h in hinges], dtype=float),
        np.array([h.a.position for h in hinges], dtype=float),
        np.array([h.b.position for h in hinges], dtype=float),
        np.array([h.a.angle for h in hinges], dtype=float),
        np.array([h.b.angle for h in hinges], dtype=float),
        mass,
        [h.stress for h in hinges],
    )


def twistor_flags(mechanism: Mechanism) -> np.ndarray:
    """
    Per hinge.

    True for the twistor law, False for the twist law (ParameterError for laws this chain does not
    cover).
    """
    for h in mechanism.hinges:
        if not hasattr(h.law, "metric"):
            raise ParameterError(
                f"hinge {h.name!r}: the analyses support the quadratic laws "
                "(twistor, twist), not fitted polynomial laws"
            )
    return np.array([h.law.coordinates == "twistor" for h in mechanism.hinges])


def hinge_indices(mechanism: Mechanism) -> tuple[np.ndarray, np.ndarray]:
    """Body indices (A, B) of every hinge."""
    return (
        np.array([mechanism.body_index(h.a.body) for h in mechanism.hinges]),
        np.array([mechanism.body_index(h.b.body) for h in mechanism.hinges]),
    )
