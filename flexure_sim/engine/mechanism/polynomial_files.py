"""
Polynomial hinge files.

The YAML that ``flexure-sim fit`` writes and a mechanism's ``law: {polynomial: FILE}`` reads, with
validation that names the file, the key and the problem.

The document holds the law of `polynomial.PolynomialLaw` (coordinates, order, scale, energy
scale and the terms), plus informational sections (``stiffness_at_rest``, ``fit``,
``provenance``). Damping is not stored: the mechanism file gives it.
"""
from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from flexure_sim.errors import FlexureSimError, shown
from flexure_sim.engine.laws.polynomial import MAX_ORDER, REST, VARIABLES, PolynomialLaw
from flexure_sim.engine.mechanism.yaml_files import read_yaml

#: Identifies the YAML files written by ``save_law`` (and ``flexure-sim fit``).
FILE_FORMAT = "flexure_sim.polynomial_hinge"
FILE_VERSION = 1


class PolynomialFileError(FlexureSimError, ValueError):
    """A polynomial hinge file is invalid; the message names the file, the key and the problem."""


def law_to_dict(law: PolynomialLaw) -> dict[str, Any]:
    """Return the YAML document of a law (without fit report or provenance)."""
    return {
        "format": FILE_FORMAT,
        "version": FILE_VERSION,
        "coordinates": law.coordinates,
        "variables": list(law.variables),
        "order": law.order,
        "potential": "U = energy * sum(coefficient * prod(((c - rest) / scale) ** exponents))",
        "rest": [float(v) for v in law.rest],
        "scale": [float(v) for v in law.scale],
        "energy": law.energy,
        "terms": [
            {"exponents": [int(v) for v in e], "coefficient": float(a)}
            for e, a in zip(law.exponents, law.coefficients)
        ],
        "stiffness_at_rest": [[float(v) for v in row] for row in law.stiffness_at_rest()],
    }


def save_law(law: PolynomialLaw, path: str | Path, extra: dict[str, Any] | None = None) -> None:
    """Write a law (and optional extra sections, e.g. fit report, provenance) as YAML."""
    doc = law_to_dict(law)
    doc.update(extra or {})
    header = (
        "# Polynomial hinge law for flexure_sim (dissertation 3.6 / 4.7); reference it from a\n"
        "# mechanism as  law: {polynomial: <this file>}.  stiffness_at_rest, fit and provenance\n"
        "# are informational.\n"
    )
    body = yaml.safe_dump(doc, sort_keys=False, default_flow_style=None, width=100)
    Path(path).write_text(header + body)


def law_from_dict(doc: Any, source: str = "<dict>") -> PolynomialLaw:
    """Validate a parsed polynomial hinge document and build the law (damping B = 0)."""

    def fail(key: str, problem: str) -> PolynomialFileError:
        return PolynomialFileError(f"{source}: {key}: {problem}")

    if not isinstance(doc, dict):
        raise PolynomialFileError(
            f"{source}: the document must be a mapping, got {type(doc).__name__}")
    if doc.get("format") != FILE_FORMAT:
        raise fail("format", f"expected {FILE_FORMAT!r} (a file written by flexure-sim fit), "
                   f"got {shown(doc.get('format'))}")
    if doc.get("version") != FILE_VERSION:
        raise fail("version", f"unsupported version {shown(doc.get('version'))} "
                   f"(this flexure_sim reads {FILE_VERSION})")
    coords = doc.get("coordinates")
    if not isinstance(coords, str) or coords not in VARIABLES:
        raise fail("coordinates", f"expected one of {', '.join(VARIABLES)}, got {shown(coords)}")
    names = VARIABLES[coords]
    k = len(names)
    if "variables" in doc and doc["variables"] != list(names):
        raise fail("variables", f"expected {list(names)} for {coords} coordinates, "
                   f"got {shown(doc['variables'])}")
    order = doc.get("order")
    if isinstance(order, bool) or not isinstance(order, int) or not 1 <= order <= MAX_ORDER:
        raise fail("order", f"expected an integer in 1..{MAX_ORDER}, got {shown(order)}")

    def numbers(key: str, value: Any, n: int) -> list[float]:
        if not isinstance(value, list) or len(value) != n:
            raise fail(key, f"expected a list of {n} numbers, got {shown(value)}")
        out = []
        for i, v in enumerate(value):
            out.append(_finite(fail, f"{key}[{i}]", v))
        return out

    if "rest" in doc and not np.array_equal(numbers("rest", doc["rest"], k), REST[coords]):
        raise fail("rest", f"must be {list(REST[coords])}: the polynomial is written about the "
                   "unstressed pose")
    scale = numbers("scale", doc.get("scale"), k)
    for i, s in enumerate(scale):
        if s <= 0:
            raise fail(f"scale[{i}]", f"must be positive, got {s}")
    energy = _finite(fail, "energy", doc.get("energy"))
    if energy <= 0:
        raise fail("energy", f"must be positive, got {energy}")
    terms = doc.get("terms")
    if not isinstance(terms, list) or not terms:
        raise fail("terms", "expected a non-empty list of {exponents: [...], coefficient: number}")
    exps, coefs = [], []
    for i, term in enumerate(terms):
        key = f"terms[{i}]"
        if not isinstance(term, dict) or set(term) != {"exponents", "coefficient"}:
            raise fail(key, "expected a mapping with keys exponents and coefficient, "
                       f"got {shown(term)}")
        e = term["exponents"]
        naturals = isinstance(e, list) and all(
            isinstance(v, int) and not isinstance(v, bool) and v >= 0 for v in e)
        if not naturals or len(e) != k:
            raise fail(f"{key}.exponents",
                       f"expected {k} non-negative integers ({', '.join(names)}), got {shown(e)}")
        if sum(e) > order:
            raise fail(f"{key}.exponents", f"total degree {sum(e)} exceeds the order {order}")
        exps.append(e)
        coefs.append(_finite(fail, f"{key}.coefficient", term["coefficient"]))
    try:
        return PolynomialLaw(coords, order, np.array(exps, dtype=int), np.array(coefs),
                             np.array(scale), energy, source=source)
    except ValueError as exc:
        raise fail("terms", str(exc)) from None


def _finite(fail, key: str, value: Any) -> float:
    if isinstance(value, str):
        try:
            value = float(value)
        except ValueError:
            pass
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise fail(key, f"expected a finite number, got {shown(value)}")
    try:
        number = float(value)
    except OverflowError:  # an integer beyond the double range
        number = math.inf
    if not math.isfinite(number):
        raise fail(key, f"expected a finite number, got {shown(value)}")
    return number


def load_law(path: str | Path) -> PolynomialLaw:
    """Read a polynomial hinge file (as written by ``flexure-sim fit``)."""
    path = Path(path)
    return law_from_dict(read_yaml(path, PolynomialFileError), source=str(path))
