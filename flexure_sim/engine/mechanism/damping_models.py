"""
Damping models built from the modes at rest.

Rayleigh damping C = alpha M + beta K and modal damping with a chosen ratio per mode, the
mechanism file's ``damping:`` block (``DampingSpec``; issue 12 item 1). ``damping_matrix``
builds the constant matrix once, from the tangent stiffness and the masses at rest, and
``model.Model`` adds the generalised force -C v to the hinges' (stepping, Jacobian,
dissipated power v^T C v, linearisation and modes; none at rest, so no effect on statics).

Both are defined on the free coordinates z_F of the linearisation about rest (diagonal mass
M, tangent stiffness K = -dQ/dz at the unstressed pose), with the M-orthonormal mode shapes
Phi (Phi^T M Phi = I, Phi^T K Phi = diag(omega^2); ``natural_modes``, which
`linear.modes` uses too).

- Rayleigh: Phi^T (alpha M + beta K) Phi = diag(alpha + beta omega_i^2), so each mode keeps
  its shape and has the damping ratio zeta_i = alpha / (2 omega_i) + beta omega_i / 2
  (Chopra, Dynamics of Structures, eq. 11.4.3). Two target ratios at two frequencies fix
  alpha and beta (eq. 11.4.4).
- Modal: C = M Phi diag(2 zeta_i omega_i) Phi^T M, so Phi^T C Phi = diag(2 zeta_i omega_i)
  (Chopra eq. 11.5.2 with Phi^T M Phi = I): each mode has exactly the ratio zeta_i.

Frame invariance: both matrices are constant, taken in the coordinates of the rest
configuration. Unlike the hinge law's dissipation (B = t_char K on each hinge's own
deflection rate, which rotates with the bodies), a constant C on the body coordinates damps
rigid rotations of the whole mechanism about the rest pose, and its modal ratios hold only
for small motion about rest (the stage's micrometre strokes; not the four-bars' large
rotations).

How C acts on the prescribed coordinates z_P (fixed bodies, the driven body), whose
velocities are known: C is a symmetric positive semi-definite matrix on all 3 n_bodies
coordinates, and the damping force is -C v with v the velocity of all coordinates (rest
configuration's root frame). Fixed coordinates have v_P = 0; the driven body's v_P enters.

- Rayleigh: C = alpha M + beta K on all coordinates (K the full tangent stiffness at rest,
  whose null space holds the rigid motions of the whole mechanism): the mass-proportional part
  damps absolute velocities (dashpots to the ground), the stiffness-proportional part the
  hinges' deformation rates, as B = t_char K does per hinge.
- Modal: the modes are those of the free coordinates with z_P held, so the ratios damp the
  motion relative to the quasi-static motion the prescribed coordinates impose, z_F - S z_P
  with S = -K_FF^-1 K_FP (the influence matrix of support motion; Chopra Sec. 9.7):
  C = T^T C_FF T, T = [I, -S]. A slow drive motion, or a rigid motion carried by the drive,
  is not damped; for C_FF = beta K_FF this gives exactly beta K on the free rows.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Optional

import numpy as np
import scipy.linalg

#: The damping models of a mechanism file's ``damping:`` block.
MODELS = ("rayleigh", "modal")


@dataclass(frozen=True)
class DampingSpec:
    """
    A mechanism's damping block: Rayleigh (``alpha`` 1/s, ``beta`` s) or modal ratios.

    Modal: ``ratios`` for the first modes (ascending frequency), ``ratio`` for every further
    mode (None: ``ratios`` names every mode).
    """

    model: str
    alpha: float = 0.0
    beta: float = 0.0
    ratios: tuple[float, ...] = ()
    ratio: Optional[float] = None

    def mode_ratios(self, n_modes: int) -> np.ndarray:
        """Return the damping ratio of each of ``n_modes`` modes (ValueError if not given)."""
        given = np.asarray(self.ratios, dtype=float)
        if given.size > n_modes or (given.size < n_modes and self.ratio is None):
            raise ValueError(f"ratios: {given.size} given for {n_modes} modes")
        return np.concatenate([given, np.full(n_modes - given.size,
                                              self.ratio if self.ratio is not None else 0.0)])


def natural_modes(stiffness: np.ndarray, mass: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """
    Return omega^2 (ascending) and M-orthonormal shapes of K phi = omega^2 M phi.

    ``mass``: the diagonal of M, or M (a spatial mechanism's, with its inertia tensors).
    ValueError if K is not positive definite (a mechanism that can move without deforming a
    hinge has no modes of its own).
    """
    w2, shapes = scipy.linalg.eigh(stiffness, np.diag(mass) if np.ndim(mass) == 1 else mass)
    if np.any(w2 <= 0):
        raise ValueError(
            "the tangent stiffness is not positive definite at this equilibrium "
            f"(smallest eigenvalue {w2.min():.3g}): the equilibrium at this input is not "
            "stable, or the mechanism can move without deforming a hinge"
        )
    return w2, shapes


def damping_matrix(spec: DampingSpec, mass: np.ndarray, stiffness: np.ndarray,
                   free: np.ndarray) -> np.ndarray:
    """
    Return C on all coordinates for ``spec`` (module docstring: how it acts on z_P).

    ``mass``: the diagonal of M; ``stiffness``: the tangent stiffness -dQ/dz at rest on all
    coordinates; ``free``: the free coordinates' indices.
    """
    mass = np.asarray(mass, dtype=float)
    K = 0.5 * (stiffness + stiffness.T)
    if spec.model == "rayleigh":
        return rayleigh_matrix(spec.alpha, spec.beta, mass, K)
    n = len(mass)
    F = np.asarray(free, dtype=int)
    P = np.setdiff1d(np.arange(n), F)
    kff = K[np.ix_(F, F)]
    w2, shapes = natural_modes(kff, mass[F])
    cff = modal_matrix(mass[F], shapes, np.sqrt(w2), spec.mode_ratios(len(F)))
    T = np.zeros((len(F), n))
    T[:, F] = np.eye(len(F))
    T[:, P] = np.linalg.solve(kff, K[np.ix_(F, P)])  # -S = K_FF^-1 K_FP
    C = T.T @ cff @ T
    return 0.5 * (C + C.T)


def rayleigh_ratios(alpha: float, beta: float, omega: np.ndarray) -> np.ndarray:
    """zeta_i = alpha / (2 omega_i) + beta omega_i / 2 for natural frequencies omega (rad/s)."""
    omega = np.asarray(omega, dtype=float)
    if np.any(omega <= 0):
        raise ValueError("omega: natural frequencies must be positive")
    return alpha / (2.0 * omega) + beta * omega / 2.0


def rayleigh_coefficients(zeta_1: float, omega_1: float, zeta_2: float,
                          omega_2: float) -> tuple[float, float]:
    """
    (alpha, beta) giving ratio zeta_1 at omega_1 and zeta_2 at omega_2 (rad/s, distinct).

    The solution of the two equations of `rayleigh_ratios`.
    """
    if omega_1 <= 0 or omega_2 <= 0 or omega_1 == omega_2:
        raise ValueError("omega_1, omega_2: must be positive and distinct")
    a = np.array([[1.0 / (2 * omega_1), omega_1 / 2], [1.0 / (2 * omega_2), omega_2 / 2]])
    alpha, beta = np.linalg.solve(a, [zeta_1, zeta_2])
    return float(alpha), float(beta)


def rayleigh_matrix(alpha: float, beta: float, mass: np.ndarray,
                    stiffness: np.ndarray) -> np.ndarray:
    """C = alpha M + beta K (``mass``: the diagonal of M, or M itself)."""
    m = np.diag(mass) if np.ndim(mass) == 1 else np.asarray(mass, dtype=float)
    return alpha * m + beta * np.asarray(stiffness, dtype=float)


def modal_matrix(mass: np.ndarray, shapes: np.ndarray, omega: np.ndarray,
                 zeta: np.ndarray | float) -> np.ndarray:
    """
    Return the modal damping matrix C = M Phi diag(2 zeta_i omega_i) Phi^T M.

    ``shapes`` Phi are M-orthonormal (columns), of natural frequencies ``omega`` (rad/s);
    ``zeta``: one ratio per mode, or one for all.
    """
    m = np.diag(mass) if np.ndim(mass) == 1 else np.asarray(mass, dtype=float)
    shapes = np.asarray(shapes, dtype=float)
    omega = np.asarray(omega, dtype=float)
    zeta = np.broadcast_to(np.asarray(zeta, dtype=float), omega.shape)
    if shapes.shape != (m.shape[0], omega.size):
        raise ValueError(f"shapes: expected ({m.shape[0]}, {omega.size}), got {shapes.shape}")
    if np.any(zeta < 0):
        raise ValueError("zeta: damping ratios must not be negative")
    mp = m @ shapes
    return mp @ np.diag(2.0 * zeta * omega) @ mp.T
