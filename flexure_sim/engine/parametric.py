"""The mechanism's hinge forces as a function of its coordinates *and* its design parameters,
in arithmetic that accepts hyper-dual numbers (``hyperdual.py``).

The engine's force paths (``assembly.py``, ``kernels.py``) take floats only. Sensitivities
need the forces with derivative parts flowing from a parameter of the mechanism file (a
notch thickness h, a hinge position, a body mass) through the stiffness formulas
(``stiffness.notch_stiffness`` / ``cantilever_stiffness``, called unchanged), the hinge
positions, the relative displacement r(z) (eq. 2.81 with the poses of eq. 6.1) and the
quadratic laws (twistor 4.7, twist 3.4). ``forces`` is that chain written with NumPy
operations only, so the same code runs on floats and on ``HyperDual`` arrays:

    r = (alpha, p),  alpha = th_B + phi_b - th_A - phi_a,
    p = R(th_A + phi_a)^T (P_B + R(th_B) c_b - P_A - R(th_A) c_a),
    c = (xi, x1, x2) (twistor, 2.132-2.135) or (tau, t1, t2) (twist, 2.106-2.108),
    total_r = dc/dr^T (W c + C dc/dr r_dot)       (W = 4K, C = 4B twistor; K, B twist),
    Q = -dr/dz^T total_r,   wrench on B = -(total_0, R(alpha)^T total_{1,2})  (3.53, 4.35).

It is the quadratic-law path of ``kernels.quadratic_forces`` written for generic
arithmetic; a test checks that both agree to rounding and that its derivative parts equal
the engine's exact Jacobians.

``Parameters`` names any numeric key of the mechanism file by its path
(``stiffness_models.notch.h``, ``hinges.a.a.at.0``, ``bodies.body4.mass``) and builds the
``Design`` -- stiffness, damping, hinge frames, masses -- with chosen keys replaced by
(hyper-dual) values.
"""
from __future__ import annotations

import copy
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Optional

import numpy as np

from . import hyperdual as hd
from .config import ConfigError, mechanism_from_dict, resolve_mechanism_path
from .mechanism import Mechanism
from .stiffness import cantilever_stiffness, notch_stiffness
from .yaml_files import read_yaml

_MODELS = {
    "notch": (notch_stiffness, ("D", "h", "t", "E", "nu")),
    "cantilever": (cantilever_stiffness, ("length", "thickness", "width", "E", "nu")),
}
_LISTS_BY_NAME = ("bodies", "hinges")


class ParameterError(ValueError):
    """A parameter path does not name a numeric key the analyses can vary (names it)."""


@dataclass
class Design:
    """Per-hinge and per-body numbers, floats or HyperDual (n hinges, N = 3 n_bodies).

    K, B (n, 3, 3): stiffness and damping in the hinge frame; ca, cb (n, 2), phia, phib
    (n,): frame a on body A and frame b on body B; mass (N,): diagonal mass matrix;
    geometry: per hinge the stiffness model's numbers (dict, with ``model``)."""

    K: Any
    B: Any
    ca: Any
    cb: Any
    phia: Any
    phib: Any
    mass: Any
    geometry: list


class Parameters:
    """A mechanism file's numbers, addressable by path; ``design(overrides)`` rebuilds the
    parametric parts with some of them replaced (hyper-dual or float)."""

    def __init__(self, name_or_path: str | Path):
        path = resolve_mechanism_path(name_or_path)
        self.path = path
        self.data = read_yaml(path, ConfigError)
        self.mechanism: Mechanism = mechanism_from_dict(self.data, source=str(path))
        self.twistor = twistor_flags(self.mechanism)

    # ---------------------------------------------------------------- paths
    def _node(self, keys: list[str], data=None):
        node = self.data if data is None else data
        for depth, key in enumerate(keys):
            where = ".".join(keys[:depth + 1])
            if isinstance(node, str) and depth >= 1 and keys[depth - 1] == "stiffness":
                # hinges.<h>.stiffness.<key> of a hinge that names a model: that model's number
                node = (self.data.get("stiffness_models") or {}).get(node, node)
            if isinstance(node, dict):
                if key not in node:
                    raise ParameterError(f"{where}: no such key in the mechanism file")
                node = node[key]
            elif isinstance(node, list):
                if keys[depth - 1] in _LISTS_BY_NAME and depth == 1:
                    found = [x for x in node if isinstance(x, dict) and x.get("name") == key]
                    if not found:
                        raise ParameterError(f"{where}: no entry named {key!r}")
                    node = found[0]
                else:
                    try:
                        node = node[int(key)]
                    except (ValueError, IndexError):
                        raise ParameterError(f"{where}: not an index of a list of {len(node)}") from None
            else:
                raise ParameterError(f"{where}: {'.'.join(keys[:depth])} is a number, not a mapping or list")
        return node

    def value(self, path: str) -> float:
        """The number at ``path`` (ParameterError if missing or not numeric)."""
        node = self._node(path.split("."))
        try:
            if isinstance(node, bool):
                raise TypeError
            return float(node)
        except (TypeError, ValueError):
            raise ParameterError(f"{path}: not a number ({node!r})") from None

    def check(self, path: str) -> float:
        """Value of a parameter the analyses can vary; ParameterError naming the problem if not."""
        v = self.value(path)
        keys = path.split(".")
        head = keys[0]
        if head == "stiffness_models" and len(keys) >= 3:
            return v
        if head == "bodies" and len(keys) == 3 and keys[2] in ("mass", "inertia"):
            return v
        if head == "hinges" and len(keys) >= 3 and keys[2] in ("a", "b", "stiffness", "damping"):
            return v
        if head == "defaults" and keys[1:] == ["damping", "t_char"]:
            return v
        raise ParameterError(f"{path}: not a design parameter the analyses vary (stiffness models, "
                             "hinge frames/stiffness/damping, body mass and inertia)")

    # --------------------------------------------------------------- design
    def design(self, overrides: Optional[dict[str, Any]] = None) -> Design:
        """The Design with the numbers at the given paths replaced (values may be HyperDual)."""
        overrides = dict(overrides or {})
        for path in overrides:
            self.check(path)
        data = copy.deepcopy(self.data)
        for path in overrides:
            keys = path.split(".")
            if keys[0] == "hinges" and len(keys) >= 4 and keys[2] == "stiffness":
                # one hinge's own copy of a named model, so only that hinge changes
                entry = self._node(keys[:2], data)
                if isinstance(entry.get("stiffness"), str):
                    entry["stiffness"] = copy.deepcopy(data["stiffness_models"][entry["stiffness"]])
        for path, val in overrides.items():
            keys = path.split(".")
            parent = self._node(keys[:-1], data)
            parent[keys[-1] if isinstance(parent, dict) else int(keys[-1])] = val
        mech = self.mechanism
        models = data.get("stiffness_models", {}) or {}
        defaults = data.get("defaults", {}) or {}
        Ks, Bs, geometry, ca, cb, phia, phib = [], [], [], [], [], [], []
        for hinge, spec in zip(mech.hinges, data["hinges"]):
            sspec = spec.get("stiffness")
            sspec = models[sspec] if isinstance(sspec, str) else sspec
            K = _stiffness(sspec) if sspec is not None else hinge.K
            damping = spec.get("damping", defaults.get("damping"))
            B = K * _num(damping["t_char"]) if "t_char" in damping else np.array(_num(damping["B"]), dtype=object)
            Ks.append(K)
            Bs.append(B)
            geometry.append(dict(sspec or {}))
            a_at, b_at = _num(spec["a"]["at"]), _num(spec["b"]["at"])
            ca.append(a_at[:2])
            cb.append(b_at[:2])
            phia.append(a_at[2] if len(a_at) > 2 else 0.0)
            phib.append(b_at[2] if len(b_at) > 2 else 0.0)
        mass = []
        for body in data["bodies"]:
            mass += [_num(body["mass"]), _num(body["mass"]), _num(body["inertia"])]
        return Design(_array(Ks), _array(Bs), _array(ca), _array(cb), _array(phia), _array(phib),
                      _array(mass), geometry)


def _num(x):
    """A number of the YAML document (PyYAML reads 69.0e9 as a string) or a HyperDual."""
    if isinstance(x, hd.HyperDual):
        return x
    if isinstance(x, (list, tuple)):
        return [_num(v) for v in x]
    return float(x)


def _stiffness(spec: dict):
    model = spec["model"]
    if model in _MODELS:
        fn, names = _MODELS[model]
        return fn(*(_num(spec[n]) for n in names))
    if "K" in spec:
        return np.array(_num(spec["K"]), dtype=object)
    kc = _num(spec.get("Kc", [0.0, 0.0]))
    kt = _num(spec["Kt"])
    return np.array([[spec["Ko"], kc[0], kc[1]], [kc[0], kt[0], 0.0], [kc[1], 0.0, kt[1]]], dtype=object)


def _array(values):
    """A float array, or a HyperDual array if any entry is hyper-dual."""
    arr = np.asarray(values, dtype=object) if not isinstance(values, np.ndarray) else values
    if any(isinstance(v, hd.HyperDual) for v in np.asarray(arr, dtype=object).ravel()):
        return hd.from_objects(arr)
    return np.asarray(arr, dtype=float)


# -------------------------------------------------------------------- the forces

@dataclass
class Forces:
    """Q (..., N) generalized forces; r (..., n, 3) deflections; wrench (..., n, 3) on body B
    in frame b (moment, fx, fy); energy (..., n)."""

    Q: Any
    r: Any
    wrench: Any
    energy: Any


def forces(design: Design, twistor: np.ndarray, ia: np.ndarray, ib: np.ndarray, z, v) -> Forces:
    """Hinge forces at coordinates z and velocities v (length N in the last axis; float or
    HyperDual), as in the module docstring."""
    A, B = 3 * ia, 3 * ib
    xA, yA, thA = z[..., A], z[..., A + 1], z[..., A + 2]
    xB, yB, thB = z[..., B], z[..., B + 1], z[..., B + 2]
    ca, cb = design.ca, design.cb
    cosA, sinA, cosB, sinB = np.cos(thA), np.sin(thA), np.cos(thB), np.sin(thB)
    beta = thA + design.phia
    ce, se = np.cos(beta), np.sin(beta)
    wa1 = cosA * ca[..., 0] - sinA * ca[..., 1]
    wa2 = sinA * ca[..., 0] + cosA * ca[..., 1]
    wb1 = cosB * cb[..., 0] - sinB * cb[..., 1]
    wb2 = sinB * cb[..., 0] + cosB * cb[..., 1]
    d1 = xB + wb1 - xA - wa1
    d2 = yB + wb2 - yA - wa2
    p1 = ce * d1 + se * d2
    p2 = -se * d1 + ce * d2
    alpha = thB + design.phib - beta
    # dr/dzz rows (alpha, p1, p2) over (xA, yA, thA, xB, yB, thB), as Assembly.relative.
    ta1, ta2 = -ce * wa2 + se * wa1, se * wa2 + ce * wa1
    tb1, tb2 = -ce * wb2 + se * wb1, se * wb2 + ce * wb1
    dr = ((0.0, 0.0, -1.0, 0.0, 0.0, 1.0),
          (-ce, -se, p2 - ta1, ce, se, tb1),
          (se, -ce, -p1 - ta2, -se, ce, tb2))
    vv = [v[..., A], v[..., A + 1], v[..., A + 2], v[..., B], v[..., B + 1], v[..., B + 2]]
    rdot = [sum(dr[i][j] * vv[j] for j in range(6)) for i in range(3)]
    c, dc = _law_coordinates(twistor, alpha, p1, p2)
    scale = np.where(twistor, 4.0, 1.0)[:, None, None]
    W, C = design.K * scale, design.B * scale
    cdot = [sum(dc[k][i] * rdot[i] for i in range(3)) for k in range(3)]
    e = [sum(W[..., k, m] * c[m] for m in range(3)) + sum(C[..., k, m] * cdot[m] for m in range(3))
         for k in range(3)]
    total = [sum(dc[k][i] * e[k] for k in range(3)) for i in range(3)]
    energy = 0.5 * sum(c[k] * W[..., k, m] * c[m] for k in range(3) for m in range(3))
    q_local = [-sum(dr[i][j] * total[i] for i in range(3)) for j in range(6)]
    Q = _scatter(q_local, ia, ib, z.shape[-1])
    ca_, sa_ = np.cos(alpha), np.sin(alpha)
    wrench = _stack([-total[0], -(ca_ * total[1] + sa_ * total[2]), -(-sa_ * total[1] + ca_ * total[2])])
    r = _stack([alpha, p1, p2])
    return Forces(Q, r, wrench, energy)


def _law_coordinates(twistor, alpha, p1, p2):
    """c (3 components) and dc/dr (3x3) for twistor (xi, x1, x2) or twist (tau, t1, t2)."""
    sg, xi = np.cos(0.5 * alpha), np.sin(0.5 * alpha)
    x1 = 0.5 * (sg * p1 + xi * p2)
    x2 = 0.5 * (-xi * p1 + sg * p2)
    if np.all(twistor):
        return (xi, x1, x2), ((0.5 * sg, 0.0, 0.0), (0.5 * x2, 0.5 * sg, 0.5 * xi), (-0.5 * x1, -0.5 * xi, 0.5 * sg))
    f, f1 = _half_cot(alpha)
    t = (alpha, f * p1 + 0.5 * alpha * p2, f * p2 - 0.5 * alpha * p1)
    dt = ((1.0, 0.0, 0.0), (f1 * p1 + 0.5 * p2, f, 0.5 * alpha), (f1 * p2 - 0.5 * p1, -0.5 * alpha, f))
    pick = (lambda a, b: _where(twistor, a, b))
    return (tuple(pick(a, b) for a, b in zip((xi, x1, x2), t)),
            tuple(tuple(pick(a, b) for a, b in zip(ra, rb)) for ra, rb in zip(
                ((0.5 * sg, 0.0, 0.0), (0.5 * x2, 0.5 * sg, 0.5 * xi), (-0.5 * x1, -0.5 * xi, 0.5 * sg)), dt)))


def _half_cot(alpha):
    """f = (a/2) cot(a/2) and f' (series below |a| = 1e-2, as hinge_laws)."""
    a_real = hd.real(alpha)
    small = np.abs(a_real) < 1e-2
    safe = _where(small, 1.0, alpha)
    s, co = np.sin(0.5 * safe), np.cos(0.5 * safe)
    f_exact = 0.5 * safe * co / s
    f1_exact = 0.5 * co / s - 0.25 * safe / (s * s)
    a2 = alpha * alpha
    f_series = 1.0 - a2 / 12.0 - a2 * a2 / 720.0 - a2 * a2 * a2 / 30240.0
    f1_series = -alpha * (1.0 / 6.0 + a2 / 180.0 + a2 * a2 / 5040.0)
    return _where(small, f_series, f_exact), _where(small, f1_series, f1_exact)


def _where(cond, x, y):
    if not isinstance(x, hd.HyperDual) and not isinstance(y, hd.HyperDual):
        return np.where(cond, x, y)
    xs, ys = hd.parts_of(x), hd.parts_of(y)
    shape = np.broadcast_shapes(np.shape(cond), xs[0].shape, ys[0].shape)
    return hd.HyperDual(*(np.where(cond, np.broadcast_to(a, shape), np.broadcast_to(b, shape))
                          for a, b in zip(xs, ys)))


def _stack(items):
    if any(isinstance(x, hd.HyperDual) for x in items):
        return hd.stack(items)
    return np.stack(np.broadcast_arrays(*items), axis=-1)


def _scatter(q_local, ia, ib, N):
    """Sum the per-hinge six forces into the N generalized forces (a linear map, applied
    part by part for HyperDuals)."""
    n = len(ia)
    S = np.zeros((6, n, N))
    for j in range(3):
        S[j, np.arange(n), 3 * ia + j] += 1.0
        S[3 + j, np.arange(n), 3 * ib + j] += 1.0

    def lin(parts):
        shape = np.broadcast_shapes(*(np.shape(p) for p in parts))
        return sum(np.broadcast_to(parts[j], shape) @ S[j] for j in range(6))

    if any(isinstance(q, hd.HyperDual) for q in q_local):
        lifted = [q if isinstance(q, hd.HyperDual) else hd.HyperDual(q) for q in q_local]
        return hd.HyperDual(*(lin([getattr(q, name) for q in lifted]) for name in "abcd"))
    return lin(q_local)


def design_of(mechanism: Mechanism) -> Design:
    """The Design of a built mechanism (floats: its K, B, frames and masses as loaded)."""
    hinges = mechanism.hinges
    mass = np.array([[b.mass, b.mass, b.inertia] for b in mechanism.bodies], dtype=float).ravel()
    return Design(
        np.array([h.K for h in hinges], dtype=float), np.array([h.B for h in hinges], dtype=float),
        np.array([h.a.position for h in hinges], dtype=float), np.array([h.b.position for h in hinges], dtype=float),
        np.array([h.a.angle for h in hinges], dtype=float), np.array([h.b.angle for h in hinges], dtype=float),
        mass, [{"model": h.stiffness_source} for h in hinges])


def twistor_flags(mechanism: Mechanism) -> np.ndarray:
    """Per hinge: True for the twistor law, False for the twist law (ParameterError for
    laws this chain does not cover)."""
    for h in mechanism.hinges:
        if not hasattr(h.law, "metric"):
            raise ParameterError(f"hinge {h.name!r}: the analyses support the quadratic laws "
                                 "(twistor, twist), not fitted polynomial laws")
    return np.array([h.law.coordinates == "twistor" for h in mechanism.hinges])


def hinge_indices(mechanism: Mechanism) -> tuple[np.ndarray, np.ndarray]:
    """Body indices (A, B) of every hinge."""
    return (np.array([mechanism.body_index(h.a.body) for h in mechanism.hinges]),
            np.array([mechanism.body_index(h.b.body) for h in mechanism.hinges]))
