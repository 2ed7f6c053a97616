"""
``flexure-sim simulate``'s hinge limits: stresses, the fatigue of a static cycle, the stroke limit.

The figures (``engine/hinges/stress.py``, ``engine/hinges/fatigue.py``) as the command's JSON,
and their lines of its table. ``usage_error``: the command's exception class for bad input.
"""
from __future__ import annotations

from typing import Optional

import numpy as np

from flexure_sim.engine.hinges import fatigue
from flexure_sim.engine.hinges.stress import no_yield_advice, stress_table
from flexure_sim.engine.hinges.stress import stroke_limit as yield_input
from flexure_sim.engine.mechanism.loader import resolve_mechanism_path
from flexure_sim.engine.solver.simulation import Simulation, Snapshot


def static_limits(args, sim: Simulation, snap: Snapshot, amplitude: float,
                  usage_error) -> dict:
    """Return a static run's ``hinge_stress``, ``stress_note`` and ``fatigue`` entries."""
    return {"hinge_stress": stress(sim, snap), "stress_note": no_yield_advice(sim.mechanism),
            "fatigue": fatigue_report(args, sim, amplitude, usage_error)}


def stress(sim: Simulation, snap: Snapshot) -> dict:
    """Peak stress and stress ratio per notch/leaf hinge (engine/hinges/stress.py)."""
    return stress_table(snap.wrenches, sim.mechanism)


def fatigue_report(args, sim: Simulation, amplitude: float, usage_error) -> Optional[dict]:
    """
    Return the fatigue of cycling the drive between --cycle-from and the static input.

    engine/hinges/fatigue.py; None without a single drive or a cycle (input equal to
    --cycle-from).
    """
    lower = args.cycle_from
    if not np.isfinite(lower):
        raise usage_error(f"--cycle-from {lower!r}: must be a finite drive input")
    if sim.drive is None or amplitude == lower:
        return None
    try:
        return fatigue.static_report(sim, lower, amplitude)
    except ValueError as exc:
        raise usage_error(f"fatigue: {exc}") from None


def stroke_limit(args, sim: Simulation, usage_error) -> dict:
    """--stroke-limit: the drive input at which the first hinge reaches its yield strength."""
    if sim.drive is None:
        names = sim.model.drives.names
        has = (f"{len(names)} drives ({', '.join(names)})" if len(names) > 1 else
               "no drive" if not names else f"the drive {names[0]!r}, not a displacement drive")
        raise usage_error(f"--stroke-limit: mechanism {sim.mechanism.name!r} has {has}: the "
                          "stroke limit is the input of a single displacement drive at which "
                          "the first hinge yields")
    try:
        u, hinge = yield_input(sim)
    except ValueError as exc:
        raise usage_error(f"--stroke-limit: {exc}") from None
    life, note = {}, fatigue.no_fatigue_advice(sim.mechanism)
    if any(h.stress is not None and h.stress.has_fatigue for h in sim.mechanism.hinges):
        for criterion in fatigue.CRITERIA:  # cycling from --cycle-from up to the input found
            point, where = fatigue.infinite_life_input(sim, args.cycle_from, u, criterion)
            life[criterion] = {"input": point, "hinge": where}
    return {"mechanism": sim.mechanism.name, "mechanism_file": str(resolve_mechanism_path(
                args.mechanism)), "mode": "stroke_limit", "stroke_limit": u, "hinge": hinge,
            "actuator_stroke": list(sim.drive.stroke), "cycle_from": args.cycle_from,
            "infinite_life": life, "fatigue_note": note}


def print_stroke_limit(out: dict) -> None:
    """Print ``stroke_limit``'s figures."""
    print(f"mechanism: {out['mechanism']}   stroke limit (first hinge at yield): "
          f"{out['stroke_limit'] * 1e6:.6g} um at hinge {out['hinge']} "
          f"(actuator stroke {out['actuator_stroke'][1] * 1e6:g} um)")
    for criterion, v in out["infinite_life"].items():
        print(f"infinite life ({criterion.capitalize()}, cycling from "
              f"{out['cycle_from'] * 1e6:g} um): up to {v['input'] * 1e6:.6g} um, "
              f"hinge {v['hinge']} first")
    if out["fatigue_note"]:
        print(f"fatigue: {out['fatigue_note']}")


def print_stress(out: dict) -> None:
    """Print a run's hinge stresses and the fatigue of its cycle, where it has them."""
    if out.get("hinge_stress"):
        print("hinge stress:  peak [MPa]  sigma_y [MPa]  ratio")
        for name, h in out["hinge_stress"].items():
            sy = "n/a" if h["sigma_y"] is None else f"{h['sigma_y'] / 1e6:.4g}"
            ratio = "n/a" if h["ratio"] is None else f"{h['ratio']:.4g}"
            print(f"{name:6s} {h['stress'] / 1e6:17.5g} {sy:>14s} {ratio:>6s}")
        if out.get("stress_note"):
            print(f"stress: {out['stress_note']}")
    if out.get("fatigue"):
        print_fatigue(out["fatigue"])


def print_fatigue(f: dict) -> None:
    """Print the fatigue of a static cycle (``fatigue.static_report``)."""
    lo, hi = f["cycle"]
    print(f"fatigue, cycling the drive {lo * 1e6:g} -> {hi * 1e6:g} um (Shigley 6-12; stress of "
          "the hinge's worst fibre):")
    if f["hinges"]:
        print("hinge  amplitude [MPa]  mean [MPa]  Goodman n  Soderberg n  S_e [MPa] at cycles")
    for name, h in f["hinges"].items():
        n = ["inf" if h[c] is None else f"{h[c]:.4g}" for c in ("goodman", "soderberg")]
        print(f"{name:6s} {h['amplitude'] / 1e6:15.5g} {h['mean'] / 1e6:11.5g} {n[0]:>10s} "
              f"{n[1]:>12s} {h['sigma_e'] / 1e6:10.4g} at {h['cycles']:.3g}")
    for criterion, c in f["critical"].items():
        life = f["infinite_life"][criterion]
        if c is not None:
            print(f"critical hinge ({criterion.capitalize()}): {c['hinge']}, n = "
                  f"{c['safety']:.4g}; infinite life up to {life['input'] * 1e6:.6g} um of "
                  f"drive input (hinge {life['hinge']})")
    if f["note"]:
        print(f"fatigue: {f['note']}")
