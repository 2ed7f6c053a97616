"""
Spatial hinge laws: coordinates, wrenches, large rotations, frame and body independence.

Expected values come from formulas written independently of the engine: the twist from
SciPy's matrix logarithm of the homogeneous transform, the twistor from SciPy's quaternion of
the rotation matrix and x = (sigma I - hat(xi)) p / 2, derivatives from central differences,
the planar laws of ``laws.quadratic`` for planar deflections.
"""
import numpy as np
import pytest
import scipy.linalg
from scipy.spatial.transform import Rotation

from flexure_sim.engine.hinges.spatial_stiffness import adjoint, transform_stiffness
from flexure_sim.engine.kinematics import quaternion as rot
from flexure_sim.engine.laws.quadratic import LawBatch, QuadraticLaw, wrench_on_element
from flexure_sim.engine.laws.spatial import SpatialLaw
from flexure_sim.engine.mechanism.parts import Fixed
from flexure_sim.engine.mechanism.spatial_parts import Body, Frame, Hinge, Mechanism
from flexure_sim.engine.solver.spatial_model import SpatialModel

RNG = np.random.default_rng(2029)
LAWS = ("twistor", "twist")


def hat(w):
    return np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])


def spd(scale_r=2.0, scale_t=3e6):
    """Return a full symmetric positive definite 6x6 stiffness with coupling terms."""
    A = RNG.normal(size=(6, 6))
    S = np.diag([scale_r] * 3 + [scale_t] * 3) ** 0.5
    return S @ (A @ A.T + 6 * np.eye(6)) @ S / 6


def transform(xi):
    M = np.zeros((4, 4))
    M[:3, :3], M[:3, 3] = hat(xi[:3]), xi[3:]
    return scipy.linalg.expm(M)


def twist_of(H):
    L = scipy.linalg.logm(H).real
    return np.r_[L[2, 1], L[0, 2], L[1, 0], L[:3, 3]]


def twistor_of(H):
    """(xi, x) from the matrix only: sigma = sqrt(1 + tr R)/2, xi = vee(R - R^T)/(4 sigma)."""
    R, p = H[:3, :3], H[:3, 3]
    sigma = 0.5 * np.sqrt(1.0 + np.trace(R))
    xi = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]]) / (4 * sigma)
    return np.r_[xi, 0.5 * (sigma * np.eye(3) - hat(xi)) @ p]


def quat(R):
    x, y, z, w = Rotation.from_matrix(R).as_quat()
    return np.array([w, x, y, z]) * (1 if w >= 0 else -1)


def deflections(n=6, angle=np.deg2rad(50), shift=2e-3):
    out = []
    for k in range(n):
        axis = RNG.normal(size=3)
        w = (angle * (k + 1) / n) * axis / np.linalg.norm(axis)
        out.append(transform(np.r_[w, shift * RNG.normal(size=3)]))
    return out


@pytest.mark.parametrize("law", LAWS)
def test_potential_at_large_rotations_equals_the_independent_formula(law):
    """
    Tens of degrees about random axes: U equals the independent formula.

    U from the engine's quaternion products equals U written through the rotation matrix
    (twistor) or the matrix logarithm (twist).
    """
    K = spd()
    L = SpatialLaw(law, K, np.zeros((6, 6)))
    for H in deflections():
        c = twistor_of(H) if law == "twistor" else twist_of(H)
        expected = 2.0 * c @ K @ c if law == "twistor" else 0.5 * c @ K @ c
        state = L.evaluate(quat(H[:3, :3]), H[:3, 3])
        assert np.allclose(state.coordinates, c, rtol=0, atol=1e-12 * np.abs(c).max())
        assert state.energy == pytest.approx(expected, rel=1e-12)


@pytest.mark.parametrize("law", LAWS)
def test_wrench_is_the_derivative_of_the_potential_under_right_perturbation(law):
    """m_b . delta = dU(D Exp(delta)): central differences of the independent potential."""
    K = spd()
    L = SpatialLaw(law, K, np.zeros((6, 6)))
    coords = twistor_of if law == "twistor" else twist_of
    scale = 2.0 if law == "twistor" else 0.5
    for H in deflections(4):
        m = L.evaluate(quat(H[:3, :3]), H[:3, 3]).wrench_on_element
        grad = np.empty(6)
        for j in range(6):
            h = 1e-6 if j < 3 else 1e-9
            d = np.zeros(6)
            d[j] = h
            up, down = coords(H @ transform(d)), coords(H @ transform(-d))
            grad[j] = scale * (up @ K @ up - down @ K @ down) / (2 * h)
        assert np.allclose(m, grad, rtol=1e-6, atol=1e-7 * np.abs(grad).max())


@pytest.mark.parametrize("law", LAWS)
def test_rates_and_damping_wrench_follow_the_coordinate_map(law):
    """
    Rates, damping wrench and dissipated power follow the coordinate map.

    c_dot = Lambda delta_dot with Lambda from differences of the independent coordinates; the
    damping wrench is Lambda^T C c_dot and dissipates c_dot^T C c_dot.
    """
    Bm = spd(1e-3, 1e3)
    L = SpatialLaw(law, np.zeros((6, 6)), Bm)
    coords = twistor_of if law == "twistor" else twist_of
    C = L.dissipation_matrix()
    for H in deflections(4):
        Lam = np.empty((6, 6))
        for j in range(6):
            d = np.zeros(6)
            d[j] = 1e-7
            Lam[:, j] = (coords(H @ transform(d)) - coords(H @ transform(-d))) / 2e-7
        rate = RNG.normal(size=6)
        st = L.evaluate(quat(H[:3, :3]), H[:3, 3], rate)
        assert np.allclose(st.rates, Lam @ rate, rtol=0, atol=1e-7 * np.abs(Lam @ rate).max())
        assert np.allclose(st.wrench_on_element, Lam.T @ C @ (Lam @ rate), rtol=1e-6)
        assert st.dissipated == pytest.approx(rate @ Lam.T @ C @ Lam @ rate, rel=1e-6)
        assert st.dissipated > 0 and st.conservative == 0.0


@pytest.mark.parametrize("law", LAWS)
def test_planar_deflections_give_the_planar_law(law):
    """
    A deflection in the plane gives the planar law.

    The spatial law's energy and wrench are the planar law's (laws.quadratic) on (rz, x, y);
    the out-of-plane wrench is exactly zero.
    """
    K6, B6 = np.diag([5.0, 6.0, 2.5, 1.6e8, 1.7e7, 8e7]), np.zeros((6, 6))
    K6[2, 3] = K6[3, 2] = 1e3
    planar = QuadraticLaw(law, K6[2:5, 2:5], np.zeros((3, 3)))
    spatial = SpatialLaw(law, K6, B6)
    for alpha, p in [(0.0, (1e-6, -2e-6)), (0.3, (1e-4, 3e-5)), (-2.5, (-2e-3, 1e-3))]:
        ev = LawBatch([planar]).evaluate([alpha], [p], np.zeros((1, 3)))
        m3 = wrench_on_element(np.array([alpha]), ev.grad)[0]
        st = spatial.evaluate(rot.quaternion_of_rpy(0, 0, alpha), (*p, 0.0))
        assert st.energy == pytest.approx(ev.energy[0], rel=1e-12, abs=1e-30)
        assert np.allclose(st.wrench_on_element[[2, 3, 4]], m3, rtol=1e-12,
                           atol=1e-12 * np.abs(m3).max())
        assert np.all(st.wrench_on_element[[0, 1, 5]] == 0.0)


def two_bodies(law, K, frame_a, frame_b, swap=False):
    """Body A fixed at the origin, body B free at (0.01, 0.02, 0.03), one hinge."""
    bodies = (Body("A", 1.0, ((1.0, 0, 0), (0, 1.0, 0), (0, 0, 1.0)), (0.0, 0.0, 0.0),
                   (1.0, 0.0, 0.0, 0.0)),
              Body("B", 0.1, ((1e-5, 0, 0), (0, 2e-5, 0), (0, 0, 3e-5)), (0.01, 0.02, 0.03),
                   tuple(rot.quaternion_of_rpy(0.3, -0.2, 0.5))))
    B = 1e-3 * K
    a, b = (frame_b, frame_a) if swap else (frame_a, frame_b)
    hinge = Hinge("h", a, b, SpatialLaw(law, K, B))
    return SpatialModel(Mechanism("pair", bodies, (hinge,), (Fixed("A"),)))


def frames(R=np.eye(3), p=np.zeros(3)):
    """Coincident frames at (0.02, 0.01, 0.04) (root), turned by q0, moved by (R, p)."""
    q0 = rot.quaternion_of_rpy(0.1, 0.7, -0.4)
    qB = rot.quaternion_of_rpy(0.3, -0.2, 0.5)
    where = np.array([0.02, 0.01, 0.04])
    q = rot.qmul(tuple(q0), tuple(quat(R)))
    moved = where + rot.matrix(q0) @ p
    fa = Frame("A", tuple(moved), q)
    fb = Frame("B", tuple(rot.matrix(qB).T @ (moved - np.array([0.01, 0.02, 0.03]))),
               rot.qconj_mul(tuple(qB), q))
    return fa, fb


@pytest.mark.parametrize("law", LAWS)
def test_energy_and_forces_do_not_depend_on_the_hinge_frame_nor_on_which_body_is_a(law):
    """
    Frames moved, turned or swapped: the same energy and forces.

    Frames moved and turned by (R, p) on both bodies with K' = Ad^T K Ad, and A and B swapped:
    the same energy and generalized forces (to 1e-12) at a state 30 degrees off.
    """
    K = spd()
    R = Rotation.from_rotvec([0.4, -1.1, 0.7]).as_matrix()
    p = np.array([3e-3, -2e-3, 5e-3])
    base = two_bodies(law, K, *frames())
    moved = two_bodies(law, transform_stiffness(K, R, p), *frames(R, p))
    swapped = two_bodies(law, K, *frames(), swap=True)
    z = base.z0.copy()
    z[6:9] += [1e-4, -2e-4, 3e-4]
    z[9:12] = np.deg2rad(30) * np.array([0.6, 0.0, 0.8])
    w = np.r_[np.zeros(6), RNG.normal(size=6)]
    ref = base.terms(z, w)
    for other in (moved, swapped):
        got = other.terms(z, w)
        assert got[5] == pytest.approx(ref[5], rel=1e-12)
        assert got[6] == pytest.approx(ref[6], rel=1e-12)
        assert np.allclose(got[0], ref[0], rtol=0, atol=1e-12 * np.abs(ref[0]).max())
    assert np.allclose(adjoint(R, p) @ np.linalg.inv(adjoint(R, p)), np.eye(6), atol=1e-14)


@pytest.mark.parametrize("law", LAWS)
def test_generalized_forces_are_minus_the_gradient_and_power_is_the_energy_rate(law):
    """
    Q = -dU/dq, and the hinge powers are the energy rates.

    Q = -dU/d(p, body rotation) by central differences on the potential; the hinge's
    conservative power is -dU/dt along the motion, its dissipated power -Q_damping . w.
    """
    K = spd()
    model = two_bodies(law, K, *frames())
    z = model.z0.copy()
    z[6:9] += [2e-4, 1e-4, -3e-4]
    z[9:12] = np.deg2rad(25) * np.array([0.0, 0.6, 0.8])
    w = np.r_[np.zeros(6), RNG.normal(size=3) * 1e-2, RNG.normal(size=3)]

    def moved(d):
        out = z.copy()
        out[6:9] += d[:3]
        R = (Rotation.from_rotvec(z[9:12]) * Rotation.from_rotvec(d[3:])).as_matrix()
        out[9:12] = Rotation.from_matrix(R).as_rotvec()
        return out

    Q, *_, power, energy, _ = model.terms(z, np.zeros(12))
    grad = np.empty(6)
    for j in range(6):
        d = np.zeros(6)
        d[j] = 1e-9 if j < 3 else 1e-7
        grad[j] = (model.terms(moved(d), 0 * w)[5] - model.terms(moved(-d), 0 * w)[5]) / (2 * d[j])
    assert np.allclose(Q[6:], -grad, rtol=1e-6, atol=1e-7 * np.abs(grad).max())
    h = 1e-7
    rate = (model.terms(moved(h * w[6:]), 0 * w)[5] - model.terms(moved(-h * w[6:]), 0 * w)[5])
    full = model.terms(z, w)
    assert full[4][0, 1] == pytest.approx(-rate / (2 * h), rel=1e-6)
    assert full[4][0, 2] == pytest.approx(-(full[0] - Q) @ w, rel=1e-12)
    assert full[4][0, 2] > 0.0
