"""
Chapter 7.1 reproduced: the dissertation's fit of generalized forces on random data.

``randomtest_data`` / ``randomtest_fit`` do what randomtest.sce and makeAB_Q.sci (Appendix B)
do: 17 random configurations, random wrenches, order 4, c_U = pinv(A) 2 Delta m (eq. 7.7);
``randomtest_report`` and ``randomtest_spread`` set them against ``fitting.fit_polynomial`` on
the same rows (docs/polynomial_hinges.md). Command line: ``python -m
flexure_sim.engine.fitting.datasets randomtest``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, TypedDict

import numpy as np

from flexure_sim.engine.fitting.least_squares import FitError, fit_polynomial
from flexure_sim.engine.laws.coordinates import twistor_coordinates
from flexure_sim.engine.kinematics.planar import rot
from flexure_sim.engine.laws.monomials import monomial_exponents, monomial_gradients
from flexure_sim.engine.fitting.wrench_data import WrenchData


# ------------------------------------------------------------------ Chapter 7.1

#: Ranges of randomtest.sce. th_dist reads "%pi/4"; alpha_dist is printed "5lpi/4", which
#: we read as %pi/4 (the other reading, 5 %pi/4, is a parameter of randomtest_data).
class RandomtestRanges(TypedDict):
    """The constants of randomtest.sce: configurations, polynomial order, angle ranges (rad)."""

    n_config: int
    order: int
    th_dist: float
    alpha_dist: float


RANDOMTEST: RandomtestRanges = {"n_config": 17, "order": 4, "th_dist": math.pi / 4,
                                "alpha_dist": math.pi / 4}


def randomtest_data(rng: np.random.Generator, n_config: int = 17, alpha_dist: float = math.pi / 4,
                    th_dist: float = math.pi / 4) -> WrenchData:
    """
    Random configurations and wrenches as randomtest.sce draws them (Appendix B, 7.1-7.6).

    Alpha uniform in +-alpha_dist/2, translation of length 3 + 5 RN at an angle uniform in
    +-th_dist/2, and m, f1, f2 uniform in (-1, 1). randomtest.sce forms x = 0.5 (sigma I -
    sk(xi))^T p0b = 0.5 R(alpha/2) p0b, i.e. p0b is the translation in frame b's axes; the
    displacement in frame a is p = R(alpha) p0b. (Scilab's generator cannot be reproduced; the seed
    is NumPy's.)
    """
    th = th_dist * rng.random(n_config) - 0.5 * th_dist
    alpha = alpha_dist * rng.random(n_config) - 0.5 * alpha_dist
    radius = 3.0 + 5.0 * rng.random(n_config)
    p0b = radius[:, None] * np.column_stack([np.cos(th), np.sin(th)])
    wrench = 1.0 - 2.0 * rng.random((n_config, 3))
    p = np.einsum("nij,nj->ni", rot(alpha), p0b)
    return WrenchData(alpha, p, wrench, "randomtest.sce")


def _delta(c: np.ndarray) -> np.ndarray:
    """
    Delta of randomtest.sce.

    Q = 2 Delta m (eq. 7.7), one generalized force per twistor parameter; 1/2 Delta_inv with
    Delta_inv Delta = I maps Q back to m.
    """
    sigma, xi, x1, x2 = c.T
    D = np.zeros((len(c), 4, 3))
    D[:, 0] = np.column_stack([-xi, -x1, -x2])
    D[:, 1] = np.column_stack([sigma, -x2, x1])
    D[:, 2, 1:] = np.column_stack([sigma, -xi])
    D[:, 3, 1:] = np.column_stack([xi, sigma])
    return D


def _delta_inv(c: np.ndarray) -> np.ndarray:
    sigma, xi, x1, x2 = c.T
    D = np.zeros((len(c), 3, 4))
    D[:, 0] = np.column_stack([-xi, sigma, x2, -x1])
    D[:, 1, 2:] = np.column_stack([sigma, xi])
    D[:, 2, 2:] = np.column_stack([-xi, sigma])
    return D


@dataclass(frozen=True)
class GeneralizedForceFit:
    """c_U of 4.69 in the full, unscaled basis (idx4.sci order) fitted as randomtest.sce does."""

    order: int
    coefficients: np.ndarray

    def wrench(self, data: WrenchData) -> np.ndarray:
        """Return m = 1/2 Delta_inv Q with Q = dU/dc (evalpoly4 of c_Sigma, c_Xi, c_X1, c_X2)."""
        c = twistor_coordinates(data.alpha, data.p).c
        Q = np.einsum(
            "nmk,m->nk",
            monomial_gradients(c, monomial_exponents(4, self.order)),
            self.coefficients,
        )
        return 0.5 * np.einsum("nij,nj->ni", _delta_inv(c), Q)


def randomtest_fit(data: WrenchData, order: int = 4) -> GeneralizedForceFit:
    """
    makeAB_Q.sci and randomtest.sce.

    Rows A_i = dU/dc of every monomial of 4.69 at c_i (unscaled sigma, xi, x1, x2), right-hand
    sides Q_i = 2 Delta m_i, c_U = pinv(A) B with Scilab's pinv tolerance (max(size) * eps *
    largest singular value).
    """
    c = twistor_coordinates(data.alpha, data.p).c
    exps = monomial_exponents(4, order)
    A = np.transpose(monomial_gradients(c, exps), (0, 2, 1)).reshape(4 * len(c), len(exps))
    B = 2.0 * np.einsum("nij,nj->ni", _delta(c), data.wrench).reshape(-1)
    coef = np.linalg.pinv(A, rcond=max(A.shape) * np.finfo(float).eps) @ B
    return GeneralizedForceFit(order, coef)


def randomtest_report(seed: int = 22, alpha_dist: float = math.pi / 4) -> dict[str, Any]:
    """
    Chapter 7.1 reproduced.

    The dissertation's fit on 17 random configurations (order 4) and its error on the training rows
    and on 17 fresh rows; and flexure_sim's fit (three equations per row) on the same rows, with
    sigma_degree 0 and 1.
    """
    rng = np.random.default_rng(seed)
    train = randomtest_data(rng, alpha_dist=alpha_dist)
    fresh = randomtest_data(rng, alpha_dist=alpha_dist)
    order = RANDOMTEST["order"]
    diss = randomtest_fit(train, order)

    def errs(pred: np.ndarray, data: WrenchData) -> dict[str, Any]:
        e = np.max(np.abs(pred - data.wrench), axis=0)
        peak = np.max(np.abs(data.wrench), axis=0)
        return {
            "max_abs": e.tolist(),
            "max_measured": peak.tolist(),
            "max_rel": (e / peak).tolist(),
        }

    n_coef = len(monomial_exponents(4, order))
    out: dict[str, Any] = {
        "seed": seed,
        "alpha_dist": alpha_dist,
        "rows": len(train),
        "dissertation_method": {
            "equations": 4 * len(train),
            "unknowns": n_coef,
            "train": errs(diss.wrench(train), train),
            "fresh": errs(diss.wrench(fresh), fresh),
        },
    }
    for sd in (0, 1):
        try:
            res = fit_polynomial(train, order, "twistor", sigma_degree=sd, test=fresh)
        except FitError as exc:
            out[f"flexure_sim_sigma_degree_{sd}"] = {"error": str(exc)}
            continue
        out[f"flexure_sim_sigma_degree_{sd}"] = {
            "equations": res.report["equations"],
            "unknowns": res.report["unknowns"],
            "train": {k: res.report["train"][k] for k in ("max_abs", "max_measured", "max_rel")},
            "fresh": {k: res.report["test"][k] for k in ("max_abs", "max_measured", "max_rel")},
        }
    return out


def randomtest_spread(n_seeds: int = 30, alpha_dist: float = math.pi / 4) -> dict[str, Any]:
    """
    Return the dissertation-method training error of Chapter 7.1 over seeds 0..n_seeds-1.

    The largest moment error (median, min, max) and the median condition number of the 68 x 70
    makeAB_Q matrix (the spread shows that the error is set by rounding).
    """
    errors, conds = [], []
    exps = monomial_exponents(4, RANDOMTEST["order"])
    for seed in range(n_seeds):
        data = randomtest_data(np.random.default_rng(seed), alpha_dist=alpha_dist)
        fit = randomtest_fit(data, RANDOMTEST["order"])
        errors.append(np.max(np.abs(fit.wrench(data) - data.wrench), axis=0))
        c = twistor_coordinates(data.alpha, data.p).c
        A = np.transpose(monomial_gradients(c, exps), (0, 2, 1)).reshape(4 * len(c), len(exps))
        s = np.linalg.svd(A, compute_uv=False)
        conds.append(s[0] / s[min(A.shape) - 1])
    e = np.array(errors)[:, 0]
    return {"seeds": n_seeds, "alpha_dist": alpha_dist, "moment_error_median": float(np.median(e)),
            "moment_error_min": float(e.min()), "moment_error_max": float(e.max()),
            "condition_number_median": float(np.median(conds))}
