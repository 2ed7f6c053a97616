"""
Design parameters of a mechanism file by path, and the Design they build.

``Parameters`` names any numeric key of the mechanism file by its path
(``stiffness_models.notch.h``, ``hinges.a.a.at.0``, ``bodies.body4.mass``) and builds the
``Design`` -- stiffness, damping, hinge frames, masses -- with chosen keys replaced by
(hyper-dual) values. There is one path from the YAML document to a Design: the values are set
into the parsed document (``doc_paths``: resolve, own stiffness copies, set; as the sweeps
do), the loader builds the mechanism from it (``loader.mechanism_from_dict``, which checks the
real parts and carries HyperDual numbers through the stiffness formulas, damping, frames and
masses, mechanism/values.py), and ``design_of`` reads the Design from that mechanism.
``parametric.forces`` evaluates the hinge forces of a Design.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, Optional

import numpy as np

from flexure_sim.errors import FlexureSimError
from flexure_sim.engine.kinematics import hyperdual as hd
from flexure_sim.engine.mechanism.doc_paths import apply, resolve_path
from flexure_sim.engine.mechanism.loader import load_document, mechanism_from_dict
from flexure_sim.engine.mechanism.parts import Mechanism


class ParameterError(FlexureSimError, ValueError):
    """A parameter path does not name a numeric key the analyses can vary (names it)."""


@dataclass
class Design:
    """
    Per-hinge and per-body numbers, floats or HyperDual (n hinges, N = 3 n_bodies).

    K, B (n, 3, 3): stiffness and damping in the hinge frame; ca, cb (n, 2), phia, phib
    (n,): frame a on body A and frame b on body B; mass (N,): diagonal mass matrix;
    geometry: per hinge its stress.StressGeometry (None without one), as the loader built it.
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

    ``design(overrides)`` builds the Design with some of them replaced (hyper-dual or float).
    """

    def __init__(self, name_or_path: str | Path, data: Optional[dict] = None):
        """
        From a built-in name or YAML path (``loader.load_document``).

        Or, with ``data``, from a parsed document whose name_or_path is only used in messages.
        """
        source = str(name_or_path)
        if data is None:
            data, source = load_document(name_or_path)
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
    def resolve(self, path: str) -> tuple[tuple, Optional[tuple], float]:
        """Return ``doc_paths.resolve_path`` of ``path``; ParameterError naming the problem."""
        def fail(problem: str) -> ParameterError:
            return ParameterError(problem if problem.startswith(path) else f"{path}: {problem}")

        return resolve_path(self.data, path, fail)

    def value(self, path: str) -> float:
        """Return the number at ``path`` (ParameterError if missing or not numeric)."""
        return self.resolve(path)[2]

    def check(self, path: str) -> float:
        """Value of a parameter the analyses can vary; ParameterError naming the problem if not."""
        v = self.value(path)
        keys = path.split(".")
        head = keys[0]
        if keys[-1] == "resolution":
            raise ParameterError(f"{path}: the mesh resolution of a model: fe hinge is not a "
                                 "design parameter")
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

        The values may be HyperDual: the loader builds the mechanism of the changed document
        (module docstring).
        """
        if not overrides:
            return design_of(self.mechanism)
        for path in overrides:
            self.check(path)
        doc = apply(self.data, [self.resolve(path)[:2] + (value,)
                                for path, value in overrides.items()])
        return design_of(mechanism_from_dict(doc, source=str(self.path)))


def _law_stiffness(hinge) -> np.ndarray:
    """
    K (3x3) of a hinge's law.

    The quadratic laws hold it, a fitted polynomial law's is its Hessian at rest (so that a
    mechanism with one still reaches the check that refuses it).
    """
    K = getattr(hinge.law, "K", None)
    return K if K is not None else hinge.law.stiffness_at_rest()


def design_of(mechanism: Mechanism) -> Design:
    """Return the Design of a built mechanism: K, B, frames and masses as the loader built them."""
    hinges = mechanism.hinges
    return Design(
        hd.asarray([_law_stiffness(h) for h in hinges]),
        hd.asarray([h.law.B for h in hinges]),
        hd.asarray([h.a.position for h in hinges]),
        hd.asarray([h.b.position for h in hinges]),
        hd.asarray([h.a.angle for h in hinges]),
        hd.asarray([h.b.angle for h in hinges]),
        hd.asarray([x for b in mechanism.bodies for x in (b.mass, b.mass, b.inertia)]),
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
