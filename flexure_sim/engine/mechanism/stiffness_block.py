"""
Hinge stiffness in a mechanism file, checked: a ``stiffness`` specification and K's validity.

Part of the loader (`config.mechanism_from_dict`); messages name the file, key and problem.
Models: ``notch`` (D, h, t, E, nu), ``cantilever`` (length, thickness, width, E, nu), both
with an optional ``material`` (a name of engine/hinges/materials.yaml: E, nu and the strengths
the model does not give itself) and the strengths of the stress and fatigue analyses: yield
``sigma_y``, ultimate ``sigma_u`` (Pa), fatigue ``sigma_e`` (Pa, fully reversed) at
``fatigue_cycles``; ``fe`` (a hinge shape and its geometry solved by finite elements,
fe_block.py; also with ``material`` and the strengths); and ``matrix`` (K: 3x3, or Ko, Kt:
[kx, ky] and optional Kc: [cx, cy]); the formulas are in `stiffness`.
"""
from __future__ import annotations

from typing import Any, Callable, Mapping

import numpy as np

from flexure_sim.engine.hinges import materials
from flexure_sim.engine.hinges import stiffness as stiffness_models
from flexure_sim.engine.kinematics import hyperdual as hd
from flexure_sim.engine.mechanism.fe_block import fe_stiffness
from flexure_sim.engine.mechanism.values import Ctx as _Ctx
from flexure_sim.engine.mechanism.values import mapping as _mapping
from flexure_sim.engine.mechanism.values import no_unknown as _no_unknown
from flexure_sim.engine.mechanism.values import number as _number
from flexure_sim.engine.mechanism.values import require as _require
from flexure_sim.engine.mechanism.values import shown as _shown
from flexure_sim.engine.mechanism.values import vector as _vector
from flexure_sim.engine.hinges.stress import StressGeometry

_STIFFNESS_KEYS: Mapping[str, tuple[Callable[..., np.ndarray], tuple[str, ...]]] = (
    stiffness_models.MODELS)


def stiffness(ctx: _Ctx, key: str, spec: Any) -> tuple[np.ndarray, str, Any]:
    """
    (K, model name, the hinge's StressGeometry or None) of a stiffness specification.

    The stress geometry holds the same numbers the stiffness formula was given.
    """
    spec = raw = _mapping(ctx, key, spec)
    model = _require(ctx, key, spec, "model")
    if not isinstance(model, str):
        raise ctx.fail(f"{key}.model",
                       f"expected a model name (notch, cantilever, fe, matrix), got "
                       f"{_shown(model)}")
    # A named material supplies E, nu and the strengths the spec does not give itself
    # (engine/hinges/materials.py); the strengths are for the stress and fatigue analyses.
    spec = materials.resolve(spec, lambda k, problem: ctx.fail(f"{key}.{k}", problem))
    strengths = _strengths(ctx, key, spec)
    sigma_y = strengths.pop("sigma_y")
    spec = {k: v for k, v in spec.items() if k not in (*materials.STRENGTH_KEYS, "material")}
    if model in _STIFFNESS_KEYS:
        fn, names = _STIFFNESS_KEYS[model]
        _no_unknown(ctx, key, spec, {"model", *names})
        args = [
            _number(ctx, f"{key}.{n}", _require(ctx, key, spec, n), positive=n != "nu")
            for n in names
        ]
        if model in ("notch", "cantilever"):
            nu = args[-1]
            if not 0 <= nu < 0.5:
                raise ctx.fail(f"{key}.nu", f"Poisson's ratio must be in [0, 0.5), got {nu}")
        with np.errstate(all="ignore"):  # overflow gives inf, checked below
            K = hd.asarray(fn(*(a if isinstance(a, hd.HyperDual) else np.float64(a)
                                for a in args)))
        if not np.all(np.isfinite(hd.real(K))):
            values = ", ".join(f"{n}={float(hd.real(a)):g}" for n, a in zip(names, args))
            raise ctx.fail(key, f"the {model} formula gives a non-finite stiffness for these "
                           f"values ({values}): check the units")
        return K, model, StressGeometry.of(model, dict(zip(names, args)), sigma_y, **strengths)
    if model == "fe":
        K, geometry = fe_stiffness(ctx, key, spec, sigma_y, strengths)
        return K, "fe", geometry
    if model == "matrix":
        given = [k for k in ("material", *materials.STRENGTH_KEYS) if k in raw]
        if given:  # would be dropped silently: no geometry, no stress
            raise ctx.fail(f"{key}.{given[0]}", "a matrix stiffness has no geometry to compute "
                           "stress from (material and strengths are for notch, cantilever and "
                           "fe models)")
        _no_unknown(ctx, key, spec, {"model", "K", "Ko", "Kt", "Kc"})
        if "K" in spec:
            rows = spec["K"]
            if not isinstance(rows, list) or len(rows) != 3:
                raise ctx.fail(f"{key}.K", "expected a 3x3 matrix (three rows of three numbers)")
            K = hd.asarray([_vector(ctx, f"{key}.K[{i}]", r, (3,)) for i, r in enumerate(rows)])
        else:
            Ko = _number(ctx, f"{key}.Ko", _require(ctx, key, spec, "Ko"))
            kt = _vector(ctx, f"{key}.Kt", _require(ctx, key, spec, "Kt"), (2,))
            kc = _vector(ctx, f"{key}.Kc", spec.get("Kc", [0.0, 0.0]), (2,))
            K = hd.asarray([[Ko, kc[0], kc[1]], [kc[0], kt[0], 0.0], [kc[1], 0.0, kt[1]]])
        return K, "matrix", None
    raise ctx.fail(f"{key}.model",
                   f"unknown stiffness model {_shown(model)} (notch, cantilever, fe, matrix)")


def _strengths(ctx: _Ctx, key: str, spec: dict) -> dict:
    """
    Return the checked strengths of a resolved spec as StressGeometry fields (and its key).

    Positive numbers; ``sigma_e`` needs the ``fatigue_cycles`` it holds for, and ``sigma_u``
    may not be below ``sigma_y``.
    """
    out = materials.strengths(
        spec, lambda k, v: _number(ctx, f"{key}.{k}", v, positive=True))
    if out["sigma_e"] is not None and out["cycles"] is None:
        raise ctx.fail(f"{key}.sigma_e", "give fatigue_cycles too: the number of cycles the "
                       "fatigue strength holds for")
    if out["cycles"] is not None and out["sigma_e"] is None:
        raise ctx.fail(f"{key}.fatigue_cycles", "a cycle count without its fatigue strength "
                       "sigma_e")
    if None not in (out["sigma_u"], out["sigma_y"]) and out["sigma_u"] < out["sigma_y"]:
        raise ctx.fail(f"{key}.sigma_u", f"the ultimate strength {out['sigma_u']:g} Pa is "
                       f"below the yield strength {out['sigma_y']:g} Pa")
    out["key"] = key
    return out


def check_spd(ctx: _Ctx, key: str, M: np.ndarray, what: str) -> None:
    """Refuse a ``what`` matrix at ``key`` that is not finite, symmetric, positive definite."""
    M = hd.real(M)  # a design's derivative parts are not checked (values.py)
    if not np.all(np.isfinite(M)):
        raise ctx.fail(key, f"{what} matrix is not finite: {M.tolist()}")
    if not np.allclose(M, M.T, rtol=1e-12, atol=0.0):
        raise ctx.fail(key, f"{what} matrix is not symmetric: {M.tolist()}")
    with np.errstate(all="ignore"):
        eig = np.linalg.eigvalsh(M)
    if not np.all(eig > 0):  # also false for NaN eigenvalues (entries near the double range)
        raise ctx.fail(key, f"{what} matrix is not positive definite: {M.tolist()}")
