"""
Hinge laws: potential energy, wrench and dissipation of an elastic element (Ch. 3, 4).

A hinge joins frame a (on body A) and frame b (on body B) that coincide when unstressed.
Its state is the relative displacement of b in a, written r = (alpha, p1, p2): alpha the
rotation of b relative to a, p the origin of b in a's coordinates.

A law is a potential U(c) in *law coordinates* c(r) (engine/laws/coordinates.py), plus a
dissipation function D = 1/2 c_dot^T C c_dot in the rates of the same coordinates:
- ``twistor``: c = (sigma, xi, x1, x2) (eqs. 2.132-2.135); the quadratic potential is
  U = 2 [xi; x]^T K [xi; x] (eq. 4.7) and the damping wrench 2 Lambda^T B dx (4.40-4.42)
  is the gradient of D = 2 [xi_dot; x_dot]^T B [xi_dot; x_dot].
- ``twist``: c = (tau, t1, t2) (eqs. 2.107-2.108); U = 1/2 d^T K d (eq. 3.4), and
  D = 1/2 d_dot^T B d_dot (the printed 3.62-3.64 repeat the twistor form; the two agree to
  second order in the displacement).

The wrench exerted *by body B on the element*, in frame b coordinates, moment about b's
origin (m_b of eqs. 3.53 and 4.35), follows from the virtual work
dW = m_b . (delta tau, delta t_b): with delta r = (delta tau, R(alpha) delta t_b),
m_b = (dU/dalpha, R(alpha)^T dU/dp). The element exerts -m_b on body B and the opposite
wrench on body A (the potential depends on the relative displacement only).

*Energy and power* (``LawBatch.power``, and ``potential_energy``, ``conservative_power``,
``dissipated_power`` on every law): U(r); the conservative power P_c = -dU/dt =
-(dU/dr) . r_dot, the power the element's elastic wrenches deliver to the two bodies (the
wrench -m_b on B dotted with the twist of b relative to a, in frame b: (alpha_dot,
R(alpha)^T p_dot)); the dissipated power P_d = r_dot^T C_r r_dot = 2 D >= 0, the power the
damping wrenches take from the bodies.

Everything is vectorised over hinges: alpha has shape (n,), p shape (n, 2), r_dot (n, 3);
arguments of another shape raise a ValueError naming the argument.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Literal, Optional, Protocol, Sequence, overload

import numpy as np

from flexure_sim.errors import as_array
from flexure_sim.engine.kinematics.hyperdual import HyperDual
from flexure_sim.engine.kinematics.relative import element_wrench
from flexure_sim.engine.laws.coordinates import COORDINATES, deflections

# ------------------------------------------------------------------------ the laws

#: W = s K and C = s B on the law coordinates of a quadratic law: U = 2 [xi; x]^T K [xi; x]
#: is 1/2 c^T (4 K) c on the twistor's (xi, x1, x2) (4.7), U = 1/2 d^T K d on the twist (3.4).
METRIC_SCALE = {"twistor": 4.0, "twist": 1.0}


@dataclass(frozen=True)
class LawEvaluation:
    """
    Laws evaluated at r = (alpha, p) with rates r_dot, for n hinges.

    energy (n,); grad (n, 3) = dU/dr; hess (n, 3, 3) = d2U/dr2;
    damping (n, 3, 3) = C_r, the matrix of the dissipation D = 1/2 r_dot^T C_r r_dot;
    damping_force (n, 3) = C_r r_dot; damping_force_dr (n, 3, 3) = d(C_r r_dot)/dr at fixed
    r_dot (exact, from the second derivatives of the coordinate map). hess, damping and
    damping_force_dr are None when ``LawBatch.evaluate`` is asked for no Jacobian.
    """

    energy: np.ndarray
    grad: np.ndarray
    hess: Optional[np.ndarray]
    damping: Optional[np.ndarray]
    damping_force: np.ndarray
    damping_force_dr: Optional[np.ndarray]


@dataclass(frozen=True)
class LawJacobians(LawEvaluation):
    """A `LawEvaluation` with its derivatives (``LawBatch.evaluate(..., jacobian=True)``)."""

    hess: np.ndarray
    damping: np.ndarray
    damping_force_dr: np.ndarray


@dataclass(frozen=True)
class HingePower:
    """
    Energy and power of n hinges (each (n,)).

    Energy U (J); conservative = P_c = -dU/dt (W), the power the elastic wrenches deliver to the
    bodies; dissipated = P_d = r_dot^T C_r r_dot = 2 D >= 0 (W), the power the damping wrenches
    take from them.
    """

    energy: np.ndarray
    conservative: np.ndarray
    dissipated: np.ndarray


class HingeLaw(Protocol):
    """What the solver needs of a hinge law."""

    @property
    def coordinates(self) -> str:
        """Name the law coordinates c(r): "twistor" or "twist"."""

    @property
    def B(self) -> np.ndarray:
        """Return the damping matrix (3, 3), moment first, in the hinge frame (eq. 4.40)."""

    def potential(self, c: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """U(c), dU/dc, d2U/dc2 for c of shape (m, k) (rows are configurations)."""

    def dissipation_matrix(self) -> np.ndarray:
        """C (k, k) of D = 1/2 c_dot^T C c_dot."""


class LawPower:
    """
    Energy and power of one law at m states.

    The states are r = (alpha (m,), p (m, 2)) with rates r_dot (m, 3) (module docstring): the
    methods every law offers, through `LawBatch.power`.
    """

    def potential_energy(self: HingeLaw, alpha, p) -> np.ndarray:
        """Potential energy U(r) (J), shape (m,)."""
        alpha, p = deflections(alpha, p)
        return LawBatch([self] * len(alpha)).power(alpha, p, np.zeros((len(alpha), 3))).energy

    def conservative_power(self: HingeLaw, alpha, p, rdot) -> np.ndarray:
        """P_c = -dU/dt = -(dU/dr) . r_dot (W), shape (m,)."""
        return LawBatch([self] * len(np.atleast_1d(alpha))).power(alpha, p, rdot).conservative

    def dissipated_power(self: HingeLaw, alpha, p, rdot) -> np.ndarray:
        """P_d = r_dot^T C_r r_dot = 2 D >= 0 (W), shape (m,)."""
        return LawBatch([self] * len(np.atleast_1d(alpha))).power(alpha, p, rdot).dissipated


@dataclass(frozen=True)
class QuadraticLaw(LawPower):
    """
    Potential U = 1/2 c^T W c and dissipation D = 1/2 c_dot^T C c_dot in the law coordinates c(r).

    The quadratic laws of eqs. 3.4 and 4.7 with the damping of 4.40.

    ``twistor`` (c = sigma, xi, x1, x2): U = 2 [xi; x]^T K [xi; x] (4.7, W = 4 K on
    (xi, x1, x2)) and D = 2 [xi_dot; x_dot]^T B [xi_dot; x_dot] (C = 4 B);
    ``twist`` (c = tau, t1, t2): U = 1/2 d^T K d (3.4) and D = 1/2 d_dot^T B d_dot.
    K, B: 3x3, moment first, forces second, in the hinge frame. Power: `LawPower`.
    In the law of a design whose numbers carry derivatives (mechanism/parameters.py), K and B
    are HyperDual arrays: the hyper-dual force chain reads them (analysis/parametric.py), the
    methods here take floats.
    """

    coordinates: str
    K: np.ndarray
    B: np.ndarray

    def __post_init__(self) -> None:
        if self.coordinates not in COORDINATES:
            raise ValueError(f"coordinates: expected one of {', '.join(COORDINATES)}, "
                             f"got {self.coordinates!r}")
        for name in ("K", "B"):
            M = getattr(self, name)
            if not isinstance(M, HyperDual):
                object.__setattr__(self, name, as_array(name, M, (3, 3)))
            elif M.shape != (3, 3):
                raise ValueError(f"{name}: expected shape (3, 3), got {M.shape}")

    def _embed(self, M: np.ndarray) -> np.ndarray:
        if self.coordinates == "twistor":
            out = np.zeros((4, 4))
            out[1:, 1:] = METRIC_SCALE["twistor"] * M
            return out
        return np.array(M, dtype=float)

    def metric(self) -> np.ndarray:
        """W (k, k) with U = 1/2 c^T W c."""
        return self._embed(self.K)

    def potential(self, c):
        W = self.metric()
        Wc = c @ W.T
        return 0.5 * np.einsum("ni,ni->n", c, Wc), Wc, np.broadcast_to(W, (c.shape[0],) + W.shape)

    def dissipation_matrix(self):
        return self._embed(self.B)


class LawBatch:
    """
    Hinges that share one coordinate type, evaluated together.

    Quadratic laws are evaluated all at once from their stacked metrics (built here,
    once); other laws one hinge at a time through ``potential``.
    """

    def __init__(self, laws: Sequence[HingeLaw]):
        coords = {law.coordinates for law in laws}
        if len(coords) != 1:
            raise ValueError(f"laws must share one coordinate type, got {sorted(coords)}")
        self.laws = list(laws)
        self.coordinates = coords.pop()
        self._map = COORDINATES[self.coordinates]
        self.quadratic = all(isinstance(law, QuadraticLaw) for law in laws)
        # One law at many states (LawPower) evaluates its potential once, on every row.
        self.single = bool(laws) and all(law is laws[0] for law in laws)
        self.W = (np.stack([law.metric() for law in laws if isinstance(law, QuadraticLaw)])
                  if self.quadratic else None)
        self.C = np.stack([law.dissipation_matrix() for law in laws])

    @overload
    def evaluate(self, alpha: np.ndarray, p: np.ndarray, rdot: np.ndarray,
                 jacobian: Literal[True] = ...) -> LawJacobians: ...

    @overload
    def evaluate(self, alpha: np.ndarray, p: np.ndarray, rdot: np.ndarray,
                 jacobian: bool) -> LawEvaluation: ...

    def evaluate(
        self, alpha: np.ndarray, p: np.ndarray, rdot: np.ndarray, jacobian: bool = True
    ) -> LawEvaluation:
        """
        Energy, dU/dr and C_r r_dot by the chain rule through c(r).

        With ``jacobian`` also d2U/dr2, C_r and d(C_r r_dot)/dr (else those fields are None):

        grad_r = dc^T U_c; hess_r = dc^T U_cc dc + sum_k U_c,k d2c_k; C_r = dc^T C dc;
        d(C_r r_dot)/dr = sum_k (C dc r_dot)_k d2c_k + dc^T C (d2c . r_dot).
        """
        alpha, p, rdot = deflections(alpha, p, rdot)
        if len(alpha) != len(self.laws):
            raise ValueError(f"alpha: expected {len(self.laws)} deflections (one per law), "
                             f"got {len(alpha)}")
        cmap = self._map(alpha, p, second=jacobian)
        c, dc = cmap.c, cmap.dc
        if self.W is not None:  # self.quadratic
            Uc = np.einsum("nij,nj->ni", self.W, c)
            energy = 0.5 * np.einsum("ni,ni->n", c, Uc)
            Ucc = self.W
        elif self.single:
            energy, Uc, Ucc = self.laws[0].potential(c)
        else:
            n, k = c.shape
            energy, Uc, Ucc = np.empty(n), np.empty((n, k)), np.empty((n, k, k))
            for i, law in enumerate(self.laws):
                e, g, h = law.potential(c[i:i + 1])
                energy[i], Uc[i], Ucc[i] = e[0], g[0], h[0]
        grad = np.einsum("nki,nk->ni", dc, Uc)
        cdot = np.einsum("nki,ni->nk", dc, rdot)
        w = np.einsum("nkl,nl->nk", self.C, cdot)
        damping_force = np.einsum("nki,nk->ni", dc, w)
        if not jacobian:
            return LawEvaluation(energy, grad, None, None, damping_force, None)
        d2c = cmap.d2c
        assert d2c is not None  # asked for with second=jacobian
        hess = np.einsum("nki,nkl,nlj->nij", dc, Ucc, dc) + np.einsum("nk,nkij->nij", Uc, d2c)
        CJ = np.einsum("nkl,nlj->nkj", self.C, dc)
        damping = np.einsum("nki,nkj->nij", dc, CJ)
        d2c_rdot = np.einsum("nkjl,nl->nkj", d2c, rdot)
        damping_force_dr = np.einsum("nk,nkij->nij", w, d2c) + np.einsum(
            "nki,nkj->nij", CJ, d2c_rdot
        )
        return LawJacobians(energy, grad, hess, damping, damping_force, damping_force_dr)

    def power(self, alpha: np.ndarray, p: np.ndarray, rdot: np.ndarray) -> HingePower:
        """
        U, P_c = -(dU/dr) .

        r_dot and P_d = (C_r r_dot) . r_dot of each hinge (module docstring; the wrench identities
        are in test_hinge_power.py).
        """
        ev = self.evaluate(alpha, p, rdot, jacobian=False)
        rdot = np.asarray(rdot, dtype=float)
        return HingePower(ev.energy, -np.einsum("ni,ni->n", ev.grad, rdot),
                          np.einsum("ni,ni->n", ev.damping_force, rdot))


def evaluate(
    laws: Sequence[HingeLaw], alpha: np.ndarray, p: np.ndarray, rdot: np.ndarray
) -> LawJacobians:
    """Evaluate n hinges sharing one coordinate type, with all derivatives (see LawBatch)."""
    return LawBatch(laws).evaluate(alpha, p, rdot, jacobian=True)


def wrench_on_element(alpha: np.ndarray, grad_r: np.ndarray) -> np.ndarray:
    """
    m_b: wrench by body B on the element, frame b coordinates, about b's origin.

    From dW = grad_r . delta r and delta r = (delta tau, R(alpha) delta t_b):
    m_b = (dU/dalpha, R(alpha)^T dU/dp) -- eqs. 3.53 and 4.35 (for the twistor quadratic
    law this equals 2 Lambda^T K [xi; x], a test checks it against comply_quat2.sci).
    Works for the dissipative part too with grad_r replaced by C_r r_dot.
    """
    alpha = as_array("alpha", alpha, (None,))
    grad_r = as_array("grad_r", grad_r, (alpha.shape[0], 3))
    return np.column_stack(element_wrench(alpha, grad_r[:, 0], grad_r[:, 1], grad_r[:, 2]))
