"""
6x6 hinge stiffness: notch and leaf against beam theory, and in mechanisms.

Independent sources: SciPy's adaptive quadrature of the beam integrals over the notch
profile; Timoshenko and Goodier's table of the rectangle's torsion coefficient; the exact
built-in torsion of a thin strip with restrained warping (Timoshenko and Gere 1961, 5.3); a
spatial parallelogram assembled from 3-D Timoshenko beam elements (Przemieniecki's 12x12
element stiffness), and the closed forms of a single leaf in torsion.
"""
import numpy as np
import pytest
import scipy.integrate

from flexure_sim.engine.analysis import spatial_linear
from flexure_sim.engine.hinges import spatial_stiffness as s6
from flexure_sim.engine.hinges import stiffness as s3
from flexure_sim.engine.mechanism.spatial_loader import spatial_from_dict
from flexure_sim.engine.solver.spatial_model import SpatialModel
from flexure_sim.engine.solver.spatial_statics import static

E, NU = 69.0e9, 0.33
G = E / (2 * (1 + NU))


def test_in_plane_blocks_are_the_planar_formulas_to_the_bit():
    K = s6.notch_stiffness(0.003, 0.00025, 0.02, E, NU)
    assert np.array_equal(K[np.ix_([2, 3, 4], [2, 3, 4])],
                          s3.notch_stiffness(0.003, 0.00025, 0.02, E, NU))
    L = s6.cantilever_stiffness(0.02, 0.0005, 0.01, E, NU)
    assert np.array_equal(L[np.ix_([2, 3, 4], [2, 3, 4])],
                          s3.cantilever_stiffness(0.02, 0.0005, 0.01, E, NU))
    assert np.count_nonzero(K - np.diag(np.diag(K))) == 0


@pytest.mark.parametrize("D, h, t", [(0.003, 0.00025, 0.02), (0.004, 0.0001, 0.005),
                                     (0.002, 0.001, 0.003), (0.01, 0.00005, 0.01)])
def test_notch_out_of_plane_terms_are_the_beam_integrals(D, h, t):
    """k_ry, k_z and k_rx from the module's formulas with SciPy's quad over the profile."""
    r = D / 2

    def thick(x):
        return h + 2 * r - 2 * np.sqrt(r * r - x * x)

    def integral(f):
        return scipy.integrate.quad(f, -r, r, epsabs=0, epsrel=1e-12, limit=400, points=[0])[0]

    kappa = 10 * (1 + NU) / (12 + 11 * NU)
    k_ry = 1 / integral(lambda x: 12 / (E * thick(x) * t**3))
    k_z = 1 / (integral(lambda x: 12 * x * x / (E * thick(x) * t**3))
               + integral(lambda x: 1 / (kappa * G * t * thick(x))))
    k_sv = 1 / integral(lambda x: 1 / (G * s6.torsion_constant(t, thick(x))))
    k_t = 1 / integral(lambda x: 12 * x * x / (E * t * thick(x) ** 3))
    K = s6.notch_stiffness(D, h, t, E, NU)
    assert K[1, 1] == pytest.approx(k_ry, rel=1e-10)
    assert K[5, 5] == pytest.approx(k_z, rel=1e-10)
    assert K[0, 0] == pytest.approx(k_sv + t * t / 12 * k_t, rel=1e-9)


@pytest.mark.parametrize("ratio, beta", [(1.0, 0.141), (1.5, 0.196), (2.0, 0.229),
                                         (3.0, 0.263), (5.0, 0.291), (10.0, 0.312)])
def test_torsion_constant_is_timoshenko_and_goodiers_table(ratio, beta):
    """J = beta a b^3 (Timoshenko and Goodier, Theory of Elasticity, 1970, table of sec. 109)."""
    assert s6.torsion_constant(ratio * 2e-3, 2e-3) / (ratio * 2e-3 * 8e-9) == pytest.approx(
        beta, abs=6e-4)


@pytest.mark.parametrize("length", [0.002, 0.005, 0.01, 0.03, 0.1, 0.5])
def test_leaf_torsion_is_within_the_stated_band_of_the_exact_built_in_strip(length):
    """
    Leaf torsion is within 11 % below the exact built-in strip.

    Saint-Venant plus restrained warping against the exact solution of a strip built in at both
    ends, (G J / L) / (1 - 2 tanh(x/2)/x), x = L sqrt(G J / (E C_w)).
    """
    width, thickness = 0.01, 0.0005
    J = s6.torsion_constant(width, thickness)
    Cw = width**3 * thickness**3 / 144
    x = length * np.sqrt(G * J / (E * Cw))
    exact = G * J / length / (1 - 2 * np.tanh(x / 2) / x)
    k = s6.cantilever_stiffness(length, thickness, width, E, NU)[1, 1]
    assert 0.885 * exact <= k <= exact * (1 + 1e-12)
    if length >= 0.5:
        assert k == pytest.approx(G * J / length, rel=0.01)


def leaf_mechanism(law, torque_axis="ry"):
    """One leaf (length along y) between the fixed ground and a body, a torque drive."""
    return spatial_from_dict({
        "name": "torsion_leaf", "space": "3d",
        "defaults": {"law": law, "damping": {"t_char": 0.0}},
        "stiffness_models": {"leaf": {"model": "cantilever", "length": 0.04,
                                      "thickness": 0.0005, "width": 0.004, "E": E, "nu": NU}},
        "bodies": [{"name": "ground", "mass": 1.0, "inertia": [1, 1, 1]},
                   {"name": "tip", "mass": 0.01, "inertia": [1e-6, 1e-6, 1e-6],
                    "pose": [0, 0.03, 0]}],
        "hinges": [{"name": "leaf", "a": {"body": "ground", "at": [0, 0.01, 0]},
                    "b": {"body": "tip", "at": [0, -0.02, 0]}, "stiffness": "leaf"}],
        "constraints": [{"type": "fixed", "body": "ground"},
                        {"type": "force", "name": "torque", "body": "tip", "axis": torque_axis,
                         "response_time": 1e-3, "stroke": [-1, 1], "slew_rate": 1}],
        "outputs": [{"name": "twist", "body": "tip", "coordinate": torque_axis}],
    })


@pytest.mark.parametrize("law", ["twistor", "twist"])
def test_a_torsion_leaf_twists_as_beam_theory_and_its_law_say(law):
    """
    Small torque: twist T / k_t with k_t = G J / L + E w^3 t^3 / (12 L^3) (module docstring).

    Large torque (about 35 deg): the pure twist theta of the law's closed form, T = k_t sin
    theta (twistor, U = 2 k sin^2(theta/2)) or T = k_t theta (twist, U = k theta^2 / 2).
    """
    model = SpatialModel(leaf_mechanism(law))
    J = s6.torsion_constant(0.004, 0.0005)
    k = G * J / 0.04 + E * 0.004**3 * 0.0005**3 / (12 * 0.04**3)
    small = static(model, 1e-7)
    assert model.output_values(small.z)[0] == pytest.approx(1e-7 / k, rel=1e-9)
    T = 0.6 * k
    big = static(model, T)
    theta = np.arcsin(0.6) if law == "twistor" else 0.6
    assert model.output_values(big.z)[0] == pytest.approx(theta, rel=1e-12)
    assert np.allclose(big.z[6:9], [0, 0.03, 0], rtol=0, atol=1e-15)


def timoshenko_element(L, EA, GJ, EIy, EIz, kGAy, kGAz):
    """
    Return the 12x12 stiffness of a 3-D Timoshenko beam along its local x axis.

    Przemieniecki, Theory of Matrix Structural Analysis, 1968, eq. 5.116; dofs (u, v, w, rx,
    ry, rz) at each end.
    """
    K = np.zeros((12, 12))
    K[0, 0] = K[6, 6] = EA / L
    K[0, 6] = K[6, 0] = -EA / L
    K[3, 3] = K[9, 9] = GJ / L
    K[3, 9] = K[9, 3] = -GJ / L
    for EI, kGA, (v, r), sign in ((EIz, kGAy, (1, 5), 1.0), (EIy, kGAz, (2, 4), -1.0)):
        phi = 12 * EI / (kGA * L * L)
        a = 12 * EI / (L**3 * (1 + phi))
        b = sign * 6 * EI / (L * L * (1 + phi))
        c = (4 + phi) * EI / (L * (1 + phi))
        d = (2 - phi) * EI / (L * (1 + phi))
        i, j, k, m = v, r, v + 6, r + 6
        for (p, q, val) in ((i, i, a), (k, k, a), (i, k, -a), (i, j, b), (i, m, b), (k, j, -b),
                            (k, m, -b), (j, j, c), (m, m, c), (j, m, d)):
            K[p, q] = K[q, p] = val
    return K


def rigid(r):
    """Node displacement (u, theta) of a point at r on a body moved by (dp, dtheta)."""
    T = np.eye(6)
    T[:3, 3:] = -np.array([[0, -r[2], r[1]], [r[2], 0, -r[0]], [-r[1], r[0], 0]])
    return T


def test_spatial_parallelogram_is_the_timoshenko_frame_model():
    """
    A spatial parallelogram is the Timoshenko frame model.

    A platform on two parallel leaves (along y, 20 mm apart along x, the second also 6 mm along
    z): its 6x6 stiffness at the platform's mass centre from the engine's exact linearisation
    equals the stiffness of the same two leaves as Timoshenko beam elements clamped in the
    ground and the platform, to 1e-9.
    """
    L, t, w = 0.02, 0.0005, 0.006
    doc = {
        "name": "parallelogram3d", "space": "3d",
        "defaults": {"law": "twistor", "damping": {"t_char": 0.0}},
        "stiffness_models": {"leaf": {"model": "cantilever", "length": L, "thickness": t,
                                      "width": w, "E": E, "nu": NU}},
        "bodies": [{"name": "ground", "mass": 1.0, "inertia": [1, 1, 1]},
                   {"name": "platform", "mass": 0.01, "inertia": [1e-6, 2e-6, 3e-6],
                    "pose": [0.004, 0.03, 0.001]}],
        "hinges": [{"name": "left", "a": {"body": "ground", "at": [-0.01, 0.01, 0.0]},
                    "b": {"body": "platform", "at": [-0.014, -0.02, -0.001]},
                    "stiffness": "leaf"},
                   {"name": "right", "a": {"body": "ground", "at": [0.01, 0.01, 0.006]},
                    "b": {"body": "platform", "at": [0.006, -0.02, 0.005]},
                    "stiffness": "leaf"}],
        "constraints": [{"type": "fixed", "body": "ground"}],
    }
    model = SpatialModel(spatial_from_dict(doc))
    K_engine = spatial_linear.linearize(model).stiffness
    K6 = s6.cantilever_stiffness(L, t, w, E, NU)
    kappa = 10 * (1 + NU) / (12 + 11 * NU)
    # element along its local x = the leaf's y; local y = the leaf's x (thickness), local
    # z = the leaf's z (width). Local -> root: columns (e_y, e_x, -e_z) of the root axes.
    Rl = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]]).T
    Ke = timoshenko_element(L, E * w * t, K6[1, 1] * L, E * t * w**3 / 12, E * w * t**3 / 12,
                            1e30, kappa * G * w * t)
    Tl = np.kron(np.eye(4), Rl.T)
    Kroot = Tl.T @ Ke @ Tl
    centre = np.array([0.004, 0.03, 0.001])
    K_frame = np.zeros((6, 6))
    for mid in (np.array([-0.01, 0.01, 0.0]), np.array([0.01, 0.01, 0.006])):
        top = mid + [0, L / 2, 0] - centre  # the leaf's end in the platform
        Kpp = Kroot[6:, 6:]
        K_frame += rigid(top).T @ Kpp @ rigid(top)
    assert np.allclose(K_engine, K_frame, rtol=0, atol=1e-9 * np.abs(K_frame).max())
    # and the platform slides along x on 2 x 12 E I / L^3, guided
    assert K_engine[0, 0] == pytest.approx(2 * 12 * E * w * t**3 / 12 / L**3, rel=1e-3)
