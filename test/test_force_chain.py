"""
One definition per formula of the hinge force chain, and its compiled and generic evaluations.

r(z) and dr/dz (kinematics/relative.py), the law coordinates (laws/coordinates.py), the
half-cotangent (kinematics/planar.py) and the quadratic law (laws/hinge_force.py) are each
written once on a generic scalar; Numba compiles them into the stepping kernel, the assembly
evaluates them on arrays, the sensitivities on HyperDual arrays. An edit of each single
definition must reach all three (a second definition anywhere would not follow it), and the
compiled and the interpreted evaluations of the same source must give the same numbers.
"""
from __future__ import annotations

import ast
import json
import os
import shutil
import subprocess
import sys

import numpy as np
import pytest

from conftest import ROOT
from flexure_sim.engine import jit as kernel_cache
from flexure_sim.engine.jit import njit
from flexure_sim.engine.kinematics import planar
from flexure_sim.engine.kinematics.relative import relative
from flexure_sim.engine.laws.coordinates import twist, twist_second, twistor, twistor_second
from flexure_sim.engine.laws.hinge_force import quadratic_hinge
from flexure_sim.engine.mechanism.loader import load_mechanism
from reference_figures import NOTCH_KX

EPS = np.finfo(float).eps


@njit(cache=True)
def _compiled_chain(twistor_law, zA, zB, vA, vB, ca, cb, phia, phib, W, C):
    return quadratic_hinge(twistor_law, True, zA, zB, vA, vB, ca, cb, phia, phib, W, C)


def _twist_map(alpha, p1, p2):
    c, dc = twist(alpha, p1, p2)
    return c, dc, twist_second(alpha, p1, p2, c)


def _twistor_map(alpha, p1, p2):
    c, dc = twistor(alpha, p1, p2)
    return c, dc, twistor_second(alpha, p1, p2, c)


_compiled_twist = njit(cache=True)(_twist_map)
_compiled_twistor = njit(cache=True)(_twistor_map)


@njit(cache=True)
def _compiled_relative(zA, zB, ca, cb, phia, phib):
    return relative(zA, zB, ca, cb, phia, phib)


# Cached like the engine's kernels, and flushed like them when a formula module changes.
kernel_cache.revalidate(kernel_cache.dispatchers_of(globals()), __file__)


def _leaves(x):
    if isinstance(x, tuple):
        return [v for item in x for v in _leaves(item)]
    return [float(np.asarray(x).reshape(-1)[0])]


def _same(compiled, interpreted):
    """Both nested results leaf by leaf, to rounding of the largest (the sines are libm's)."""
    a, b = np.array(_leaves(compiled)), np.array(_leaves(interpreted))
    assert a.shape == b.shape
    np.testing.assert_allclose(a, b, rtol=0, atol=4 * EPS * max(1.0, np.abs(b).max()))


def _tuple3(M):
    return tuple(tuple(float(x) for x in row) for row in M)


@pytest.mark.parametrize("twistor_law", [True, False])
def test_the_compiled_chain_is_the_interpreted_chain(twistor_law):
    """quadratic_hinge compiled by Numba and run as Python on floats: the same numbers."""
    rng = np.random.default_rng(7)
    for k in range(40):
        angle_scale = 3e-3 if k % 2 else 0.3  # half-cotangent: series (< 1e-2) and closed form
        zA = tuple(rng.normal(size=3) * (1e-3, 1e-3, angle_scale))
        zB = tuple(rng.normal(size=3) * (1e-3, 1e-3, angle_scale))
        vA, vB = tuple(rng.normal(size=3)), tuple(rng.normal(size=3))
        ca, cb = tuple(rng.normal(size=2) * 1e-2), tuple(rng.normal(size=2) * 1e-2)
        phia, phib = rng.normal(size=2) * 0.1
        G = rng.normal(size=(3, 3))
        W, C = _tuple3(G @ G.T * 1e3), _tuple3(G @ G.T * 1e-1)
        args = (zA, zB, vA, vB, ca, cb, float(phia), float(phib), W, C)
        _same(_compiled_chain(twistor_law, *args),
              quadratic_hinge(twistor_law, True, *(_floats(a) for a in args)))
        _same(_compiled_relative(*args[:2], *args[4:8]),
              relative(*(_floats(a) for a in args[:2] + args[4:8])))


def _floats(x):
    return tuple(_floats(v) for v in x) if isinstance(x, tuple) else float(x)


def test_the_compiled_coordinate_maps_and_half_cotangent_are_the_interpreted_ones():
    rng = np.random.default_rng(8)
    for alpha in np.concatenate([rng.uniform(-3, 3, 30), rng.uniform(-2e-2, 2e-2, 30),
                                 [0.0, planar.HALF_COT_SERIES, -planar.HALF_COT_SERIES]]):
        p1, p2 = rng.normal(size=2) * 1e-3
        for compiled, generic in ((_compiled_twist, _twist_map),
                                  (_compiled_twistor, _twistor_map)):
            _same(compiled(alpha, p1, p2), generic(float(alpha), float(p1), float(p2)))
            # and on arrays: the same numbers, entry by entry
            _same(generic(np.array([alpha]), np.array([p1]), np.array([p2])),
                  generic(float(alpha), float(p1), float(p2)))


def test_half_cotangent_series_and_closed_form_meet():
    """Both branches agree across the threshold and with finite differences of f."""
    for a in (planar.HALF_COT_SERIES * (1 - 1e-9), planar.HALF_COT_SERIES * (1 + 1e-9)):
        f, f1, f2 = planar.half_cot(a)
        assert f == pytest.approx(0.5 * a / np.tan(0.5 * a), rel=4 * EPS)
        h = 1e-4
        plus, minus = planar.half_cot(a + h), planar.half_cot(a - h)
        assert f1 == pytest.approx((plus[0] - minus[0]) / (2 * h), rel=1e-7)
        assert f2 == pytest.approx((plus[1] - minus[1]) / (2 * h), rel=1e-7)


@pytest.mark.parametrize("module", ["solver/kernels.py", "solver/assembly.py",
                                    "analysis/parametric.py", "laws/quadratic.py",
                                    "laws/hinge_force.py"])
def test_the_chains_evaluations_compute_no_trigonometry_of_their_own(module):
    """Every sine and cosine of the chain is in its formula modules (kinematics, coordinates)."""
    tree = ast.parse((ROOT / "flexure_sim" / "engine" / module).read_text())
    trig = [node.lineno for node in ast.walk(tree) if isinstance(node, ast.Call)
            and isinstance(node.func, ast.Attribute) and node.func.attr in ("sin", "cos", "tan")]
    assert not trig, f"{module} lines {trig}"


def test_hinge_stiffness_and_damping_live_in_the_law_only():
    """No unread Hinge.K / Hinge.B copies next to the law's own."""
    import dataclasses

    from flexure_sim.engine.mechanism.parts import Hinge

    names = {f.name for f in dataclasses.fields(Hinge)}
    assert "K" not in names and "B" not in names
    assert names == {"name", "a", "b", "law", "stiffness_source", "stress"}
    hinge = load_mechanism("microstage").hinges[0]
    assert hinge.law.K[1, 1] == pytest.approx(NOTCH_KX, rel=1e-3)


# --------------------------------------------- an edit of each formula reaches every path

#: The stage with hinges a and c on the twist law, the others on the twistor law, at poses
#: with hinge rotations on both sides of the half-cotangent's series threshold (1e-2 rad):
#: the forces on every body by the compiled kernel (Assembly.report), by the vectorised
#: assembly with its Jacobians (Assembly.forces) and by the generic chain on floats and on
#: HyperDual numbers (analysis/parametric.py), and five steps of the compiled loop.
EVALUATE = r"""
import json, sys
import numpy as np, yaml
from flexure_sim.engine.analysis.parametric import forces
from flexure_sim.engine.kinematics import hyperdual as hd
from flexure_sim.engine.mechanism.loader import mechanism_from_dict
from flexure_sim.engine.mechanism.parameters import design_of, hinge_indices, twistor_flags
from flexure_sim.engine.solver.assembly import Assembly
from flexure_sim.engine.solver.simulation import Simulation
path = sys.argv[1]
doc = yaml.safe_load(open(path))
for h in doc["hinges"]:
    if h["name"] in ("a", "c"):
        h["law"] = "twist"
mech = mechanism_from_dict(doc, source=path)
asm = Assembly(mech)
ia, ib = hinge_indices(mech)
rng = np.random.default_rng(0)
z0 = np.array([b.pose for b in mech.bodies], dtype=float).ravel()
out = {"paths": [], "alpha": []}
for scale in (3e-3, 3e-2):
    z = z0 + rng.normal(size=z0.size) * np.tile([1e-5, 1e-5, scale], len(mech.bodies))
    v = rng.normal(size=z0.size) * 1e-2
    kernel = asm.report(z, v)[0]
    vectorised = asm.forces(z, v, jacobian=True).Q
    generic = forces(design_of(mech), twistor_flags(mech), ia, ib, z, v).Q
    dual = forces(design_of(mech), twistor_flags(mech), ia, ib,
                  hd.HyperDual(z, 1.0, 0.0, 0.0), hd.HyperDual(v)).Q.a
    out["paths"].append([q.tolist() for q in (kernel, vectorised, generic, dual)])
    twist = [mech.hinge_index(name) for name in ("a", "c")]
    out["alpha"] += asm.relative(z, second=False)[0][twist, 0].tolist()
sim = Simulation(mech)
sim.set_command(1e-6)
sim.step(5)
out["stepped"] = sim.state.z.tolist()
print(json.dumps(out))
"""

#: (file, the line of the one definition, the edited line): each edit scales one formula's
#: result by a factor of its own, so each changes the forces.
EDITS = [
    ("kinematics/relative.py", "    alpha = thB + phib - beta\n",
     "    alpha = 1.01 * (thB + phib - beta)\n"),
    ("kinematics/quaternion.py", "    return (0.5 * (sigma * p[0] + pxi[0]),",
     "    return (0.502 * (sigma * p[0] + pxi[0]),"),
    ("laws/coordinates.py", "    c = (alpha, f * p1 + half * p2, f * p2 - half * p1)\n",
     "    c = (alpha, 1.003 * f * p1 + half * p2, f * p2 - half * p1)\n"),
    ("kinematics/planar.py", "    return (where(small, 1.0 - a2 / 12.0",
     "    return (1.004 * where(small, 1.0 - a2 / 12.0"),
]


def _evaluate(root) -> dict:
    env = {**os.environ, "PYTHONPATH": str(root)}
    env.pop("NUMBA_DISABLE_JIT", None)
    env.pop("NUMBA_CACHE_DIR", None)
    stage = str(ROOT / "config" / "microstage.yaml")
    out = subprocess.run([sys.executable, "-c", EVALUATE, stage], cwd=root, env=env,
                         capture_output=True, text=True, timeout=900)
    assert out.returncode == 0, out.stderr
    return json.loads(out.stdout.strip().splitlines()[-1])


def _agree(paths):
    """Check that the four evaluations of each state agree to rounding (sums in other orders)."""
    for state in paths:
        ref = np.array(state[0])
        for other in state[1:]:
            np.testing.assert_allclose(other, ref, rtol=0, atol=1e-12 * np.abs(ref).max())


@pytest.mark.slow
def test_an_edit_of_each_formula_reaches_every_evaluation_and_the_cached_kernels(tmp_path):
    """
    Edit each single definition in a copy of the package: every evaluation follows it.

    The copy runs twice in fresh processes, as a user's next run would: before the edits
    (which compiles and caches the kernels) and after them. After the edits the compiled
    kernel, the vectorised assembly and the generic chain on floats and hyper-duals still
    agree, and all of them moved: a second copy of a formula in any of them (or a stale
    compiled kernel: Numba's cache must follow the formula modules, engine/jit.py) would not.
    """
    package = tmp_path / "flexure_sim"
    shutil.copytree(ROOT / "flexure_sim", package,
                    ignore=shutil.ignore_patterns("__pycache__", "*.pyc"))
    before = _evaluate(tmp_path)
    _agree(before["paths"])
    alpha = np.abs(np.array(before["alpha"]))
    assert np.any(alpha < planar.HALF_COT_SERIES) and np.any(alpha > planar.HALF_COT_SERIES)
    cached = list((package / "engine" / "solver" / "__pycache__").glob("kernels.*.nbi"))
    assert cached, "the first run cached no kernel: the test would prove nothing"
    for name, line, edited in EDITS:
        source = package / "engine" / name
        text = source.read_text()
        assert text.count(line) == 1, (name, line)
        source.write_text(text.replace(line, edited))
    after = _evaluate(tmp_path)
    _agree(after["paths"])
    for old, new in zip(before["paths"], after["paths"]):
        for q_old, q_new in zip(old, new):
            moved = np.abs(np.array(q_new) - np.array(q_old)).max()
            assert moved > 1e-3 * np.abs(q_old).max()
    assert not np.allclose(after["stepped"], before["stepped"], rtol=1e-9, atol=0)
