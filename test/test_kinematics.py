"""Planar twist / twistor kinematics (dissertation Ch. 2)."""
import numpy as np
import pytest

from flexure_sim.engine.kinematics import planar as kin


def test_example_2_1_twist_of_a_displacement():
    # Frame b at (2, 1), rotated by 30 degrees: twist (pi/6, 2.21, 0.45), pole (-0.86, 4.23).
    d = kin.twist_from_displacement(kin.rot(np.pi / 6), np.array([2.0, 1.0]))
    assert d[0] == pytest.approx(np.pi / 6)
    assert d[1:] == pytest.approx([2.21, 0.45], abs=0.006)
    pole = kin.J @ d[1:] / d[0]
    assert pole == pytest.approx([-0.86, 4.23], abs=0.01)


def test_example_2_2_displacement_of_a_twist():
    # Twist of angle pi/2 about the pole (-1, 1): t = alpha * (y_p, -x_p) = pi/2 * (1, 1).
    R, p = kin.displacement_from_twist(np.array([np.pi / 2, np.pi / 2, np.pi / 2]))
    assert R == pytest.approx(kin.rot(np.pi / 2))
    assert p == pytest.approx([0.0, 2.0], abs=1e-12)


def test_section_2_7_4_twistor_example():
    # Origin of b at (2, 2 sqrt 3), rotated by pi/3: q = sqrt3/2 + 1/2 e1e2 + sqrt3 e1e + e2e.
    q = kin.twistor_from_displacement(kin.rot(np.pi / 3), np.array([2.0, 2.0 * np.sqrt(3.0)]))
    assert q == pytest.approx((np.sqrt(3) / 2, 0.5, np.sqrt(3), 1.0))


def _random_displacements(rng, n):
    angles = np.concatenate(
        [
            rng.uniform(-np.pi, np.pi, n),
            [
                0.0,
                1e-9,
                -1e-7,
                5e-5,
                np.pi - 1e-9,
                -np.pi + 1e-9,
                np.pi - 1e-3,
                -(np.pi - 0.05),
                3.0,
            ],
        ]
    )
    for a in angles:
        yield a, rng.normal(size=2) * rng.choice([1e-6, 1e-2, 1.0, 10.0])


def test_round_trips_twist_and_twistor():
    rng = np.random.default_rng(1)
    for alpha, p in _random_displacements(rng, 200):
        R = kin.rot(alpha)
        d = kin.twist_from_displacement(R, p)
        R2, p2 = kin.displacement_from_twist(d)
        assert R2 == pytest.approx(R, abs=1e-12)
        assert p2 == pytest.approx(p, rel=1e-9, abs=1e-12 * max(1.0, np.abs(p).max()))
        q = kin.twistor_from_displacement(R, p)
        assert q.sigma**2 + q.xi**2 == pytest.approx(1.0, abs=1e-14)
        assert q.sigma >= 0
        R3, p3 = kin.displacement_from_twistor(q)
        assert R3 == pytest.approx(R, abs=1e-12)
        assert p3 == pytest.approx(p, rel=1e-9, abs=1e-12 * max(1.0, np.abs(p).max()))
        # The twistor's vector part is sin(alpha/2)/alpha times the twist (same pole).
        qt = kin.twistor_from_twist(d)
        assert np.array(qt) == pytest.approx(
            np.array(q), rel=1e-9, abs=1e-12 * max(1.0, np.abs(p).max())
        )


def test_pure_translation():
    p = np.array([3e-6, -2e-6])
    assert kin.twist_from_displacement(np.eye(2), p) == pytest.approx([0.0, *p])
    assert kin.twistor_from_displacement(np.eye(2), p) == pytest.approx((1.0, 0.0, *(p / 2)))


def test_small_sigma_branch_keeps_the_sign_of_the_rotation():
    for alpha in (np.pi - 0.01, -(np.pi - 0.01), np.pi - 0.19):
        q = kin.twistor_from_displacement(kin.rot(alpha), np.zeros(2))
        assert q.sigma < 0.1
        assert q.xi == pytest.approx(np.sin(alpha / 2), abs=1e-12)


def test_adjoint_maps_a_twist_between_frames():
    # A body rotating at omega about the origin of c: the velocity of the origin of c'
    # (at p, turned by phi) is omega J p, seen in c' coordinates R^T omega J p.
    phi, p, omega = 0.4, np.array([0.3, -0.2]), 1.7
    Ad = kin.adjoint(kin.rot(phi), p)
    twist_in_c_prime = np.concatenate([[omega], kin.rot(phi).T @ (omega * kin.J @ p)])
    assert Ad @ twist_in_c_prime == pytest.approx([omega, 0.0, 0.0], abs=1e-15)
