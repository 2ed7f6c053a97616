"""
Several named drives in the stage node (pure Python, no ROS): parameters, validation, filters.

A mechanism with one displacement drive keeps the node's single-drive interface (parameters
``stroke_min``, ``stroke_max``, ``slew_rate``; one `drive_input.CommandFilter`). With several
drives, or a force drive, each drive ``<name>`` has its own parameters
``drives.<name>.stroke_min`` / ``stroke_max`` / ``slew_rate`` (defaults from the mechanism
file; a force drive's in N and N/s, or N m on theta) and its own `CommandFilter`;
`FilterBank` holds them behind the one-filter interface the stepping loop uses, with vectors
(one value per drive, ``drive_names`` order) where a single filter has numbers.
"""
from __future__ import annotations

from dataclasses import replace
from typing import Any, Mapping, Optional, Sequence

import numpy as np

from flexure_sim.node.inputs.command_checks import CommandFilter, DriveLimits, limits_problem
from flexure_sim.node.inputs.drive_kind import command_kind, command_limits, units  # noqa: F401
from flexure_sim.node.params.table import ParamSpec

#: The per-drive limit parameters, as ``drives.<name>.<key>``.
LIMIT_KEYS = ("stroke_min", "stroke_max", "slew_rate")


def named_drives(mechanism: Any) -> tuple:
    """
    Return the drives that get per-drive parameters and topics.

    All of them, unless there is one displacement drive only (the single-drive interface).
    """
    drives = mechanism.drives
    if len(drives) == 1 and drives[0].kind == "displacement":
        return ()
    return drives


def parameter_name(drive: str, key: str) -> str:
    """``drives.<drive>.<key>``."""
    return f"drives.{drive}.{key}"


def drive_parameter_specs(drives: Sequence[Any]) -> list[ParamSpec]:
    """Return the per-drive limit parameters of ``drives`` (none: the single-drive interface)."""
    out = []
    for d in drives:
        unit, rate = units(d)
        what = {"force": "force", "voltage": "actuator voltage"}.get(
            command_kind(d), "actuator stroke")
        lo, hi, slew = command_limits(d)
        out += [
            ParamSpec(parameter_name(d.name, "stroke_min"), lo, float, unit,
                      False, None, None, f"Drive {d.name}: lower end of its {what}; commands "
                      "below it are clamped."),
            ParamSpec(parameter_name(d.name, "stroke_max"), hi, float, unit,
                      False, None, None, f"Drive {d.name}: upper end of its {what}; commands "
                      "above it are clamped."),
            ParamSpec(parameter_name(d.name, "slew_rate"), slew, float, rate,
                      False, 0.0, None, f"Drive {d.name}: speed limit (> 0): its target moves "
                      "towards each new command at most this fast."),
        ]
    return out


def in_command_units(specs: Sequence[ParamSpec], drive: Any) -> list[ParamSpec]:
    """``specs`` with the single-drive limit parameters in ``drive``'s command unit (V, V/s)."""
    unit, rate = units(drive)
    return [replace(s, unit=rate if s.name == "slew_rate" else unit)
            if s.name in LIMIT_KEYS else s for s in specs]


def stroke_ends(mechanism: Any) -> list[tuple[str, Optional[str], str]]:
    """
    Return the stroke-end parameters of a mechanism's drives.

    Each as (parameter, drive name or None for the single-drive ``stroke_min``/``stroke_max``,
    unit), for the engine's static check of a new end (``engine_guard.StrokeProbe``).
    """
    named = named_drives(mechanism)
    if not named:
        return [(k, None, units(d)[0]) for d in mechanism.drives
                for k in ("stroke_max", "stroke_min")]
    return [(parameter_name(d.name, k), d.name, units(d)[0]) for d in named
            for k in ("stroke_max", "stroke_min")]


def drive_limits(values: Mapping[str, Any], drive: str) -> DriveLimits:
    """Return the limits of one named drive from the parameter values."""
    return DriveLimits(*(float(values[parameter_name(drive, k)]) for k in LIMIT_KEYS))


def drives_problem(values: Mapping[str, Any], names: Sequence[str]) -> Optional[str]:
    """Why the per-drive limits in ``values`` are invalid (naming the drive), or None."""
    for name in names:
        problem = limits_problem(*(values[parameter_name(name, k)] for k in LIMIT_KEYS))
        if problem is not None:
            return f"drives.{name}.{problem}"
    return None


class BankCounters:
    """Per-drive command counters, flattened as ``<drive>_<counter>`` (diagnostics)."""

    def __init__(self, bank: "FilterBank") -> None:
        self._bank = bank

    def as_dict(self) -> dict[str, int]:
        out: dict[str, int] = {}
        for name, f in zip(self._bank.names, self._bank.filters):
            out.update({f"{name}_{k}": v for k, v in f.counters.as_dict().items()})
        return out


class FilterBank:
    """
    One `CommandFilter` per named drive, used like one filter with vector targets.

    ``applied``/``target``: one value per drive (``names`` order), for
    ``Simulation.set_command``; ``settled`` when every drive is.
    """

    def __init__(self, names: Sequence[str], limits: Sequence[DriveLimits]) -> None:
        self.names = tuple(names)
        self.filters = [CommandFilter(lim) for lim in limits]
        self.counters = BankCounters(self)
        #: Per drive, whether the last `begin_tick` counted its target as rate-limited.
        self.limited = [False] * len(self.filters)

    def filter(self, name: str) -> CommandFilter:
        return self.filters[self.names.index(name)]

    @property
    def applied(self) -> np.ndarray:
        return np.array([f.applied for f in self.filters])

    @property
    def target(self) -> np.ndarray:
        return np.array([f.target for f in self.filters])

    @property
    def settled(self) -> bool:
        return all(f.settled for f in self.filters)

    def differs(self, command: Any) -> bool:
        """Whether the applied targets are not ``command`` (a vector, or one value for all)."""
        return bool(np.any(np.asarray(command) != self.applied))

    def begin_tick(self, period: float) -> bool:
        """`CommandFilter.begin_tick` per drive; True if any was counted (see ``limited``)."""
        self.limited = [f.begin_tick(period) for f in self.filters]
        return any(self.limited)

    def advance(self, dt: float) -> np.ndarray:
        return np.array([f.advance(dt) for f in self.filters])

    def hold(self, values: Sequence[float]) -> None:
        for f, v in zip(self.filters, values):
            f.hold(v)

    def reset(self) -> None:
        for f in self.filters:
            f.reset()

    def describe(self, values: Sequence[float]) -> str:
        """Per-drive values as text, e.g. ``x 1e-06, y 0``."""
        return ", ".join(f"{n} {v:g}" for n, v in zip(self.names, values))

    def values(self) -> list[tuple[str, float]]:
        """Diagnostics entries: each drive's target and applied target."""
        out = []
        for name, f in zip(self.names, self.filters):
            out += [(f"drive_{name}_target", f.target), (f"drive_{name}_applied", f.applied)]
        return out
