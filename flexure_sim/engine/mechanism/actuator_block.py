"""
The ``actuator:`` block of a drive (a piezo stack, engine/actuators/piezo.py), checked.

Part of the loader (`config_constraints`); messages name the file, the key and the problem::

    actuator:
      command: voltage           # voltage (V) | displacement (nominal, m; default)
      v_min: 0.0                 # V (default 0): the voltage of the stroke's minimum
      v_max: 150.0               # V: the voltage of the stroke's maximum; d = stroke / range
      bandwidth: 2000.0          # amplifier -3 dB bandwidth, Hz (default 0: unlimited)
      stiffness: 1.0e8           # stack stiffness k_s, N/m (default: rigid)
      hysteresis: {alpha: 0.3, beta: 0.02, gamma: 0.008}   # Bouc-Wen, beta and gamma in 1/V
      creep: [{ratio: 0.015, tau: 0.1}, {ratio: 0.015, tau: 1.0}]   # Kelvin-Voigt, tau in s
"""
from __future__ import annotations

from typing import Any

from flexure_sim.engine.mechanism.values import Ctx, mapping, no_unknown, number, require, shown
from flexure_sim.engine.actuators.piezo import COMMANDS, CreepElement, PiezoSpec

KEYS = {"command", "v_min", "v_max", "bandwidth", "stiffness", "hysteresis", "creep"}


def actuator_spec(ctx: Ctx, key: str, raw: Any, stroke: tuple[float, float]) -> PiezoSpec:
    """Read the ``actuator:`` block at ``key`` of a drive of ``stroke`` [min, max]."""
    spec = mapping(ctx, key, raw)
    no_unknown(ctx, key, spec, KEYS)
    command = spec.get("command", "displacement")
    if command not in COMMANDS:
        raise ctx.fail(f"{key}.command", f"expected one of {', '.join(COMMANDS)}, "
                       f"got {shown(command)}")
    v_min = number(ctx, f"{key}.v_min", spec.get("v_min", 0.0))
    v_max = number(ctx, f"{key}.v_max", require(ctx, key, spec, "v_max"))
    if not v_max > v_min:
        raise ctx.fail(f"{key}.v_max", f"must be above v_min ({v_min:g} V), got {v_max:g}")
    gain = (stroke[1] - stroke[0]) / (v_max - v_min)
    if not 0 < gain < float("inf"):
        raise ctx.fail(key, f"the nominal gain stroke / (v_max - v_min) = {gain:g} m/V is not "
                       "a positive finite number: check the units")
    values: dict[str, Any] = dict(gain=gain, v_max=v_max, v_min=v_min, s_min=stroke[0],
                                  command=command)
    if "bandwidth" in spec:
        values["bandwidth"] = number(ctx, f"{key}.bandwidth", spec["bandwidth"], nonnegative=True)
    if "stiffness" in spec:
        values["stiffness"] = number(ctx, f"{key}.stiffness", spec["stiffness"], positive=True)
    if "hysteresis" in spec:
        values.update(_hysteresis(ctx, f"{key}.hysteresis", spec["hysteresis"]))
    if "creep" in spec:
        values["creep"] = _creep(ctx, f"{key}.creep", spec["creep"])
    return PiezoSpec(**values)


def _hysteresis(ctx: Ctx, key: str, raw: Any) -> dict[str, float]:
    """
    Bouc-Wen parameters (actuators/piezo.py, P4): alpha >= 0; beta > 0 and |gamma| <= beta.

    The bounds keep h bounded and the loop closed: p = beta + gamma > 0 is the rate at which a
    sweep saturates, m = beta - gamma >= 0 that of the branch before h changes sign.
    """
    spec = mapping(ctx, key, raw)
    no_unknown(ctx, key, spec, {"alpha", "beta", "gamma"})
    alpha = number(ctx, f"{key}.alpha", require(ctx, key, spec, "alpha"), nonnegative=True)
    beta = number(ctx, f"{key}.beta", require(ctx, key, spec, "beta"), positive=True)
    gamma = number(ctx, f"{key}.gamma", spec.get("gamma", 0.0))
    if abs(gamma) > beta:
        raise ctx.fail(f"{key}.gamma", f"must lie within [-beta, beta] = [{-beta:g}, {beta:g}] "
                       f"1/V (a bounded, closed loop), got {gamma:g}")
    return {"alpha": alpha, "beta": beta, "gamma": gamma}


def _creep(ctx: Ctx, key: str, raw: Any) -> tuple[CreepElement, ...]:
    """Kelvin-Voigt elements (actuators/piezo.py, P5): a list of {ratio >= 0, tau > 0 (s)}."""
    if not isinstance(raw, list):
        raise ctx.fail(key, f"expected a list of {{ratio, tau}} elements, got {shown(raw)}")
    out = []
    for i, item in enumerate(raw):
        where = f"{key}[{i}]"
        item = mapping(ctx, where, item)
        no_unknown(ctx, where, item, {"ratio", "tau"})
        out.append(CreepElement(
            number(ctx, f"{where}.ratio", require(ctx, where, item, "ratio"), nonnegative=True),
            number(ctx, f"{where}.tau", require(ctx, where, item, "tau"), positive=True)))
    return tuple(out)
