"""Tolerance table of docs/analyses.md: gain, first mode and peak stress of the stage per
+-10 um of each hinge's neck thickness h, predicted from the exact hyper-dual sensitivities
(second-order Taylor: value + d dh + 1/2 d2 dh^2, the first mode too) next to the
engine re-solving the changed mechanism.

    python scripts/tolerance_table.py [--input U] [--dh DH]
"""

from __future__ import annotations

import argparse
import copy

from flexure_sim.engine.analysis import linear
from flexure_sim.engine.mechanism.parameters import Parameters
from flexure_sim.engine.analysis.sensitivity import sensitivities
from flexure_sim.engine.solver.simulation import Simulation
from flexure_sim.engine.hinges.stress import stress_table


def resolve(params: Parameters, hinge: str, h: float, u: float) -> tuple[float, float, float]:
    """Gain, first mode (Hz), peak stress (Pa) with hinge's h changed, by the engine."""
    data = copy.deepcopy(params.data)
    entry = next(e for e in data["hinges"] if e["name"] == hinge)
    entry["stiffness"] = dict(data["stiffness_models"][entry["stiffness"]], h=h)
    changed = Parameters(f"microstage with hinges.{hinge}.stiffness.h = {h}", data)
    mech = changed.mechanism
    sim = Simulation(mech)
    snap = sim.static(u).snapshot
    table = stress_table(snap.wrenches, mech)
    peak = max(v["stress"] for v in table.values())
    first = linear.modes(linear.linearize(sim, u, wrenches=False)).frequencies[0]
    return snap.output / u, first, peak


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--input", type=float, default=2e-6, help="drive input (m), default 2e-6")
    parser.add_argument("--dh", type=float, default=10e-6, help="change of h (m), default 10e-6")
    args = parser.parse_args()
    params = Parameters("microstage")
    u, dh = args.input, args.dh
    print(
        "| hinge | dh | gain: predicted / re-solved | first mode [Hz]: predicted / re-solved "
        "| peak stress [MPa]: predicted / re-solved |"
    )
    print("| --- | --- | --- | --- | --- |")
    for hinge in "abcdefg":
        path = f"hinges.{hinge}.stiffness.h"
        res = sensitivities(params, [path], ["gain", "first_mode", "peak_stress"], u)
        h0 = params.value(path)
        for sign in (+1, -1):
            d = sign * dh
            pred = []
            for o in ("gain", "first_mode", "peak_stress"):
                v, g = res["values"][o], res["gradient"][o][path]
                pred.append(v + g * d + 0.5 * res["second"][o][f"{path}|{path}"] * d * d)
            gain, first, peak = resolve(params, hinge, h0 + d, u)
            print(
                f"| {hinge} | {d * 1e6:+.0f} um | {pred[0]:.5f} / {gain:.5f} "
                f"| {pred[1]:.3f} / {first:.3f} | {pred[2] / 1e6:.4f} / {peak / 1e6:.4f} |"
            )
    v = res["values"]
    print(
        f"\nat drive input {u * 1e6:g} um; base: gain {v['gain']:.5f}, first mode "
        f"{v['first_mode']:.3f} Hz, peak stress {v['peak_stress'] / 1e6:.4f} MPa"
    )


if __name__ == "__main__":
    main()
