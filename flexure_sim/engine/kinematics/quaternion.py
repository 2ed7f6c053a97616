"""
Rotations of the spatial engine: unit quaternions, rotation vectors, and their Jacobians.

Conventions (used everywhere in flexure_sim.engine.spatial):

- A quaternion is (w, x, y, z), Hamilton's product; the unit quaternion q rotates body
  coordinates into root coordinates, v_root = R(q) v_body, and q_A q_B is R_A R_B.
- A body's orientation is R = R0 Exp(phi): R0 its rest orientation, phi in R^3 the *rotation
  vector* relative to it, in body coordinates (the body's rotation coordinates). Exp is
  Rodrigues' formula, Exp(phi) = I + sin(t)/t hat(phi) + (1 - cos t)/t^2 hat(phi)^2, t = |phi|;
  its quaternion is (cos(t/2), sin(t/2)/t phi).
- Angular velocities are in body coordinates, omega with dR/dt = R hat(omega); then
  dphi/dt = Jr^-1(phi) omega, Jr^-1(phi) = I + 1/2 hat(phi) + c(t^2) hat(phi)^2 with
  c = 1/t^2 - (1 + cos t)/(2 t sin t) (the right Jacobian of SO(3); e.g. Barfoot, "State
  Estimation for Robotics", 2017, eq. 7.77a; Chirikjian, "Stochastic Models, Information Theory
  and Lie Groups" vol. 2, 2012, 10.2).

Working range of the rotation coordinates: |phi| <= pi, where every orientation has a rotation
vector and Jr^-1 is regular (it is singular only at |phi| = 2 pi); the engine refuses states
beyond it (``solver.spatial_model.SpatialModel.check_range``). Planar motion about the rest
orientation's z
axis keeps phi = (0, 0, theta - theta0) exactly.

The scalar functions below are formulas on a generic scalar (``kinematics.scalar``): compiled
for the stepping kernel and evaluated on hyper-dual numbers for exact Jacobians. Near t = 0
each uses its Taylor series in s = t^2 (coefficients from the series of cos, sin and
(t/2) cot(t/2)), so every one is smooth there.
"""
from __future__ import annotations

import numpy as np

from flexure_sim.engine.kinematics.scalar import formula, real

#: Below this t^2 the exponential's coefficients come from their series (truncation < 1e-20).
EXP_SERIES = 1e-2
#: Below this t^2 c(s) and c'(s) come from their series: the closed forms cancel (c' loses
#: ~1e-13 at s = 0.5), the series' first omitted term is below 1e-15 of c' at s = 1.
JR_SERIES = 1.0
#: Below this |vector part|^2 the rotation angle factor comes from the series of asin.
ANGLE_SERIES = 1e-6

#: Taylor coefficients of c(s) = (1 - (t/2) cot(t/2)) / t^2 in s = t^2.
_C_SERIES = (1.0 / 12.0, 1.0 / 720.0, 1.0 / 30240.0, 1.0 / 1209600.0, 1.0 / 47900160.0,
             691.0 / 1307674368000.0, 1.0 / 74724249600.0, 3617.0 / 10670622842880000.0,
             43867.0 / 5109094217170944000.0, 174611.0 / 802857662698291200000.0,
             77683.0 / 14101100039391805440000.0)


@formula(inline=False)
def exp_coefficients(s):
    """Return (cos(t/2), sin(t/2)/t) for s = t^2: the quaternion Exp(phi) = (a, b phi)."""
    if real(s) < EXP_SERIES:
        c4 = -1.0 / 46080.0 + s / 10321920.0
        s4 = -1.0 / 645120.0 + s / 185794560.0
        cosine = 1.0 + s * (-1.0 / 8.0 + s * (1.0 / 384.0 + s * c4))
        sine = 0.5 + s * (-1.0 / 48.0 + s * (1.0 / 3840.0 + s * s4))
        return cosine, sine
    t = np.sqrt(s)
    return np.cos(0.5 * t), np.sin(0.5 * t) / t


@formula(inline=False)
def jr_coefficient(s):
    """
    Return c(s) and dc/ds, c = 1/t^2 - (1 + cos t)/(2 t sin t) of Jr^-1 (module docstring).

    c = (1 - f)/s with f = (t/2) cot(t/2); dc/ds = -(1 - f)/s^2 - f'(t)/(2 t s),
    f'(t) = cot(t/2)/2 - t/(4 sin^2(t/2)).
    """
    if real(s) < JR_SERIES:
        c = 0.0 * s
        dc = 0.0 * s
        for k in range(10, -1, -1):
            c = c * s + _C_SERIES[k]
        for k in range(10, 0, -1):
            dc = dc * s + k * _C_SERIES[k]
        return c, dc
    t = np.sqrt(s)
    h = 0.5 * t
    sn, cs = np.sin(h), np.cos(h)
    f = h * cs / sn
    df = 0.5 * cs / sn - t / (4.0 * sn * sn)
    return (1.0 - f) / s, -(1.0 - f) / (s * s) - df / (2.0 * t * s)


@formula(inline=False)
def angle_factor(m, sigma):
    """
    Return G = t / sin(t/2) of a unit quaternion (sigma, v), m = |v|^2, t = 2 atan2(|v|, sigma).

    The rotation vector of the quaternion is G v (t in [0, 2 pi)). Near m = 0 (sigma > 0)
    G = 2 asin(n)/n = 2 + m/3 + 3 m^2/20 + 5 m^3/56 + ..., n = sqrt(m).
    """
    if real(m) < ANGLE_SERIES and real(sigma) > 0.0:
        return 2.0 + m * (1.0 / 3.0 + m * (3.0 / 20.0 + m * (5.0 / 56.0)))
    n = np.sqrt(m)
    return 2.0 * half_angle(n, sigma) / n


@formula(inline=False)
def half_angle(n, sigma):
    """
    Return atan2(n, sigma) for n >= 0, in [0, pi], through arctan only.

    arctan(n / sigma) where |sigma| >= n (plus pi for sigma < 0), pi/2 - arctan(sigma / n)
    elsewhere: each branch is analytic, so the complex step and hyper-dual numbers pass it
    (NumPy's arctan2 takes neither complex numbers nor a branch-free derivative).
    """
    if abs(real(sigma)) >= real(n):
        if real(sigma) > 0.0:
            return np.arctan(n / sigma)
        return np.arctan(n / sigma) + np.pi
    return 0.5 * np.pi - np.arctan(sigma / n)


@formula(inline=False)
def qmul(a, b):
    """Hamilton product a b of quaternions given as 4-tuples (w, x, y, z)."""
    return (a[0] * b[0] - a[1] * b[1] - a[2] * b[2] - a[3] * b[3],
            a[0] * b[1] + a[1] * b[0] + a[2] * b[3] - a[3] * b[2],
            a[0] * b[2] - a[1] * b[3] + a[2] * b[0] + a[3] * b[1],
            a[0] * b[3] + a[1] * b[2] - a[2] * b[1] + a[3] * b[0])


@formula(inline=False)
def qconj_mul(a, b):
    """Return conj(a) b: the rotation of b relative to a."""
    return (a[0] * b[0] + a[1] * b[1] + a[2] * b[2] + a[3] * b[3],
            a[0] * b[1] - a[1] * b[0] - a[2] * b[3] + a[3] * b[2],
            a[0] * b[2] + a[1] * b[3] - a[2] * b[0] - a[3] * b[1],
            a[0] * b[3] - a[1] * b[2] + a[2] * b[1] - a[3] * b[0])


@formula(inline=False)
def quaternion_exp(phi0, phi1, phi2):
    """Return the quaternion of Exp(phi): (cos(t/2), sin(t/2)/t phi) (module docstring)."""
    a, b = exp_coefficients(phi0 * phi0 + phi1 * phi1 + phi2 * phi2)
    return a, b * phi0, b * phi1, b * phi2


@formula(inline=False)
def matrix_of(q):
    """Return the rotation matrix of a unit quaternion, rows first, as a 9-tuple."""
    w, x, y, z = q
    return (1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y - w * z), 2.0 * (x * z + w * y),
            2.0 * (x * y + w * z), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z - w * x),
            2.0 * (x * z - w * y), 2.0 * (y * z + w * x), 1.0 - 2.0 * (x * x + y * y))


@formula(inline=False)
def rotate(R, v):
    """Return R v for a 9-tuple matrix R and a 3-tuple v."""
    return (R[0] * v[0] + R[1] * v[1] + R[2] * v[2],
            R[3] * v[0] + R[4] * v[1] + R[5] * v[2],
            R[6] * v[0] + R[7] * v[1] + R[8] * v[2])


@formula(inline=False)
def rotate_back(R, v):
    """Return R^T v for a 9-tuple matrix R and a 3-tuple v."""
    return (R[0] * v[0] + R[3] * v[1] + R[6] * v[2],
            R[1] * v[0] + R[4] * v[1] + R[7] * v[2],
            R[2] * v[0] + R[5] * v[1] + R[8] * v[2])


@formula(inline=False)
def cross(a, b):
    """Return a x b of 3-tuples."""
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


@formula
def twistor_translation(sigma, xi, p):
    """
    Return x = 1/2 (sigma p + p x xi): the dual part's vector of the unit dual quaternion.

    Of the displacement (R, p) with rotation quaternion (sigma, xi): q_d = 1/2 p q_r
    (``laws.spatial``). Restricted to the plane (xi = (0, 0, xi_z), p = (p1, p2, 0)) it is
    the planar twistor's x = 1/2 (sigma I - xi J) p (dissertation eq. 2.178, whose twistor
    (sigma, xi, x1, x2) is the planar restriction of the dual quaternion), term by term in the
    same floating-point operations.
    """
    pxi = cross(p, xi)
    return (0.5 * (sigma * p[0] + pxi[0]), 0.5 * (sigma * p[1] + pxi[1]),
            0.5 * (sigma * p[2] + pxi[2]))


@formula(inline=False)
def rotation_vector(q):
    """Return the rotation vector (t in [0, 2 pi)) of a unit quaternion (w, x, y, z)."""
    g = angle_factor(q[1] * q[1] + q[2] * q[2] + q[3] * q[3], q[0])
    return g * q[1], g * q[2], g * q[3]


@formula(inline=False)
def phi_rate(phi, omega):
    """Return dphi/dt = Jr^-1(phi) omega = omega + phi x omega / 2 + c phi x (phi x omega)."""
    c = jr_coefficient(phi[0] * phi[0] + phi[1] * phi[1] + phi[2] * phi[2])[0]
    a = cross(phi, omega)
    b = cross(phi, a)
    return (omega[0] + 0.5 * a[0] + c * b[0], omega[1] + 0.5 * a[1] + c * b[1],
            omega[2] + 0.5 * a[2] + c * b[2])


# ------------------------------------------------------- plain NumPy, for files and reports

def quaternion_of_rpy(roll: float, pitch: float, yaw: float) -> np.ndarray:
    """
    Return the quaternion of fixed-axis roll, pitch, yaw (REP-103, URDF ``rpy``).

    R = Rz(yaw) Ry(pitch) Rx(roll), as (w, x, y, z).
    """
    half = 0.5 * np.array([roll, pitch, yaw], dtype=float)
    qx = (np.cos(half[0]), np.sin(half[0]), 0.0, 0.0)
    qy = (np.cos(half[1]), 0.0, np.sin(half[1]), 0.0)
    qz = (np.cos(half[2]), 0.0, 0.0, np.sin(half[2]))
    return np.array(qmul(qz, qmul(qy, qx)))


def matrix(q) -> np.ndarray:
    """Return the 3x3 rotation matrix of a unit quaternion (w, x, y, z)."""
    return np.array(matrix_of(tuple(float(c) for c in q))).reshape(3, 3)


def quaternion_of_vector(phi) -> np.ndarray:
    """Return the quaternion of Exp(phi) for a rotation vector phi."""
    return np.array(quaternion_exp(*(float(c) for c in phi)))


def vector_of_quaternion(q) -> np.ndarray:
    """Return the rotation vector of a unit quaternion, sign chosen so that |phi| <= pi."""
    q = np.asarray(q, dtype=float)
    if q[0] < 0.0:
        q = -q
    return np.array(rotation_vector(tuple(q)))
