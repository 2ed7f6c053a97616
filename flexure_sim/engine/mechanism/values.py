"""
Checked reading of values from a mechanism file, with messages that name the file and the key.

`Ctx.fail` builds the one-line ``file: key: problem`` message of every `ConfigError`; the
primitive checks (numbers, vectors, mappings, required and unknown keys, names) are shared by
the mechanism loader (`config`) and other readers of YAML documents.

A number may be a HyperDual (kinematics/hyperdual.py): a design parameter set into the
document by mechanism/parameters.py, seeded for its derivatives. It is checked by its real part
and passed on unchanged, so the loader builds the mechanism of a design -- stiffness, damping,
frames, masses -- with derivative parts, by the same code that builds it from a file.
"""
from __future__ import annotations

import math
from typing import Any, Mapping, cast

import numpy as np

from flexure_sim.errors import FlexureSimError, shown
from flexure_sim.engine.kinematics.hyperdual import HyperDual


class ConfigError(FlexureSimError, ValueError):
    """A mechanism file is invalid; the message names the file, the key and the problem."""


class Ctx:
    """Builds error messages that name the file and the key path."""

    def __init__(self, source: str):
        self.source = source

    def fail(self, key: str, problem: str) -> ConfigError:
        return ConfigError(f"{self.source}: {key}: {problem}")


def number(ctx: Ctx, key: str, value: Any, *, positive=False, nonnegative=False) -> float:
    if isinstance(value, HyperDual) and value.shape == ():  # module docstring
        number(ctx, key, float(value.a.real), positive=positive, nonnegative=nonnegative)
        # The seeded scalar stands for the float through every formula of the build.
        return cast(float, value)
    if isinstance(value, str):
        # PyYAML (YAML 1.1) reads 69.0e9 (no exponent sign) as a string: accept it.
        try:
            value = float(value)
        except ValueError:
            pass
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ctx.fail(key, f"expected a number, got {shown(value)}")
    try:
        v = float(value)
    except OverflowError:  # an integer beyond the double range
        raise ctx.fail(key, f"must be finite, got {shown(value)}") from None
    if not math.isfinite(v):
        raise ctx.fail(key, f"must be finite, got {shown(value)}")
    if positive and v <= 0:
        raise ctx.fail(key, f"must be positive, got {shown(value)}")
    if nonnegative and v < 0:
        raise ctx.fail(key, f"must not be negative, got {shown(value)}")
    return v


def vector(ctx: Ctx, key: str, value: Any, lengths: tuple[int, ...]) -> list[float]:
    if not isinstance(value, (list, tuple)) or len(value) not in lengths:
        want = " or ".join(str(n) for n in lengths)
        raise ctx.fail(key, f"expected a list of {want} numbers, got {shown(value)}")
    return [number(ctx, f"{key}[{i}]", v) for i, v in enumerate(value)]


def mapping(ctx: Ctx, key: str, value: Any) -> dict:
    if not isinstance(value, dict):
        raise ctx.fail(key, f"expected a mapping, got {type(value).__name__}")
    return value


def require(ctx: Ctx, key: str, data: dict, name: str) -> Any:
    if name not in data:
        raise ctx.fail(f"{key}.{name}" if key else name, "missing required key")
    return data[name]


def no_unknown(ctx: Ctx, key: str, data: dict, allowed: set[str]) -> None:
    unknown = sorted(set(data) - allowed, key=str)  # YAML keys need not be strings
    if unknown:
        where = f"{key}.{key_text(unknown[0])}" if key else key_text(unknown[0])
        raise ctx.fail(where, f"unknown key (allowed: {', '.join(sorted(allowed))})")


def key_text(key: Any) -> str:
    """
    Return a mapping key of the file as it appears in a key path.

    The key is quoted unless it is a plain word.
    """
    return key if isinstance(key, str) and key.isidentifier() else shown(key, 30)


def name(ctx: Ctx, key: str, value: Any) -> str:
    if not isinstance(value, str) or not value:
        raise ctx.fail(key, f"expected a non-empty name, got {shown(value)}")
    word = all(ch.isalnum() or ch == "_" for ch in value)
    if not (value.isascii() and value[0].isalpha() and word):
        raise ctx.fail(
            key, f"{shown(value)} is not a valid name (ASCII letters, digits, '_', starting "
            "with a letter;"
            " names become ROS topic and frame names)"
        )
    return value


def body_ref(ctx: Ctx, key: str, spec: dict, by_name: Mapping[str, Any]) -> str:
    """Return the body named by ``spec["body"]``, which must be one of ``by_name``."""
    name = spec.get("body")
    if name is None:
        raise ctx.fail(key, "missing required key")
    if not isinstance(name, str):
        raise ctx.fail(key, f"expected a body name, got {shown(name)}")
    if name not in by_name:
        raise ctx.fail(key, f"unknown body {shown(name)} (bodies: {', '.join(by_name)})")
    return name


def axis(ctx: Ctx, key: str, value: Any) -> tuple[float, float]:
    """Return the unit vector along a non-zero 2-vector ``value``."""
    v = np.array(vector(ctx, key, value, (2,)))
    largest = np.max(np.abs(v))
    if largest == 0:
        raise ctx.fail(key, "axis must not be zero")
    v = v / largest  # first, so that the norm of components near the double range is finite
    v = v / np.linalg.norm(v)
    return float(v[0]), float(v[1])
