"""
Polynomial hinge laws: potentials of order N in twistor or twist coordinates (4.69, 3.67).

The dissertation writes the potential of an elastic element as a polynomial of order N in
its law coordinates c (Sections 3.6 and 4.7),

    twistor (4.69):  U = sum_{i1+i2+i3+i4 <= N} c_U(idx) sigma^i1 xi^i2 x1^i3 x2^i4,
    twist   (3.67):  U = sum_{i1+i2+i3 <= N}    c_U(idx) tau^i1 t1^i2 t2^i3,

with the coefficients in one array indexed by idx4.sci (Appendix B). flexure_sim stores the
same polynomials written about the unstressed pose and in scaled variables,

    U(c) = E * sum_j a_j prod_k u_k^(e_jk),    u_k = (c_k - c_k^rest) / s_k,

rest = (1, 0, 0, 0) for twistors and 0 for twists. Expanding the powers of
u_sigma = (sigma - 1)/s_sigma gives back the form of 4.69 with the same order N; the shift and
the scales s_k (lengths for x, t; the data ranges in a fit) keep the monomials of order up
to 8 of size one, and the energy scale E keeps the coefficients of size one.

*Unstressed equilibrium.* U(rest) = 0 and dU/dr(rest) = 0 (the zero- and first-order
conditions of Section 3.6): the constant term and the terms linear in the vector
coordinates (xi, x1, x2) or (tau, t1, t2) must be absent. For twistors the term u_sigma is
allowed: dsigma/dr = (-xi/2, 0, 0) vanishes at rest, so (sigma - 1) ~ -alpha^2/8 is second
order in the displacement.

*Generalized forces.* dU/dc_k is again a polynomial, of order N - 1, whose coefficients
follow from those of U (eqs. 4.75-4.78 for twistors, 3.73-3.75 for twists):
c_k(idx(i - e_k)) = i_k c_U(idx(i)); the second derivatives apply the same rule twice. The
wrench m_b then follows through the virtual-displacement map (eqs. 4.82-4.84, 3.82), which
``hinge_laws.evaluate`` and ``hinge_laws.wrench_on_element`` implement for every law.

*Independence of bodies and frames (3.69, 4.70).* Moving both hinge frames by G = (R, p)
maps the coordinates linearly (d = Ad(G) d', and for twistors sigma = sigma',
[xi; x] = Ad(G)[xi'; x']), so the law becomes another polynomial of the same order:
``transform_frames``. Swapping bodies A and B inverts the displacement (d -> -d,
(sigma, xi, x) -> (sigma, -xi, -x)), again a linear map: ``swap_bodies``. The *same*
coefficients give the same energy after a swap only when the polynomial is even in the
vector coordinates (as the quadratic laws are); see docs/polynomial_hinges.md.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np

from flexure_sim.errors import as_array
from flexure_sim.engine.laws.quadratic import LawPower, QuadraticLaw, evaluate
from flexure_sim.engine.kinematics.planar import adjoint, transform_stiffness
from flexure_sim.engine.laws.monomials import (
    compose_linear, derivative_coefficients, describe_monomial, monomial_exponents,
    monomial_index, monomials,
)

#: Names of the law coordinates, in the order of c.
VARIABLES: dict[str, tuple[str, ...]] = {
    "twistor": ("sigma", "xi", "x1", "x2"),
    "twist": ("tau", "t1", "t2"),
}

#: Law coordinates of the unstressed pose.
REST: dict[str, tuple[float, ...]] = {"twistor": (1.0, 0.0, 0.0, 0.0), "twist": (0.0, 0.0, 0.0)}

#: Highest order accepted (the monomial count grows as N^4 / 24 for twistors).
MAX_ORDER = 12


# ------------------------------------------------------------------------- the law

@dataclass(frozen=True)
class PolynomialLaw(LawPower):
    """
    Polynomial hinge law: a potential U(c) and a dissipation D.

    Potential U(c) = E sum_j a_j prod_k ((c_k - rest_k) / s_k)^(e_jk) and dissipation
    D = 1/2 c_dot^T C c_dot, C the damping B embedded as the quadratic laws embed it (4 B on
    (xi, x) for twistors, B for twists); E = energy, a = coefficients, s = scale,
    e = exponents. Energy and power: `hinge_laws.LawPower`.

    coordinates: "twistor" (c = sigma, xi, x1, x2) or "twist" (c = tau, t1, t2);
    order: N, the largest total degree allowed; exponents (M, k) and coefficients (M,) the
    terms; scale (k,) the s_k (dimensionless for sigma, xi, tau; metres for x, t);
    energy: E in joules; B: 3x3 damping matrix (moment first, in the hinge frame), mapped to
    the law coordinates as the quadratic laws do (4 B on (xi, x) for twistors, B for
    twists), so that a polynomial fitted to a quadratic law damps like it.
    The terms must leave the unstressed pose an unstressed equilibrium (module docstring).
    """

    coordinates: str
    order: int
    exponents: np.ndarray
    coefficients: np.ndarray
    scale: np.ndarray
    energy: float
    B: np.ndarray = field(default_factory=lambda: np.zeros((3, 3)))
    source: str = ""
    _table: np.ndarray = field(init=False, repr=False, compare=False)
    _pairs: tuple = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        if self.coordinates not in VARIABLES:
            raise ValueError(
                f"coordinates must be one of {sorted(VARIABLES)}, got {self.coordinates!r}"
            )
        names = VARIABLES[self.coordinates]
        k = len(names)
        integer = isinstance(self.order, (int, np.integer)) and not isinstance(self.order, bool)
        if not integer or not 1 <= self.order <= MAX_ORDER:
            raise ValueError(f"order must be an integer in 1..{MAX_ORDER}, got {self.order!r}")
        order = int(self.order)
        exps = np.asarray(self.exponents)
        if (
            exps.ndim != 2
            or exps.shape[1] != k
            or (exps.size and not np.all(exps == np.round(exps)))
        ):
            raise ValueError(
                f"exponents must be an (M, {k}) array of integers, got shape {exps.shape}"
            )
        exps = exps.astype(int)
        coef = np.asarray(self.coefficients, dtype=float)
        if coef.shape != (exps.shape[0],):
            raise ValueError(f"coefficients must have shape ({exps.shape[0]},), got {coef.shape}")
        if not np.all(np.isfinite(coef)):
            raise ValueError("coefficients must be finite")
        scale = np.asarray(self.scale, dtype=float)
        if scale.shape != (k,) or not np.all(np.isfinite(scale)) or np.any(scale <= 0):
            raise ValueError(
                f"scale must be {k} positive numbers ({', '.join(names)}), got {self.scale!r}"
            )
        if not (np.isfinite(self.energy) and self.energy > 0):
            raise ValueError(f"energy must be a positive number of joules, got {self.energy!r}")
        B = np.asarray(self.B, dtype=float)
        if (
            B.shape != (3, 3)
            or not np.all(np.isfinite(B))
            or not np.allclose(B, B.T, rtol=1e-12, atol=0.0)
        ):
            raise ValueError("B must be a symmetric 3x3 matrix")
        if np.any(exps < 0) or np.any(exps.sum(axis=1) > order):
            bad = int(np.nonzero((exps < 0).any(axis=1) | (exps.sum(axis=1) > order))[0][0])
            raise ValueError(
                f"term {bad} ({describe_monomial(exps[bad], names)}) is not a monomial of order "
                f"<= {order}"
            )
        if len({tuple(e) for e in exps}) != len(exps):
            raise ValueError("exponents repeat a monomial (each term must appear once)")
        # The vector coordinates: all but sigma for twistors (u_sigma may appear alone).
        vector = names[1:] if self.coordinates == "twistor" else names
        for e, a in zip(exps, coef):
            deg = int(e.sum())
            if a != 0.0 and (deg == 0 or (deg == 1 and names[int(np.argmax(e))] in vector)):
                raise ValueError(
                    f"term {describe_monomial(e, names)} has degree {deg}: the unstressed pose "
                    "must be an "
                    f"unstressed equilibrium (U = 0 and dU/dr = 0 at rest), so the constant term "
                    f"and the terms linear in {', '.join(vector)} must be absent"
                )
        object.__setattr__(self, "exponents", exps)
        object.__setattr__(self, "coefficients", coef)
        object.__setattr__(self, "scale", scale)
        object.__setattr__(self, "energy", float(self.energy))
        object.__setattr__(self, "order", order)
        object.__setattr__(self, "B", B)
        # Dense coefficients of U and of its first and second derivatives (4.75-4.78).
        dense = np.zeros(len(monomial_exponents(k, order)))
        for e, a in zip(exps, coef):
            dense[monomial_index(e, order)] = a
        first = [derivative_coefficients(dense, k, order, i) for i in range(k)]
        pairs = tuple((i, j) for i in range(k) for j in range(i, k))
        second = [derivative_coefficients(first[i], k, order, j) for i, j in pairs]
        object.__setattr__(self, "_table", np.column_stack([dense, *first, *second]))
        object.__setattr__(self, "_pairs", pairs)

    # ------------------------------------------------------------ HingeLaw protocol
    @property
    def variables(self) -> tuple[str, ...]:
        """Names of the law coordinates."""
        return VARIABLES[self.coordinates]

    @property
    def rest(self) -> np.ndarray:
        """Law coordinates of the unstressed pose."""
        return np.array(REST[self.coordinates])

    def potential(self, c: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """U (m,), dU/dc (m, k), d2U/dc2 (m, k, k) for rows c (m, k) -- exact (4.69-4.78)."""
        k = len(self.scale)
        c = as_array("c", np.atleast_2d(c), (None, k))
        u = (c - self.rest) / self.scale
        vals = monomials(u, monomial_exponents(k, self.order)) @ self._table
        U = self.energy * vals[:, 0]
        grad = self.energy * vals[:, 1:1 + k] / self.scale
        hess = np.empty((len(c), k, k))
        for col, (i, j) in enumerate(self._pairs):
            h = self.energy * vals[:, 1 + k + col] / (self.scale[i] * self.scale[j])
            hess[:, i, j] = h
            hess[:, j, i] = h
        return U, grad, hess

    def dissipation_matrix(self) -> np.ndarray:
        """C of D = 1/2 c_dot^T C c_dot: B embedded as the quadratic laws embed it (4.40, 3.62)."""
        return QuadraticLaw(self.coordinates, np.zeros((3, 3)), self.B).dissipation_matrix()

    # ------------------------------------------------------------------- helpers
    def stiffness_at_rest(self) -> np.ndarray:
        """
        K = d2U/dr2 at the unstressed pose (3x3, moment first, hinge frame).

        The small-displacement stiffness (eq. 4.52), used for reporting and default damping.
        """
        ev = evaluate([self], np.zeros(1), np.zeros((1, 2)), np.zeros((1, 3)))
        H = ev.hess[0]
        return 0.5 * (H + H.T)

    def with_damping(self, B: np.ndarray) -> "PolynomialLaw":
        """Return the same potential with damping matrix B (3x3)."""
        return dataclasses.replace(self, B=np.asarray(B, dtype=float))

    def dense_coefficients(self) -> np.ndarray:
        """
        Coefficients of all monomials of order <= N.

        They are in idx4.sci order (first column of the internal table).
        """
        return self._table[:, 0].copy()

    def _from_dense(self, dense: np.ndarray, B: np.ndarray) -> "PolynomialLaw":
        exps = monomial_exponents(len(self.scale), self.order)
        keep = dense != 0.0
        return dataclasses.replace(self, exponents=exps[keep], coefficients=dense[keep], B=B)

    def _linear_map(self, T: np.ndarray) -> "PolynomialLaw":
        """
        Return the law P'(c') = P(T c') for c - rest = T (c' - rest).

        T is a linear map of the vector coordinates that fixes the rest pose.
        """
        k = len(self.scale)
        M = (T / self.scale[:, None]) * self.scale[None, :]
        return self._from_dense(
            compose_linear(self.dense_coefficients(), k, self.order, M), self.B
        )


def transform_frames(law: PolynomialLaw, R: np.ndarray, p: np.ndarray) -> PolynomialLaw:
    """
    Return the law for hinge frames moved by G = (R, p) on both bodies (3.69, 4.70).

    The relative displacement is conjugated by G, so its twist maps as d = Ad(G) d' and the
    twistor as sigma = sigma', [xi; x] = Ad(G) [xi'; x'] (4.65, the vector part is
    proportional to the twist). The returned law U'(c') = U(c) is a polynomial of the same
    order; its damping is B' = Ad^T B Ad, as for the stiffness (transform_stiffness).
    """
    Ad = adjoint(np.asarray(R, dtype=float), np.asarray(p, dtype=float))
    k = len(law.scale)
    T = np.eye(k)
    T[k - 3:, k - 3:] = Ad
    moved = law._linear_map(T)
    return dataclasses.replace(moved, B=transform_stiffness(law.B, R, p))


def swap_bodies(law: PolynomialLaw) -> PolynomialLaw:
    """
    Return the law seen with bodies A and B exchanged.

    The displacement of a in b is the inverse one, whose twist is -d and whose twistor is (sigma,
    -xi, -x). U'(c') = U(c) flips the sign of every term of odd degree in the vector coordinates;
    the damping is unchanged.
    """
    k = len(law.scale)
    T = -np.eye(k)
    if law.coordinates == "twistor":
        T[0, 0] = 1.0
    return law._linear_map(T)


def quadratic_as_polynomial(
    K: np.ndarray, coordinates: str, B: np.ndarray | None = None
) -> PolynomialLaw:
    """
    Return the quadratic law of ``coordinates`` with stiffness K.

    U = 2 [xi; x]^T K [xi; x] (4.7) or U = 1/2 d^T K d (3.4) -- written as a PolynomialLaw of order
    2 (unit scales, E = 1 J): the same energy as QuadraticLaw(coordinates, K, B) everywhere.
    """
    W = QuadraticLaw(coordinates, np.asarray(K, dtype=float), np.zeros((3, 3))).metric()
    k = W.shape[0]
    exps, coefs = [], []
    for i in range(k):
        for j in range(i, k):
            if W[i, j] != 0.0:
                e = [0] * k
                e[i] += 1
                e[j] += 1
                exps.append(e)
                coefs.append(0.5 * W[i, i] if i == j else W[i, j])
    return PolynomialLaw(
        coordinates,
        2,
        np.array(exps, dtype=int),
        np.array(coefs),
        np.ones(k),
        1.0,
        np.zeros((3, 3)) if B is None else np.asarray(B, dtype=float),
    )


__all__ = [
    "MAX_ORDER", "REST", "VARIABLES", "PolynomialLaw", "quadratic_as_polynomial", "swap_bodies",
    "transform_frames",
]
