"""
The figures docs/optimization.md quotes, recomputed by running the shipped studies.

Each number is read from the page and must agree with the optimiser or the engine to half a unit
of its last printed digit (as test_analyses_doc.py does for docs/analyses.md).
"""
import re
from pathlib import Path

import pytest

from flexure_sim.engine.analysis import linear
from flexure_sim.engine.analysis.optimize import solve
from flexure_sim.engine.analysis.optimize_study import load_optimize_study
from flexure_sim.engine.hinges import fatigue, stress
from flexure_sim.engine.mechanism.loader import mechanism_from_dict
from flexure_sim.engine.solver.simulation import Simulation
from test_analyses_doc import agrees

ROOT = Path(__file__).resolve().parent.parent
DOC = ROOT / "docs" / "optimization.md"
STUDIES = ROOT / "config" / "studies"


def _text():
    return DOC.read_text(encoding="utf-8").replace("**", "")


def _find(pattern):
    match = re.search(pattern, " ".join(_text().split()))
    assert match, f"docs/optimization.md no longer says {pattern!r}"
    return match.groups()


def _row(first):
    for line in _text().splitlines():
        if line.split() and line.split()[0] == first:
            return line.split()
    raise AssertionError(f"no row {first!r}")


def _figures(study, x):
    """Return the engine's figures of design x (static solve, modes, stress, fatigue)."""
    mech = mechanism_from_dict(study.document(x))
    sim = Simulation(mech)
    static = sim.static(2e-6)
    modes = linear.modes(linear.linearize(sim, 2e-6, wrenches=False, static=static))
    report = fatigue.static_report(sim, 0.0, 2e-6)
    return {"first_mode": modes.frequencies[0], "gain": static.snapshot.output / 2e-6,
            "goodman": report["critical"]["goodman"]["safety"],
            "ratio": stress.peak_ratio(stress.stress_table(static.snapshot.wrenches, mech))[1],
            "life": report["infinite_life"]["goodman"]["input"],
            "limit": stress.stroke_limit(sim)[0], "force": static.snapshot.drive_force}


@pytest.mark.slow
def test_worked_example_figures():
    study = load_optimize_study(STUDIES / "stage_first_mode.yaml")
    r = solve(study)
    assert r.status == "optimal"
    start, end = _find(r"first_mode: ([\d.]+) -> ([\d.]+) Hz")
    agrees(start, r.history[0]["objective"], "start")
    agrees(end, r.objective, "optimum")
    (iterations,) = _find(r"SLSQP converges in (\d+) iterations")
    # the path to the optimum moves with rounding (scipy version, the order of sums): the count
    # within a few iterations; the optimum itself to every printed digit
    assert abs(int(iterations) - r.iterations) <= 5
    for v, x, b in zip(study.variables, r.x, r.bounds):
        row = _row(v.name)
        agrees(row[2], x, v.name)
        assert row[5] == (b["at"] or "-"), v.name
        assert float(row[6]) == pytest.approx(b["multiplier"], rel=1e-3, abs=0.05), v.name
    mult = {c["text"]: c["multiplier"] for c in r.constraints}
    agrees(_find(r"gain >= 26 26 26 yes ([\d.]+)")[0], mult["gain >= 26"], "gain multiplier")
    agrees(_find(r"fatigue_safety >= 4 \[hinge c\] 4 4 yes ([\d.]+)")[0],
           mult["fatigue_safety >= 4 [hinge c]"], "fatigue multiplier")
    before = _figures(study, study.start)
    after = _figures(study, r.x)
    for label, key, scale in (("first mode \\[Hz\\]", "first_mode", 1),
                              ("gain", "gain", 1),
                              ("Goodman safety factor, hinge c \\(critical\\)", "goodman", 1),
                              ("peak stress ratio at 2 µm", "ratio", 1),
                              ("infinite-life stroke \\(Goodman, from 0\\)", "life", 1e6),
                              ("stroke limit \\(yield\\)", "limit", 1e6),
                              ("drive force at 2 µm", "force", 1)):
        a, b = _find(rf"\| {label} \| ([\d.]+)[^|]* \| ([\d.]+)[^|]*\|")
        agrees(a, before[key] * scale, f"{key} as designed")
        agrees(b, after[key] * scale, f"{key} optimised")


@pytest.mark.slow
def test_infeasible_message_and_least_violating_design():
    study = load_optimize_study(STUDIES / "stage_gain_40.yaml")
    r = solve(study)
    assert r.status == "infeasible"
    (quoted,) = _find(r"flexure-sim optimize: infeasible: (no design .*?%\))")
    assert quoted == r.message
    (gain,) = _find(r"c–g at 0.15 mm, gain (\d+\.\d+)")
    agrees(gain, r.values["gain"], "least-violating gain")
    assert list(r.x) == pytest.approx([4e-4, 4e-4] + [1.5e-4] * 5, rel=1e-9)


@pytest.mark.slow
def test_xy_stage_figures():
    study = load_optimize_study(STUDIES / "xy_stage_first_mode.yaml")
    r = solve(study)
    assert r.status == "optimal"
    start, end = _find(r"The first mode rises from ([\d.]+) to ([\d.]+) Hz")
    agrees(start, r.history[0]["objective"], "start")
    agrees(end, r.objective, "optimum")
    guide, decouple = _find(r"the guide leaves to ([\d.]+) mm and the decoupling leaves to "
                            r"([\d.]+) mm")
    agrees(guide, r.x[1] * 1e3, "t_guide")
    agrees(decouple, r.x[2] * 1e3, "t_decouple")
    assert r.bounds[0]["at"] == "upper"
    mult = {c["text"]: c["multiplier"] for c in r.constraints}
    coupling, direct = _find(r"coupling limit \(multiplier ([\d.]+) Hz per unit of gain.y.x\) "
                             r"and the gain limit \(([\d.]+) Hz per unit of gain\)")
    agrees(coupling, mult["gain.y.x <= 0.004"], "coupling multiplier")
    agrees(direct, mult["gain.x.x >= 6.7"], "gain multiplier")
