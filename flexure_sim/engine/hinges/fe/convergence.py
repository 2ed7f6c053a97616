"""
Mesh convergence of a finite-element hinge: three refinements and Richardson extrapolation.

The resolution n (elements across every section, mesh.py) is doubled twice, n, 2n, 4n, which
halves every element each time. For a quantity Q with error C h^p, the three values give the
observed order and the extrapolated limit (L. F. Richardson, Phil. Trans. R. Soc. A 210
(1911) 307; the "grid convergence index" practice of P. J. Roache, J. Fluids Eng. 116 (1994)
405):

    p = log2((Q_n - Q_2n) / (Q_2n - Q_4n)),   Q* = Q_4n + (Q_4n - Q_2n) / (2^p - 1),

and the error of the value at resolution m is |Q_m - Q*| / |Q*|. Isoparametric P2 elements
converge in energy at order 4 in h for smooth solutions (the compliance is an energy); the
observed p says whether the meshes are in that regime. When the two differences are at
rounding level the sequence has converged and the error is the last difference.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from flexure_sim.engine.hinges.fe.solves import Case, solve


def richardson(q1: float, q2: float, q4: float) -> tuple[float, float]:
    """(observed order p, extrapolated limit) of values at resolutions n, 2n, 4n."""
    d1, d2 = q1 - q2, q2 - q4
    tiny = 1e-12 * max(abs(q4), 1e-300)
    if abs(d2) <= tiny or abs(d1) <= tiny or d1 * d2 < 0 or abs(d1) <= abs(d2):
        return float("nan"), q4  # at rounding level, or not converging monotonically
    p = float(np.log2(d1 / d2))
    return p, q4 - d2 / (2.0 ** p - 1.0)


def study(case: Case, levels: tuple[int, int, int] | None = None) -> dict:
    """
    Run the case at three resolutions (default n/2, n, 2n for the case's n) and extrapolate.

    Returns {"levels", "stiffness": (3 levels, 3) diagonal of K^, "peak": (3, 3) peak stresses,
    "order": per quantity, "limit": extrapolated, "error": relative error at the case's own
    resolution} for the diagonal stiffnesses (Ko, Kx, Ky) and the three peak stresses.
    """
    n = case.n
    levels = levels or (max(n // 2, 2), n, 2 * n)
    if levels[1] != 2 * levels[0] or levels[2] != 2 * levels[1]:
        raise ValueError(f"levels: expected n, 2n, 4n, got {levels}")
    results = [solve(replace(case, n=m)) for m in levels]
    stiff = np.array([np.diag(np.linalg.inv(r.compliance)) for r in results])
    peak = np.array([r.peak for r in results])
    out = {"levels": list(levels), "stiffness": stiff, "peak": peak,
           "seconds": [r.seconds for r in results]}
    for name, values in (("stiffness", stiff), ("peak", peak)):
        order, limits = zip(*(richardson(*values[:, j]) for j in range(3)))
        at = levels.index(n) if n in levels else 2
        limit = np.array(limits)
        error = np.abs(values[at] - limit) / np.abs(limit)
        # Without an order, bound the error by the last change as well.
        error = np.where(np.isnan(order), error + np.abs(values[2] - values[1]) / np.abs(limit),
                         error)
        out[f"{name}_order"] = np.array(order)
        out[f"{name}_limit"] = np.array(limit)
        out[f"{name}_error"] = error
    return out
