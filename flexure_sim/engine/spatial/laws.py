"""
Spatial hinge laws: potential energy, wrench, dissipation, energy and power of one hinge.

A hinge's law is a potential U(c) and a dissipation D = 1/2 c_dot^T C c_dot in its law
coordinates c (``coordinates``: the twistor, the vector part of the unit dual quaternion of
the deflection, or the twist, its logarithm):

- ``twistor``: U = 2 c^T K c (eq. 4.7 in space: W = 4 K) and D = 2 c_dot^T B c_dot;
- ``twist``: U = 1/2 c^T K c (eq. 3.4) and D = 1/2 c_dot^T B c_dot;

K and B 6x6 in the hinge frame, rotation first. Near rest both are 1/2 d^T K d in the
deflection d, so K is the hinge's stiffness matrix; both are frame-independent (a
conjugation of the deflection maps c by the adjoint, ``stiffness.transform_stiffness``) and
independent of which body is called A (inverting the deflection negates c). The twistor law
is smooth at every rotation; the twist law holds for rotations below 2 pi.

The wrench body B exerts on the element is m_b = Lambda^T (W c + C c_dot) (``coordinates``),
in frame b, moment about b's origin; the hinge exerts -m_b on B. Energy and power as the
planar laws report them (``engine.hinge_laws``): U, the conservative power P_c = -dU/dt (what
the elastic wrenches deliver to the bodies) and the dissipated power P_d = c_dot^T C c_dot
>= 0.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...errors import as_array
from . import coordinates


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
    """The quadratic twistor or twist law with 6x6 stiffness K and damping B (module doc)."""

    coordinates: str
    K: np.ndarray
    B: np.ndarray

    def __post_init__(self) -> None:
        if self.coordinates not in coordinates.KINDS:
            raise ValueError(f"coordinates: expected one of {', '.join(coordinates.KINDS)}, "
                             f"got {self.coordinates!r}")
        object.__setattr__(self, "K", as_array("K", self.K, (6, 6)))
        object.__setattr__(self, "B", as_array("B", self.B, (6, 6)))

    @property
    def kind(self) -> int:
        """Return the law's coordinate type as the kernel's integer code."""
        return coordinates.KINDS[self.coordinates]

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
        of b's origin relative to a (as in ``chain``), both in b's coordinates.
        """
        q = as_array("quaternion", quaternion, (4,))
        p = as_array("p", p, (3,))
        r = as_array("rate", rate, (6,))
        W = self.metric()[None]
        C = self.dissipation_matrix()[None]
        c, cdot, m, me = coordinates.law_terms(self.kind, tuple(q), tuple(p), tuple(r[:3]),
                                               tuple(r[3:]), W, C, 0)
        c, cdot, me = np.array(c), np.array(cdot), np.array(me)
        return LawState(c, cdot, np.array(m), float(0.5 * c @ W[0] @ c),
                        float(-me @ r), float(cdot @ C[0] @ cdot))

    def potential_energy(self, quaternion, p) -> float:
        """Return U (J) at the deflection (R(quaternion), p)."""
        return self.evaluate(quaternion, p).energy
