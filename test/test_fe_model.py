"""
The ``model: fe`` hinge in SI units: scaling, the disk cache, and its design derivatives.

Derivatives are checked against central differences of independently meshed solves; the cache
against a second load and against damaged entries.
"""

import json
import subprocess
import sys
import warnings

import numpy as np
import pytest

from conftest import ROOT
from flexure_sim.engine.kinematics import hyperdual as hd
from flexure_sim.engine.hinges.fe import cache, fe_model as model, solves

GEO = {"D": 3e-3, "h": 0.25e-3, "t": 0.02}


@pytest.fixture(autouse=True)
def fresh_cache(tmp_path, monkeypatch):
    """Give each test a cache directory of its own."""
    monkeypatch.setenv("FLEXURE_SIM_CACHE", str(tmp_path / "cache"))
    return tmp_path / "cache" / "fe"


def test_stiffness_scales_with_E_plate_thickness_and_size():
    # Plane elasticity: K_oo ~ E t ell^2, forces ~ E t, at fixed proportions.
    K = model.stiffness("circular", GEO, 69e9, 0.33, "stress", n=8)
    big = {"D": 6e-3, "h": 0.5e-3, "t": 0.01}  # twice the size, half the plate
    K2 = model.stiffness("circular", big, 2 * 69e9, 0.33, "stress", n=8)
    assert np.diag(K2) == pytest.approx(np.diag(K) * np.array([4.0, 1.0, 1.0]), rel=1e-12)
    c = model.stress_coefficients("circular", GEO, 0.33, "stress", n=8)
    c2 = model.stress_coefficients("circular", big, 0.33, "stress", n=8)
    # sigma = m s_m / (t h^2): twice h and half t -> half; forces: sigma = f s_f / (t h) -> same
    assert c2 == pytest.approx([c[0] / 2, c[1], c[2]], rel=1e-12)


def test_second_load_comes_from_the_cache(fresh_cache):
    case = solves.Case("circular", (12.0,), 0.33, "stress", 8)
    first = solves.solve(case)
    assert first.seconds > 0 and len(list(fresh_cache.glob("*.json"))) == 1
    again = solves.solve(case)
    assert again.seconds == 0.0  # read, not solved (its time: flexure-sim bench)
    assert np.array_equal(again.compliance, first.compliance)
    assert np.array_equal(again.peak, first.peak)


@pytest.mark.parametrize("damage, problem", [
    (lambda p: p.write_bytes(b"\x00\x01binary"), "not valid JSON"),
    (lambda p: p.write_text('{"key": {"shape": "leaf"}, "results": {}}'),
     "another solve's key"),
    (lambda p: p.write_text(p.read_text().replace('"peak": [', '"peak": ["x", ')),
     "not numeric or of the wrong size"),
    (lambda p: p.write_text(p.read_text()[:40]), "not valid JSON"),
])
def test_a_corrupt_cache_entry_is_recomputed_with_a_message(fresh_cache, damage, problem):
    case = solves.Case("circular", (12.0,), 0.33, "stress", 8)
    good = solves.solve(case)
    (entry,) = fresh_cache.glob("*.json")
    damage(entry)
    with pytest.warns(cache.CacheWarning, match=problem) as record:
        again = solves.solve(case)
    assert str(entry) in str(record[0].message)
    assert again.seconds > 0 and np.allclose(again.compliance, good.compliance, rtol=1e-12)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the entry was rewritten: no message the next time
        assert solves.solve(case).seconds == 0.0
    assert json.loads(entry.read_text())["key"]["shape"] == "circular"


def test_an_unwritable_cache_only_warns(tmp_path, monkeypatch):
    blocker = tmp_path / "file"
    blocker.write_text("not a directory")
    monkeypatch.setenv("FLEXURE_SIM_CACHE", str(blocker))
    with pytest.warns(cache.CacheWarning, match="cannot be written"):
        res = solves.solve(solves.Case("circular", (12.0,), 0.33, "stress", 4))
    assert np.all(np.isfinite(res.compliance))


def test_cache_location_follows_xdg(monkeypatch, tmp_path):
    monkeypatch.delenv("FLEXURE_SIM_CACHE")
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert cache.directory() == tmp_path / "xdg" / "flexure_sim" / "fe"


def _fd(f, x0, rel):
    """Central first and second differences of f at x0 with step rel * x0."""
    dx = rel * x0
    fp, f0, fm = f(x0 + dx), f(x0), f(x0 - dx)
    return (fp - fm) / (2 * dx), (fp - 2 * f0 + fm) / dx ** 2


def test_hyper_dual_derivatives_match_differences_of_independent_meshes():
    # d/dh and d2/dh2 of every stiffness entry and stress coefficient through the hyper-dual
    # path (moved meshes, model.STEP) against central differences of solves meshed afresh at
    # h +- 2 % (first) and +- 5 % (second): re-meshing adds noise of ~1e-5 of the stiffness and
    # ~5e-5 of the sampled peak stress, which smaller steps would amplify (at +- 1 % the second
    # difference of Kx is 2.6 % off, while the hyper-dual value moves 1e-4 from n = 16 to 32).
    n, h0 = 16, GEO["h"]

    def K(h):
        return np.diag(model.stiffness("circular", dict(GEO, h=h), 69e9, 0.33, "stress", n))

    def S(h):
        return np.array(model.stress_coefficients("circular", dict(GEO, h=h), 0.33, "stress",
                                                  n), dtype=float)

    seeded = dict(GEO, h=hd.HyperDual(h0, 1.0, 1.0, 0.0))
    Kh = np.diag(model.stiffness("circular", seeded, 69e9, 0.33, "stress", n))
    Sh = model.stress_coefficients("circular", seeded, 0.33, "stress", n)
    d1, _ = _fd(K, h0, 2e-2)
    _, d2 = _fd(K, h0, 5e-2)
    s1, _ = _fd(S, h0, 2e-2)
    for j in range(3):
        assert Kh[j].b == pytest.approx(d1[j], rel=1e-3)
        assert Kh[j].c == pytest.approx(d1[j], rel=1e-3)
        assert Kh[j].d == pytest.approx(d2[j], rel=1e-2)
        assert Sh[j].b == pytest.approx(s1[j], rel=1e-2)
    # Ko ~ h^(5/2) for thin necks (Paros-Weisbord): h dKo/dh / Ko is near 2.5.
    assert h0 * Kh[0].b / Kh[0].a == pytest.approx(2.5, rel=0.05)


def test_mixed_derivative_of_two_geometry_parameters():
    # d2 Ko / dD dh by hyper-dual seeds D + e1, h + e2 against a central mixed difference of
    # independently meshed solves.
    n = 12
    seeded = dict(GEO, D=hd.HyperDual(GEO["D"], 1.0, 0.0, 0.0),
                  h=hd.HyperDual(GEO["h"], 0.0, 1.0, 0.0))
    ko = model.stiffness("circular", seeded, 69e9, 0.33, "stress", n)[0, 0]

    def f(D, h):
        return model.stiffness("circular", dict(GEO, D=D, h=h), 69e9, 0.33, "stress", n)[0, 0]

    dD, dh = 1e-2 * GEO["D"], 1e-2 * GEO["h"]
    D0, h0 = GEO["D"], GEO["h"]
    mixed = (f(D0 + dD, h0 + dh) - f(D0 + dD, h0 - dh) - f(D0 - dD, h0 + dh)
             + f(D0 - dD, h0 - dh)) / (4 * dD * dh)
    assert ko.d == pytest.approx(mixed, rel=2e-2)
    assert ko.b == pytest.approx((f(D0 + dD, h0) - f(D0 - dD, h0)) / (2 * dD), rel=1e-3)


def test_E_and_plate_thickness_derivatives_are_exact():
    seeded = dict(GEO, t=hd.HyperDual(GEO["t"], 1.0, 1.0, 0.0))
    K = model.stiffness("circular", seeded, 69e9, 0.33, "stress", 8)
    assert K[0, 0].b == pytest.approx(K[0, 0].a / GEO["t"], rel=1e-12) and K[0, 0].d == 0


@pytest.mark.parametrize("where", ["main", "thread"])
def test_meshing_a_hinge_leaves_a_closed_pipe_an_error_not_a_killed_process(where):
    """Meshing restores SIGPIPE, which gmsh's initialisation resets to kill the process."""
    script = (
        "import os, threading\n"
        "from flexure_sim.engine.hinges.fe.mesh import mesh_profile\n"
        "from flexure_sim.engine.hinges.fe.shapes import profile\n"
        "prof = profile('circular', (12.0,))\n"
        f"if {where!r} == 'thread':\n"
        "    t = threading.Thread(target=mesh_profile, args=(prof, 4)); t.start(); t.join()\n"
        "else:\n"
        "    mesh_profile(prof, 4)\n"
        "r, w = os.pipe(); os.close(r)\n"
        "try:\n"
        "    os.write(w, b'x')\n"
        "except BrokenPipeError:\n"
        "    print('BrokenPipeError')\n"
    )
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                         cwd=ROOT, timeout=300)
    assert out.returncode == 0, (out.returncode, out.stderr)  # -13: killed by SIGPIPE
    assert out.stdout.strip() == "BrokenPipeError"
