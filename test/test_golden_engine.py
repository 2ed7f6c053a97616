"""
Golden engine figures: refactors of the engine must not change a result to the bit.

The step response, the static solution, the linear model's modes and the exact design
sensitivities of the stage and of the XY stage are computed and compared with
``data/golden_engine.json`` (written from the code before the work it guards) as float64 hex
strings, bit for bit.

Regenerate (only when a change of the results is intended, and say why in the commit):
``FLEXURE_GOLDEN_WRITE=1 scripts/run_tests.sh test/test_golden_engine.py``.
"""
from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np

from flexure_sim.engine.analysis import linear
from flexure_sim.engine.analysis.sensitivity import sensitivities
from flexure_sim.engine.mechanism.loader import load_mechanism
from flexure_sim.engine.mechanism.parameters import Parameters
from flexure_sim.engine.solver.simulation import Simulation

GOLDEN = Path(__file__).parent / "data" / "golden_engine.json"


def _hex(values) -> list[str]:
    return [float(v).hex() for v in np.ravel(np.asarray(values, dtype=float))]


def _flatten(tree, prefix=""):
    """{path: [hex, ...]} of a nested dict of numbers and arrays."""
    out = {}
    for key, value in tree.items():
        path = f"{prefix}{key}"
        if isinstance(value, dict):
            out.update(_flatten(value, path + "/"))
        else:
            out[path] = _hex(value)
    return out


def engine_figures() -> dict[str, list[str]]:
    figures = {}
    sim = Simulation(load_mechanism("microstage"))
    sim.set_command(1.35e-6)
    sim.step(50)
    snap = sim.snapshot()
    figures["stage/step50"] = {"z": sim.state.z, "v": sim.state.v, "output": snap.output,
                               "wrenches": snap.wrenches, "drive_force": snap.drive_force,
                               "potential": snap.potential_energy, "kinetic": snap.kinetic_energy,
                               "dissipated": snap.dissipated, "work": snap.drive_work}
    static = Simulation(load_mechanism("microstage")).static(1.35e-6)
    figures["stage/static"] = {"z": static.z, "output": static.snapshot.output,
                               "compression": static.snapshot.compression,
                               "wrenches": static.snapshot.wrenches}
    lin = linear.linearize(Simulation(load_mechanism("microstage")), 1.35e-6)
    modes = linear.modes(lin)
    figures["stage/linear"] = {"A": lin.A, "B": lin.B, "C": lin.C, "D": lin.D,
                               "frequencies": modes.frequencies}
    params = Parameters("microstage")
    paths = ["hinges.a.stiffness.h", "hinges.e.stiffness.h", "bodies.body4.mass"]
    res = sensitivities(params, paths, ["gain", "first_mode", "peak_stress"], 2e-6)
    figures["stage/sensitivity"] = {"values": res["values"], "gradient": res["gradient"],
                                    "second": res["second"]}
    xy = Simulation(load_mechanism("xy_stage"))
    xy_static = xy.static(np.array([1e-6, -0.5e-6]))
    figures["xy/static"] = {"z": xy_static.z, "wrenches": xy_static.snapshot.wrenches}
    return _flatten(figures)


def test_engine_figures_are_the_golden_bits():
    got = engine_figures()
    if os.environ.get("FLEXURE_GOLDEN_WRITE") == "1":
        GOLDEN.write_text(json.dumps(got, indent=0, sort_keys=True) + "\n")
    want = json.loads(GOLDEN.read_text())
    differ = sorted(k for k in set(want) | set(got) if want.get(k) != got.get(k))
    worst = {}
    for k in differ:
        if k in want and k in got and len(want[k]) == len(got[k]):
            a = np.array([float.fromhex(x) for x in want[k]])
            b = np.array([float.fromhex(x) for x in got[k]])
            worst[k] = float(np.max(np.abs(a - b) / np.maximum(np.abs(a), 1e-300)))
    assert not differ, f"figures that changed (max relative change): {worst or differ}"
