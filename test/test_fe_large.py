"""
Large deflection of finite-element hinges against the Euler elastica, and the Chapter 7 data.

The elastica (inextensible Euler-Bernoulli beam with exact kinematics) is solved here as a
boundary-value problem with scipy's solve_bvp: an independent second method for a slender
leaf bent through a large rotation.
"""

import numpy as np
import pytest
from scipy.integrate import solve_bvp

from flexure_sim.engine.fitting.least_squares import wrench_errors
from flexure_sim.engine.fitting.wrench_data import WrenchData
from flexure_sim.engine.hinges.fe import large, mesh, fe_model as model, samples, shapes, solves
from flexure_sim.engine.laws.quadratic import QuadraticLaw


@pytest.fixture(autouse=True)
def fresh_cache(tmp_path, monkeypatch):
    """Give each test a cache directory of its own."""
    monkeypatch.setenv("FLEXURE_SIM_CACHE", str(tmp_path / "cache"))


def _rot(a):
    return np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])


def elastica_wrench(L, EI, EA, alpha, end):
    """
    m_b of a leaf clamped at (-L/2, 0) (tangent along x) whose other end is clamped at ``end``.

    With its tangent at angle alpha: the force F = (F_x, F_y) and the moment body B applies
    there, the moment taken about b's origin (end + R(alpha) (-L/2, 0)), in frame b. The
    extensible elastica: with the axial force N = F . (cos, sin)(theta) and stretch
    1 + N / EA, x' = (1 + N/EA) cos(theta), y' = (1 + N/EA) sin(theta), theta' = m / EI,
    m' = -(x' F_y - y' F_x).
    """
    s = np.linspace(0.0, L, 201)

    def ode(s, z, p):
        x, y, th, m = z
        fx, fy = p
        stretch = 1.0 + (fx * np.cos(th) + fy * np.sin(th)) / EA
        dx, dy = stretch * np.cos(th), stretch * np.sin(th)
        return np.vstack([dx, dy, m / EI, -(dx * fy - dy * fx)])

    def bc(za, zb, p):
        return np.array([za[0] + L / 2, za[1], za[2], zb[0] - end[0], zb[1] - end[1],
                         zb[2] - alpha])

    kap = alpha / L  # start from the circular arc
    guess = np.vstack([-L / 2 + np.sin(kap * s) / kap, (1 - np.cos(kap * s)) / kap, kap * s,
                       np.full_like(s, EI * kap)])
    sol = solve_bvp(ode, bc, s, guess, p=[0.0, 0.0], tol=1e-10, max_nodes=100000)
    assert sol.success, sol.message
    F = sol.p
    M_end = sol.sol(L)[3]
    arm = _rot(alpha) @ np.array([L / 2, 0.0])  # end relative to b's origin
    m_b = M_end + arm[0] * F[1] - arm[1] * F[0]
    fb = _rot(alpha).T @ F
    return np.array([m_b, fb[0], fb[1]])


def test_leaf_bent_through_half_a_radian_matches_the_elastica():
    # A leaf of length 40 T (T = 1, E = 1, unit width: EI = 1/12, EA = 1), plane stress, its
    # far end turned by 0.5 rad and put 0.3 T off the circular arc across it: the
    # finite-element wrench (Saint Venant-Kirchhoff, total Lagrangian) agrees with the
    # extensible elastica to 3 %: the two models differ by the clamps' boundary layers, of
    # order T/L = 2.5 % (measured: 0.7 % in the moment, 1.8 % in the force; at L = 80 T they
    # halve, 0.24 % and 0.9 %), and by shear, O((T/L)^2).
    L, nu, alpha = 40.0, 0.3, 0.5
    prof = shapes.profile("leaf", (L, 0.0))
    solver = large.LargeDeflection(mesh.mesh_profile(prof, 4), prof.half, nu, "stress")
    kap = alpha / L
    arc_end = np.array([-L / 2 + np.sin(alpha) / kap, (1 - np.cos(alpha)) / kap])
    end = arc_end + _rot(alpha) @ np.array([0.0, 0.3])
    p = end + _rot(alpha) @ np.array([-L / 2, 0.0])
    fe = solver.wrench(alpha, p)
    ref = elastica_wrench(L, 1.0 / 12.0, 1.0, alpha, end)
    scale = np.array([abs(ref[0]), np.hypot(ref[1], ref[2]), np.hypot(ref[1], ref[2])])
    assert np.abs(fe - ref) / scale == pytest.approx(np.zeros(3), abs=3e-2)
    # The quadratic laws are far from this: the wrench's moment is not K_oo alpha here.
    assert abs(ref[0] - alpha / 12.0 / L) > 0.05 * abs(ref[0])


def test_small_deflection_is_the_linear_stiffness():
    # At micro-displacements the large-deflection solve is the linear one: m_b = K r.
    prof = shapes.profile("circular", (12.0,))
    m = mesh.mesh_profile(prof, 6)
    K = np.linalg.inv(solves.solve(solves.Case("circular", (12.0,), 0.33, "stress", 6))
                      .compliance)
    solver = large.LargeDeflection(m, prof.half, 0.33, "stress")
    r = np.array([2e-6, 1e-8, -3e-7])
    assert solver.wrench(r[0], r[1:]) == pytest.approx(K @ r, rel=2e-4)


def test_wrench_samples_in_SI_and_the_quadratic_law_near_rest():
    # The stage's notch hinge over a tiny range: samples in SI are the linear stiffness
    # times r, so the twistor quadratic law of the model: fe stiffness (same mesh) fits them
    # to 1e-3; in the hinge frame's convention, every sample within the stress-limited range.
    geo = {"D": 3e-3, "h": 0.25e-3, "t": 0.02}
    r, w = samples.wrench_samples("circular", geo, 69e9, 0.33, 1e-5, 5, seed=3, n=6)
    box = samples.working_box("circular", geo, 0.33, 1e-5, n=6)
    assert np.all(np.abs(r / box).sum(axis=1) <= 1.0 + 1e-12)
    K = model.stiffness("circular", geo, 69e9, 0.33, n=6)
    err = wrench_errors(QuadraticLaw("twistor", K, np.zeros((3, 3))),
                        WrenchData(r[:, 0], r[:, 1:], w))
    assert err["worst_rel"] < 1e-3
    # A leaf: the samples are in the cantilever's convention (leaf along y: f_y axial).
    leaf = {"length": 0.01, "thickness": 1e-3, "width": 5e-3, "fillet": 0.0}
    r, w = samples.wrench_samples("leaf", leaf, 3.45e9, 0.3, 1e-5, 4, seed=1, n=4)
    Kl = model.stiffness("leaf", leaf, 3.45e9, 0.3, n=4)
    assert Kl[2, 2] > 50 * Kl[1, 1]  # axial (y) much stiffer than shear (x)
    assert w == pytest.approx(r @ Kl.T, rel=2e-3, abs=1e-3 * np.abs(w).max())
