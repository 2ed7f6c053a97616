"""
Hinge laws.

Wrench = gradient of the potential, invariance (3.3, 4.6), small displacements (4.52).
"""

import numpy as np
import pytest

from flexure_sim.engine.kinematics import planar as kin
from flexure_sim.engine.laws.quadratic import QuadraticLaw, evaluate, wrench_on_element
from reference_figures import NOTCH_KO, NOTCH_KX, NOTCH_KY

K_NOTCH = np.diag([NOTCH_KO, NOTCH_KX, NOTCH_KY])
# A general, coupled, positive-definite stiffness (moment first), to exercise every term.
K_GENERAL = np.array([[2.0, 30.0, -12.0], [30.0, 4.0e4, 5.0e3], [-12.0, 5.0e3, 2.0e4]])
LAWS = ["twistor", "twist"]


def law(kind, K=K_GENERAL, t_char=1e-3):
    return QuadraticLaw(kind, K, t_char * K)


def ev(lw, r, rdot=None):
    r = np.atleast_2d(r)
    rdot = np.zeros_like(r) if rdot is None else np.atleast_2d(rdot)
    return evaluate([lw] * len(r), r[:, 0], r[:, 1:], rdot)


CONFIGS = [np.array([0.3, 0.02, -0.01]), np.array([-1.1, -0.05, 0.04]), np.array([2.5, 0.1, 0.2]),
           np.array([4e-3, 2e-6, -3e-6]), np.array([-3e-5, 1e-7, 2e-7])]


def fd_grad(f, x, h):
    g = np.zeros_like(x)
    for i in range(len(x)):
        e = np.zeros_like(x)
        e[i] = h[i]
        g[i] = (f(x + e) - f(x - e)) / (2 * h[i])
    return g


@pytest.mark.parametrize("kind", LAWS)
@pytest.mark.parametrize("r", CONFIGS)
def test_gradient_hessian_and_damping_derivative_are_exact(kind, r):
    lw = law(kind)
    scale = np.maximum(np.abs(r), 1e-6) * 1e-5
    e = ev(lw, r)
    g_fd = fd_grad(lambda x: ev(lw, x).energy[0], r, scale)
    assert e.grad[0] == pytest.approx(g_fd, rel=1e-6, abs=1e-9 * np.abs(e.grad).max())
    H_fd = np.array([fd_grad(lambda x: ev(lw, x).grad[0, i], r, scale) for i in range(3)])
    assert e.hess[0] == pytest.approx(H_fd, rel=1e-5, abs=1e-7 * np.abs(e.hess).max())
    rdot = np.array([0.7, -0.02, 0.03])
    d = ev(lw, r, rdot)
    dfd = np.array(
        [fd_grad(lambda x: ev(lw, x, rdot).damping_force[0, i], r, scale) for i in range(3)]
    )
    assert d.damping_force_dr[0] == pytest.approx(
        dfd, rel=1e-5, abs=1e-7 * np.abs(d.damping_force_dr).max()
    )
    assert d.damping_force[0] == pytest.approx(d.damping[0] @ rdot)


@pytest.mark.parametrize("kind", LAWS)
def test_small_displacement_stiffness_is_K(kind):
    # eq. 4.52: near the unstressed pose both laws reduce to 1/2 r^T K r.
    assert ev(law(kind), np.zeros(3)).hess[0] == pytest.approx(K_GENERAL, rel=1e-12)
    assert ev(law(kind), np.zeros(3)).damping[0] == pytest.approx(1e-3 * K_GENERAL, rel=1e-12)


def _lam(q, sign):
    """Lambda of eq. 4.27 (sign=-1, Lam_ba of comply_quat2.sci) or Lam_ab (sign=+1)."""
    x = np.array([q.x1, q.x2])
    L = np.zeros((3, 3))
    L[0, 0] = q.sigma
    L[0, 1:] = sign * kin.hat(x)
    L[1:, 1:] = q.sigma * np.eye(2) + sign * q.xi * kin.J
    return L


def test_twistor_wrench_matches_comply_quat2():
    """
    m_b = 2 Lambda K [xi; x] (4.35) and the viscous wrench 2 Lambda B dx (4.40-4.42).

    Written out as comply_quat2.sci does, with the frames' own velocities.
    """
    rng = np.random.default_rng(7)
    K, B = K_GENERAL, 1e-3 * K_GENERAL
    for _ in range(20):
        # Frames a and b anywhere in the plane, with body-frame velocities.
        Ra, pa = kin.rot(rng.uniform(-3, 3)), rng.normal(size=2)
        alpha, p = rng.uniform(-2.5, 2.5), rng.normal(size=2) * 0.05
        Rb, pb = kin.compose((Ra, pa), (kin.rot(alpha), p))
        oma, va = rng.normal(), rng.normal(size=2)
        omb, vb = rng.normal(), rng.normal(size=2)
        q = kin.twistor_from_displacement(Ra.T @ Rb, Ra.T @ (pb - pa))
        we_b = 2 * _lam(q, -1) @ K @ q.vector
        dx = 0.5 * _lam(q, -1).T @ np.r_[omb, vb] - 0.5 * _lam(q, +1).T @ np.r_[oma, va]
        wv_b = 2 * _lam(q, -1) @ B @ dx
        # Ours: r and r_dot of frame b relative to frame a.
        # d/dt alpha = omb - oma; d/dt p = R_a^T (v_b,glob - v_a,glob) - J p (oma).
        vb_g, va_g = Rb @ vb, Ra @ va
        pdot = Ra.T @ (vb_g - va_g) - oma * kin.J @ p
        rdot = np.r_[omb - oma, pdot]
        e = ev(QuadraticLaw("twistor", K, B), np.r_[alpha, p], rdot)
        m_el = wrench_on_element(np.array([alpha]), e.grad)[0]
        m_v = wrench_on_element(np.array([alpha]), e.damping_force)[0]
        assert m_el == pytest.approx(we_b, rel=1e-10, abs=1e-12 * np.abs(we_b).max())
        assert m_v == pytest.approx(wv_b, rel=1e-9, abs=1e-12 * np.abs(wv_b).max())


def _relative(Ha, Hb):
    R, p = kin.relative(Ha, Hb)
    return np.r_[kin.angle_of(R), p]


@pytest.mark.parametrize("kind", LAWS)
def test_potential_does_not_depend_on_which_body_is_A(kind):
    rng = np.random.default_rng(3)
    for _ in range(20):
        Ha = (kin.rot(rng.uniform(-3, 3)), rng.normal(size=2))
        Hb = kin.compose(Ha, (kin.rot(rng.uniform(-2, 2)), rng.normal(size=2) * 0.1))
        u_ab = ev(law(kind), _relative(Ha, Hb)).energy[0]
        u_ba = ev(law(kind), _relative(Hb, Ha)).energy[0]
        assert u_ba == pytest.approx(u_ab, rel=1e-12)


@pytest.mark.parametrize("kind", LAWS)
def test_potential_does_not_depend_on_where_the_frames_are(kind):
    """
    Sections 3.3 / 4.6.

    Moving both coincident frames by G needs K' = Ad^T K Ad; without transforming K the energy
    changes (the control).
    """
    rng = np.random.default_rng(5)
    for _ in range(20):
        Ha = (kin.rot(rng.uniform(-3, 3)), rng.normal(size=2))
        Hb = kin.compose(Ha, (kin.rot(rng.uniform(-2, 2)), rng.normal(size=2) * 0.1))
        G = (kin.rot(rng.uniform(-3, 3)), rng.normal(size=2) * 0.05)
        r = _relative(Ha, Hb)
        r_moved = _relative(kin.compose(Ha, G), kin.compose(Hb, G))
        K_moved = kin.transform_stiffness(K_GENERAL, *G)
        u = ev(law(kind), r).energy[0]
        assert ev(law(kind, K_moved), r_moved).energy[0] == pytest.approx(u, rel=1e-10)
        assert abs(ev(law(kind), r_moved).energy[0] - u) > 1e-3 * u


def test_twistor_and_twist_laws_agree_for_small_displacements():
    r = np.array([1e-4, 2e-7, -1e-7])
    u1 = ev(law("twistor", K_NOTCH), r).energy[0]
    u2 = ev(law("twist", K_NOTCH), r).energy[0]
    assert u1 == pytest.approx(u2, rel=1e-8)
    # ... and differ at large rotation: U_twistor = 4 sin^2(a/2)/a^2 U_twist.
    r = np.array([1.0, 0.0, 0.0])
    assert ev(law("twistor"), r).energy[0] / ev(law("twist"), r).energy[0] == pytest.approx(
        4 * np.sin(0.5) ** 2
    )
