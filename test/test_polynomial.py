"""
Polynomial hinge laws (3.6, 4.7).

Indexing as Appendix B, exact derivatives, the rest conditions, damping, the frame/body claims of
3.69/4.70, and the hinge file.
"""
import math

import numpy as np
import pytest
import yaml

from flexure_sim.engine.kinematics import planar as kin
from flexure_sim.engine.laws.quadratic import QuadraticLaw, evaluate
from flexure_sim.engine.laws.monomials import (
    derivative_coefficients,
    monomial_exponents,
    monomial_index,
    monomials,
)
from flexure_sim.engine.laws.polynomial import (
    PolynomialLaw,
    quadratic_as_polynomial,
    swap_bodies,
    transform_frames,
)
from flexure_sim.engine.mechanism.polynomial_files import (
    PolynomialFileError,
    law_from_dict,
    load_law,
    save_law,
)

K_GENERAL = np.array([[2.0, 30.0, -12.0], [30.0, 4.0e4, 5.0e3], [-12.0, 5.0e3, 2.0e4]])
COORDS = ["twistor", "twist"]


# ------------------------------------------------------------ Appendix B, literally

def idx4_sci(i1, i2, i3, i4, N):
    """idx4.sci ported line by line (1-based)."""
    table = np.ones((N + 1, 4), dtype=int)
    for j in range(1, 4):
        for i in range(1, N + 1):
            table[i, j] = table[i - 1, j] + table[i, j - 1]
    ix = 1
    for i in range(N + 1, N + 1 - i4, -1):
        ix += table[i - 1, 3]
    N3 = N - i4
    for i in range(N3 + 1, N3 + 1 - i3, -1):
        ix += table[i - 1, 2]
    N2 = N3 - i3
    for i in range(N2 + 1, N2 + 1 - i2, -1):
        ix += table[i - 1, 1]
    N1 = N2 - i2
    for i in range(N1 + 1, N1 + 1 - i1, -1):
        ix += table[i - 1, 0]
    return ix


def evalpoly4_sci(x1, x2, x3, x4, N, c):
    """evalpoly4.sci ported line by line."""
    val, index, val4 = 0.0, 0, 1.0
    for i4 in range(N + 1):
        val3 = val4
        for i3 in range(N - i4 + 1):
            val2 = val3
            for i2 in range(N - i4 - i3 + 1):
                val1 = val2
                for i1 in range(N - i4 - i3 - i2 + 1):
                    val += c[index] * val1
                    index += 1
                    val1 *= x1
                val2 *= x2
            val3 *= x3
        val4 *= x4
    return val


@pytest.mark.parametrize("N", [0, 1, 2, 4, 6])
def test_monomial_order_is_that_of_idx4_and_evalpoly4(N):
    exps = monomial_exponents(4, N)
    assert len(exps) == math.comb(N + 4, 4)
    for j, e in enumerate(exps):
        assert idx4_sci(*e, N) == j + 1
        assert monomial_index(e, N) == j
    rng = np.random.default_rng(N)
    c = rng.normal(size=len(exps))
    x = rng.uniform(-1.5, 1.5, 4)
    assert monomials(x[None], exps)[0] @ c == pytest.approx(evalpoly4_sci(*x, N, c), rel=1e-12)


def test_derivative_coefficients_are_those_of_randomtest_sce():
    """c_Sigma(index) = (i1+1) c_U(idx4(i1+1, i2, i3, i4, N)) etc. (4.75-4.78)."""
    N = 4
    rng = np.random.default_rng(0)
    cU = rng.normal(size=math.comb(N + 4, 4))
    lower = monomial_exponents(4, N - 1)
    for var in range(4):
        mine = derivative_coefficients(cU, 4, N, var)
        for j, e in enumerate(lower):
            up = list(e)
            up[var] += 1
            expected = (e[var] + 1) * cU[idx4_sci(*up, N) - 1]
            assert mine[monomial_index(e, N)] == pytest.approx(expected, rel=1e-15)
        # and the degree-N entries of the derivative are zero
        top = monomial_exponents(4, N).sum(axis=1) == N
        assert np.all(mine[top] == 0)


# ------------------------------------------------------------------ random laws

def random_law(coords, order, rng, sigma=True, scale=None, energy=1.3):
    """Return a general polynomial law: every admissible term, random coefficients."""
    k = 4 if coords == "twistor" else 3
    exps = monomial_exponents(k, order)
    deg = exps.sum(axis=1)
    keep = deg >= 2
    if coords == "twistor":
        keep |= (deg == 1) & (exps[:, 0] == 1)
        if not sigma:
            keep &= exps[:, 0] == 0
    exps = exps[keep]
    if scale is None:
        scale = (
            np.array([0.05, 0.4, 2e-3, 3e-3])
            if coords == "twistor"
            else np.array([0.8, 4e-3, 6e-3])
        )
    coef = rng.normal(size=len(exps))
    # a positive-definite quadratic part so the law is a plausible hinge
    B = rng.normal(size=(k, k))
    for e_i, e in enumerate(exps):
        if e.sum() == 2 and (coords == "twist" or e[0] == 0):
            i, j = np.nonzero(e)[0][[0, -1]]
            coef[e_i] = (B @ B.T + 3 * np.eye(k))[i, j] * (0.5 if i == j else 1.0)
    return PolynomialLaw(coords, order, exps, coef, scale, energy)


def ev(law, r, rdot=None):
    r = np.atleast_2d(r)
    rdot = np.zeros_like(r) if rdot is None else np.atleast_2d(rdot)
    return evaluate([law] * len(r), r[:, 0], r[:, 1:], rdot)


def fd(f, x, h):
    g = []
    for i in range(len(x)):
        e = np.zeros_like(x)
        e[i] = h[i]
        g.append((f(x + e) - f(x - e)) / (2 * h[i]))
    return np.array(g).T


CONFIGS = [
    np.array([0.3, 2e-3, -1e-3]),
    np.array([-1.1, -4e-3, 3e-3]),
    np.array([2.5, 1e-2, 5e-3]),
    np.array([4e-3, 2e-6, -3e-6]),
]


@pytest.mark.parametrize("coords", COORDS)
@pytest.mark.parametrize("order", [2, 3, 5])
@pytest.mark.parametrize("r", CONFIGS)
def test_wrench_is_the_exact_gradient_and_the_hessian_is_exact(coords, order, r):
    rng = np.random.default_rng(order)
    law = random_law(coords, order, rng).with_damping(1e-3 * K_GENERAL)
    h = np.maximum(np.abs(r), 1e-4) * 1e-5
    e = ev(law, r)
    g_fd = fd(lambda x: ev(law, x).energy[0], r, h)
    assert e.grad[0] == pytest.approx(g_fd, rel=1e-6, abs=1e-8 * np.abs(e.grad).max())
    H_fd = fd(lambda x: ev(law, x).grad[0], r, h)
    assert e.hess[0] == pytest.approx(H_fd, rel=1e-5, abs=1e-7 * np.abs(e.hess).max())
    rdot = np.array([0.7, -0.02, 0.03])
    d = ev(law, r, rdot)
    D_fd = fd(lambda x: ev(law, x, rdot).damping_force[0], r, h)
    assert d.damping_force_dr[0] == pytest.approx(
        D_fd, rel=1e-5, abs=1e-7 * np.abs(d.damping_force_dr).max()
    )


@pytest.mark.parametrize("coords", COORDS)
def test_potential_derivatives_in_law_coordinates_are_exact(coords):
    """
    dU/dc and d2U/dc2 against finite differences of U and dU/dc.

    They are checked at general c (sigma off the unit circle too: the polynomial is defined on all
    of R^4).
    """
    rng = np.random.default_rng(11)
    law = random_law(coords, 6, rng)
    k = len(law.scale)
    for _ in range(5):
        c = law.rest + rng.uniform(-1, 1, k) * law.scale
        U, g, H = law.potential(c[None])
        h = law.scale * 1e-5
        g_fd = fd(lambda x: law.potential(x[None])[0][0], c, h)
        H_fd = fd(lambda x: law.potential(x[None])[1][0], c, h)
        assert g[0] == pytest.approx(g_fd, rel=1e-6, abs=1e-9 * abs(g).max())
        assert H[0] == pytest.approx(H_fd, rel=1e-6, abs=1e-8 * abs(H).max())
        assert np.array_equal(H[0], H[0].T)


@pytest.mark.parametrize("coords", COORDS)
def test_unstressed_pose_is_an_unstressed_equilibrium(coords):
    rng = np.random.default_rng(5)
    law = random_law(coords, 6, rng)
    e = ev(law, np.zeros(3))
    assert e.energy[0] == 0.0
    assert np.all(e.grad[0] == 0.0)
    # The stiffness at rest is the Hessian there (4.52) and is what reporting uses.
    assert law.stiffness_at_rest() == pytest.approx(e.hess[0], rel=1e-14)


@pytest.mark.parametrize("coords,exps,what", [
    ("twistor", [[0, 0, 0, 0]], "sigma^0"),
    ("twistor", [[0, 1, 0, 0]], "xi"),
    ("twistor", [[0, 0, 0, 1]], "x2"),
    ("twist", [[1, 0, 0]], "tau"),
    ("twist", [[0, 1, 0]], "t1"),
])
def test_constant_and_linear_terms_are_rejected(coords, exps, what):
    k = len(exps[0])
    with pytest.raises(ValueError) as err:
        PolynomialLaw(coords, 3, np.array(exps), np.array([0.5]), np.ones(k), 1.0)
    msg = str(err.value)
    assert "unstressed equilibrium" in msg and "degree" in msg


def test_sigma_minus_one_is_allowed_for_twistors():
    """(sigma - 1) ~ -alpha^2/8 has zero gradient at rest: a second-order term in r."""
    law = PolynomialLaw("twistor", 2, np.array([[1, 0, 0, 0]]), np.array([-8.0]), np.ones(4), 1.0)
    e = ev(law, np.zeros(3))
    assert e.energy[0] == 0 and np.all(e.grad == 0)
    assert e.hess[0, 0, 0] == pytest.approx(2.0)  # U = -8 (cos(a/2) - 1) = a^2 + ...


@pytest.mark.parametrize("coords", COORDS)
def test_quadratic_laws_are_order_two_polynomials_with_the_same_damping(coords):
    """
    4.7 and 3.4 written as polynomials.

    Same energy, wrench, Hessian and dissipation (the damping metric 4B on (xi, x) for twistors, B
    for twists).
    """
    K, B = K_GENERAL, 1e-3 * K_GENERAL
    poly = quadratic_as_polynomial(K, coords, B)
    quad = QuadraticLaw(coords, K, B)
    r = np.array([[0.7, 0.02, -0.03], [2.0, 0.1, 0.05], [-1e-4, 3e-7, 1e-7]])
    rdot = np.array([[0.3, 1e-3, -2e-3], [0.0, 0.1, 0.0], [1.0, 0.0, 1.0]])
    a = evaluate([poly] * 3, r[:, 0], r[:, 1:], rdot)
    b = evaluate([quad] * 3, r[:, 0], r[:, 1:], rdot)
    for name in ("energy", "grad", "hess", "damping", "damping_force", "damping_force_dr"):
        x, y = getattr(a, name), getattr(b, name)
        assert x == pytest.approx(y, rel=1e-12, abs=1e-14 * np.abs(y).max()), name
    assert poly.stiffness_at_rest() == pytest.approx(K, rel=1e-12)


# ------------------------------------------------- independence (3.69, 4.70)

def _relative(Ha, Hb):
    R, p = kin.relative(Ha, Hb)
    return np.r_[kin.angle_of(R), p]


def _poses(rng):
    Ha = (kin.rot(rng.uniform(-3, 3)), rng.normal(size=2))
    Hb = kin.compose(Ha, (kin.rot(rng.uniform(-1.5, 1.5)), rng.normal(size=2) * 5e-3))
    return Ha, Hb


@pytest.mark.parametrize("coords", COORDS)
def test_moving_the_frames_gives_another_polynomial_of_the_same_order(coords):
    """
    3.69 / 4.70.

    For frames a' = a G, b' = b G there are coefficients c' of the same order with the same energy
    (transform_frames); the same coefficients alone would not do.
    """
    rng = np.random.default_rng(3)
    law = random_law(coords, 5, rng)
    for _ in range(10):
        Ha, Hb = _poses(rng)
        G = (kin.rot(rng.uniform(-3, 3)), rng.normal(size=2) * 4e-3)
        moved = transform_frames(law, *G)
        assert moved.order == law.order and np.all(moved.exponents.sum(axis=1) <= law.order)
        r = _relative(Ha, Hb)
        r_moved = _relative(kin.compose(Ha, G), kin.compose(Hb, G))
        u = ev(law, r).energy[0]
        assert ev(moved, r_moved).energy[0] == pytest.approx(u, rel=1e-9, abs=1e-12)
        assert abs(ev(law, r_moved).energy[0] - u) > 1e-3 * abs(u)
        # Still an unstressed equilibrium at rest.
        assert np.all(ev(moved, np.zeros(3)).grad == 0)


@pytest.mark.parametrize("coords", COORDS)
def test_transform_frames_of_a_quadratic_law_is_the_adjoint_stiffness(coords):
    G = (kin.rot(0.7), np.array([3e-3, -2e-3]))
    moved = transform_frames(quadratic_as_polynomial(K_GENERAL, coords, 1e-3 * K_GENERAL), *G)
    K_moved = kin.transform_stiffness(K_GENERAL, *G)
    assert moved.stiffness_at_rest() == pytest.approx(K_moved, rel=1e-10)
    assert moved.B == pytest.approx(1e-3 * K_moved, rel=1e-12)
    r = np.array([0.9, 4e-3, -1e-3])
    assert ev(moved, r).energy[0] == pytest.approx(
        ev(QuadraticLaw(coords, K_moved, K_moved), r).energy[0], rel=1e-10
    )


@pytest.mark.parametrize("coords", COORDS)
def test_swapping_the_bodies_needs_the_swapped_coefficients_unless_the_law_is_even(coords):
    """
    The claim holds as 'there exist coefficients' (swap_bodies flips the odd terms).

    With the same coefficients a polynomial with odd terms changes its energy when A and B are
    exchanged; an even one (e.g. the quadratic laws) does not.
    """
    rng = np.random.default_rng(8)
    law = random_law(coords, 4, rng)
    swapped = swap_bodies(law)
    k = len(law.scale)
    vec = law.exponents[:, 1:].sum(axis=1) if coords == "twistor" else law.exponents.sum(axis=1)
    even = PolynomialLaw(
        coords,
        4,
        law.exponents[vec % 2 == 0],
        law.coefficients[vec % 2 == 0],
        law.scale,
        law.energy,
    )
    assert k == law.exponents.shape[1]
    for _ in range(10):
        Ha, Hb = _poses(rng)
        r_ab, r_ba = _relative(Ha, Hb), _relative(Hb, Ha)
        u = ev(law, r_ab).energy[0]
        assert ev(swapped, r_ba).energy[0] == pytest.approx(u, rel=1e-10, abs=1e-13)
        assert abs(ev(law, r_ba).energy[0] - u) > 1e-6 * abs(u)
        assert ev(even, r_ba).energy[0] == pytest.approx(ev(even, r_ab).energy[0], rel=1e-10)


def test_the_twistor_quadratic_law_is_its_own_swap():
    law = quadratic_as_polynomial(K_GENERAL, "twistor")
    assert swap_bodies(law).dense_coefficients() == pytest.approx(law.dense_coefficients(), abs=0)


# ------------------------------------------------------------------- the file

def test_file_round_trip(tmp_path):
    law = random_law("twistor", 4, np.random.default_rng(2))
    path = tmp_path / "hinge.yaml"
    save_law(law, path, {"fit": {"note": "x"}})
    back = load_law(path)
    assert back.coordinates == law.coordinates and back.order == law.order
    assert np.array_equal(back.exponents, law.exponents)
    assert np.array_equal(back.coefficients, law.coefficients)
    assert np.array_equal(back.scale, law.scale) and back.energy == law.energy
    assert back.source == str(path)
    doc = yaml.safe_load(path.read_text())
    assert np.array(doc["stiffness_at_rest"]) == pytest.approx(law.stiffness_at_rest(), rel=1e-15)


@pytest.mark.parametrize(
    "edit,key,fragment",
    [
        (lambda d: d.update(format="something"), "format", "flexure_sim.polynomial_hinge"),
        (lambda d: d.update(coordinates="quaternion"), "coordinates", "twistor, twist"),
        (lambda d: d.update(order=2.5), "order", "integer"),
        (lambda d: d.update(scale=[1.0, 1.0]), "scale", "list of 4 numbers"),
        (lambda d: d["scale"].__setitem__(2, -1.0), "scale[2]", "positive"),
        (lambda d: d.update(energy=".nan"), "energy", "finite"),
        (
            lambda d: d["terms"][1].__setitem__("coefficient", "abc"),
            "terms[1].coefficient",
            "finite number",
        ),
        (
            lambda d: d["terms"][0].__setitem__("exponents", [0, 2, 0]),
            "terms[0].exponents",
            "4 non-negative integers",
        ),
        (
            lambda d: d["terms"][0].__setitem__("exponents", [0, 9, 0, 0]),
            "terms[0].exponents",
            "exceeds the order",
        ),
        (
            lambda d: d["terms"].append({"exponents": [0, 0, 1, 0], "coefficient": 1.0}),
            "terms",
            "unstressed equilibrium",
        ),
        (lambda d: d.update(rest=[0, 0, 0, 0]), "rest", "unstressed pose"),
    ],
)
def test_bad_files_name_the_file_key_and_problem(tmp_path, edit, key, fragment):
    law = random_law("twistor", 3, np.random.default_rng(4), sigma=False)
    path = tmp_path / "bad_hinge.yaml"
    save_law(law, path)
    doc = yaml.safe_load(path.read_text())
    edit(doc)
    path.write_text(yaml.safe_dump(doc))
    with pytest.raises(PolynomialFileError) as err:
        load_law(path)
    msg = str(err.value)
    assert msg.startswith(f"{path}: {key}:"), msg
    assert fragment in msg, msg


def test_missing_file_and_bad_yaml(tmp_path):
    with pytest.raises(PolynomialFileError, match="cannot read"):
        load_law(tmp_path / "nope.yaml")
    p = tmp_path / "broken.yaml"
    p.write_text("terms: [\n")
    with pytest.raises(PolynomialFileError, match="not valid YAML"):
        load_law(p)
    with pytest.raises(PolynomialFileError, match="must be a mapping"):
        law_from_dict([1, 2], "x.yaml")
