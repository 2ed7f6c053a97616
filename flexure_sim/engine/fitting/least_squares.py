"""
Fitting polynomial hinge laws to measured (displacement, wrench) pairs (Ch. 7, Appendix B).

Data: rows of r = (alpha, px, py) -- rotation (rad) and translation (m) of frame b relative
to frame a, in frame a -- and m_b = (m, fx, fy) -- the wrench exerted by body B on the
elastic element, in frame b coordinates, moment about b's origin (N m, N; eqs. 4.34-4.35,
Chapter 7). The potential's virtual work gives (``hinge_laws.wrench_on_element``)

    m_b = (dU/dalpha, R(alpha)^T dU/dp),   dU/dr = (dc/dr)^T dU/dc,

and dU/dc is linear in the coefficients, so every row gives three linear equations for them:
the method of makeAB_Q.sci, written in r instead of in the generalized forces of (7.7). The
difference matters for twistors: sigma and xi are tied by sigma^2 + xi^2 = 1, so the four
generalized forces of (7.7) are not determined by the three wrench components (randomtest.sce
picks one particular solution, Q = 2 Delta m). Working in r uses exactly the three measured
numbers per row.

*Identifiability.* Only U on the displacement manifold is observed, and only up to a
constant. For twist coordinates every monomial is identifiable. For twistors, on the data
(|alpha| < pi) sigma = +sqrt(1 - xi^2) is a function of xi: a polynomial of order N in
(sigma, xi, x) equals p0(xi, x) + sigma p1(xi, x) there (reduce sigma^2 = 1 - xi^2), and that
form is unique, so at most the terms with sigma-exponent <= 1 are identifiable (the other
C(N+4,4) - C(N+3,3) - C(N+2,3) coefficients of 4.69 are not). For the rotations of flexure
hinges sigma - 1 ~ -xi^2/2 is, to many digits, already a polynomial in xi, and the sigma p1
terms are numerically collinear with the xi terms. The fit therefore uses
``sigma_degree = 0`` by default (polynomials in xi, x1, x2) and ``sigma_degree = 1`` on
request (useful only for rotations approaching pi); a design whose columns are still
dependent is reported as rank-deficient (or solved with a ridge if ``regularization`` > 0).

*Scaling.* Each law variable is divided by its largest deviation from rest in the data, so
the monomials lie in [-1, 1]; the moment rows are divided by the RMS moment and the force
rows by the RMS force magnitude (relative errors count equally); the columns are then
equilibrated to unit norm and the system solved by SVD. Orders up to 8 stay well
conditioned (the condition number is reported).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Optional

import numpy as np

from flexure_sim.errors import FlexureSimError
from flexure_sim.engine.laws.coordinates import COORDINATES
from flexure_sim.engine.laws.quadratic import wrench_on_element
from flexure_sim.engine.kinematics.planar import rot
from flexure_sim.engine.laws.monomials import (
    describe_monomial, monomial_exponents, monomial_gradients,
)
from flexure_sim.engine.laws.polynomial import MAX_ORDER, REST, VARIABLES, PolynomialLaw
from flexure_sim.engine.fitting.wrench_data import COLUMNS, MAX_ABS_VALUE, WrenchData

#: A design whose smallest singular value (unit-norm columns) is below this fraction of the
#: largest is rank-deficient.
RANK_TOLERANCE = 1e-10

#: Wrench components, in the order of the CSV and of every per-component list.
COMPONENTS = ("m", "fx", "fy")


class FitError(FlexureSimError, ValueError):
    """The data cannot determine the requested polynomial; the message says why."""


# -------------------------------------------------------------- prediction, errors

def predict_wrench(law, alpha: np.ndarray, p: np.ndarray) -> np.ndarray:
    """
    m_b (n, 3) of a law at displacements r = (alpha, p).

    The chain rule of ``hinge_laws.evaluate`` (vectorised over rows of one law) and
    ``wrench_on_element``.
    """
    alpha = np.asarray(alpha, dtype=float)
    cmap = COORDINATES[law.coordinates](alpha, np.asarray(p, dtype=float))
    _, Uc, _ = law.potential(cmap.c)
    return wrench_on_element(alpha, np.einsum("nki,nk->ni", cmap.dc, Uc))


def wrench_errors(law, data: WrenchData) -> dict[str, Any]:
    """
    Errors of the law's wrench against the data, per component (m, fx, fy).

    Rms and max_abs (N m, N, N), max_rel = max |error| / max |measured| of that component (the
    figures of Chapter 7.1), and worst_rel = the largest max_rel.
    """
    err = predict_wrench(law, data.alpha, data.p) - data.wrench
    peak = np.max(np.abs(data.wrench), axis=0)
    max_abs = np.max(np.abs(err), axis=0)
    rel = np.where(
        peak > 0, max_abs / np.where(peak > 0, peak, 1.0), np.where(max_abs > 0, np.inf, 0.0)
    )
    return {
        "rows": len(data),
        "rms": [float(v) for v in np.sqrt(np.mean(err**2, axis=0))],
        "max_abs": [float(v) for v in max_abs],
        "max_measured": [float(v) for v in peak],
        "max_rel": [float(v) for v in rel],
        "worst_rel": float(np.max(rel)),
    }


# ------------------------------------------------------------------------ fitting

def basis_exponents(coordinates: str, order: int, sigma_degree: int = 0) -> np.ndarray:
    """
    Exponents of the fitted terms.

    All monomials of order <= N in the scaled law coordinates except the constant and the linear
    terms in the vector coordinates (fixed by the unstressed equilibrium); for twistors only
    sigma-exponents <= sigma_degree (0 or 1, the identifiable ones, see the module docstring).
    idx4.sci order.
    """
    if coordinates not in VARIABLES:
        raise FitError(f"coordinates must be twistor or twist, got {coordinates!r}")
    k = len(VARIABLES[coordinates])
    exps = monomial_exponents(k, order)
    deg = exps.sum(axis=1)
    keep = deg >= 2
    if coordinates == "twistor":
        if sigma_degree not in (0, 1):
            raise FitError(
                "sigma_degree must be 0 or 1 (higher powers of sigma are not identifiable), got "
                f"{sigma_degree!r}"
            )
        keep &= exps[:, 0] <= sigma_degree
        keep |= (exps[:, 0] == 1) & (deg == 1) & (sigma_degree == 1)
    return exps[keep]


@dataclass(frozen=True)
class FitResult:
    """The fitted law (damping B = 0: the mechanism file supplies it) and a JSON-ready report."""

    law: PolynomialLaw
    report: dict[str, Any]


def _scales(coordinates: str, c: np.ndarray) -> np.ndarray:
    """s_k: the largest deviation of each law coordinate from rest in the data."""
    dev = np.max(np.abs(c - np.array(REST[coordinates])), axis=0)
    # A variable that never moves keeps scale 1 (its terms then make the design singular,
    # which the rank test reports by name).
    return np.where(dev > 0, dev, 1.0)


def _design(
    coordinates: str, exps: np.ndarray, data: WrenchData, scale: np.ndarray, energy: float
) -> np.ndarray:
    """
    Return a (n, 3, M).

    Column j is m_b of the term energy * u^e_j at each row (u = scaled c).
    """
    cmap = COORDINATES[coordinates](data.alpha, data.p)
    u = (cmap.c - np.array(REST[coordinates])) / scale
    dU_dc = monomial_gradients(u, exps) * (energy / scale)  # (n, M, k)
    grad_r = np.einsum("nki,nmk->nim", cmap.dc, dU_dc)  # (n, 3, M)
    R = rot(data.alpha)
    out = np.empty_like(grad_r)
    out[:, 0] = grad_r[:, 0]
    out[:, 1:] = np.einsum("nji,njm->nim", R, grad_r[:, 1:])  # m_b = (dU/dalpha, R^T dU/dp)
    return out


def number_of_unknowns(coordinates: str, order: int, sigma_degree: int = 0) -> int:
    """How many coefficients a fit of this order determines."""
    return len(basis_exponents(coordinates, order, sigma_degree))


def fit_polynomial(
    data: WrenchData,
    order: int,
    coordinates: str = "twistor",
    *,
    regularization: float = 0.0,
    sigma_degree: int = 0,
    test: Optional[WrenchData] = None,
) -> FitResult:
    """
    Least-squares fit of an order-N polynomial law to measured wrenches (makeAB_Q.sci).

    regularization: lambda >= 0 of the ridge min ||A y - b||^2 + lambda ||y||^2 on the
    scaled, column-equilibrated system (unit-norm columns, so lambda is dimensionless: singular
    values s are filtered by s^2 / (s^2 + lambda)). With lambda = 0 a rank-deficient design is
    an error that names the undetermined terms.
    test: held-out data, whose errors go into the report.
    """
    if (
        isinstance(order, bool)
        or not isinstance(order, (int, np.integer))
        or not 2 <= order <= MAX_ORDER
    ):
        raise FitError(f"order must be an integer from 2 to {MAX_ORDER}, got {order!r}")
    order = int(order)
    if coordinates not in VARIABLES:
        raise FitError(f"coordinates must be twistor or twist, got {coordinates!r}")
    if not (np.isfinite(regularization) and regularization >= 0):
        raise FitError(f"regularization must be a non-negative number, got {regularization!r}")
    table = np.column_stack([data.alpha, data.p, data.wrench])
    if not np.all(np.isfinite(table)) or np.max(np.abs(table), initial=0.0) > MAX_ABS_VALUE:
        raise FitError(_overflow(data))
    exps = basis_exponents(coordinates, order, sigma_degree)
    names = VARIABLES[coordinates]
    n, M = len(data), len(exps)
    if 3 * n < M:
        raise FitError(
            f"too few rows for order {order}: {n} rows give {3 * n} equations (3 per row), but an "
            f"order-{order} "
            f"polynomial in {coordinates} coordinates has {M} unknown coefficients; "
            f"give at least {math.ceil(M / 3)} rows or lower the order"
        )
    m_rms = float(np.sqrt(np.mean(data.wrench[:, 0] ** 2)))
    f_rms = float(np.sqrt(np.mean(np.sum(data.wrench[:, 1:] ** 2, axis=1))))
    if m_rms == 0 and f_rms == 0:
        raise FitError(f"{data.source}: every wrench is zero: there is nothing to fit")
    length = float(np.max(np.linalg.norm(data.p, axis=1))) or 1.0
    energy = max(m_rms, f_rms * length)
    # Row weights: relative errors of moments and of forces count equally (a component that
    # is zero throughout falls back to the energy scale).
    w_m = 1.0 / m_rms if m_rms > 0 else length / energy
    w_f = 1.0 / f_rms if f_rms > 0 else 1.0 / energy
    w = np.array([w_m, w_f, w_f])
    cmap = COORDINATES[coordinates](data.alpha, data.p)
    scale = _scales(coordinates, cmap.c)
    A = (_design(coordinates, exps, data, scale, energy) * w[None, :, None]).reshape(3 * n, M)
    b = (data.wrench * w).reshape(3 * n)
    norms = np.linalg.norm(A, axis=0)
    dead = np.nonzero(norms == 0)[0]
    if len(dead) and regularization == 0:
        raise FitError(
            "rank-deficient design: the data do not determine the "
            f"term{'s' if len(dead) > 1 else ''} "
            f"{', '.join(describe_monomial(exps[j], names) for j in dead[:6])}"
            f"{' ...' if len(dead) > 6 else ''} "
            f"(their wrench is zero at every row: the data never move "
            f"{_unmoved(cmap.c, coordinates, exps[dead]) or 'the variables they involve'}); "
            f"use more varied data, a lower order, or --regularization"
        )
    norms = np.where(norms > 0, norms, 1.0)
    An = A / norms
    if not (np.all(np.isfinite(An)) and np.all(np.isfinite(b))):
        raise FitError(_overflow(data))
    try:
        U, s, Vt = np.linalg.svd(An, full_matrices=False)
    except np.linalg.LinAlgError:
        raise FitError(_overflow(data)) from None
    cond = float(s[0] / s[-1]) if s[-1] > 0 else math.inf
    rank = int(np.sum(s > RANK_TOLERANCE * s[0]))
    if rank < M and regularization == 0:
        null = Vt[-1]
        top = np.argsort(-np.abs(null))[:4]
        raise FitError(
            f"rank-deficient design: numerical rank {rank} < {M} unknowns (condition number "
            f"{cond:.3g}); "
            "the data cannot separate the terms "
            f"{', '.join(describe_monomial(exps[j], names) for j in top)} "
            f"(the combination with weights {', '.join(f'{null[j]:+.2f}' for j in top)} leaves "
            "every "
            f"wrench unchanged); use more varied data, a lower order, or --regularization"
        )
    if regularization > 0:
        filt = s / (s**2 + regularization)
    else:
        filt = 1.0 / s
    y = Vt.T @ (filt * (U.T @ b))
    coef = y / norms
    law = PolynomialLaw(coordinates, order, exps, coef, scale, energy)
    report: dict[str, Any] = {
        "coordinates": coordinates,
        "order": order,
        "sigma_degree": sigma_degree if coordinates == "twistor" else None,
        "rows": n,
        "equations": 3 * n,
        "unknowns": M,
        "equations_per_unknown": 3 * n / M,
        "rank": rank,
        "condition_number": cond,
        "regularization": float(regularization),
        "scale": {name: float(v) for name, v in zip(names, scale)},
        "energy_scale": energy,
        "row_weights": {"moment": float(w[0]), "force": float(w[1])},
    }
    train = wrench_errors(law, data)
    report["train"] = train
    report["train_rms"] = train["rms"]
    report["train_max_abs"] = train["max_abs"]
    report["train_max_rel"] = train["worst_rel"]
    if test is not None:
        held = wrench_errors(law, test)
        report["test"] = held
        report["test_rms"] = held["rms"]
        report["test_max_abs"] = held["max_abs"]
        report["test_max_rel"] = held["worst_rel"]
    K = law.stiffness_at_rest()
    report["stiffness_at_rest"] = [[float(v) for v in row] for row in K]
    report["stable_at_rest"] = bool(np.all(np.linalg.eigvalsh(K) > 0))
    return FitResult(law, report)


def _overflow(data: WrenchData) -> str:
    """Why the fit's arithmetic would leave the double range: the worst value and its row."""
    table = np.column_stack([data.alpha, data.p, data.wrench])
    size = np.where(np.isfinite(table), np.abs(table), np.inf)
    row, col = np.unravel_index(np.argmax(size), table.shape)
    return (f"{data.source}: row {row + 1}, column {COLUMNS[col]!r}: {table[row, col]:g} is too "
            f"large to fit (values must be finite with |value| <= {MAX_ABS_VALUE:g}, or the "
            "least-squares system overflows): check the units (SI)")


def _unmoved(c: np.ndarray, coordinates: str, exps: np.ndarray) -> str:
    """Names of the variables that never leave their rest value and appear in ``exps``."""
    dev = np.max(np.abs(c - np.array(REST[coordinates])), axis=0)
    used = exps.sum(axis=0) > 0
    return ", ".join(n for n, d, u in zip(VARIABLES[coordinates], dev, used) if d == 0 and u)


def summarize_errors(report: dict[str, Any], which: str = "test") -> str:
    """One line per component: max |error| against the largest measured value."""
    part = report[which]
    units = ("N m", "N", "N")
    return "\n".join(
        f"  {name:3s} max |error| {err:.3g} {unit} of max {peak:.3g} {unit} ({rel:.3g}), rms "
        f"{rms:.3g} {unit}"
        for name, unit, err, peak, rel, rms in zip(
            COMPONENTS, units, part["max_abs"], part["max_measured"], part["max_rel"], part["rms"]
        )
    )
