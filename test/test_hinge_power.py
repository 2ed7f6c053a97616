"""
Energy and power of each hinge law.

Checked like Drake's force elements (multibody/plant/test/energy_and_power_test.cc), apart from any
integrator.

At random states of every law (twistor and twist quadratic, twistor and twist polynomial):
- the potential energy equals an independent formula (kinematics' twistor / twist maps, or
  the polynomial summed term by term);
- conservative power = -dU/dt along a random smooth motion r(t), dU/dt by an 8th-order
  central difference of U(r(t)) (tolerance: 1000 eps sum_k |w_k U_k| / h, a bound on the
  difference's rounding; the truncation error is far below it at the step used);
- the power the element's wrenches deliver to two moving bodies -- the wrench -m_b on B at
  frame b, the opposite wrench on A -- computed from the bodies' absolute twists, equals the
  conservative power (and minus the dissipated power for the damping wrench), to a multiple of
  machine epsilon times the sizes of the terms;
- dissipated power >= 0 and = c_dot^T C c_dot, c_dot the rate of kinematics' independent
  coordinates (difference quotient), and = r_dot^T B r_dot at the unstressed pose.
"""

from __future__ import annotations

import numpy as np
import pytest

from flexure_sim.engine.kinematics import planar as kin
from flexure_sim.engine.fitting.least_squares import basis_exponents
from flexure_sim.engine.laws.quadratic import LawBatch, QuadraticLaw, evaluate, wrench_on_element
from flexure_sim.engine.laws.polynomial import PolynomialLaw

EPS = np.finfo(float).eps
#: 9-point central difference of the first derivative (error O(h^8)).
STENCIL = np.array([1 / 280, -4 / 105, 1 / 5, -4 / 5, 0.0, 4 / 5, -1 / 5, 4 / 105, -1 / 280])
H = 2.5e-3  # s: small enough for the truncation error to stay below the rounding bound
M = 40  # random states per law


def _spd(rng, scales, floor=3.0):
    A = rng.normal(size=(3, 3))
    D = np.diag(scales)
    return D @ (A @ A.T + floor * np.eye(3)) @ D


def _laws():
    rng = np.random.default_rng(20261124)
    scales = [1.5, 1.0e4, 4.0e3]  # N m / rad, N / m: a coupled flexure stiffness
    K, B = _spd(rng, scales), 1e-3 * _spd(rng, scales)
    tw = basis_exponents("twistor", 4, sigma_degree=1)
    t3 = basis_exponents("twist", 3)
    return {
        "twistor": QuadraticLaw("twistor", K, B),
        "twist": QuadraticLaw("twist", K, B),
        "poly_twistor": PolynomialLaw(
            "twistor", 4, tw, rng.normal(size=len(tw)), [0.5, 0.5, 1e-3, 1e-3], 2.0, B
        ),
        "poly_twist": PolynomialLaw(
            "twist", 3, t3, rng.normal(size=len(t3)), [1.0, 2e-3, 2e-3], 2.0, B
        ),
    }


LAWS = _laws()


def _states(seed):
    """r0, a rate v and an acceleration a per state: r(t) = r0 + v t + a t^2 / 2."""
    rng = np.random.default_rng(seed)

    def triple():
        return np.column_stack([rng.uniform(-2.5, 2.5, M), rng.normal(size=(M, 2)) * 1e-3])

    return triple(), triple(), triple()


def _path(r0, v, a, t):
    r = r0 + v * t + 0.5 * a * t * t
    return r[:, 0], r[:, 1:]


def _rate(f, r0, v, a):
    """d/dt f(r(t)) at t = 0 by the 9-point stencil, and its rounding bound."""
    values = np.array([f(*_path(r0, v, a, k * H)) for k in range(-4, 5)])
    derivative = np.tensordot(STENCIL, values, axes=1) / H
    rounding = np.tensordot(np.abs(STENCIL), np.abs(values), axes=1) / H
    return derivative, rounding


@pytest.mark.parametrize("name", LAWS)
def test_conservative_power_is_minus_the_rate_of_the_potential(name):
    law = LAWS[name]
    r0, v, a = _states(1)
    dU, rounding = _rate(law.potential_energy, r0, v, a)
    power = law.conservative_power(r0[:, 0], r0[:, 1:], v)
    # U sums terms of both signs (random polynomial coefficients), so each U_k carries up to a
    # few hundred eps of rounding: observed max |P_c + dU/dt| = 51 eps * rounding (poly_twistor).
    tol = 1000 * EPS * rounding
    assert np.all(np.abs(power + dU) <= tol), np.max(np.abs(power + dU) / (EPS * rounding))
    assert np.all(np.abs(power) > 1e4 * tol)  # the test is not vacuous


def _independent_coordinates(coordinates, alpha, p):
    """Law coordinates from kinematics' own maps (trans2cliff2.sci, eq. 2.106), row by row."""
    rows = []
    for al, pp in zip(alpha, p):
        if coordinates == "twistor":
            q = kin.twistor_from_displacement(kin.rot(al), pp)
            rows.append([q.sigma, q.xi, q.x1, q.x2])
        else:
            rows.append(kin.twist_from_displacement(kin.rot(al), pp))
    return np.array(rows)


@pytest.mark.parametrize("name", LAWS)
def test_potential_energy_matches_an_independent_formula(name):
    law = LAWS[name]
    r0, _, _ = _states(2)
    c = _independent_coordinates(law.coordinates, r0[:, 0], r0[:, 1:])
    if isinstance(law, QuadraticLaw):
        vec = c[:, 1:] if law.coordinates == "twistor" else c
        weight = 2.0 if law.coordinates == "twistor" else 0.5  # eqs. 4.7 and 3.4
        terms = weight * vec[:, :, None] * law.K[None] * vec[:, None, :]
    else:
        u = (c - law.rest) / law.scale
        terms = (
            law.energy * law.coefficients * np.prod(u[:, None, :] ** law.exponents[None], axis=2)
        )
    expected = terms.reshape(len(c), -1).sum(axis=1)
    size = np.abs(terms).reshape(len(c), -1).sum(axis=1)
    U = law.potential_energy(r0[:, 0], r0[:, 1:])
    assert np.all(np.abs(U - expected) <= 64 * EPS * size), np.max(
        np.abs(U - expected) / (EPS * size)
    )


@pytest.mark.parametrize("name", LAWS)
def test_dissipated_power_is_the_rate_quadratic_form_and_never_negative(name):
    law = LAWS[name]
    r0, v, a = _states(3)
    k = 4 if law.coordinates == "twistor" else 3
    cdot, rounding = _rate(
        lambda al, p: _independent_coordinates(law.coordinates, al, p), r0, v, a
    )
    C = np.zeros((k, k))
    C[-3:, -3:] = (4.0 if law.coordinates == "twistor" else 1.0) * law.B  # eqs. 4.40, 3.62
    expected = np.einsum("ni,ij,nj->n", cdot, C, cdot)
    bound = 2 * np.einsum("ni,ij,nj->n", np.abs(cdot), np.abs(C), 10 * EPS * rounding)
    got = law.dissipated_power(r0[:, 0], r0[:, 1:], v)
    assert np.all(np.abs(got - expected) <= bound), np.max(np.abs(got - expected) / bound)
    assert np.all(got >= 0)
    # = r_dot^T B_eff r_dot with the engine's effective damping matrix C_r
    B_eff = evaluate([law] * M, r0[:, 0], r0[:, 1:], v).damping
    quad = np.einsum("ni,nij,nj->n", v, B_eff, v)
    assert np.all(
        np.abs(got - quad)
        <= 16 * EPS * np.einsum("ni,nij,nj->n", np.abs(v), np.abs(B_eff), np.abs(v))
    )
    # at the unstressed pose B_eff = B: P_d = r_dot^T B r_dot exactly (eq. 4.52's damping twin)
    at_rest = law.dissipated_power(np.zeros(M), np.zeros((M, 2)), v)
    assert at_rest == pytest.approx(np.einsum("ni,ij,nj->n", v, law.B, v), rel=1e-13)


def test_dissipated_power_is_never_negative_for_a_singular_damping():
    """B positive semi-definite of rank 1 (damping along one direction only), random states."""
    rng = np.random.default_rng(4)
    w = rng.normal(size=3) * [1.0, 1e3, 1e3]
    B = np.outer(w, w)
    for coordinates in ("twistor", "twist"):
        law = QuadraticLaw(coordinates, np.eye(3), B)
        r0, v, _ = _states(5)
        assert np.all(law.dissipated_power(r0[:, 0], r0[:, 1:], v) >= 0)


# ----------------------------------------------- wrench . velocity on two moving bodies


def _two_bodies(seed):
    """Random poses and twists of bodies A and B and hinge frames fixed on them."""
    rng = np.random.default_rng(seed)
    g = {key: rng.normal(size=(M, 2)) * 1e-2 for key in ("xA", "xB", "pa", "pb")}
    g.update({key: rng.uniform(-np.pi, np.pi, M) for key in ("thA", "thB", "phia", "phib")})
    g.update(
        vA=rng.normal(size=(M, 2)) * 1e-2,
        vB=rng.normal(size=(M, 2)) * 1e-2,
        wA=rng.normal(size=M),
        wB=rng.normal(size=M),
    )
    return g


def _relative(g):
    """
    Return r = (alpha, p) of frame b in frame a and its rate r_dot, from the bodies' motion.

    Frame origins x_f = x + R(theta) p_f, velocities v + w J R(theta) p_f; p = R_a^T (x_b - x_a)
    whose rate is R_a^T (v_b - v_a) - w_A J p (d/dt R_a^T = -w_A J R_a^T).
    """
    RA, RB = kin.rot(g["thA"]), kin.rot(g["thB"])
    xa = g["xA"] + np.einsum("nij,nj->ni", RA, g["pa"])
    xb = g["xB"] + np.einsum("nij,nj->ni", RB, g["pb"])
    va = g["vA"] + g["wA"][:, None] * (xa - g["xA"]) @ kin.J.T
    vb = g["vB"] + g["wB"][:, None] * (xb - g["xB"]) @ kin.J.T
    Ra = kin.rot(g["thA"] + g["phia"])
    alpha = np.remainder(g["thB"] + g["phib"] - g["thA"] - g["phia"] + np.pi, 2 * np.pi) - np.pi
    p = np.einsum("nji,nj->ni", Ra, xb - xa)
    pdot = np.einsum("nji,nj->ni", Ra, vb - va) - g["wA"][:, None] * p @ kin.J.T
    rdot = np.column_stack([g["wB"] - g["wA"], pdot])
    return alpha, p, rdot, xb


def _power_on_bodies(g, alpha, m_b, xb):
    """
    Return the power of the wrench -m_b on B and of the opposite wrench on A.

    The wrench on B is in frame b coordinates, about b's origin; both with the bodies' absolute
    twists. Also returns the sum of |terms|.
    """
    Rb = kin.rot(g["thB"] + g["phib"])
    F = -np.einsum("nij,nj->ni", Rb, m_b[:, 1:])  # force on B, world coordinates
    m = -m_b[:, 0]  # moment on B about b's origin
    point_on_B = g["vB"] + g["wB"][:, None] * (xb - g["xB"]) @ kin.J.T
    point_on_A = g["vA"] + g["wA"][:, None] * (xb - g["xA"]) @ kin.J.T
    terms = np.column_stack(
        [
            m * g["wB"],
            np.sum(F * point_on_B, axis=1),
            -m * g["wA"],
            -np.sum(F * point_on_A, axis=1),
        ]
    )
    return terms.sum(axis=1), np.abs(terms).sum(axis=1)


@pytest.mark.parametrize("name", LAWS)
def test_wrench_times_velocity_is_the_power(name):
    law = LAWS[name]
    g = _two_bodies(6)
    alpha, p, rdot, xb = _relative(g)
    ev = evaluate([law] * M, alpha, p, rdot)
    power = LawBatch([law] * M).power(alpha, p, rdot)
    elastic, size = _power_on_bodies(g, alpha, wrench_on_element(alpha, ev.grad), xb)
    assert np.all(np.abs(elastic - power.conservative) <= 64 * EPS * size)
    damping, size = _power_on_bodies(g, alpha, wrench_on_element(alpha, ev.damping_force), xb)
    assert np.all(np.abs(damping + power.dissipated) <= 64 * EPS * size)
    assert np.max(np.abs(power.conservative)) > 1e6 * np.max(64 * EPS * size)


def test_relative_rate_of_the_two_bodies_is_the_derivative_of_r():
    """The test's own kinematics (_relative): r_dot against a difference quotient of r."""
    g = _two_bodies(7)
    alpha, p, rdot, _ = _relative(g)
    h = 1e-6
    moved = dict(g)
    for key, rate in (("thA", "wA"), ("thB", "wB"), ("xA", "vA"), ("xB", "vB")):
        moved[key] = g[key] + h * g[rate]
    alpha2, p2, _, _ = _relative(moved)
    fd = np.column_stack([np.remainder(alpha2 - alpha + np.pi, 2 * np.pi) - np.pi, p2 - p]) / h
    assert fd == pytest.approx(rdot, rel=1e-4, abs=1e-6)


def test_a_batch_of_different_laws_reports_each_hinge_as_its_law_does():
    r0, v, _ = _states(8)
    for coordinates in ("twistor", "twist"):
        laws = [law for law in LAWS.values() if law.coordinates == coordinates]
        mixed = [laws[i % 2] for i in range(M)]
        batch = LawBatch(mixed).power(r0[:, 0], r0[:, 1:], v)
        for i in range(2):
            rows = slice(i, None, 2)
            law = laws[i]
            args = (r0[rows, 0], r0[rows, 1:])
            assert batch.energy[rows] == pytest.approx(law.potential_energy(*args), rel=1e-14)
            assert batch.conservative[rows] == pytest.approx(
                law.conservative_power(*args, v[rows]), rel=1e-14
            )
            assert batch.dissipated[rows] == pytest.approx(
                law.dissipated_power(*args, v[rows]), rel=1e-14
            )


@pytest.mark.parametrize(
    "call,name",
    [
        (lambda law: law.potential_energy(np.zeros(3), np.zeros((3, 3))), "p"),
        (
            lambda law: law.conservative_power(np.zeros(3), np.zeros((3, 2)), np.zeros((2, 3))),
            "rdot",
        ),
        (lambda law: law.dissipated_power(0.1, np.zeros((1, 2)), np.zeros((1, 3))), "alpha"),
        (lambda law: wrench_on_element(np.zeros(2), np.zeros((2, 2))), "grad_r"),
        (lambda law: QuadraticLaw("twist", np.eye(2), np.eye(3)), "K"),
        (
            lambda law: LawBatch([law]).power(np.zeros(2), np.zeros((2, 2)), np.zeros((2, 3))),
            "alpha",
        ),
    ],
    ids=["p", "rdot", "alpha", "grad_r", "K", "one law per deflection"],
)
def test_arguments_of_the_wrong_shape_are_named(call, name):
    for law in LAWS.values():
        with pytest.raises(ValueError) as err:
            call(law)
        assert str(err.value).startswith(f"{name}: expected"), str(err.value)


def test_a_polynomial_law_names_coordinates_of_the_wrong_width():
    with pytest.raises(ValueError, match=r"^c: expected shape \(n, 4\), got shape \(2, 3\)"):
        LAWS["poly_twistor"].potential(np.zeros((2, 3)))
