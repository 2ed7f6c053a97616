"""
Damping in a mechanism file, checked: each hinge's ``damping`` and the mechanism's ``damping:``.

Part of the loader (`config.mechanism_from_dict`); messages name the file, key and problem.

The mechanism's block (optional; the formulas and how C acts on the driven and fixed
coordinates are in `damping_models`)::

    damping: {model: rayleigh, alpha: 10.0, beta: 1.0e-6}      # C = alpha M + beta K
    damping: {model: rayleigh, ratios: [[0.01, 300.0], [0.02, 3000.0]]}
                                     # [zeta, f (Hz)] twice: alpha, beta from Chopra eq. 11.4.4
    damping: {model: modal, ratio: 0.01}                        # every mode
    damping: {model: modal, ratios: [0.01, 0.015], ratio: 0.02} # the first modes, then the rest
"""
from __future__ import annotations

from typing import Any

import numpy as np

from flexure_sim.engine.kinematics import hyperdual as hd
from flexure_sim.engine.mechanism.values import Ctx as _Ctx
from flexure_sim.engine.mechanism.values import mapping as _mapping
from flexure_sim.engine.mechanism.values import no_unknown as _no_unknown
from flexure_sim.engine.mechanism.values import number as _number
from flexure_sim.engine.mechanism.values import require as _require
from flexure_sim.engine.mechanism.values import shown as _shown
from flexure_sim.engine.mechanism.values import vector as _vector
from flexure_sim.engine.mechanism.damping_models import MODELS, DampingSpec, rayleigh_coefficients


def hinge_damping(ctx: _Ctx, key: str, spec: Any, K: np.ndarray) -> np.ndarray:
    """Return a hinge's damping matrix B: ``{t_char: s}`` (B = t_char K) or ``{B: 3x3}``."""
    if spec is None:
        raise ctx.fail(
            key, "missing damping (give {t_char: seconds} or {B: 3x3}, here or in defaults)"
        )
    spec = _mapping(ctx, key, spec)
    _no_unknown(ctx, key, spec, {"t_char", "B"})
    if "t_char" in spec:
        with np.errstate(all="ignore"):
            B = K * _number(ctx, f"{key}.t_char", spec["t_char"], nonnegative=True)
        if not np.all(np.isfinite(hd.real(B))):
            raise ctx.fail(f"{key}.t_char",
                           "t_char times the stiffness is not finite: check the units")
        return B
    if "B" in spec:
        rows = spec["B"]
        if not isinstance(rows, list) or len(rows) != 3:
            raise ctx.fail(f"{key}.B", "expected a 3x3 matrix")
        B = hd.asarray([_vector(ctx, f"{key}.B[{i}]", r, (3,)) for i, r in enumerate(rows)])
        with np.errstate(all="ignore"):
            real = hd.real(B)
            psd = np.allclose(real, real.T) and np.all(np.linalg.eigvalsh(real) >= 0)
        if not psd:
            raise ctx.fail(f"{key}.B", "damping matrix must be symmetric positive semi-definite")
        return B
    raise ctx.fail(key, "give t_char or B")


def mechanism_damping(ctx: _Ctx, raw: Any, n_modes: int) -> DampingSpec:
    """
    Read the ``damping:`` block of a mechanism with ``n_modes`` free coordinates.

    Ratios must not be negative; Rayleigh's alpha and beta (given, or from two target ratios)
    must not be negative either (C would then not be positive semi-definite).
    """
    spec = _mapping(ctx, "damping", raw)
    model = _require(ctx, "damping", spec, "model")
    if model not in MODELS:
        raise ctx.fail("damping.model",
                       f"unknown damping model {_shown(model)} ({', '.join(MODELS)})")
    if model == "rayleigh":
        _no_unknown(ctx, "damping", spec, {"model", "alpha", "beta", "ratios"})
        if "ratios" in spec:
            if "alpha" in spec or "beta" in spec:
                raise ctx.fail("damping", "give either alpha and beta or ratios, not both")
            return _rayleigh_from_ratios(ctx, spec["ratios"])
        if "alpha" not in spec and "beta" not in spec:
            raise ctx.fail("damping", "give alpha (1/s) and beta (s), or ratios: "
                           "[[zeta1, f1_hz], [zeta2, f2_hz]]")
        alpha, beta = (_number(ctx, f"damping.{k}", spec.get(k, 0.0), nonnegative=True)
                       for k in ("alpha", "beta"))
        return DampingSpec("rayleigh", alpha=alpha, beta=beta)
    _no_unknown(ctx, "damping", spec, {"model", "ratio", "ratios"})
    ratio = (_number(ctx, "damping.ratio", spec["ratio"], nonnegative=True)
             if "ratio" in spec else None)
    raw_ratios = spec.get("ratios", [])
    if not isinstance(raw_ratios, list):
        raise ctx.fail("damping.ratios", f"expected a list of damping ratios, got "
                       f"{_shown(raw_ratios)}")
    ratios = tuple(_number(ctx, f"damping.ratios[{i}]", r, nonnegative=True)
                   for i, r in enumerate(raw_ratios))
    if not ratios and ratio is None:
        raise ctx.fail("damping", "give ratio (every mode) or ratios (one per mode)")
    if len(ratios) > n_modes or (len(ratios) < n_modes and ratio is None):
        raise ctx.fail("damping.ratios",
                       f"{len(ratios)} ratios for a mechanism with {n_modes} modes (its free "
                       "coordinates): give one per mode, or fewer and ratio for the rest")
    return DampingSpec("modal", ratios=ratios, ratio=ratio)


def _rayleigh_from_ratios(ctx: _Ctx, raw: Any) -> DampingSpec:
    """Alpha and beta from ``ratios: [[zeta1, f1_hz], [zeta2, f2_hz]]`` (Chopra eq. 11.4.4)."""
    if not isinstance(raw, list) or len(raw) != 2:
        raise ctx.fail("damping.ratios", f"expected two [zeta, frequency_hz] pairs, got "
                       f"{_shown(raw)}")
    pairs = [_vector(ctx, f"damping.ratios[{i}]", p, (2,)) for i, p in enumerate(raw)]
    for i, (zeta, f) in enumerate(pairs):
        _number(ctx, f"damping.ratios[{i}][0]", zeta, nonnegative=True)
        _number(ctx, f"damping.ratios[{i}][1]", f, positive=True)
    (z1, f1), (z2, f2) = pairs
    if f1 == f2:
        raise ctx.fail("damping.ratios", f"the two frequencies must differ, got {f1:g} Hz twice")
    alpha, beta = rayleigh_coefficients(z1, 2 * np.pi * f1, z2, 2 * np.pi * f2)
    (z1, f1), (z2, f2) = sorted(pairs, key=lambda p: p[1])
    # With alpha, beta >= 0, zeta = alpha/(2 omega) + beta omega/2 at f2 > f1 lies between
    # zeta1 f1/f2 (beta = 0) and zeta1 f2/f1 (alpha = 0); at either end the solve may leave
    # a rounding error of either sign in the coefficient that is zero.
    low, high = z1 * f1 / f2, z1 * f2 / f1
    tol = 1e-12 * max(z1, z2)
    if not low - tol <= z2 <= high + tol:
        which = "beta" if z2 < low else "alpha"
        need = beta if z2 < low else alpha
        raise ctx.fail("damping.ratios", f"zeta {z1:g} at {f1:g} Hz and {z2:g} at {f2:g} Hz "
                       f"need a negative {which} ({which} = {need:.6g} "
                       f"{'s' if which == 'beta' else '1/s'}), which would add energy: with "
                       f"zeta {z1:g} at {f1:g} Hz, Rayleigh damping (zeta = alpha/(2 omega) + "
                       f"beta omega/2, alpha, beta >= 0) gives {low:.6g} to {high:.6g} at "
                       f"{f2:g} Hz")
    return DampingSpec("rayleigh", alpha=max(alpha, 0.0), beta=max(beta, 0.0))
