"""
Spatial rotations: quaternions, rotation vectors, the right Jacobian, and the working range.

Expected values come from SciPy's Rotation and matrix exponential, from a 50-digit Decimal
evaluation of the Jacobian's coefficient, and, for a tumbling rigid body, from SciPy's DOP853
on the quaternion equations of motion.
"""
from decimal import Decimal, getcontext

import numpy as np
import pytest
import scipy.integrate
import scipy.linalg
from scipy.spatial.transform import Rotation

from flexure_sim.engine.kinematics import scalar
from flexure_sim.engine.kinematics import quaternion as rot
from flexure_sim.engine.mechanism.spatial_loader import spatial_from_dict
from flexure_sim.engine.solver.model import SolverError
from flexure_sim.engine.solver.spatial_simulation import SpatialSimulation

RNG = np.random.default_rng(29)


def hat(w):
    return np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])


def vectors():
    """Rotation vectors from 0 and 1e-9 rad to nearly pi, about random axes."""
    out = [np.zeros(3), np.array([1e-9, 0.0, 0.0]), np.array([0.0, 0.0, 3e-3])]
    for norm in (1e-5, 0.05, 0.3, 1.0, 2.0, 3.1):
        axis = RNG.normal(size=3)
        out.append(norm * axis / np.linalg.norm(axis))
    return out


@pytest.mark.parametrize("phi", vectors())
def test_quaternion_and_matrix_of_a_rotation_vector_are_scipys(phi):
    x, y, z, w = Rotation.from_rotvec(phi).as_quat()
    q = rot.quaternion_of_vector(phi)
    assert np.allclose(q, [w, x, y, z], rtol=0, atol=1e-16)
    assert np.allclose(rot.matrix(q), Rotation.from_rotvec(phi).as_matrix(), rtol=0,
                       atol=4e-16)
    assert np.allclose(rot.vector_of_quaternion(q), phi, rtol=1e-14, atol=1e-20)


def _decimal_c(s) -> Decimal:
    """c(s) = 1/t^2 - (1 + cos t) / (2 t sin t) to 50 digits (series of sin and cos)."""
    getcontext().prec = 60
    t = Decimal(s).sqrt()
    term, sin, cos = t, Decimal(0), Decimal(0)
    for k in range(1, 80, 2):
        sin += term
        term *= -t * t / ((k + 1) * (k + 2))
    term = Decimal(1)
    for k in range(0, 80, 2):
        cos += term
        term *= -t * t / ((k + 1) * (k + 2))
    return 1 / (t * t) - (1 + cos) / (2 * t * sin)


@pytest.mark.parametrize("s", [1e-8, 1e-3, 0.3, 0.999, 1.0, 1.001, 2.5, 6.0, 9.5])
def test_jacobian_coefficient_and_its_derivative_to_rounding_on_both_sides_of_the_series(s):
    c, dc = rot.jr_coefficient(s)
    assert abs(c - float(_decimal_c(s))) <= 2e-15 * float(_decimal_c(s))
    h = Decimal("1e-20")
    ds = float((_decimal_c(Decimal(s) + h) - _decimal_c(Decimal(s) - h)) / (2 * h))
    if s >= 1e-3:  # the difference quotient above is exact to ~1e-25 here
        assert abs(dc - ds) <= 2e-13 * abs(ds)


@pytest.mark.parametrize("phi", vectors()[2:])
def test_phi_rate_is_the_inverse_right_jacobian(phi):
    """d/dt Exp(phi(t)) = Exp(phi) hat(omega) for dphi/dt = Jr^-1(phi) omega (SciPy's expm)."""
    omega = RNG.normal(size=3)
    rate = np.array(rot.phi_rate(tuple(phi), tuple(omega)))
    h = 1e-6
    expm = scipy.linalg.expm
    dR = (expm(hat(phi + h * rate)) - expm(hat(phi - h * rate))) / (2 * h)
    assert np.allclose(dR, scipy.linalg.expm(hat(phi)) @ hat(omega), rtol=0, atol=1e-8)


def test_hyperdual_evaluation_gives_exact_derivatives_of_the_formula():
    """
    quaternion_exp on hyper-dual numbers: exact derivatives of the compiled formula.

    Its values are the float evaluation's, its derivatives the central differences of it (to
    their truncation).
    """
    for phi in vectors()[3:]:
        seeds = scalar.seeded(phi, np.eye(3))
        out = np.empty(4, dtype=object)
        for k, part in enumerate(rot.quaternion_exp(*seeds)):
            out[k] = part
        assert np.allclose(scalar.values_of(out), rot.quaternion_exp(*phi), rtol=0, atol=5e-16)
        J = scalar.derivatives_of(out, 3)
        h = 1e-6
        fd = np.column_stack([(np.array(rot.quaternion_exp(*(phi + h * e)))
                               - np.array(rot.quaternion_exp(*(phi - h * e)))) / (2 * h)
                              for e in np.eye(3)])
        assert np.allclose(J, fd, rtol=0, atol=1e-9)


def _tumbler(inertia):
    return {
        "name": "tumbler", "space": "3d",
        "defaults": {"law": "twistor", "damping": {"t_char": 0.0}},
        "bodies": [
            {"name": "ground", "mass": 1.0, "inertia": [1.0, 1.0, 1.0], "pose": [0, 0, 0]},
            {"name": "top", "mass": 0.1, "inertia": list(inertia), "pose": [0, 0, 0.1]},
        ],
        "hinges": [{"name": "loose", "a": {"body": "ground", "at": [0, 0, 0.1]},
                    "b": {"body": "top", "at": [0, 0, 0]},
                    "stiffness": {"model": "matrix",
                                  "K": np.diag([1e-12] * 3 + [1e3] * 3).tolist()}}],
        "constraints": [{"type": "fixed", "body": "ground"}],
    }


def test_a_tumbling_body_follows_the_quaternion_equations_through_150_degrees():
    """
    A free body spinning about an unstable axis turns through 150 degrees as DOP853 says.

    The body is held at its centre by a hinge without rotational stiffness; the reference
    integrates dq/dt = q (0, omega) / 2 and Euler's equations. The rotation-vector coordinates
    are singularity-free through large turns.
    """
    inertia = np.array([1e-4, 2e-4, 3e-4])
    sim = SpatialSimulation(spatial_from_dict(_tumbler(inertia)), dt=1e-3)
    omega0 = np.array([0.05, 2.0, 0.05])
    sim.state.v[9:12] = omega0

    def f(t, x):
        q, w = x[:4], x[4:]
        dq = 0.5 * np.array(rot.qmul(tuple(q), (0.0, *w)))
        return np.concatenate([dq, (np.cross(inertia * w, w)) / inertia])

    ref = scipy.integrate.solve_ivp(f, (0, 1.3), np.r_[1.0, 0, 0, 0, omega0], method="DOP853",
                                    rtol=1e-12, atol=1e-14, dense_output=True)
    turned = 0.0
    for k in range(13):
        sim.step(100)
        x = ref.sol(sim.state.t)
        q = sim.snapshot().quaternions[1]
        turned = max(turned, np.linalg.norm(sim.state.z[9:12]))
        assert min(np.abs(q - x[:4]).max(), np.abs(q + x[:4]).max()) < 2e-6
        assert np.allclose(sim.state.v[9:12], x[4:], rtol=0, atol=2e-5)
    assert turned > np.deg2rad(140)


def test_beyond_pi_from_rest_is_refused_naming_the_body():
    sim = SpatialSimulation(spatial_from_dict(_tumbler([1e-4, 1e-4, 1e-4])), dt=1e-2)
    sim.state.v[9:12] = [0.0, 0.0, 3.0]
    with pytest.raises(SolverError, match="body 'top' turned .* beyond the rotation"):
        sim.step(200)
