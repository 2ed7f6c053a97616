"""
Spatial hinge laws: law coordinates (twistor, twist), potential, wrench, energy and power.

A hinge's deflection is the displacement D = (R, p) of its frame b relative to its frame a
(R = R_a^T R_b, p = R_a^T (P_b - P_a): p is b's origin in a's coordinates), as the planar
engine's r = (alpha, p). Its unit dual quaternion (Clifford's dual quaternion; the planar
twistor of dissertation eqs. 2.129-2.135 is its restriction to the plane) is

    q = q_r + eps q_d,    q_r = (sigma, xi),    q_d = 1/2 p q_r = (sigma_0, x),
    sigma_0 = -1/2 p . xi,    x = 1/2 (sigma p + p x xi),

with q_r the quaternion of R. The law coordinates c are 6-vectors, rotation first:

- ``twistor``: c = (xi, x), the dual quaternion's vector part = sin(theta^/2) s^ for the
  dual angle theta^ and screw axis s^ (the planar (xi, x1, x2) of eq. 4.7 are its entries
  z, x, y when the motion is planar);
- ``twist``: c = (omega, v) = log D, omega = G(q_r) xi the rotation vector
  (``kinematics.quaternion.angle_factor``) and v = Jl^-1(omega) p = p - omega x p / 2
  + c omega x (omega x p) (planar: eqs. 2.106-2.108).

A law is a potential U(c) and a dissipation D = 1/2 c_dot^T C c_dot (``SpatialLaw``):

- ``twistor``: U = 2 c^T K c (eq. 4.7 in space: W = 4 K) and D = 2 c_dot^T B c_dot;
- ``twist``: U = 1/2 c^T K c (eq. 3.4) and D = 1/2 c_dot^T B c_dot;

K and B 6x6 in the hinge frame, rotation first. Near rest both are 1/2 d^T K d in the
deflection d, so K is the hinge's stiffness matrix. Both are frame-independent (a
conjugation of the deflection maps c by the adjoint, ``hinges.spatial_stiffness.
transform_stiffness``) and independent of which body is called A (inverting the deflection
negates c). The twistor law is smooth at every rotation; the twist law holds below 2 pi.

A virtual motion of frame b relative to a, D -> D Exp(delta) with delta = (dw, dv) in b's
coordinates (the relative twist, moment first), changes the coordinates by dc = Lambda delta:

- twistor: dq = 1/2 q (dw + eps dv), so d xi = 1/2 (sigma dw + xi x dw) and
  dx = 1/2 (sigma dv + xi x dv) + 1/2 (sigma_0 dw + x x dw) -- eq. 4.27 in space;
- twist: Lambda = Jr^-1 of SE(3) at c, which by the transference principle is the SO(3)
  formula I + 1/2 hat(c) + c(s) hat(c)^2 evaluated on the dual vector omega + eps v:
  Lambda = [[A, 0], [B, A]], A = Jr^-1(omega), B its derivative along v.

The wrench body B exerts on the element (frame b coordinates, moment about b's origin) is
m_b = Lambda^T (W c + C c_dot) (eqs. 3.53, 4.35, 4.40); the hinge exerts -m_b on B. Energy and
power as the planar laws report them (``laws.quadratic``): U, the conservative power
P_c = -dU/dt = -m_elastic . delta_dot (what the elastic wrenches deliver to the bodies) and the
dissipated power P_d = c_dot^T C c_dot >= 0. The functions on scalars are formulas on
a generic scalar (``kinematics.scalar``: compiled, and evaluated on hyper-dual numbers).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from flexure_sim.engine.kinematics import hyperdual as hd
from flexure_sim.engine.kinematics.scalar import formula
from flexure_sim.engine.kinematics.quaternion import angle_factor, cross, jr_coefficient
from flexure_sim.engine.kinematics.quaternion import twistor_translation
from flexure_sim.errors import as_array

#: Law coordinate types (the ``law`` of a hinge), as in the planar engine.
TWISTOR, TWIST = 0, 1
KINDS = {"twistor": TWISTOR, "twist": TWIST}


@formula(inline=False)
def dual_quaternion(qr, p):
    """Return sigma, xi, sigma_0, x of the displacement (R(qr), p) (module docstring)."""
    sigma = qr[0]
    xi = (qr[1], qr[2], qr[3])
    return (sigma, xi, -0.5 * (p[0] * xi[0] + p[1] * xi[1] + p[2] * xi[2]),
            twistor_translation(sigma, xi, p))


@formula(inline=False)
def _twistor_rate(sigma, xi, sigma0, x, dw, dv):
    """Return Lambda (dw, dv) for the twistor coordinates (module docstring)."""
    a = cross(xi, dw)
    b = cross(xi, dv)
    e = cross(x, dw)
    return (0.5 * (sigma * dw[0] + a[0]), 0.5 * (sigma * dw[1] + a[1]),
            0.5 * (sigma * dw[2] + a[2]),
            0.5 * (sigma * dv[0] + b[0] + sigma0 * dw[0] + e[0]),
            0.5 * (sigma * dv[1] + b[1] + sigma0 * dw[1] + e[1]),
            0.5 * (sigma * dv[2] + b[2] + sigma0 * dw[2] + e[2]))


@formula(inline=False)
def _twistor_wrench(sigma, xi, sigma0, x, g):
    """Return Lambda^T g for the twistor coordinates: moment, then force."""
    g1 = (g[0], g[1], g[2])
    g2 = (g[3], g[4], g[5])
    a = cross(xi, g1)
    b = cross(x, g2)
    e = cross(xi, g2)
    return (0.5 * (sigma * g1[0] - a[0] + sigma0 * g2[0] - b[0]),
            0.5 * (sigma * g1[1] - a[1] + sigma0 * g2[1] - b[1]),
            0.5 * (sigma * g1[2] - a[2] + sigma0 * g2[2] - b[2]),
            0.5 * (sigma * g2[0] - e[0]), 0.5 * (sigma * g2[1] - e[1]),
            0.5 * (sigma * g2[2] - e[2]))


@formula(inline=False)
def _jr_inverse(w, c, u):
    """Return u + w x u / 2 + c w x (w x u) (A u of the module docstring)."""
    a = cross(w, u)
    b = cross(w, a)
    return (u[0] + 0.5 * a[0] + c * b[0], u[1] + 0.5 * a[1] + c * b[1],
            u[2] + 0.5 * a[2] + c * b[2])


@formula(inline=False)
def _jr_inverse_t(w, c, u):
    """Return A^T u = u - w x u / 2 + c w x (w x u)."""
    a = cross(w, u)
    b = cross(w, a)
    return (u[0] - 0.5 * a[0] + c * b[0], u[1] - 0.5 * a[1] + c * b[1],
            u[2] - 0.5 * a[2] + c * b[2])


@formula(inline=False)
def _jr_inverse_dual(w, v, c, dc, u, sign):
    """
    Return B u (sign 1) or B^T u (sign -1), B the dual part of Jr^-1(w + eps v).

    B u = sign v x u / 2 + c (w x (v x u) + v x (w x u)) + 2 dc (w . v) w x (w x u); the
    last two terms are symmetric operators.
    """
    vu = cross(v, u)
    wu = cross(w, u)
    a = cross(w, vu)
    b = cross(v, wu)
    e = cross(w, wu)
    k = 2.0 * dc * (w[0] * v[0] + w[1] * v[1] + w[2] * v[2])
    return (0.5 * sign * vu[0] + c * (a[0] + b[0]) + k * e[0],
            0.5 * sign * vu[1] + c * (a[1] + b[1]) + k * e[1],
            0.5 * sign * vu[2] + c * (a[2] + b[2]) + k * e[2])


@formula(inline=False)
def _matvec(M, h, c):
    """Return M[h] c for a stack of 6x6 matrices M and a 6-tuple c."""
    return (M[h, 0, 0] * c[0] + M[h, 0, 1] * c[1] + M[h, 0, 2] * c[2] + M[h, 0, 3] * c[3]
            + M[h, 0, 4] * c[4] + M[h, 0, 5] * c[5],
            M[h, 1, 0] * c[0] + M[h, 1, 1] * c[1] + M[h, 1, 2] * c[2] + M[h, 1, 3] * c[3]
            + M[h, 1, 4] * c[4] + M[h, 1, 5] * c[5],
            M[h, 2, 0] * c[0] + M[h, 2, 1] * c[1] + M[h, 2, 2] * c[2] + M[h, 2, 3] * c[3]
            + M[h, 2, 4] * c[4] + M[h, 2, 5] * c[5],
            M[h, 3, 0] * c[0] + M[h, 3, 1] * c[1] + M[h, 3, 2] * c[2] + M[h, 3, 3] * c[3]
            + M[h, 3, 4] * c[4] + M[h, 3, 5] * c[5],
            M[h, 4, 0] * c[0] + M[h, 4, 1] * c[1] + M[h, 4, 2] * c[2] + M[h, 4, 3] * c[3]
            + M[h, 4, 4] * c[4] + M[h, 4, 5] * c[5],
            M[h, 5, 0] * c[0] + M[h, 5, 1] * c[1] + M[h, 5, 2] * c[2] + M[h, 5, 3] * c[3]
            + M[h, 5, 4] * c[4] + M[h, 5, 5] * c[5])


@formula(inline=False)
def law_terms(kind, qr, p, dw, dv, W, C, h):
    """
    Return (c, c_dot, m_b, m_elastic) of hinge h: coordinates, rates and wrenches (6-tuples).

    kind: TWISTOR or TWIST; (qr, p): the deflection (quaternion of R, p); (dw, dv): the
    relative twist rate of b in b's coordinates; W[h], C[h]: the 6x6 matrices of
    U = 1/2 c^T W c and D = 1/2 c_dot^T C c_dot. m_b = Lambda^T (W c + C c_dot) is the wrench
    body B exerts on the element (elastic and viscous), m_elastic = Lambda^T W c.
    """
    if kind == TWISTOR:
        sigma, xi, sigma0, x = dual_quaternion(qr, p)
        c = (xi[0], xi[1], xi[2], x[0], x[1], x[2])
        cdot = _twistor_rate(sigma, xi, sigma0, x, dw, dv)
        e = _matvec(W, h, c)
        d = _matvec(C, h, cdot)
        g = (e[0] + d[0], e[1] + d[1], e[2] + d[2], e[3] + d[3], e[4] + d[4], e[5] + d[5])
        return (c, cdot, _twistor_wrench(sigma, xi, sigma0, x, g),
                _twistor_wrench(sigma, xi, sigma0, x, e))
    g0 = angle_factor(qr[1] * qr[1] + qr[2] * qr[2] + qr[3] * qr[3], qr[0])
    w = (g0 * qr[1], g0 * qr[2], g0 * qr[3])
    cs, dcs = jr_coefficient(w[0] * w[0] + w[1] * w[1] + w[2] * w[2])
    # v = Jl^-1(w) p = p - w x p / 2 + c w x (w x p): A^T applied to p
    v = _jr_inverse_t(w, cs, p)
    c = (w[0], w[1], w[2], v[0], v[1], v[2])
    rw = _jr_inverse(w, cs, dw)
    rv = _jr_inverse(w, cs, dv)
    bw = _jr_inverse_dual(w, v, cs, dcs, dw, 1.0)
    cdot = (rw[0], rw[1], rw[2], bw[0] + rv[0], bw[1] + rv[1], bw[2] + rv[2])
    e = _matvec(W, h, c)
    d = _matvec(C, h, cdot)
    g = (e[0] + d[0], e[1] + d[1], e[2] + d[2], e[3] + d[3], e[4] + d[4], e[5] + d[5])
    return c, cdot, _twist_wrench(w, v, cs, dcs, g), _twist_wrench(w, v, cs, dcs, e)


@formula(inline=False)
def _twist_wrench(w, v, cs, dcs, g):
    """Return Lambda^T g = (A^T g1 + B^T g2, A^T g2) for the twist coordinates."""
    g1 = (g[0], g[1], g[2])
    g2 = (g[3], g[4], g[5])
    a = _jr_inverse_t(w, cs, g1)
    b = _jr_inverse_dual(w, v, cs, dcs, g2, -1.0)
    e = _jr_inverse_t(w, cs, g2)
    return a[0] + b[0], a[1] + b[1], a[2] + b[2], e[0], e[1], e[2]


@dataclass(frozen=True)
class LawState:
    """One hinge's law evaluated at a deflection and rate (``SpatialLaw.evaluate``)."""

    coordinates: np.ndarray
    rates: np.ndarray
    wrench_on_element: np.ndarray
    energy: float
    conservative: float
    dissipated: float


@dataclass(frozen=True)
class SpatialLaw:
    """
    The quadratic twistor or twist law with 6x6 stiffness K and damping B (module doc).

    K and B are float arrays, or HyperDual arrays when a design parameter is seeded
    (``analysis.spatial_sensitivity``: such a law is read for its matrices, not evaluated).
    """

    coordinates: str
    K: np.ndarray
    B: np.ndarray

    def __post_init__(self) -> None:
        if self.coordinates not in KINDS:
            raise ValueError(f"coordinates: expected one of {', '.join(KINDS)}, "
                             f"got {self.coordinates!r}")
        for key in ("K", "B"):
            value = getattr(self, key)
            if isinstance(value, hd.HyperDual):
                if value.shape != (6, 6):
                    raise ValueError(f"{key}: expected a 6x6 matrix, got shape {value.shape}")
            else:
                object.__setattr__(self, key, as_array(key, value, (6, 6)))

    @property
    def kind(self) -> int:
        """Return the law's coordinate type as the kernel's integer code."""
        return KINDS[self.coordinates]

    def _scale(self) -> float:
        return 4.0 if self.coordinates == "twistor" else 1.0

    def metric(self) -> np.ndarray:
        """W (6x6) with U = 1/2 c^T W c."""
        return self._scale() * self.K

    def dissipation_matrix(self) -> np.ndarray:
        """C (6x6) with D = 1/2 c_dot^T C c_dot."""
        return self._scale() * self.B

    def evaluate(self, quaternion, p, rate=(0.0, 0.0, 0.0, 0.0, 0.0, 0.0)) -> LawState:
        """
        Evaluate the law at deflection (R(quaternion), p) and relative twist rate ``rate``.

        ``rate`` = (dw, dv): the angular velocity of frame b relative to a and the velocity
        of b's origin relative to a (as in ``solver.spatial_chain``), both in b's coordinates.
        """
        q = as_array("quaternion", quaternion, (4,))
        p = as_array("p", p, (3,))
        r = as_array("rate", rate, (6,))
        W = self.metric()[None]
        C = self.dissipation_matrix()[None]
        c, cdot, m, me = law_terms(self.kind, tuple(q), tuple(p), tuple(r[:3]), tuple(r[3:]),
                                   W, C, 0)
        c, cdot, me = np.array(c), np.array(cdot), np.array(me)
        return LawState(c, cdot, np.array(m), float(0.5 * c @ W[0] @ c),
                        float(-me @ r), float(cdot @ C[0] @ cdot))

    def potential_energy(self, quaternion, p) -> float:
        """Return U (J) at the deflection (R(quaternion), p)."""
        return self.evaluate(quaternion, p).energy
