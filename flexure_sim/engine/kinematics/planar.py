"""
Planar kinematics: rotations, twists and twistors (dissertation Ch. 2).

Conventions (used everywhere in flexure_sim):
- A planar displacement of frame b relative to frame a is (R, p): R = rot(alpha) is the
  orientation of b in a, p the origin of b in a's coordinates (eq. 2.81: q_a = p + R q_b).
- The twist of that displacement is d = (tau, t1, t2) = alpha * (1, y_p, -x_p), with
  (x_p, y_p) the pole (eqs. 2.88-2.90, 2.107-2.108).
- The twistor is (sigma, xi, x1, x2) = (cos(alpha/2), sin(alpha/2), sin(alpha/2) * (y_p, -x_p))
  (eqs. 2.129-2.135); its vector part (xi, x1, x2) equals sin(alpha/2)/alpha times the twist.
- Planar wrenches and twists are ordered moment/rotation first, then the two force /
  translation components ("moment first, forces second").

All functions take plain floats / NumPy arrays; the angle-valued ones also accept arrays
of shape (n,) (with vectors of shape (n, 2)) to act on many hinges at once.
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np

from flexure_sim.errors import as_array
from flexure_sim.engine.kinematics.quaternion import exp_coefficients, twistor_translation
from flexure_sim.engine.kinematics.scalar import formula, real, where

#: sk(1), the 2x2 generator of planar rotations (eq. 2.93): J @ [x, y] = [-y, x].
J = np.array([[0.0, -1.0], [1.0, 0.0]])

#: Below this |alpha| the series branches of the twist formulas are used.
_SMALL_ANGLE = 1e-4
#: Below this |alpha| (alpha/2) cot(alpha/2) and its derivatives come from their series
#: (the exact first derivative loses ~eps/alpha^2 to cancellation; the series' first
#: omitted terms are below 1e-21 here).
HALF_COT_SERIES = 1e-2


class Twistor(NamedTuple):
    """
    Twistor (Clifford) parameters of a planar displacement (eqs. 2.131-2.135).

    sigma = cos(alpha/2), xi = sin(alpha/2), x = (x1, x2) the translation in the
    intermediate frame; sigma**2 + xi**2 == 1.
    """

    sigma: float
    xi: float
    x1: float
    x2: float

    @property
    def vector(self) -> np.ndarray:
        """Return the vector part (xi, x1, x2), the argument of the quadratic potential (4.7)."""
        return np.array([self.xi, self.x1, self.x2])


def rot(alpha):
    """2x2 rotation matrix (eq. 2.94); for an array of angles, shape (n, 2, 2)."""
    c, s = np.cos(alpha), np.sin(alpha)
    return np.stack([np.stack([c, -s], -1), np.stack([s, c], -1)], -2)


def angle_of(R: np.ndarray) -> float:
    """Rotation angle in (-pi, pi] of a 2x2 rotation matrix."""
    return float(np.arctan2(R[1, 0] - R[0, 1], R[0, 0] + R[1, 1]))


def hat(v: np.ndarray) -> np.ndarray:
    """Return the moment map of a 2-vector, [-v2, v1] = J v (hat.sci)."""
    return v @ J.T


# ----------------------------------------------------------------------------- twist

def twist_from_displacement(R: np.ndarray, p: np.ndarray) -> np.ndarray:
    """
    Twist (tau, t1, t2) of the displacement (R, p) (eqs. 2.95-2.108).

    tau = alpha, t = alpha * J^-1 (I - R)^-1 p = (alpha/2) (cot(alpha/2) I - J) p; the pure
    translation branch (alpha -> 0) gives t = p, and a series is used for small alpha.
    """
    alpha = angle_of(as_array("R", R, (2, 2)))
    return np.concatenate(([alpha], log_translation_matrix(alpha) @ as_array("p", p, (2,))))


def displacement_from_twist(d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(R, p) of a twist d = (tau, t1, t2) (eqs. 2.91-2.92): p = (I - R) J t / tau."""
    d = as_array("d", d, (3,))
    alpha = float(d[0])
    return rot(alpha), exp_translation_matrix(alpha) @ d[1:]


@formula
def half_cot(a):
    """
    f(a) = (a/2) cot(a/2) (f(0) = 1), f'(a) and f''(a): the one definition, on any scalar.

    f' = cot(a/2)/2 - a / (4 sin^2(a/2)), f'' = -1/(2 sin^2(a/2)) + a cos(a/2) / (4 sin^3(a/2));
    below ``HALF_COT_SERIES`` the series f = 1 - a^2/12 - a^4/720 - a^6/30240 and its
    derivatives, with the closed form evaluated at a safe angle (kinematics/scalar.py). Floats in
    the compiled force kernel, arrays of angles, HyperDual arrays (kinematics/scalar.py).
    """
    small = np.abs(real(a)) < HALF_COT_SERIES
    safe = where(small, 1.0, a)
    s, c = np.sin(0.5 * safe), np.cos(0.5 * safe)
    s2 = s * s
    a2 = a * a
    a4 = a2 * a2
    return (where(small, 1.0 - a2 / 12.0 - a4 / 720.0 - a4 * a2 / 30240.0, 0.5 * safe * c / s),
            where(small, -a * (1.0 / 6.0 + a2 / 180.0 + a4 / 5040.0),
                  0.5 * c / s - 0.25 * safe / s2),
            where(small, -1.0 / 6.0 - a2 / 60.0 - a4 / 1008.0,
                  -0.5 / s2 + 0.25 * safe * c / (s2 * s)))


def log_translation_matrix(alpha) -> np.ndarray:
    """V^-1(alpha) with t = V^-1 p: (alpha/2) cot(alpha/2) I - (alpha/2) J (eq. 2.106)."""
    alpha = np.asarray(alpha, dtype=float)
    f = half_cot(alpha)[0]
    return f[..., None, None] * np.eye(2) - 0.5 * alpha[..., None, None] * J


def exp_translation_matrix(alpha) -> np.ndarray:
    """V(alpha) with p = V t: (sin(alpha) I + vers(alpha) J) / alpha (eq. 2.91)."""
    alpha = np.asarray(alpha, dtype=float)
    small = np.abs(alpha) < _SMALL_ANGLE
    a = np.where(small, 1.0, alpha)
    s_over = np.where(small, 1.0 - alpha**2 / 6.0, np.sin(a) / a)
    v_over = np.where(small, alpha / 2.0 - alpha**3 / 24.0, (1.0 - np.cos(a)) / a)
    return s_over[..., None, None] * np.eye(2) + v_over[..., None, None] * J


# --------------------------------------------------------------------------- twistor

def twistor_from_displacement(R: np.ndarray, p: np.ndarray) -> Twistor:
    """
    Twistor of (R, p) as trans2cliff2.sci (eqs. 2.174-2.179).

    sigma = sqrt(tr R + 2) / 2 >= 0; xi from the antisymmetric part of R when sigma > 0.1,
    else xi = sqrt(1/2 - tr(R)/4) with the sign of (R21 - R12) and then sigma = (R21 - R12)
    / (4 xi) (the numerically careful branches of Section 2.8, with sigma recomputed so it
    keeps full precision near alpha = pi); x = (sigma I - sk(xi)) p / 2
    (``quaternion.twistor_translation``).
    """
    R, p = as_array("R", R, (2, 2)), as_array("p", p, (2,))
    tr = R[0, 0] + R[1, 1]
    sigma = 0.5 * np.sqrt(max(tr + 2.0, 0.0))
    m21 = 0.5 * (R[1, 0] - R[0, 1])
    if sigma > 0.1:
        xi = m21 / (2.0 * sigma)
    else:
        xi = np.sqrt(max(0.5 - 0.25 * tr, 0.0))
        if m21 < 0:
            xi = -xi
        # Near alpha = pi, sqrt(tr + 2) loses half the digits; sin(alpha) = 2 sigma xi
        # gives sigma to full precision (and sigma >= 0, as xi has the sign of m21).
        sigma = m21 / (2.0 * xi)
    x = twistor_translation(sigma, (0.0, 0.0, xi), (p[0], p[1], 0.0))
    return Twistor(float(sigma), float(xi), float(x[0]), float(x[1]))


def displacement_from_twistor(q: Twistor) -> tuple[np.ndarray, np.ndarray]:
    """
    (R, p) of a twistor (eqs. 2.171-2.172, p2R.sci):.

    R = (1 - 2 xi^2) I + 2 sigma sk(xi), p = 2 (sigma I + sk(xi)) x.
    """
    sigma, xi = q.sigma, q.xi
    R = (1.0 - 2.0 * xi * xi) * np.eye(2) + 2.0 * sigma * xi * J
    p = 2.0 * (sigma * np.eye(2) + xi * J) @ np.array([q.x1, q.x2])
    return R, p


def twistor_from_twist(d: np.ndarray) -> Twistor:
    """
    Twistor of a twist: (cos(tau/2), sin(tau/2)/tau * (tau, t1, t2)) (eqs. 2.132-2.135).

    The exponential of the dual vector tau + eps t, so its coefficients are those of the
    quaternion exponential (``quaternion.exp_coefficients``, with their series near 0).
    """
    d = as_array("d", d, (3,))
    a, k = exp_coefficients(float(d[0]) ** 2)
    return Twistor(float(a), float(k * d[0]), float(k * d[1]), float(k * d[2]))


# ------------------------------------------------------------------ frames / adjoint

def adjoint(R: np.ndarray, p: np.ndarray) -> np.ndarray:
    """
    Adjoint map Ad(R, p) of a planar displacement (eq. 4.38, 3.23), 3x3 on (omega, v1, v2).

    For a frame c' with pose (R, p) relative to frame c, Ad = [[1, 0], [-J p, R]] maps a
    twist expressed in c' (angular rate, velocity of c''s origin in c' coordinates) to the
    same twist expressed in c (velocity of c's origin in c coordinates). Wrenches map the
    other way with Ad^-T = [[1, hat(p)^T R], [0, R]] (eq. 4.37).
    """
    R, p = as_array("R", R, (2, 2)), as_array("p", p, (2,))
    A = np.zeros((3, 3))
    A[0, 0] = 1.0
    A[1:, 0] = -J @ p
    A[1:, 1:] = R
    return A


def transform_stiffness(K: np.ndarray, R: np.ndarray, p: np.ndarray) -> np.ndarray:
    """
    Stiffness for hinge frames moved by (R, p) on both bodies (Sections 3.3, 4.6).

    With a' = a*(R, p) and b' = b*(R, p), the relative displacement is conjugated, so its
    twist (and the twistor's vector part, which is proportional to it) maps as
    d = Ad(R, p) d'. The same potential 1/2 d^T K d is then 1/2 d'^T K' d' with
    K' = Ad^T K Ad.
    """
    Ad = adjoint(R, p)
    return Ad.T @ as_array("K", K, (3, 3)) @ Ad


def compose(pose_a: tuple[np.ndarray, np.ndarray], pose_b: tuple[np.ndarray, np.ndarray]):
    """Compose planar poses (R_a, p_a) * (R_b, p_b) = (R_a R_b, p_a + R_a p_b)."""
    Ra, pa = pose_a
    Rb, pb = pose_b
    return Ra @ Rb, pa + Ra @ pb


def relative(pose_a, pose_b):
    """Pose of b relative to a, (R_a^T R_b, R_a^T (p_b - p_a))."""
    Ra, pa = pose_a
    Rb, pb = pose_b
    return Ra.T @ Rb, Ra.T @ (pb - pa)
