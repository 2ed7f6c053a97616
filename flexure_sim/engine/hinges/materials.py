"""
Materials by name: the shipped table (materials.yaml), lookup, and a hinge's strengths.

A stiffness model of a mechanism file may name its material (``material: 7075-T6``) instead of
giving E and nu; the material also supplies the strengths the stress and fatigue analyses need:
yield ``sigma_y``, ultimate ``sigma_u`` and the fully reversed fatigue strength ``sigma_e`` at
``fatigue_cycles`` cycles. A number the model gives itself overrides the material's (the stage
keeps the dissertation's E = 69 GPa with the strengths of 6061-T6). Without a material and
without these numbers a hinge has no strength, and every analysis that needs one says which key
to add (``missing_strength``): there is no default material.

The table is package data next to this module (``materials.yaml``), read with importlib.resources:
one location in a source checkout, a pip install and a colcon install (setup.py's
``package_data``), with no search order to get wrong, and always the table of the code that
reads it. Every value carries its source; the loader refuses one without.

``resolve`` is the one place where a stiffness specification and its material meet: the loader
(mechanism/stiffness_block.py) and the design parameters (mechanism/parameters.py) both call it,
so a hinge's E, nu, yield and fatigue strength (floats, or hyper-dual where varied) are the
same wherever they are read, for every stiffness model (notch, cantilever, fe).
"""
from __future__ import annotations

import difflib
import math
from dataclasses import dataclass
from functools import lru_cache
from importlib import resources
from typing import Any, Callable, Mapping, Optional

import yaml

from flexure_sim.errors import FlexureSimError

#: Properties of every material in the table, in SI units.
PROPERTIES = ("E", "nu", "density", "sigma_y", "sigma_u", "sigma_e")
#: What a material gives a stiffness model: its elastic constants ...
ELASTIC_KEYS = ("E", "nu")
#: ... and the strengths of the stress and fatigue analyses (Pa; cycles of sigma_e).
STRENGTH_KEYS = ("sigma_y", "sigma_u", "sigma_e", "fatigue_cycles")
TABLE_FILE = "materials.yaml"


class MaterialError(FlexureSimError, ValueError):
    """An unknown material name, or a material table that is not valid (names the problem)."""


@dataclass(frozen=True)
class Material:
    """
    One named material: its ``values`` (PROPERTIES, SI) and the ``source`` of each.

    ``cycles``: the number of cycles its fatigue strength sigma_e holds for.
    """

    name: str
    description: str
    values: Mapping[str, float]
    cycles: float
    sources: Mapping[str, str]

    def __getitem__(self, key: str) -> float:
        return self.values[key]


def _read_table(text: str, origin: str) -> dict[str, Material]:
    """Parse and check a material table (every value positive, finite, with a source)."""
    def fail(key: str, problem: str) -> MaterialError:
        return MaterialError(f"{origin}: {key}: {problem}")

    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        raise MaterialError(f"{origin}: not valid YAML: {exc}") from None
    if not isinstance(data, dict) or not isinstance(data.get("materials"), dict):
        raise fail("materials", "expected a mapping of material names")
    out = {}
    for name, spec in data["materials"].items():
        key = f"materials.{name}"
        if not isinstance(spec, dict):
            raise fail(key, "expected a mapping of properties")
        unknown = sorted(set(spec) - {"description", *PROPERTIES})
        if unknown:
            raise fail(f"{key}.{unknown[0]}", f"unknown property ({', '.join(PROPERTIES)})")
        values, sources, cycles = {}, {}, math.nan
        for prop in PROPERTIES:
            entry = spec.get(prop)
            if not isinstance(entry, dict) or "value" not in entry:
                raise fail(f"{key}.{prop}", "missing: expected {value: ..., source: ...}")
            source = entry.get("source")
            if not isinstance(source, str) or not source.strip():
                raise fail(f"{key}.{prop}.source", "every value needs its source")
            value = _positive(entry["value"], f"{key}.{prop}.value", fail)
            if prop == "nu" and not value < 0.5:
                raise fail(f"{key}.nu.value", f"Poisson's ratio must be below 0.5, got {value}")
            if prop == "sigma_e":
                cycles = _positive(entry.get("cycles"), f"{key}.sigma_e.cycles", fail)
            values[prop], sources[prop] = value, source
        if values["sigma_u"] < values["sigma_y"]:
            raise fail(f"{key}.sigma_u", "ultimate strength below the yield strength")
        out[str(name)] = Material(str(name), str(spec.get("description", "")), values, cycles,
                                  sources)
    return out


def _positive(value: Any, key: str, fail) -> float:
    if isinstance(value, str):
        try:
            value = float(value)  # PyYAML reads 69.0e9 as a string
        except ValueError:
            pass
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not (
            math.isfinite(value) and value > 0):
        raise fail(key, f"expected a positive finite number, got {value!r}")
    return float(value)


@lru_cache(maxsize=1)
def table() -> dict[str, Material]:
    """Return the shipped material table by name (read once)."""
    ref = resources.files(__package__).joinpath(TABLE_FILE)
    origin = f"flexure_sim/engine/hinges/{TABLE_FILE}"
    try:
        text = ref.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise MaterialError(f"{origin}: the material table cannot be read ({exc}): the "
                            "install is incomplete (setup.py installs it as package data)"
                            ) from None
    return _read_table(text, origin)


def names() -> list[str]:
    """Return the names of the shipped materials, in table order."""
    return list(table())


def _normal(name: str) -> str:
    """Return a name for matching: lower case, without spaces, hyphens and underscores."""
    return "".join(ch for ch in name.lower() if ch not in " -_")


def lookup(name: Any) -> Material:
    """Return the material ``name`` (case, spaces and hyphens ignored); MaterialError if none."""
    if not isinstance(name, str) or not name.strip():
        raise MaterialError(f"expected a material name ({', '.join(names())}), got {name!r}")
    by_normal = {_normal(n): m for n, m in table().items()}
    found = by_normal.get(_normal(name))
    if found is None:
        close = difflib.get_close_matches(_normal(name), list(by_normal), n=1, cutoff=0.6)
        hint = f" (did you mean {by_normal[close[0]].name}?)" if close else ""
        raise MaterialError(f"unknown material {name!r}{hint}; the table has "
                            f"{', '.join(names())} (flexure_sim/engine/hinges/{TABLE_FILE}), "
                            "or give E, nu and the strengths as numbers")
    return found


def resolve(spec: Mapping[str, Any],
            fail: Optional[Callable[[str, str], Exception]] = None) -> dict:
    """
    Return a stiffness specification with its material's numbers filled in.

    Where ``spec`` names a ``material``, every key of ELASTIC_KEYS and STRENGTH_KEYS the spec
    does not give itself comes from the material (the spec's own numbers win), and ``material``
    becomes the table's name. ``fail(key, problem)`` builds the error for an unknown name
    (MaterialError without it). A spec without a material is returned as it is (copied).
    """
    out = dict(spec)
    if "material" not in spec:
        return out
    try:
        m = lookup(spec["material"])
    except MaterialError as exc:
        if fail is None:
            raise
        raise fail("material", str(exc)) from None
    out["material"] = m.name
    for key in ELASTIC_KEYS + ("sigma_y", "sigma_u"):
        out.setdefault(key, m[key])
    if "sigma_e" not in spec:  # the table's strength comes with its own cycle count
        out["sigma_e"], out["fatigue_cycles"] = m["sigma_e"], m.cycles
    return out


def strengths(spec: Mapping[str, Any], number: Callable[[str, Any], Any]) -> dict:
    """
    Return a resolved spec's strengths as StressGeometry fields.

    {"sigma_y", "sigma_u", "sigma_e", "cycles", "material"}, None where absent; ``number(key,
    value)`` reads each number (the loader's checked reading, or the parameters' plain one that
    keeps hyper-dual values).
    """
    def get(key):
        return number(key, spec[key]) if key in spec else None

    return {"sigma_y": get("sigma_y"), "sigma_u": get("sigma_u"), "sigma_e": get("sigma_e"),
            "cycles": get("fatigue_cycles"), "material": spec.get("material")}


def missing_strength(what: str, key: str) -> str:
    """
    Return the advice for a hinge without a strength: which key to add where.

    ``what``: "yield strength" or "fatigue strength"; ``key``: the stiffness specification's
    key in the mechanism file (``stiffness_models.notch``).
    """
    numbers = "sigma_y" if what == "yield strength" else "sigma_e, fatigue_cycles and sigma_u"
    where = f"to {key}" if key else "to its stiffness model"
    return (f"no {what}: add material: NAME ({', '.join(names())}) or {numbers} {where}")
