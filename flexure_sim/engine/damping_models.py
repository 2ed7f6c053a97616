"""
Damping models built from the modes at rest.

Rayleigh damping C = alpha M + beta K and modal damping with a chosen ratio per mode (issue
12 item 1; not yet wired into the engine's stepping).

Both act on the free coordinates of a linearisation (`linear.LinearModel`: diagonal mass M,
tangent stiffness K) about the rest configuration, with the M-orthonormal mode shapes Phi
(Phi^T M Phi = I, Phi^T K Phi = diag(omega^2); `linear.modes`).

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
"""
from __future__ import annotations

import numpy as np


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
